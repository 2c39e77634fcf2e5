# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The pedestal: its file (config/pedestal.yaml: drives, namespaces, joints) and the
``worm_gear_sim_pedestal`` process: a trajectory naming both drives' joints is split,
compensated by each drive with its own parameters and merged back in the input's order,
equal to the offline twin; each drive keeps its single-drive interface in its namespace;
SIGINT ends it quietly."""

from __future__ import annotations

import signal
import sys
from pathlib import Path

import numpy as np
import pytest
from processes import start_logged, stop_and_read

from worm_gear_sim import ConfigError
from worm_gear_sim.config.pedestal import load_pedestal
from worm_gear_sim.joint_trajectory.compensate import TrajectoryCompensator

ROOT = Path(__file__).resolve().parents[2]


def test_the_default_pedestal_has_two_drives_with_their_own_joints_and_parameters():
    az, el = load_pedestal()
    assert (az.name, el.name) == ('azimuth', 'elevation')
    assert (az.joint, el.joint) == ('azimuth_worm_input_joint', 'elevation_worm_input_joint')
    assert el.config.load.output_torque == 5.0 and az.config.load.output_torque == 0.0
    assert el.config.geometry.flywheel_radius != az.config.geometry.flywheel_radius


@pytest.mark.parametrize('text, words', [
    ('pedestal: {drives: {}}', 'expected "pedestal: drives:"'),
    ('pedestal: {drives: {a: {}, b: {}}}', "'worm_input_joint' is used by more than one"),
    ('pedestal: {drives: {"a/b": {}}}', 'not a ROS name token'),
    ('pedestal: {drives: {a: {params: x}}}', 'takes "params_file" and "parameters"'),
    ('pedestal: {drives: {a: {params_file: missing.yaml}}}', 'missing.yaml'),
    ('pedestal: {drives: {a: {parameters: {load.output_torque: -1.0e+9}}}}', "drive 'a'"),
])
def test_bad_pedestal_files_are_one_line_errors(tmp_path, text, words):
    p = tmp_path / 'pedestal.yaml'
    p.write_text(text)
    with pytest.raises(ConfigError) as exc:
        load_pedestal(p)
    assert words in str(exc.value) and '\n' not in str(exc.value)


def two_axis_message(joints, stamp_ns=0):
    from builtin_interfaces.msg import Duration, Time
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
    msg = JointTrajectory()
    msg.header.stamp = Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
    msg.joint_names = list(joints)
    # azimuth 0 -> 0.5 rad and elevation 0 -> -0.2 rad of worm angle, cubic (pos + vel)
    for t, a, e in ((0.0, 0.0, 0.0), (0.02, 0.25, -0.1), (0.04, 0.5, -0.2)):
        p = JointTrajectoryPoint()
        vals = {'azimuth_worm_input_joint': (a, 12.5 if t == 0.02 else 0.0),
                'elevation_worm_input_joint': (e, -5.0 if t == 0.02 else 0.0)}
        p.positions = [vals[j][0] for j in joints]
        p.velocities = [vals[j][1] for j in joints]
        p.time_from_start = Duration(sec=0, nanosec=int(round(t * 1e9)))
        msg.points.append(p)
    return msg


@pytest.mark.ros
def test_the_pedestal_process_splits_compensates_and_merges_like_the_twin(
        ros_dds_context, ros_subprocess_env, tmp_path):
    pytest.importorskip('trajectory_msgs')
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from trajectory_msgs.msg import JointTrajectory

    from worm_gear_sim.ros.trajectory_bridge import from_message
    proc, log = start_logged(
        [sys.executable, '-c', 'import sys; from worm_gear_sim.ros.startup import '
         'pedestal_main; sys.exit(pedestal_main())'], ros_subprocess_env,
        tmp_path / 'pedestal.log')
    node = rclpy.create_node('pedestal_probe', context=ros_dds_context)
    ex = SingleThreadedExecutor(context=ros_dds_context)
    ex.add_node(node)
    out: dict[str, list] = {'pedestal': [], 'azimuth': []}
    pub = node.create_publisher(JointTrajectory, '/pedestal/reference_trajectory', 10)
    pub_az = node.create_publisher(JointTrajectory, '/azimuth/reference_trajectory', 10)
    node.create_subscription(JointTrajectory, '/pedestal/compensated_trajectory',
                             out['pedestal'].append, 10)
    node.create_subscription(JointTrajectory, '/azimuth/worm_gear_sim/compensated_trajectory',
                             out['azimuth'].append, 10)

    def spin_until(pred, timeout):
        import time
        t0 = time.monotonic()
        while not pred():
            if time.monotonic() - t0 > timeout or proc.poll() is not None:
                return False
            ex.spin_once(timeout_sec=0.02)
        return True

    try:
        assert spin_until(lambda: pub.get_subscription_count() > 0 and
                          pub_az.get_subscription_count() > 0 and
                          node.count_publishers('/pedestal/compensated_trajectory') > 0 and
                          node.count_publishers(
                              '/azimuth/worm_gear_sim/compensated_trajectory') > 0, 90.0), \
            'pedestal did not come up'
        want_names = {('worm_gear_sim', '/azimuth'), ('worm_gear_sim', '/elevation'),
                      ('pedestal', '/')}
        assert spin_until(lambda: want_names <= set(node.get_node_names_and_namespaces()),
                          10.0), node.get_node_names_and_namespaces()
        joints = ('elevation_worm_input_joint', 'azimuth_worm_input_joint')
        msg = two_axis_message(joints)
        pub.publish(msg)
        assert spin_until(lambda: out['pedestal'], 30.0)
        msg_az = two_axis_message(joints[1:])
        pub_az.publish(msg_az)
        assert spin_until(lambda: out['azimuth'], 30.0)
    finally:
        ex.shutdown()
        node.destroy_node()
        rc, text = stop_and_read(proc, log, signal.SIGINT)
    assert rc == 0 and 'Traceback' not in text, text
    drives = {d.joint: d.config for d in load_pedestal()}
    got = from_message(out['pedestal'][0])
    assert got.joint_names == joints                       # the input's order
    want = TrajectoryCompensator(drives).compensate(from_message(msg)).trajectory
    np.testing.assert_allclose(got.time_from_start, want.time_from_start, atol=1e-9)
    for x, y in ((got.positions, want.positions), (got.velocities, want.velocities),
                 (got.accelerations, want.accelerations)):
        np.testing.assert_allclose(x, y, rtol=0, atol=1e-9)
    # each axis with its own drive: the elevation's correction is not the azimuth's, scaled
    d_az = want.positions[:, 1] - TrajectoryCompensator(drives).compensate(
        from_message(msg), predict=False).axes[joints[1]].reference
    assert np.ptp(d_az) > 1e-5
    # the azimuth drive's own node, in its namespace, answers its single joint the same way
    got_az = from_message(out['azimuth'][0])
    np.testing.assert_allclose(got_az.positions[:, 0], want.positions[:, 1], rtol=0,
                               atol=1e-9)


@pytest.mark.ros
def test_the_pass_demo_streams_a_pass_through_the_pedestal_process(ros_subprocess_env,
                                                                    tmp_path):
    """scripts/run_pass.sh's two processes: every trajectory comes back equal to its twin
    and the table shows both axes' pointing error cut (exit 0)."""
    import subprocess
    proc, log = start_logged(
        [sys.executable, '-c', 'import sys; from worm_gear_sim.ros.startup import '
         'pedestal_main; sys.exit(pedestal_main())'], ros_subprocess_env,
        tmp_path / 'pedestal.log')
    try:
        demo = subprocess.run(
            [sys.executable, '-m', 'worm_gear_sim.ros.pass_demo', '--duration', '6',
             '-o', str(tmp_path / 'pass')], env=ros_subprocess_env, capture_output=True,
            text=True, timeout=240)
    finally:
        rc, text = stop_and_read(proc, log, signal.SIGINT)
    assert demo.returncode == 0, demo.stdout + demo.stderr
    assert rc == 0 and 'Traceback' not in text, text
    assert '1/1 compensated trajectories received' in demo.stdout, demo.stdout
    twin = float(demo.stdout.split('offline twin: ')[1].split()[0])
    assert twin <= 1e-9
    assert (tmp_path / 'pass' / 'pass.png').is_file()
