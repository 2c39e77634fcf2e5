# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The bag recorder (for installs without ``ros2 bag``): what it writes is what was
published, with receive times on the node's clock, readable by records.read_bag."""

from __future__ import annotations

import time

import numpy as np
import pytest

pytest.importorskip('rclpy')


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_recorder_writes_what_was_published(ros_context, tmp_path, storage):
    import rclpy
    from builtin_interfaces.msg import Time
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import JointState

    from worm_gear_sim.records import read_bag
    from worm_gear_sim.ros.bag_recorder import BagRecorder

    rec = BagRecorder(tmp_path / 'bag', storage=storage, context=ros_context)
    pub_node = rclpy.create_node('servo', context=ros_context)
    ref = pub_node.create_publisher(JointState, 'worm_angle_reference', QoSProfile(depth=100))
    js = pub_node.create_publisher(JointState, 'measured_joint_states', QoSProfile(depth=100))
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(rec)
    ex.add_node(pub_node)
    deadline = time.monotonic() + 5
    while (ref.get_subscription_count() == 0 or js.get_subscription_count() == 0) \
            and time.monotonic() < deadline:
        ex.spin_once(timeout_sec=0.01)
    base = 1_763_890_855_000_000_000
    x = np.linspace(0.0, 0.05, 30)
    for k, v in enumerate(x):
        s = base + k * 1_000_000
        m = JointState(name=['worm_input_joint'], position=[float(v)])
        m.header.stamp = Time(sec=s // 10**9, nanosec=s % 10**9)
        ref.publish(m)
        e = JointState(name=['antenna_joint', 'worm_joint'], position=[v / 56, float(v)])
        e.header.stamp = Time(sec=s // 10**9, nanosec=s % 10**9)
        js.publish(e)
    t0 = rec.get_clock().now().nanoseconds
    deadline = time.monotonic() + 5
    while sum(rec.counts.values()) < 60 and time.monotonic() < deadline:
        ex.spin_once(timeout_sec=0.01)
    rec.close()
    ex.shutdown()
    rec.destroy_node()
    pub_node.destroy_node()
    assert rec.counts['/worm_angle_reference'] == 30 == rec.counts['/measured_joint_states']
    r = read_bag(tmp_path / 'bag')
    np.testing.assert_array_equal(r.command_values, x)
    assert r.t0_ns == base and r.source['command_stamp'] == 'header.stamp'
    np.testing.assert_array_equal(r.measured['theta4'], x / 56)
    np.testing.assert_array_equal(r.measured['theta2'], x)
    assert np.all(r.command_receive_ns >= t0 - 10**9)        # receive times: the node clock


def test_recorder_command_line_errors(tmp_path, capsys):
    from worm_gear_sim.ros.bag_recorder import main
    assert main(['x', '-o', str(tmp_path), '--duration', '0.1']) == 2
    assert 'exists already' in capsys.readouterr().err
    assert main(['x', '-o', str(tmp_path / 'b'), '--topic', 'foo:Twist']) == 2
    assert 'NAME:Float64' in capsys.readouterr().err
