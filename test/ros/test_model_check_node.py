# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The node's live model check in-process (rclpy executors, /clock driven by the test):
measured_joint_states -> ~/prediction_residual (stamped, measured - predicted per measured
joint) and the 'model check' status of /diagnostics (WARN above node.residual_warn_rms over
node.residual_window); bad samples are rejected and counted, the node keeps running."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip('rclpy')

from worm_gear_sim import Config  # noqa: E402
from worm_gear_sim.dynamics.profiles import make_profile  # noqa: E402

pytestmark = pytest.mark.ros

T0_NS = 1_000_000_000
TICK_NS = 1_000_000


class Encoders:
    """measured_joint_states publisher and ~/prediction_residual subscriber on the probe."""

    def __init__(self, h):
        from rclpy.qos import QoSProfile
        from sensor_msgs.msg import JointState
        self.JointState = JointState
        self.pub = h.probe.create_publisher(JointState, 'measured_joint_states',
                                            QoSProfile(depth=100))
        self.residuals: list = []
        h.probe.create_subscription(JointState, '/worm_gear_sim/prediction_residual',
                                    self.residuals.append, 1000)
        assert h.spin_until(lambda: self.pub.get_subscription_count() > 0 and
                            h.node.count_subscribers('/worm_gear_sim/prediction_residual'))

    def publish(self, stamp_ns: int, names, positions) -> None:
        m = self.JointState()
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(int(stamp_ns), 10**9)
        m.name = list(names)
        m.position = [float(p) for p in positions]
        self.pub.publish(m)


def _status(h):
    from worm_gear_sim.ros.diagnostics import level_name
    st = [s for s in h.node.diagnostic_statuses() if s.name.endswith(': model check')]
    assert len(st) == 1
    return level_name(st[0].level), st[0].message, {kv.key: kv.value for kv in st[0].values}


def test_prediction_residual_and_warn(ros_harness):
    h = ros_harness({'node.residual_window': 0.0105})     # 10 ticks of 1 ms
    enc = Encoders(h)
    names = Config().node.joint_names
    level, msg, _ = _status(h)
    assert level == 'OK' and 'idle' in msg
    cmds = make_profile(Config().replace({'input.start_time': 0.002}).input).theta1(
        np.arange(60) * 1e-3)
    offsets = [(0.0, 2e-4)] * 30 + [(0.0, 0.0)] * 30
    for k, (c, (o2, o4)) in enumerate(zip(cmds, offsets)):
        assert h.command(c)
        ns = T0_NS + k * TICK_NS
        assert h.tick_to(ns, timeout=60.0 if k == 0 else 5.0)   # the first loads kernels
        js = h.joint_states[-1]
        th = list(js.position)                           # theta1..theta4 predicted at ns
        enc.publish(ns, (names[1], names[3]), (th[1] + o2, th[3] + o4))
        assert h.spin_until(lambda k=k: len(enc.residuals) > k), f'no residual at tick {k}'
        r = enc.residuals[-1]
        assert r.header.stamp.sec * 10**9 + r.header.stamp.nanosec == ns
        assert list(r.name) == [names[1], names[3]]
        assert r.position[0] == pytest.approx(0.0, abs=1e-15)
        assert r.position[1] == pytest.approx(o4, abs=1e-15)
        if k == 29:
            level, msg, vals = _status(h)
            assert level == 'WARN' and names[3] in msg and names[1] not in msg, msg
            assert float(vals[f'residual_rms_{names[3]} [rad]']) == pytest.approx(2e-4)
    level, msg, vals = _status(h)          # the last 10 ticks all matched
    assert level == 'OK', msg
    assert vals['samples'] == '60'
    # the antenna really moved and rang: the check compared a live, changing prediction
    assert np.ptp([m.position[3] for m in h.joint_states]) > 1e-3


def test_bad_measurements_rejected_and_counted(ros_harness):
    h = ros_harness()
    enc = Encoders(h)
    names = Config().node.joint_names
    for k in range(5):
        assert h.command(0.01 * k)
        assert h.tick_to(T0_NS + k * TICK_NS, timeout=60.0 if k == 0 else 5.0)
    last = T0_NS + 4 * TICK_NS
    bad = [
        ((names[3],), (0.1, 0.2)),                       # 1 name, 2 positions
        ((names[3],), (math.nan,)),                      # not finite
        (('some_other_joint',), (0.0,)),                 # no monitored joint
    ]
    for nm, pos in bad:
        enc.publish(last, nm, pos)
    enc.publish(last + 10**9, (names[3],), (0.0,))     # 1 s ahead of the prediction
    h.spin_for(0.3)
    assert enc.residuals == []
    _, _, vals = _status(h)
    assert vals['rejected_malformed'] == '1' and vals['rejected_non_finite'] == '1'
    assert vals['rejected_no_monitored_joint'] == '1'
    assert vals['rejected_outside_prediction'] == '1'
    # the node keeps running: a good (unstamped: reception time = the last tick) sample
    th4 = h.joint_states[-1].position[3]
    enc.publish(0, (names[3],), (th4 + 1e-6,))
    assert h.spin_until(lambda: len(enc.residuals) == 1)
    r = enc.residuals[0]
    assert r.position[0] == pytest.approx(1e-6, abs=1e-15)
    assert r.header.stamp.sec * 10**9 + r.header.stamp.nanosec == last
    assert h.tick_to(T0_NS + 5 * TICK_NS)


def test_glitches_a_joint_named_twice_and_a_flood_are_rejected_by_reason(ros_harness):
    """Absurd finite values, another drive's encoder (+3 rad) and a joint named twice are
    rejected (implausible, malformed), a burst of 20 samples per command period has one
    used per period (surplus), the model check says WARN naming the implausible ones, and
    what it shows is the good samples' residual."""
    h = ros_harness()
    names = Config().node.joint_names
    th4 = []
    for k in range(5):
        assert h.command(0.01 * k)
        assert h.tick_to(T0_NS + k * TICK_NS, timeout=60.0 if k == 0 else 5.0)
        th4.append(h.joint_states[-1].position[3])
    node = h.node

    def measured(stamp_ns, nm, pos):         # the subscription's callback, in-process
        m = h.JointState(name=list(nm), position=[float(p) for p in pos])
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(int(stamp_ns), 10**9)
        node._on_measured(m)

    at = T0_NS + 2 * TICK_NS
    for value in (1e300, 1e150, th4[2] + 3.0):
        measured(at, (names[3],), (value,))
    measured(at, (names[3], names[3]), (th4[2], th4[2] + 1.0))
    for j in range(20):                        # 20 samples within one period, 2e-6 off
        measured(at + j * TICK_NS // 20, (names[3],),
                 (th4[2] + j / 20 * (th4[3] - th4[2]) + 2e-6,))
    _, msg, vals = _status(h)
    assert vals['rejected_implausible'] == '3' and vals['rejected_malformed'] == '1'
    assert vals['rejected_surplus'] == '18' and vals['samples'] == '2'
    assert 'implausible' in msg
    assert float(vals[f'residual_rms_{names[3]} [rad]']) == pytest.approx(2e-6, rel=1e-3)
