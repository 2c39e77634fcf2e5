# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Trajectory compensation offline (worm_gear_sim.joint_trajectory.compensate): the controller's
spline reading of waypoints (known polynomials reproduced exactly), the compensated positions equal
reference + feedforward_series of the same samples, the controller's own interpolation of
the dense output follows the compensated path, the paper's move rings >= 50x less, bad
trajectories are one-line errors."""

from __future__ import annotations

import re

import numpy as np
import pytest

from worm_gear_sim import Config
from worm_gear_sim.joint_trajectory.compensate import compensate_trajectory, jtc_sample
from worm_gear_sim.realtime import feedforward_series


def _poly(c, t):
    p = np.polynomial.Polynomial(c)
    return p(t), p.deriv()(t), p.deriv(2)(t)


@pytest.mark.parametrize('degree, use_v, use_a', [(1, False, False), (3, True, False),
                                                   (5, True, True)])
def test_the_spline_rule_reproduces_polynomials_of_its_degree(degree, use_v, use_a):
    rng = np.random.default_rng(degree)
    c = rng.normal(size=degree + 1)
    tw = np.array([0.0, 0.3, 0.7, 1.0])
    # one polynomial per segment would do; one over all of them must be reproduced too
    p, v, a = _poly(c, tw)
    t = np.linspace(0.0, 1.0, 1001)
    want = _poly(c, t)
    got = jtc_sample(tw, p, t, v if use_v else None, a if use_a else None)
    if degree == 1:
        np.testing.assert_allclose(got[0], want[0], atol=1e-12)
        np.testing.assert_allclose(got[1][1:-1], want[1][1:-1], atol=1e-12)
    else:
        for k in range(3):
            np.testing.assert_allclose(got[k][1:-1], want[k][1:-1], atol=1e-9)
    held = jtc_sample(tw, p, np.array([2.0]), v if use_v else None, a if use_a else None)
    assert held[0][0] == pytest.approx(p[-1]) and held[1][0] == 0.0


def _paper_move_waypoints(cfg):
    """The paper's 18-step move (trapezoidal velocity, 20 ms, 4 ms ramps, from 0.01 s) as
    5 sparse waypoints with positions and velocities: the cubic rule reproduces each
    quadratic piece exactly (the acceleration jumps at the knots, so a quintic with one
    acceleration per waypoint could not)."""
    from worm_gear_sim.dynamics.profiles import TrapezoidalProfile
    prof = TrapezoidalProfile(cfg.input.target_angle, 0.02, 0.004, 0.01)
    knots = np.array([0.01, 0.014, 0.026, 0.03, 0.05])
    rate = prof.amplitude / (0.02 - 0.004)
    return knots, prof.theta1(knots), np.array([0.0, rate, rate, 0.0, 0.0]), None, prof


def test_the_compensated_trajectory_is_the_offline_twin_and_cuts_the_ringing_50x():
    cfg = Config()
    tw, p, v, a, prof = _paper_move_waypoints(cfg)
    ct = compensate_trajectory(cfg, tw, p, v, a, start_position=0.0, settle=0.25)
    # positions = reference + feedforward_series of the same dense samples, exactly
    np.testing.assert_array_equal(ct.position, ct.reference + feedforward_series(
        cfg, ct.t, ct.reference))
    # the spline reading of the sparse waypoints is the paper's move
    np.testing.assert_allclose(ct.reference, prof.theta1(ct.t), atol=1e-12)
    after = ct.t > 0.035
    ring_raw = np.ptp(ct.raw_error[after])
    ring_comp = np.ptp(ct.predicted_error[after])
    assert ring_raw > 50 * ring_comp, (ring_raw, ring_comp)


def test_the_controllers_interpolation_of_the_output_keeps_the_compensation():
    """The dense output read back with the controller's own rules (cubic from positions and
    velocities, quintic with accelerations too) at 20 kHz: it stays within 1 % of the
    move's amplitude of the straight-line path the model predicts for (measured 0.48 % /
    0.45 %; 0.63 % for the quintic before dense_rates limited the accelerations), and
    driving the model with it, the antenna rings >= 50x less than with the raw trajectory
    (measured 473x / 352x; the straight-line path 263x)."""
    from worm_gear_sim import SampledProfile, simulate
    cfg = Config()
    tw, p, v, a, _ = _paper_move_waypoints(cfg)
    ct = compensate_trajectory(cfg, tw, p, v, a, start_position=0.0, settle=0.25)
    t = np.arange(0.0, ct.t[-1], 5e-5)
    ref, _, _ = jtc_sample(tw, p, t, v, a, start_position=0.0)
    line = np.interp(t, ct.t, ct.position)
    after = t > 0.035
    raw = np.ptp(ct.raw_error[ct.t > 0.035])
    for vel, acc in ((ct.velocity, None), (ct.velocity, ct.acceleration)):
        cmd, _, _ = jtc_sample(ct.t, ct.position, t, vel, acc)
        assert np.max(np.abs(cmd - line)) <= 0.01 * np.ptp(ct.position)
        tr = simulate(cfg, SampledProfile(t, cmd), t_end=float(t[-1]), record_every=25,
                      theta1_initial=float(cmd[0]))
        err = np.interp(t, tr.t, tr.theta[:, 2]) - ref * tr.output_per_input
        assert raw > 50 * np.ptp(err[after]), (raw, np.ptp(err[after]))


@pytest.mark.parametrize('times, pos, vel, words', [
    ([], [], None, 'no waypoints'), ([0.0, 0.1], [0.0], None, '1 positions for 2'),
    ([0.0, 0.1, 0.1], [0, 1, 2], None, 'does not increase'),
    ([0.0, 0.1], [0.0, float('nan')], None, 'positions[1] is not finite'),
    ([0.0, 0.1], [0.0, 1.0], [0.0], '1 velocities'), ([-0.1, 0.1], [0, 1], None, '>= 0'),
    ([0.0, 4000.0], [0, 1], None, 'longer than')])
def test_bad_trajectories_are_one_line_errors(times, pos, vel, words):
    with pytest.raises(ValueError, match=re.escape(words)) as exc:
        jtc_sample(times, pos, [0.05], vel)
    assert '\n' not in str(exc.value)
