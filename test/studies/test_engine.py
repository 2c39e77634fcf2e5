# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Study logic (worm_gear_sim.studies): cases, metrics, engines (serial, threads, Dask)."""

import math

import numpy as np
import pytest

from worm_gear_sim import studies as S
from worm_gear_sim.config.usable import Config
from worm_gear_sim.dynamics.derived import derive
from worm_gear_sim.dynamics.layout import P_CGKG_LIN
from worm_gear_sim.dynamics.model import pack_parameters
from worm_gear_sim.dynamics.spectrum import dominant_frequency
from worm_gear_sim.schema.validation import ConfigError

SHORT = 0.03     # s: the move ends at 0.02 s, 10 ms of ringing is enough for the checks


@pytest.fixture(scope='module')
def base():
    return Config().replace({'input.end_time': SHORT})


def test_module_overrides_geometry_keeps_ratio_and_lead_angle(base):
    d2 = derive(base)
    for m in (1.0, 3.0, 5.0):
        cfg = base.replace(S.module_overrides(base, m, 'geometry'))
        d = derive(cfg)
        assert d.ratio == pytest.approx(d2.ratio, rel=1e-12)
        assert d.lead_angle == pytest.approx(d2.lead_angle, rel=1e-12)
        assert cfg.geometry.gear_pitch_radius == pytest.approx(0.056 * m / 2)
        assert cfg.geometry.lead == pytest.approx(math.pi * m * 1e-3, rel=1e-7)   # pi M
        assert cfg.geometry.module == m
        p, p2 = pack_parameters(cfg), pack_parameters(base)       # tooth stiffness ~ M
        assert p[P_CGKG_LIN] == pytest.approx(p2[P_CGKG_LIN] * m / 2)
        assert d.J_g == pytest.approx(d2.J_g * (m / 2) ** 5, rel=1e-12)
        assert d.K_w == d2.K_w and d.J_4 == d2.J_4          # shafts, flywheel unchanged


def test_module_overrides_stiffness_only_and_identity_at_m2(base):
    ov = S.module_overrides(base, 4.0, 'stiffness')
    assert set(ov) == {'geometry.module'}
    assert base.replace(S.module_overrides(base, 2.0, 'geometry')) == base
    with pytest.raises(ValueError):
        S.module_overrides(base, 2.0, 'volume')
    with pytest.raises(ValueError):
        S.module_overrides(base, 0.0)


@pytest.mark.parametrize('name', S.PAPER_STUDIES)
def test_paper_studies_are_valid(base, name):
    st = S.paper_study(name, base)
    assert st.cases and st.title and st.x_label
    for c in st.cases:
        S.case_config(base, c.overrides)     # every case is a valid config (at its step)
        assert math.isfinite(c.x)
    assert len({(c.series, c.label) for c in st.cases}) == len(st.cases)


def test_unknown_study(base):
    with pytest.raises(ValueError, match='unknown study'):
        S.paper_study('gravity', base)


def test_parse_values():
    assert S.parse_values('0,1, 2') == ['0', '1', '2']
    assert [float(v) for v in S.parse_values(range_spec='0:1:3')] == [0.0, 0.5, 1.0]
    assert [float(v) for v in S.parse_values(range_spec='1:100:3', log=True)] == \
        pytest.approx([1.0, 10.0, 100.0])
    for kw in ({'text': '1,,2'}, {'range_spec': '0:1'}, {'range_spec': 'a:b:3'},
               {'range_spec': '0:1:0'}, {'range_spec': '0:1:3', 'log': True}, {}):
        with pytest.raises(ValueError):
            S.parse_values(**kw)


def test_param_study_numeric_and_categorical():
    st = S.param_study(['mesh.phase_offset'], [0.0, 1.0, 2.0])
    assert [c.x for c in st.cases] == [0.0, 1.0, 2.0] and not st.categorical
    st = S.param_study(['friction.model'], ['stribeck', 'off'])
    assert st.categorical and [c.x for c in st.cases] == [0.0, 1.0]
    assert st.cases[1].overrides == {'friction.model': 'off'}


def test_frequency_estimators_on_a_known_signal():
    t = np.arange(0, 0.4, 1e-5)
    y = 3e-4 * np.sin(2 * np.pi * 94.5 * t + 0.3) + 1e-6 * np.sin(2 * np.pi * 1561 * t) + 0.002
    assert dominant_frequency(t, y) == pytest.approx(94.5, rel=2e-3)
    assert S.zero_crossing_frequency(t, y) == pytest.approx(94.5, rel=2e-3)
    assert math.isnan(dominant_frequency(t[:8], y[:8]))
    assert math.isnan(S.zero_crossing_frequency(t, np.ones_like(t)))


def test_run_case_metrics(base):
    r = S.run_case(base, {'input.end_time': 0.07})
    # default drive: the antenna rings at ~94.5 Hz with ~3.3e-4 rad after the 18-step move
    assert r['amp4'] == pytest.approx(3.33e-4, rel=0.02)
    assert r['freq4_hz'] == pytest.approx(94.5, rel=0.02)
    assert 0 < r['amp2'] < r['amp4']
    assert r['eq4'] == pytest.approx(0.1130973355 / 56, rel=1e-6)
    assert r['t_move'] == pytest.approx(0.02) and r['t_end'] == pytest.approx(0.07)
    assert r['half_pp4'] <= r['amp4'] * (1 + 1e-12)
    assert 0 < r['kernel_s'] <= r['case_s']
    # the amplitude step from the modes (>= 20 steps per period of the 8.6 kHz worm mode):
    # the default 4 us gives 29, kept; a 10 us base (11.6) is divided by 2
    assert r['steps'] == round(0.07 / 4e-6)
    r10 = S.run_case(base, {'input.end_time': 0.07, 'integrator.time_step': 1e-5})
    assert r10['steps'] == round(0.07 / 5e-6)
    assert r10['amp4'] == pytest.approx(r['amp4'], rel=0.01)


def _fake_trajectory(t, theta1, theta):
    from worm_gear_sim.dynamics.trajectory import Trajectory
    n = t.size
    return Trajectory(t=t, theta1=theta1, theta1_dot=np.zeros(n), theta=theta,
                      omega=np.zeros((n, 3)), alpha=np.zeros((n, 3)), aux=np.zeros((n, 8)),
                      output_per_input=1 / 56)


def test_oscillation_metrics_window_and_definitions():
    t = np.arange(0, 0.2, 1e-4)
    theta1 = np.where(t > 0.0, 1.0, 0.0)                  # a step just after t = 0
    eq = np.array([1.0, 1 / 56, 1 / 56])
    theta = np.tile(eq, (t.size, 1))
    theta[:, 2] += 2e-3 * np.sin(2 * np.pi * 50 * t) + 5e-4    # ringing about an offset
    theta[0] = 0.0                                        # at rest before the step
    m = S.oscillation_metrics(_fake_trajectory(t, theta1, theta), 0.0, eq)
    assert m['amp2'] == 0.0                               # t = 0 is not after the move
    assert m['amp4'] == pytest.approx(2.5e-3, rel=1e-3)   # max |theta4 - eq|
    assert m['half_pp4'] == pytest.approx(2e-3, rel=1e-3)
    assert m['mean4'] == pytest.approx(eq[2] + 5e-4, rel=1e-3)
    assert m['freq4_hz'] == pytest.approx(50.0, rel=1e-3)
    assert m['max_err2'] == 0.0 and m['max_err4'] == pytest.approx(2.5e-3, rel=1e-3)
    with pytest.raises(ValueError, match='before the move'):
        S.oscillation_metrics(_fake_trajectory(t, theta1, theta), 0.5, eq)


def test_run_case_too_short(base):
    with pytest.raises(ValueError, match='before the move'):
        S.run_case(base, {'input.end_time': 0.01})


def test_experiment_cases_cover_models_and_conventions():
    cases = S.experiment_cases()
    assert {(m, c) for m, c, _ in cases} == {(m, c) for m in ('nonlinear', 'linear')
                                             for c in ('kinematic', 'paper')}
    lin = [ov for m, _, ov in cases if m == 'linear'][0]
    assert lin['mesh.stiffness_model'] == 'linear' and lin['friction.model'] == 'constant'
    assert lin['friction.constant_coefficient'] == 0.145


@pytest.mark.parametrize('serial', [True, False])
def test_run_cases_rejects_bad_override_in_worker_config(base, serial):
    """On threads as serially: the failed case's own ConfigError naming the key."""
    cases = [S.Case('x', 's', 0.0, 'ok', {}), S.Case('x', 's', 1.0, 'bad', {'mesh.nope': 1.0})]
    with pytest.raises(ConfigError, match='mesh.nope'):
        S.run_cases(base, cases, serial=serial, workers=2)


@pytest.mark.parametrize('engine', S.ENGINES)
def test_serial_threads_and_local_cluster_give_identical_numbers(base, engine):
    cases = [S.Case('t', 'tooth', m, f'x{m}', {'mesh.gear_tooth_stiffness_multiplier': m})
             for m in (0.5, 1.0, 2.0)]
    cases.append(S.Case('t', 'fly', 0.0, 'off', {'geometry.flywheel_enabled': False}))
    serial = S.run_cases(base, cases, serial=True)
    parallel = S.run_cases(base, cases, workers=2, engine=engine)
    assert [r['label'] for r in parallel] == [c.label for c in cases]     # case order kept
    for a, b in zip(serial, parallel):
        for k in S.METRIC_COLUMNS:
            va, vb = a[k], b[k]
            assert (va == vb) or (math.isnan(va) and math.isnan(vb)), k
    assert serial[0]['amp4'] != serial[2]['amp4']       # the cases differ
