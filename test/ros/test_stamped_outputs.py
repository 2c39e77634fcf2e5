# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Every output that answers a sample carries that sample's stamp: ``~/positioning_error``,
``~/worm_error``, ``~/feedforward`` and ``~/backdrive_margin`` are sensor_msgs/JointState of
one named joint, stamped as the prediction or correction they belong to, so that a bag
aligns them with the references sample by sample; ``node.float64_outputs`` (read-only)
publishes them as std_msgs/Float64 instead, for servos that need that type."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

pytest.importorskip('rclpy')

from rclpy.parameter import Parameter  # noqa: E402

from worm_gear_sim import Config  # noqa: E402
from worm_gear_sim.dynamics.profiles import TrapezoidalProfile  # noqa: E402

pytestmark = pytest.mark.ros

NS = 10**9
BASE = 1_795_430_808_000_000_000           # stamps on an epoch-like sim clock
JOINTS = Config().node.joint_names
OUTPUTS = ('positioning_error', 'worm_error', 'feedforward', 'backdrive_margin')


def _ns(msg: Any) -> int:
    return msg.header.stamp.sec * NS + msg.header.stamp.nanosec


def _listen(h: Any) -> dict[str, list[Any]]:
    """JointState subscriptions of the probe to the node's four answers."""
    got: dict[str, list[Any]] = {k: [] for k in OUTPUTS}
    for k in OUTPUTS:
        h.probe.create_subscription(h.JointState, f'/worm_gear_sim/{k}', got[k].append, 1000)
    return got


def _by_stamp(msgs: list[Any]) -> dict[int, Any]:
    return {_ns(m): m for m in msgs}


def test_stamped_path_answers_carry_the_sample_stamp(ros_harness):
    """The paper's move as stamped references: each error message has the stamp of the
    joint_states it belongs to and equals theta4 - theta1_ref l_w/r_g (theta2 - theta1) at
    that stamp; each feed-forward message has the stamp of its ~/compensated_command and
    equals command - reference; the back-drive margin has the stamp of the newest
    prediction, whose state it is computed from."""
    h = ros_harness()
    for k in OUTPUTS:
        info = h.probe.get_publishers_info_by_topic(f'/worm_gear_sim/{k}')
        assert [i.topic_type for i in info] == ['sensor_msgs/msg/JointState'], k
    got = _listen(h)
    assert h.spin_until(lambda: all(
        h.node.count_subscribers(f'/worm_gear_sim/{k}') > 0 for k in OUTPUTS))
    assert h.wait_clock(BASE - 10_000_000)
    move = TrapezoidalProfile(0.1130973, 0.02, 0.004, 0.005)
    t = np.arange(80) * 1e-3
    x = move.theta1(t)
    stamps = (BASE + np.round(t * 1e9).astype(np.int64)).tolist()
    ref = dict(zip(stamps, x.tolist()))
    assert h.references(list(zip(stamps, x.tolist())))
    n = len(stamps)
    assert h.spin_until(lambda: len(h.joint_states) >= n and len(got['positioning_error']) >= n
                        and len(got['worm_error']) >= n
                        and len(got['feedforward']) >= len(h.compensated) > 0)
    js = _by_stamp(h.joint_states)
    assert set(stamps) <= set(js)
    ratio = h.node.sim.derived.output_per_input
    for key, joint, value in (
            ('positioning_error', JOINTS[3],
             lambda s: js[s].position[3] - ref[s] * ratio),
            ('worm_error', JOINTS[1], lambda s: js[s].position[1] - js[s].position[0])):
        msgs = _by_stamp(got[key])
        assert set(msgs) == set(js), key              # one answer per prediction, its stamp
        for s in stamps:
            assert list(msgs[s].name) == [joint]
            assert msgs[s].position[0] == pytest.approx(value(s), abs=1e-12)
    cc = _by_stamp(h.compensated)
    ff = _by_stamp(got['feedforward'])
    assert set(ff) == set(cc) and len(ff) == len(got['feedforward'])
    deltas = []
    for s, m in ff.items():
        assert list(m.name) == [JOINTS[0]]
        deltas.append(m.position[0])
        assert cc[s].position[0] - ref[s] == pytest.approx(m.position[0], abs=1e-15)
    assert np.ptp(deltas) > 1e-4                      # the correction moves with the move
    h.spin_for(0.2)
    got['backdrive_margin'].clear()        # any of the diagnostics timer before the stream
    h.node.publish_diagnostics()
    assert h.spin_until(lambda: got['backdrive_margin'])
    margin = got['backdrive_margin'][-1]
    assert _ns(margin) == max(js) == stamps[-1]
    assert list(margin.name) == [JOINTS[2]]
    assert margin.position[0] == pytest.approx(h.node.backdrive_margins()[0], rel=1e-12)


def test_float64_path_answers_carry_the_tick_stamp(ros_harness):
    """Unstamped commands, ticks on /clock: the errors and the feed-forward carry the stamp
    of the tick's joint_states."""
    h = ros_harness()
    got = _listen(h)
    assert h.spin_until(lambda: all(
        h.node.count_subscribers(f'/worm_gear_sim/{k}') > 0 for k in OUTPUTS))
    ticks = []
    for k, c in enumerate([0.0, 0.0, 0.01, 0.02, 0.03, 0.03]):
        assert h.command(c)
        ns = 1_000_000_000 + k * 1_000_000
        h.set_clock(ns)
        assert h.spin_until(lambda ns=ns, k=k: bool(
            h.joint_states and _ns(h.joint_states[-1]) == ns
            and len(got['feedforward']) >= k + 1 and len(got['positioning_error']) >= k + 1))
        ticks.append(ns)
    for key in ('positioning_error', 'worm_error', 'feedforward'):
        assert [_ns(m) for m in got[key]] == ticks, key
    js = _by_stamp(h.joint_states)
    ratio = h.node.sim.derived.output_per_input
    for m in got['positioning_error']:
        s = _ns(m)
        # the Float64 path measures the error against the command in force at the tick
        assert m.position[0] == pytest.approx(js[s].position[3] - js[s].position[0] * ratio,
                                              abs=1e-12)


def test_float64_outputs_are_an_opt_in(ros_harness):
    """node.float64_outputs: true publishes the four answers as std_msgs/Float64 (no
    stamp), the values unchanged; the parameter is read-only and declared false by
    default."""
    assert Config().node.float64_outputs is False
    h = ros_harness({'node.float64_outputs': True})
    for k in OUTPUTS:
        info = h.probe.get_publishers_info_by_topic(f'/worm_gear_sim/{k}')
        assert [i.topic_type for i in info] == ['std_msgs/msg/Float64'], k
    got: list[float] = []
    h.probe.create_subscription(h.Float64, '/worm_gear_sim/positioning_error',
                                lambda m: got.append(m.data), 100)
    assert h.spin_until(lambda: h.node.count_subscribers('/worm_gear_sim/positioning_error')
                        > 0)
    assert h.command(0.01)
    h.set_clock(1_000_000_000)
    assert h.spin_until(lambda: got and h.joint_states)
    js = h.joint_states[-1]
    ratio = h.node.sim.derived.output_per_input
    assert got[-1] == pytest.approx(js.position[3] - js.position[0] * ratio, abs=1e-12)
    res = h.node.set_parameters([Parameter('node.float64_outputs', value=False)])
    assert not res[0].successful
