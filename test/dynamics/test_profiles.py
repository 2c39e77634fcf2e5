# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Input profiles: rates are the derivatives of the angles, end points, CSV input."""

import numpy as np
import pytest

from worm_gear_sim import (
    Config,
    ConfigError,
    RampProfile,
    SampledProfile,
    SCurveProfile,
    StepProfile,
    TrapezoidalProfile,
    make_profile,
)

A, T, TA, T0 = 0.11309733552923255, 0.02, 0.004, 0.003


@pytest.mark.parametrize('prof', [
    RampProfile(A, T, T0), TrapezoidalProfile(A, T, TA, T0), SCurveProfile(A, T, TA, T0),
    SampledProfile([0.0, 0.01, 0.02, 0.05], [0.0, 0.02, -0.01, 0.03]),
], ids=['ramp', 'trapezoidal', 's_curve', 'sampled'])
def test_rate_is_the_derivative_and_endpoints(prof):
    t = np.linspace(0.0, 0.06, 60001)
    th, td = prof.theta1(t), prof.theta1_dot(t)
    fd = np.gradient(th, t)
    ok = np.isclose(td, fd, rtol=0, atol=1e-3 * max(1.0, np.abs(td).max()))
    assert np.sum(~ok) <= 8          # only the samples straddling a kink of the rate
    assert th[0] == pytest.approx(float(prof.theta1(np.array([0.0]))[0]))
    assert prof.final_value == pytest.approx(th[-1])


@pytest.mark.parametrize('cls', [TrapezoidalProfile, SCurveProfile])
def test_move_profiles_reach_the_target_at_rest(cls):
    prof = cls(A, T, TA, T0)
    assert prof.theta1(np.array([T0]))[0] == 0.0
    assert prof.theta1(np.array([T0 + T]))[0] == pytest.approx(A, abs=1e-15)
    assert prof.theta1_dot(np.array([T0, T0 + T, T0 + T + 1.0])) == pytest.approx(0.0)
    assert np.all(np.diff(prof.theta1(np.linspace(0, 0.05, 5001))) >= -1e-16)   # monotone
    # peak rate: area of the velocity profile equals the move
    assert prof.peak_rate == pytest.approx(A / (T - TA))


def test_s_curve_has_continuous_acceleration():
    prof = SCurveProfile(A, T, TA, T0)
    t = np.linspace(0, 0.03, 300001)
    acc = np.gradient(prof.theta1_dot(t), t)
    assert np.abs(np.diff(acc)).max() < 0.01 * np.abs(acc).max()
    trap = TrapezoidalProfile(A, T, TA, T0)
    acc_t = np.gradient(trap.theta1_dot(t), t)
    assert np.abs(np.diff(acc_t)).max() > 0.3 * np.abs(acc_t).max()   # the trapezoid jumps


def test_step_profile():
    prof = StepProfile(0.1, 0.01)
    assert list(prof.theta1(np.array([0.0, 0.01, 0.01 + 1e-9]))) == [0.0, 0.0, 0.1]
    assert StepProfile(0.1).theta1(np.array([0.0, 1e-5]))[1] == 0.1


def test_sampled_hold_and_csv(tmp_path):
    hold = SampledProfile([0.0, 1.0, 2.0], [0.0, 1.0, 3.0], interpolation='hold')
    assert list(hold.theta1(np.array([-1.0, 0.5, 1.0, 1.5, 9.0]))) == [0, 0, 1, 1, 3]
    f = tmp_path / 'cmd.csv'
    f.write_text('# radar slew\nt,theta1\n0.0,0.0\n0.01,0.02\n0.02,0.02\n')
    cfg = Config().replace({'input.profile': 'csv', 'input.csv_path': str(f)})
    prof = make_profile(cfg.input)
    assert prof.theta1(np.array([0.005]))[0] == pytest.approx(0.01)
    assert prof.theta1_dot(np.array([0.005]))[0] == pytest.approx(2.0)


@pytest.mark.parametrize('content, words', [
    ('t,theta1\n0.0,0.0\n0.0,0.1\n', 'increase'),
    ('t,theta1\n0.0,0.0\n0.01,nan\n', 'not a finite angle'),
    ('t,theta1\n0.0,0.0\n0.01,inf\n', 'finite'),
    ('0.0\n0.01\n', 'no header'),
    ('t,theta1\nzero,one\n', 'not a finite time'),
    ('t,theta1\n0.0,0.0\n0.01,\n', 'empty'),
])
def test_bad_csv_is_a_clear_error(tmp_path, content, words):
    f = tmp_path / 'bad.csv'
    f.write_text(content)
    with pytest.raises(ConfigError) as exc:
        SampledProfile.from_csv(f)
    assert exc.value.key == 'input.csv_path' and words in str(exc.value)
    with pytest.raises(ConfigError, match='not found'):
        SampledProfile.from_csv(tmp_path / 'missing.csv')
    with pytest.raises(ConfigError) as exc:
        Config().replace({'input.profile': 'csv'})
    assert exc.value.key == 'input.csv_path'


def test_motion_span_of_sampled_commands():
    from worm_gear_sim.dynamics.profiles import motion_span
    t = np.arange(8) * 0.5
    assert motion_span(t, np.zeros(8)) is None
    assert motion_span(t, [0, 0, 1, 2, 2, 2, 2, 2]) == (0.5, 1.5)
    assert motion_span(t, [0, 1, 0, 0, 0, 0, 0, 0]) == (0.0, 1.0)      # out and back
    assert motion_span(t, [0, 0, 0, 0, 0, 0, 0, 3]) == (3.0, 3.5)      # last sample moves
    assert motion_span(t, [0, 1e-9, 0, 0, 0, 5, 5, 5], tol=1e-6) == (2.0, 2.5)
