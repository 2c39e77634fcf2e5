# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Trajectories under hostile input, in the core (the hostile review's cases 1 and 2; the node's
side: test/ros/test_hostile_node.py): a far-future trajectory replaced before it starts does not
move the next start; sub-period waypoints give dense velocities and accelerations that
the controller's interpolation reads back without a jump beyond the dense points; the
compensated command never steps more than node.max_command_jump."""

from __future__ import annotations

import numpy as np
import pytest

from worm_gear_sim import Config
from worm_gear_sim.joint_trajectory.compensate import (
    MAX_START_AHEAD,
    JointTrajectoryData,
    TrajectoryCompensator,
    TrajectoryRejected,
    compensate_trajectory,
    jtc_sample,
)
from worm_gear_sim.joint_trajectory.rates import consistent_rates
from worm_gear_sim.joint_trajectory.timeline import CommandTimeline

J = 'worm_input_joint'
NOW = 1_795_000_000_000_000_000


def traj(times, pos, stamp_ns=0, vel=None):
    return JointTrajectoryData((J,), np.asarray(times, float),
                               np.asarray(pos, float).reshape(-1, 1),
                               None if vel is None else np.asarray(vel, float).reshape(-1, 1),
                               None, stamp_ns)


@pytest.fixture(scope='module')
def cfg():
    return Config()


def test_a_far_future_trajectory_replaced_before_its_start_does_not_move_the_next_start(cfg):
    """T1 (stamp 0) to 0.5 rad; T2 stamped 2^31-1 s starting at -0.5 (within the limit it
    is ahead of now only in this test's clock: the twin has no now); T3 (stamp 0) to 0.6
    rad: T3 starts from 0.5, where T1 left the drive, not from T2's -0.5."""
    comp = TrajectoryCompensator({J: cfg})
    comp.compensate(traj([0.1, 0.2], [0.5, 0.5]), now_ns=NOW)
    far = (2**31 - 1) * 10**9
    comp.compensate(traj([0.0, 0.1], [-0.5, -0.5], stamp_ns=far), now_ns=far - 10**9)
    now3 = NOW + 2 * 10**9
    out = comp.compensate(traj([0.1, 0.2], [0.6, 0.6]), now_ns=now3).axes[J]
    assert out.reference[0] == pytest.approx(0.5, abs=1e-12)
    # the compensated command moves no more between its points than the reference's
    # correction does at rest: no step at the start
    assert abs(out.position[0] - 0.5) < 1e-3
    assert np.abs(np.diff(out.position)).max() < 0.02


def test_a_stamp_beyond_the_limit_is_refused_as_future_stamp(cfg):
    comp = TrajectoryCompensator({J: cfg})
    ahead = int((MAX_START_AHEAD + 1) * 1e9)
    with pytest.raises(TrajectoryRejected) as exc:
        comp.compensate(traj([0.1], [0.1], stamp_ns=NOW + ahead), now_ns=NOW)
    assert exc.value.reason == 'future_stamp' and '3600 s ahead' in str(exc.value)
    # at the limit: accepted
    comp.compensate(traj([0.1], [0.1], stamp_ns=NOW + ahead - 2 * 10**9), now_ns=NOW)


def test_the_timeline_splices_at_the_stamp_and_drops_what_starts_later():
    tl = CommandTimeline()
    assert tl.position(5) is None
    tl.splice(0, np.array([0.0, 1.0]), np.array([0.0, 1.0]))
    tl.splice(10 * 10**9, np.array([0.0]), np.array([-5.0]))     # queued far ahead
    assert tl.position(500_000_000) == pytest.approx(0.5)
    assert tl.position(20 * 10**9) == -5.0
    tl.splice(2 * 10**9, np.array([0.0, 1.0]), np.array([1.0, 2.0]))   # starts earlier
    assert len(tl) == 2 and tl.position(20 * 10**9) == 2.0


@pytest.mark.parametrize('gap, step', [(1e-12, 0.1), (1e-4, 0.05), (3e-4, 0.3)])
def test_sub_period_waypoints_are_read_back_without_a_jump_beyond_the_dense_points(
        cfg, gap, step):
    """Positions-only waypoints ``gap`` apart (issue: 1e-12 s read back at 1.48e7 rad,
    100 us at 0.018 rad on a 0.05 rad move): read back with the controller's cubic and
    quintic rules at 50 kHz, the output strays from the straight line through its dense
    points by less than 0.6 of the largest dense step (the bound of dense_rates)."""
    ct = compensate_trajectory(cfg, [0.05, 0.05 + gap], [0.0, step], predict=False,
                               settle=0.05)
    t = np.arange(0.0, ct.t[-1], 2e-5)
    line = np.interp(t, ct.t, ct.position)
    big = np.abs(np.diff(ct.position)).max()
    for acc in (None, ct.acceleration):
        cmd, _, _ = jtc_sample(ct.t, ct.position, t, ct.velocity, acc)
        assert np.abs(cmd - line).max() < 0.6 * big
        assert cmd.max() <= ct.position.max() + 0.6 * big
    assert np.abs(ct.velocity).max() <= big / 1e-3 * (1 + 1e-12)


def test_consistent_rates_keep_a_smooth_paths_own_derivatives():
    dt = 1e-3
    t = np.arange(0.0, 0.2, dt)
    p = np.sin(2 * np.pi * 10 * t) * t            # starts at rest-ish, smooth
    w = 2 * np.pi * 10
    v = np.sin(w * t) + w * t * np.cos(w * t)
    a = 2 * w * np.cos(w * t) - w**2 * t * np.sin(w * t)
    v2, a2 = consistent_rates(p, v, a, dt)
    inner = slice(2, -2)
    np.testing.assert_allclose(v2[inner], v[inner], atol=1e-12 + 0.01 * np.abs(v).max())
    np.testing.assert_allclose(a2[inner], a[inner], atol=0.02 * np.abs(a).max())


def test_a_compensated_step_beyond_max_command_jump_is_refused(cfg):
    """A 0.1 rad step within one picosecond asks the model inverse for 1.3 rad steps
    between dense points: beyond node.max_command_jump (1 rad), refused whole."""
    comp = TrajectoryCompensator({J: cfg})
    with pytest.raises(TrajectoryRejected) as exc:
        comp.compensate(traj([0.05, 0.05 + 1e-12], [0.0, 0.1]), now_ns=NOW)
    assert exc.value.reason == 'command_limits'
    assert 'node.max_command_jump' in str(exc.value) and '\n' not in str(exc.value)
    # the same trajectory, half the step: within the limit, and from then on a start
    # far from the position commanded is refused too
    comp.compensate(traj([0.05, 0.05 + 1e-12], [0.0, 0.05]), now_ns=NOW)
    with pytest.raises(TrajectoryRejected, match='starts 4.95 rad from'):
        comp.compensate(traj([0.0, 0.1], [5.0, 5.0]), now_ns=NOW + 3 * 10**9)
