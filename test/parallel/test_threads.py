# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The batch API (worm_gear_sim.parallel.threads): N runs on threads equal N serial calls bit
for bit (computed in this run), and a bad item is named (index, key) and never gives a row."""

from __future__ import annotations

import numpy as np
import pytest

from worm_gear_sim.config.usable import Config, config_from_mapping
from worm_gear_sim.dynamics.load import SampledLoad
from worm_gear_sim.dynamics.model import DriveModel
from worm_gear_sim.dynamics.profiles import Profile, RampProfile, StepProfile
from worm_gear_sim.dynamics.simulation import simulate
from worm_gear_sim.dynamics.stepping import SimulationError
from worm_gear_sim.parallel import threads as B
from worm_gear_sim.schema.validation import ConfigError

T_END = 0.015          # s: 3750 steps at the default 4 us, the move under way

FIELDS = ('t', 'theta1', 'theta1_dot', 'theta', 'omega', 'alpha', 'aux')


@pytest.fixture(scope='module')
def base():
    return Config().replace({'input.end_time': T_END})


def overrides(i: int) -> dict:
    return {'mesh.phase_offset': 0.3 * i, 'friction.mu_kinetic': 0.05 + 0.01 * i}


def same(a, b) -> bool:
    """Bit for bit: every recorded array and the integrator's counters."""
    return all(np.array_equal(getattr(a, f), getattr(b, f)) for f in FIELDS) \
        and a.stats == b.stats


def test_parameter_sets_on_threads_equal_serial_calls(base):
    sets = [base.replace(overrides(i)) for i in range(4)]
    serial = [simulate(c, record_every=3) for c in sets]
    batch = B.simulate_batch([overrides(i) for i in range(4)], record_every=3, base=base,
                             workers=2)
    assert len(batch) == 4
    assert all(same(a, b) for a, b in zip(serial, batch))
    assert not np.array_equal(serial[0].theta, serial[1].theta)     # the sets differ


def test_commands_and_loads_per_item_equal_serial_calls(base):
    model = DriveModel(base)
    profiles = [StepProfile(1e-3, 1e-3), RampProfile(0.02, 0.01), RampProfile(-0.01, 0.005)]
    t_ends = [0.01, 0.012, 0.008]
    t = np.linspace(0.0, 0.02, 21)
    loads = [None, SampledLoad(t, 2.0 * np.sin(300.0 * t)), None]
    serial = [simulate(model, p, te, load=ld) for p, te, ld in zip(profiles, t_ends, loads)]
    batch = B.simulate_batch(model, profiles, np.array(t_ends), loads=loads, workers=3)
    assert all(same(a, b) for a, b in zip(serial, batch))
    assert [len(b.t) for b in batch] == [2501, 3001, 2001]


def test_map_batch_keeps_order_reports_progress_and_lets_bugs_through():
    seen = []
    out = B.map_batch(lambda x: x * x, range(7), workers=2,
                      on_result=lambda i, r: seen.append(i))
    assert out == [x * x for x in range(7)] and sorted(seen) == list(range(7))

    def buggy(x):
        if x == 3:
            raise TypeError('a bug, not a bad item')
        return x

    for w in (1, 2):
        with pytest.raises(TypeError, match='a bug'):
            B.map_batch(buggy, range(6), workers=w, errors='collect')
    with pytest.raises(ValueError, match='errors='):
        B.map_batch(abs, [1], errors='ignore')


def test_a_refused_batch_starts_no_new_item():
    """errors='raise': after the first failure only the items already running finish."""
    import threading
    go, started = threading.Event(), []

    def fn(x):
        started.append(x)
        if x == 0:
            raise ValueError('item 0 is bad')
        go.wait(timeout=5.0)           # held until the failure is seen
        return x

    with pytest.raises(B.BatchError, match='set 0: item 0 is bad'):
        B.map_batch(fn, range(40), workers=2, on_result=lambda i, r: go.set())
    assert len(started) <= 4, started


def test_map_like_serial_raises_the_failed_items_own_error():
    def fn(x):
        if x in (2, 5):
            raise ConfigError(f'k{x}', 'bad')
        return -x

    seen = []
    for w in (1, 2):
        with pytest.raises(ConfigError, match='k2: bad'):
            B.map_like_serial(fn, range(8), workers=w, on_result=lambda i, r: seen.append(r))
    assert all(isinstance(r, int) for r in seen)
    assert B.map_like_serial(fn, [0, 1, 3], workers=2) == [0, -1, -3]


BAD_KEY = 'friction.mu_kinetic'


def test_a_bad_override_refuses_the_batch_before_any_run(base, monkeypatch):
    ran = []
    monkeypatch.setattr(B, 'simulate', lambda *a, **k: ran.append(1))
    sets = [overrides(0), {BAD_KEY: -0.1}, overrides(2), {'mesh.nope': 1.0}]
    with pytest.raises(B.BatchError) as err:
        B.simulate_batch(sets, base=base, workers=2)
    assert err.value.indices == (1, 3)
    assert BAD_KEY in err.value.keys and 'mesh.nope' in err.value.keys
    assert f'set 1: {BAD_KEY}' in str(err.value) and 'set 3' in str(err.value)
    assert not ran


def test_an_unusable_set_is_named_and_the_others_run(base):
    # every field in range, the set as a whole not simulable (the tooth stiffness of
    # Eqs. 16-17 overflows): given as a Config that skipped the usable check
    nested = base.to_nested_dict()
    nested['mesh']['worm_fit_b'] = 0.5
    unusable = config_from_mapping(nested, usable=False)
    sets = [base.replace(overrides(0)), unusable, base.replace(overrides(2))]
    with pytest.raises(B.BatchError) as err:
        B.simulate_batch(sets, workers=2)
    assert err.value.indices == (1,) and 'mesh.worm_fit_b' in err.value.keys
    out = B.simulate_batch(sets, workers=2, errors='collect')
    assert isinstance(out[1], B.BatchFailure) and out[1].index == 1
    assert isinstance(out[1].error, ConfigError) and 'mesh.worm_fit_b' in out[1].keys
    assert same(out[0], simulate(sets[0])) and same(out[2], simulate(sets[2]))


class _NanAfter(Profile):
    """A command that becomes NaN after ``t_bad``: the integration stops there."""

    name = 'nan-after'

    def __init__(self, t_bad: float) -> None:
        self.t_bad = t_bad

    def theta1(self, t):
        t = np.asarray(t, float)
        return np.where(t < self.t_bad, 1e-3 * t, np.nan)

    def theta1_dot(self, t):
        return np.full_like(np.asarray(t, float), 1e-3)


def test_a_failed_run_is_named_never_returned_as_rows(base):
    profiles = [RampProfile(0.01, 0.01), _NanAfter(0.004), RampProfile(0.02, 0.01)]
    out = B.simulate_batch(base, profiles, 0.01, workers=2, errors='collect')
    assert isinstance(out[1], B.BatchFailure) and out[1].index == 1
    assert isinstance(out[1].error, SimulationError)
    assert same(out[0], simulate(base, profiles[0], 0.01))
    assert same(out[2], simulate(base, profiles[2], 0.01))
    with pytest.raises(B.BatchError, match='set 1: integration stopped') as err:
        B.simulate_batch(base, profiles, 0.01, workers=2)
    assert err.value.indices == (1,)


def test_batch_arguments_are_checked(base):
    with pytest.raises(ValueError, match='lengths differ: sets 2, t_end 3'):
        B.simulate_batch([base, base], t_end=[0.01, 0.01, 0.01])
    with pytest.raises(ValueError, match='needs base='):
        B.simulate_batch([overrides(0)])
    out = B.simulate_batch([overrides(0)], errors='collect')
    assert isinstance(out[0], B.BatchFailure) and 'base=' in str(out[0])
    with pytest.raises(B.BatchError, match=r'set 0: t_end = nan'):
        B.simulate_batch(base, t_end=[float('nan'), 0.01])
    with pytest.raises(ValueError, match='max_bytes'):
        B.simulate_batch([base] * 3, t_end=1.0, max_bytes=1e6)


def test_the_gust_study_on_threads_equals_serial():
    """``sweep gust`` (and ``play``) run their scenario runs on threads: the rows equal the
    serial ones."""
    from worm_gear_sim.studies.play_gust import gust_rows
    serial = gust_rows(Config(), (0.2,), seeds=(1,), workers=1)
    threaded = gust_rows(Config(), (0.2,), seeds=(1,), workers=2)
    assert serial == threaded and len(serial) == 2
    assert serial[0]['rms_err4'] != serial[1]['rms_err4']      # the series differ
