# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The trajectory interface in-process: ``reference_trajectory`` (trajectory_msgs/
JointTrajectory of the worm input joint) in, ``~/compensated_trajectory`` out.  What the
node publishes equals the core's offline twin (TrajectoryCompensator fed the same
trajectories) at every output point; a replacing trajectory starts where the last one was;
every kind of bad trajectory is rejected whole, counted, nothing forwarded, the node alive."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip('rclpy')
pytest.importorskip('trajectory_msgs')

from builtin_interfaces.msg import Duration, Time  # noqa: E402
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint  # noqa: E402

from worm_gear_sim.joint_trajectory.compensate import (  # noqa: E402
    TRAJECTORY_REJECT_REASONS,
    TrajectoryCompensator,
)
from worm_gear_sim.ros.trajectory_bridge import from_message  # noqa: E402

pytestmark = pytest.mark.ros

NOW_NS = 1_795_000_000_123_456_789
JOINT = 'worm_input_joint'


def message(times, positions, velocities=None, stamp_ns=0, joints=(JOINT,)):
    msg = JointTrajectory()
    msg.header.stamp = Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
    msg.header.frame_id = 'pedestal'
    msg.joint_names = list(joints)
    for i, t in enumerate(times):
        p = JointTrajectoryPoint()
        p.positions = [float(x) for x in np.atleast_1d(positions[i])]
        if velocities is not None:
            p.velocities = [float(x) for x in np.atleast_1d(velocities[i])]
        sec = math.floor(t)
        p.time_from_start = Duration(sec=sec, nanosec=int(round((t - sec) * 1e9)))
        msg.points.append(p)
    return msg


def as_arrays(msg):
    t = np.array([p.time_from_start.sec + p.time_from_start.nanosec * 1e-9
                  for p in msg.points])
    return (t, np.array([p.positions for p in msg.points]),
            np.array([p.velocities for p in msg.points]),
            np.array([p.accelerations for p in msg.points]))


class Trajectories:
    def __init__(self, h):
        self.h = h
        self.out: list[JointTrajectory] = []
        self.pub = h.probe.create_publisher(JointTrajectory, 'reference_trajectory', 10)
        h.probe.create_subscription(JointTrajectory, '/worm_gear_sim/compensated_trajectory',
                                    self.out.append, 10)
        assert h.spin_until(lambda: self.pub.get_subscription_count() > 0 and
                            h.node.count_subscribers(
                                '/worm_gear_sim/compensated_trajectory') > 0)

    def send(self, msg, expect_output: bool = True, timeout: float = 20.0) -> bool:
        c = self.h.node.counters
        n_in, n_out = c['trajectories_received'], len(self.out)
        self.pub.publish(msg)
        if not self.h.spin_until(lambda: c['trajectories_received'] > n_in, timeout):
            return False
        if not expect_output:
            self.h.node.trajectories.wait()
            self.h.spin_for(0.1)
            return len(self.out) == n_out
        return self.h.spin_until(lambda: len(self.out) > n_out, timeout)


def paper_waypoints():
    """The paper's 18-step move as 5 waypoints (positions and velocities: the cubic rule
    reproduces its quadratic pieces), from 10 ms after the start."""
    amp = math.radians(18.0)                     # worm angle [rad] of the move
    knots = np.array([0.01, 0.014, 0.026, 0.03, 0.05])
    rate = amp / 0.016
    pos = np.array([0.0, 0.5 * rate * 0.004, amp - 0.5 * rate * 0.004, amp, amp])
    vel = np.array([0.0, rate, rate, 0.0, 0.0])
    return knots, pos, vel


def test_published_trajectory_equals_the_offline_twin_and_replacements_start_in_place(
        ros_harness):
    h = ros_harness({'load.output_torque': 5.0})
    assert h.wait_clock(NOW_NS)
    tr = Trajectories(h)
    knots, pos, vel = paper_waypoints()
    twin = TrajectoryCompensator({JOINT: h.node.rt.model})
    first = message(knots, pos, vel, NOW_NS + 10**9)
    assert tr.send(first)
    # the twin is fed what the message carries (times to the nanosecond: a knot on a
    # sample instant decides on which side the acceleration's jump falls)
    want = twin.compensate(from_message(first))
    np.testing.assert_allclose(from_message(first).positions[:, 0], pos, atol=1e-15)
    got = tr.out[-1]
    assert list(got.joint_names) == [JOINT] and got.header == first.header
    t, p, v, a = as_arrays(got)
    d = want.trajectory
    assert t.size == d.time_from_start.size == 151         # 0.05 + 0.1 s settle at 1 kHz
    np.testing.assert_allclose(t, d.time_from_start, rtol=0, atol=1e-9)
    for x, y in ((p, d.positions), (v, d.velocities), (a, d.accelerations)):
        np.testing.assert_allclose(x, y, rtol=0, atol=1e-9)
    delta = want.axes[JOINT].delta
    assert np.ptp(delta) > 1e-4                            # a real correction
    # a replacement 30 ms into the first, back to 0.1 rad: it starts where the first
    # trajectory's reference is at that instant (the controller's rule), as the twin says
    stamp2 = NOW_NS + 10**9 + 30_000_000
    second = message([0.02, 0.05], [0.1, 0.1], None, stamp2)
    assert tr.send(second)
    assert twin.start_position(JOINT, stamp2) == pytest.approx(pos[3], abs=1e-12)
    want2 = twin.compensate(from_message(second))
    assert want2.axes[JOINT].reference[0] == pytest.approx(pos[3], abs=1e-12)
    t2, p2, _, _ = as_arrays(tr.out[-1])
    np.testing.assert_allclose(p2, want2.trajectory.positions, rtol=0, atol=1e-9)
    assert h.node.counters['trajectories_compensated'] == 2


BAD = [
    ('empty', lambda: message([], [])),
    ('empty', lambda: message([0.1], [1.0], joints=())),
    ('unknown_joint', lambda: message([0.1], [1.0], joints=('antenna_joint',))),
    ('duplicate_joint', lambda: message([0.1], [[1.0, 1.0]], joints=(JOINT, JOINT))),
    ('not_increasing', lambda: message([0.1, 0.1], [1.0, 2.0])),
    ('not_increasing', lambda: message([0.2, 0.1], [1.0, 2.0])),
    ('not_finite', lambda: message([0.1, 0.2], [1.0, float('nan')])),
    ('not_finite', lambda: message([0.1, 0.2], [1.0, 2.0], [0.0, float('inf')])),
    ('length_mismatch', lambda: message([0.1, 0.2], [[1.0], [1.0, 2.0]])),
    ('length_mismatch', lambda: message([0.1, 0.2], [1.0, 2.0], [[0.0], []])),
    ('too_long', lambda: message([4000.0], [1.0])),
    ('too_long', lambda: message([700.0], [1.0])),      # 700 101 dense points > 600 000
    ('past_stamp', lambda: message([0.1], [1.0], stamp_ns=NOW_NS - 10**9)),
    ('future_stamp', lambda: message([0.1], [1.0], stamp_ns=NOW_NS + 3601 * 10**9)),
    ('command_limits', lambda: message([0.001], [2e4])),      # beyond node.max_command_abs
]


def test_bad_trajectories_are_rejected_whole_counted_and_nothing_is_forwarded(ros_harness):
    assert {r for r, _ in BAD} == set(TRAJECTORY_REJECT_REASONS) - {'busy'}
    h = ros_harness()
    assert h.wait_clock(NOW_NS)
    tr = Trajectories(h)
    c = h.node.counters
    for reason, make in BAD:
        before = c[f'rejected_trajectory_{reason}']
        assert tr.send(make(), expect_output=False), reason
        assert c[f'rejected_trajectory_{reason}'] == before + 1, reason
    assert not tr.out and c['trajectories_compensated'] == 0
    assert c['trajectories_received'] == len(BAD)
    # the node is alive and the next good trajectory goes through, from its first waypoint
    assert tr.send(message([0.05], [0.3], stamp_ns=NOW_NS + 10**9))
    t, p, _, _ = as_arrays(tr.out[-1])
    assert p[0, 0] == pytest.approx(0.3, abs=1e-3) and c['trajectories_compensated'] == 1


def test_a_flood_of_trajectories_is_bounded_and_counted_busy(ros_harness, monkeypatch):
    """While the worker is held, trajectories wait until their compensated points would
    exceed MAX_PENDING_POINTS (here lowered to 1000: two of 351 points wait, the third is
    'busy'); a burst of many short ones is all taken; released, every waiting one is
    published, in order."""
    import threading

    from worm_gear_sim.ros import trajectory_bridge
    monkeypatch.setattr(trajectory_bridge, 'MAX_PENDING_POINTS', 1000)
    h = ros_harness()
    assert h.wait_clock(NOW_NS)
    tr = Trajectories(h)
    bridge = h.node.trajectories
    gate = threading.Event()
    work = bridge._compensate_and_publish

    def held(*args):
        gate.wait(30.0)
        work(*args)
    bridge._compensate_and_publish = held
    c = h.node.counters
    for k in range(3):                   # 0.25 s + 0.1 s settle at 1 kHz: 351 points each
        tr.pub.publish(message([0.25], [0.1 * (k + 1)], stamp_ns=NOW_NS + (k + 1) * 10**9))
    assert h.spin_until(lambda: c['trajectories_received'] == 3)
    assert c['rejected_trajectory_busy'] == 1 and not tr.out
    gate.set()
    assert h.spin_until(lambda: len(tr.out) == 2, 30.0)
    ends = [as_arrays(m)[1][-1, 0] for m in tr.out]
    np.testing.assert_allclose(ends, [0.1, 0.2], atol=1e-3)
    # with the real limit, bursts of short trajectories (within the topics' depth of 10)
    # are taken whole while the worker is held
    monkeypatch.setattr(trajectory_bridge, 'MAX_PENDING_POINTS', 2_000_000)
    gate.clear()
    for burst in range(3):
        for k in range(8):
            tr.pub.publish(message([0.02], [0.01 * k],
                                   stamp_ns=NOW_NS + (10 + 8 * burst + k) * 10**9))
        want = 3 + 8 * (burst + 1)
        assert h.spin_until(lambda n=want: c['trajectories_received'] == n)
    gate.set()
    assert h.spin_until(lambda: c['trajectories_compensated'] == 2 + 24, 30.0)
    assert c['rejected_trajectory_busy'] == 1
