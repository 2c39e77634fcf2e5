# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A parameter set is proven usable before it is accepted (API, config
files, CLI), and absurd states or commands give a clear ValueError, never a NaN state."""

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from processes import cli_in_process

from worm_gear_sim.config.files import load_config
from worm_gear_sim.config.usable import Config, check_usable, config_from_mapping
from worm_gear_sim.dynamics.modal import modes
from worm_gear_sim.dynamics.simulation import Simulator, simulate
from worm_gear_sim.dynamics.usability import OMEGA_DT_MAX, SPRING_RATIO_MIN
from worm_gear_sim.schema.sections import ANGLE_LIMIT
from worm_gear_sim.schema.validation import ConfigError

REPO = Path(__file__).resolve().parents[2]

# In-range values (each inside its declared range) that made the model fail before: the
# reason each fails is asserted, not only that it does.
UNUSABLE = [
    # Eq. 16: c_w k_w varies by e^(360 b) = e^180 over a mesh cycle; the calibrated mean stays,
    # the minimum collapses: the mesh no longer holds the gear (was LinAlgError: Singular)
    ({'mesh.worm_fit_b': 0.5}, 'mesh.worm_fit_b', ['e^(360 |b|)', 'singular stiffness']),
    ({'mesh.gear_fit_b': -0.4}, 'mesh.gear_fit_b', ['e^(360 |b|)', 'singular stiffness']),
    # the calibration of Eq. 16 overflows (was "math domain error")
    ({'mesh.contact_mapping': 'sawtooth', 'mesh.worm_fit_b': 0.9745}, 'mesh.worm_fit_b',
     ['overflow']),
    ({'mesh.worm_fit_b': 0.9745}, 'mesh.worm_fit_b', ['singular stiffness']),
    # tooth stiffness <= 1e-9 N/m (was LinAlgError)
    ({'mesh.stiffness_model': 'linear', 'mesh.gear_tooth_stiffness_linear': 1e-9},
     'mesh.gear_tooth_stiffness_linear', ['mesh l_w^2 k_Y', 'singular stiffness']),
    ({'mesh.worm_tooth_stiffness_multiplier': 1e-12}, 'mesh.worm_tooth_stiffness_multiplier',
     ['singular stiffness']),
    # a hair-thin worm shaft: the motor no longer holds the drive (was LinAlgError)
    ({'shafts.worm_shaft_radius': 1.9e-8}, 'shafts.worm_shaft_radius',
     ['worm shaft K_w', 'singular stiffness']),
    # a 0.4 nm worm: 52 MHz mode, omega dt = 3300 (was a Newton failure mid-run)
    # (the set-valued friction law integrates these trials; with the tanh law Newton cannot
    # follow the unresolved mode and the diagnosis names it)
    ({'geometry.worm_length': 4e-10, 'friction.direction': 'regularized'},
     'geometry.worm_length', ['not resolved', 'worm']),
    ({'geometry.gear_pitch_radius': 1.6e-4, 'friction.direction': 'regularized'},
     'geometry.gear_pitch_radius', ['not resolved']),
]


@pytest.mark.parametrize('overrides, key, words', UNUSABLE,
                         ids=[next(iter(o)) + '=' + str(list(o.values())[-1])
                              for o, _, _ in UNUSABLE])
def test_unusable_in_range_sets_raise_config_error_naming_the_key(overrides, key, words):
    meta = Config.metadata()
    for k, v in overrides.items():            # really inside the declared range
        m = meta[k]
        if m['lo'] is not None and isinstance(v, float):
            assert m['lo'] <= v <= m['hi'], k
    with pytest.raises(ConfigError) as exc:
        Config().replace(overrides)
    assert exc.value.key == key
    msg = str(exc.value)
    assert msg.startswith(f'{key} = '), msg
    for w in words:
        assert w in msg, (w, msg)
    # the same set from a file (the node's and the CLI's path) and at the Simulator
    nested = {}
    for k, v in overrides.items():
        sec, name = k.split('.')
        nested.setdefault(sec, {})[name] = v
    with pytest.raises(ConfigError) as exc2:
        config_from_mapping(nested)
    assert exc2.value.key == key
    cfg = config_from_mapping(nested, usable=False)     # built unchecked: the API refuses it
    with pytest.raises(ConfigError):
        Simulator(cfg)
    with pytest.raises(ConfigError):
        Simulator(Config()).reconfigure(cfg)


def test_rule_thresholds_sit_where_the_numerics_break():
    """Just inside each rule the model works (finite modes and a move); the rules are not
    wider than the failures they prevent."""
    # mesh: a weak but representable mesh (factor 1e-6 above the singular limit) still runs
    base = Config()
    weak = base.replace({'mesh.worm_tooth_stiffness_multiplier': 1e-4,
                         'mesh.gear_tooth_stiffness_multiplier': 1e-4})
    assert np.all(np.isfinite(modes(weak).undamped_hz))
    tr = simulate(weak, t_end=0.005)
    assert np.all(np.isfinite(tr.theta))
    # resolution: the worm mode just below omega dt = pi integrates the 18-step move
    f_worm = modes(base).undamped_hz[-1]
    scale = (2 * math.pi * f_worm * 1e-5 / (0.9 * OMEGA_DT_MAX)) ** 2   # J_w ~ worm_length
    short = base.replace({'geometry.worm_length': 0.015 * scale})
    w_dt = 2 * math.pi * modes(short).undamped_hz[-1] * 1e-5
    assert 0.8 * OMEGA_DT_MAX < w_dt < OMEGA_DT_MAX
    tr = simulate(short, t_end=0.03)
    assert np.all(np.isfinite(tr.theta))
    assert SPRING_RATIO_MIN == 1e-9


def test_changed_keys_are_named_when_no_rule_applies():
    # check_usable names the keys given as changed, first the suspects among them
    cfg = Config().replace({'mesh.worm_fit_b': 0.001})
    check_usable(cfg)                       # usable: no error, remembered
    with pytest.raises(ConfigError) as exc:
        Config().replace({'load.output_torque': 1.0, 'mesh.worm_fit_b': 0.5})
    assert exc.value.key == 'mesh.worm_fit_b'
    assert 'load.output_torque' not in str(exc.value)


def test_defaults_and_shipped_config_are_usable():
    check_usable(Config())
    check_usable(load_config())


def test_config_file_with_an_unusable_value(tmp_path):
    f = tmp_path / 'p.yaml'
    f.write_text('worm_gear_sim:\n  ros__parameters:\n    mesh:\n      worm_fit_b: 0.5\n')
    with pytest.raises(ConfigError) as exc:
        load_config(f)
    assert exc.value.key == 'mesh.worm_fit_b'


def _cli(*args):
    return cli_in_process(*args)      # the whole entry point, in this process


@pytest.mark.parametrize('setting, key', [
    ('mesh.worm_fit_b=0.5', 'mesh.worm_fit_b'),
    ('mesh.worm_fit_b=0.98', 'mesh.worm_fit_b'),
    ('mesh.worm_tooth_stiffness_multiplier=1e-12', 'mesh.worm_tooth_stiffness_multiplier'),
])
def test_cli_names_the_key_in_one_line_exit_2(setting, key, tmp_path):
    r = _cli('simulate', '--set', setting, '--end-time', '0.01', '-o', str(tmp_path / 'x.csv'),
             '--no-plot')
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith('worm-gear-sim: error: ' + key), lines[0]
    assert 'Traceback' not in r.stderr and 'Singular matrix' not in r.stderr


# ---- absurd initial states and commands ----------------------------------------------------
@pytest.mark.parametrize('theta1', [1e20, -1e20, float('nan'), float('inf'), 2 * ANGLE_LIMIT])
def test_absurd_initial_command_is_a_value_error(theta1):
    with pytest.raises(ValueError, match='theta1'):
        Simulator(Config(), theta1=theta1)
    sim = Simulator(Config())
    before = sim.state
    with pytest.raises(ValueError, match='theta1'):
        sim.reset(theta1)
    after = sim.state
    assert after.t == before.t and np.array_equal(after.theta, before.theta)


@pytest.mark.parametrize('kwargs, word', [
    (dict(theta=[1e20, 0, 0]), 'theta'),
    (dict(theta=[0, float('nan'), 0]), 'theta'),
    (dict(theta=[0, 0]), '3 numbers'),
    (dict(theta='abc'), '3 numbers'),
    (dict(omega=[1e300, 0, 0]), 'omega'),
    (dict(omega=[0, 0, float('inf')]), 'omega'),
    (dict(t0=float('nan')), 't0'),
    (dict(t0=1e300), 't0'),
])
def test_absurd_initial_state_is_a_value_error(kwargs, word):
    sim = Simulator(Config())
    with pytest.raises(ValueError, match=word):
        sim.reset(0.0, **kwargs)
    assert np.all(np.isfinite(sim.state.theta)) and sim.t == 0.0


def test_large_but_legal_angle_stays_finite():
    sim = Simulator(Config(), theta1=1e6)
    sim.advance_to(0.002, 1e6 + 0.01)
    s = sim.state
    assert np.all(np.isfinite(s.theta)) and np.all(np.isfinite(s.omega))
    assert abs(s.theta[0] - (1e6 + 0.01)) < 1e-2


@pytest.mark.parametrize('args, word', [
    ((float('nan'), 0.0), 't_target'),
    ((float('inf'), 0.0), 't_target'),
    ((1e300, 0.0), 't_target'),
    ((0.001, 1e20), 'theta1'),
    ((0.001, float('nan')), 'theta1'),
    ((0.001, 'x'), 'theta1'),
])
def test_advance_to_rejects_non_finite_or_huge_inputs(args, word):
    sim = Simulator(Config())
    with pytest.raises(ValueError, match=word):
        sim.advance_to(*args)
    assert sim.t == 0.0 and np.all(np.isfinite(sim.state.theta))
    sim.advance_to(0.001, 0.001)            # still usable afterwards
    assert sim.t == pytest.approx(0.001)


def test_advance_to_huge_span_is_refused_up_front():
    """advance_to(1e4) at the default dt = 4 us is 2.5e9 steps: a clear error naming the
    limit and how to raise it, instantly, before any allocation or integration."""
    sim = Simulator(Config())
    with pytest.raises(ValueError) as exc:
        sim.advance_to(1e4, 0.0)
    msg = str(exc.value)
    assert 'max_steps' in msg and f'{1e4 / sim.dt:.2g} steps' in msg and 'iter_run' in msg
    assert sim.t == 0.0
    # the limit is the caller's to raise; spans are integrated in bounded chunks
    n = sim.advance_to(200 * sim.dt, 0.0, max_steps=200)
    assert n == 200
    with pytest.raises(ValueError, match='max_steps'):
        sim.advance_to(1.0, 0.0, max_steps=200)


@pytest.mark.parametrize('overrides, words', [
    # accepted (the 2 ms trial passes) but the paper's move stops mid-run: the error names
    # the parameter behind it
    # (the tanh law: its band is what the first case narrows, and the set-valued law
    # integrates the unresolved gear of the second)
    ({'friction.regularization_velocity': 1e-10, 'friction.direction': 'regularized'},
     ['friction.regularization_velocity', 'near step']),
])
def test_integration_failure_names_the_likely_cause(overrides, words):
    from worm_gear_sim.dynamics.stepping import SimulationError
    cfg = Config().replace(overrides)
    with pytest.raises(SimulationError) as exc:
        simulate(cfg, t_end=0.03)
    msg = str(exc.value)
    assert 'integration stopped at t =' in msg and 'likely cause' in msg
    for w in words:
        assert w in msg, (w, msg)


# ---- the node (as a user hits it: -p at start-up, the parameter service) -------------------
@pytest.mark.parametrize('param, key', [
    ('mesh.worm_fit_b:=0.5', 'mesh.worm_fit_b'),
    ('mesh.worm_tooth_stiffness_multiplier:=1e-12', 'mesh.worm_tooth_stiffness_multiplier'),
])
def test_node_start_up_with_an_unusable_value_is_one_line_exit_2(param, key,
                                                                  ros_subprocess_env):
    pytest.importorskip('rclpy')
    proc = subprocess.run([sys.executable, '-m', 'worm_gear_sim.ros', '--ros-args',
                           '-p', param], cwd=REPO, env=ros_subprocess_env,
                          capture_output=True, text=True, timeout=120)
    text = (proc.stdout + proc.stderr).strip()
    assert proc.returncode == 2, text
    assert 'Traceback' not in text and 'Singular matrix' not in text, text
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert len(lines) == 1 and key in lines[0], text


def test_node_rejects_an_unusable_set_and_keeps_running(ros_harness):
    """Over the parameter service: rejected with the reason naming the key, the state
    untouched, and the next commands still integrate (it used to end the node)."""
    from rclpy.parameter import Parameter
    h = ros_harness(sim_time=False)
    assert h.command(0.0)
    assert h.spin_until(lambda: h.node.counters['ticks'] >= 5)
    res = h.set_parameters([Parameter('mesh.worm_fit_b', value=0.5)])
    assert not res[0].successful and 'mesh.worm_fit_b' in res[0].reason, res
    assert h.node.get_parameter('mesh.worm_fit_b').value == pytest.approx(0.000656069)
    for k in range(1, 6):
        assert h.command(0.001 * k)
    ticks = h.node.counters['ticks']
    assert h.spin_until(lambda: h.node.counters['ticks'] >= ticks + 5)
    assert h.node.config.mesh.worm_fit_b == pytest.approx(0.000656069)


def test_modes_and_resync_refuse_absurd_inputs():
    with pytest.raises(ValueError, match='theta1'):
        modes(Config(), theta1=1e20)          # the mesh phase is meaningless there
    with pytest.raises(ValueError, match='sliding_rate'):
        modes(Config(), sliding_rate=float('nan'))
    sim = Simulator(Config())
    with pytest.raises(ValueError, match='resync'):
        sim.resync(float('nan'))
    assert sim.t == 0.0


def test_cli_modes_at_an_absurd_angle_is_one_line():
    r = _cli('modes', '--theta1', '1e20')
    assert r.returncode == 2 and 'theta1' in r.stderr and 'Traceback' not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr


@pytest.mark.parametrize('overrides, key', [
    # the gear mode at omega dt ~ 4 (at 10 us): the trial passes, the paper's move did not
    ({'geometry.gear_width': 6e-7, 'friction.direction': 'regularized',
      'integrator.time_step': 1e-5}, 'geometry.gear_width'),
    # the worm on a 1e-12 m shaft of a 1e-9 m module: its mode at ~GHz; accepted before and
    # then 25 893 simulation errors live
    ({'shafts.worm_shaft_length': 1e-12, 'geometry.module': 1e-9},
     'shafts.worm_shaft_length'),
])
def test_a_set_whose_highest_mode_the_step_cannot_resolve_is_rejected(overrides, key):
    """Fewer than 2 steps per period of the highest linearised mode: rejected when the set
    is built, the reason names the mode (Hz), the step, omega dt and the keys."""
    with pytest.raises(ConfigError) as exc:
        Config().replace(overrides)
    msg = str(exc.value)
    for w in ('not resolved', 'Hz', 'integrator.time_step', 'omega dt'):
        assert w in msg, (w, msg)
    assert key in exc.value.keys or key in msg, msg


def test_node_rejects_a_set_it_cannot_integrate_while_a_stream_runs(ros_harness):
    """The set that was accepted and then failed 25 893 times live (a worm shaft of 1e-12 m
    on a 1e-9 m module: its highest mode at GHz) is rejected by the parameter service with
    the mode and the step named, at once; the stream goes on, no simulation error, and a
    valid set is accepted after it."""
    import time

    from rclpy.parameter import Parameter
    h = ros_harness(sim_time=False)
    assert h.command(0.0)
    assert h.spin_until(lambda: h.node.counters['ticks'] >= 5)
    t0 = time.monotonic()
    res = h.set_parameters([Parameter('shafts.worm_shaft_length', value=1e-12),
                            Parameter('geometry.module', value=1e-9)])
    took = time.monotonic() - t0
    assert not res[0].successful and 'not resolved' in res[0].reason, res
    assert 'Hz' in res[0].reason and 'integrator.time_step' in res[0].reason
    assert took < 5.0, took
    for k in range(1, 6):
        assert h.command(0.001 * k)
    ticks = h.node.counters['ticks']
    assert h.spin_until(lambda: h.node.counters['ticks'] >= ticks + 5)
    assert h.node.rt.counters['simulation_errors'] == 0
    res = h.set_parameters([Parameter('friction.mu_kinetic', value=0.05)])
    assert res[0].successful
