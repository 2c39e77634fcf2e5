# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Calibrating a running node (``worm_gear_sim_calibrate``), all as processes over DDS: a
plant (a node in /plant with other parameters, standing in for servo + drive: it takes the
stamped references and its joint_states are the encoders) and the node to calibrate (the
defaults).  The calibrator streams the excitation, fits two parameters, validates on the
held-out move and sets them on the node in one atomic set; with a wrong encoder topic it
stops with one line and the node keeps its parameters."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from processes import start_logged, stop_and_read

pytest.importorskip('rclpy')

pytestmark = pytest.mark.ros

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / 'config' / 'worm_gear_sim.yaml'
# the plant stands in for a physical drive, which never skips time: a loaded machine that
# starves its process for more than node.max_catch_up (0.05 s by default) would otherwise
# skip physics in the middle of a move (an overrun) and the records would not be the drive's
PLANT = {'load.output_viscous_coefficient': 5.0, 'geometry.flywheel_radius': 0.115,
         'node.max_catch_up': 5.0}
KEYS = 'geometry.flywheel_radius,load.output_viscous_coefficient'


def _node(ns: str, params: dict, env, log: Path):
    args = [sys.executable, '-m', 'worm_gear_sim.ros', '--ros-args', '--params-file',
            str(CONFIG), '--log-level', 'warn', '-r', f'__ns:={ns}']
    for k, v in params.items():
        args += ['-p', f'{k}:={v!r}']
    return start_logged(args, env, log)


def _get(ctx, names):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import parameter_value_to_python
    from rclpy.parameter_client import AsyncParameterClient
    node = rclpy.create_node('calibration_check', context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    try:
        client = AsyncParameterClient(node, '/worm_gear_sim')
        assert client.wait_for_services(timeout_sec=60.0)
        fut = client.get_parameters(names)
        ex.spin_until_future_complete(fut, timeout_sec=30.0)
        return [parameter_value_to_python(v) for v in fut.result().values]
    finally:
        ex.shutdown()
        node.destroy_node()


def test_a_running_node_is_calibrated_against_its_drive_and_updated_atomically(
        ros_dds_context, ros_subprocess_env, tmp_path):
    plant = _node('/plant', PLANT, ros_subprocess_env, tmp_path / 'plant.log')
    target = _node('/', {}, ros_subprocess_env, tmp_path / 'target.log')
    names = KEYS.split(',')
    try:
        # a drive that does not answer on the given encoder topic: one line, nothing applied
        bad = subprocess.run(
            [sys.executable, '-m', 'worm_gear_sim.ros.calibrate', '--fit', KEYS, '-o',
             str(tmp_path / 'bad.yaml'), '--servo-topic', '/plant/worm_angle_reference',
             '--measured-topic', '/no_encoders', '--settle-timeout', '2', '--serial', '--yes'],
            env=ros_subprocess_env, capture_output=True, text=True, timeout=180)
        assert bad.returncode == 2, bad.stdout + bad.stderr
        assert 'no measured joint states on /no_encoders' in bad.stderr
        assert 'nothing applied' in bad.stderr and 'Traceback' not in bad.stderr
        assert not (tmp_path / 'bad.yaml').exists()
        assert _get(ros_dds_context, names) == [0.12, 0.0]
        run = subprocess.run(
            [sys.executable, '-m', 'worm_gear_sim.ros.calibrate', '--fit', KEYS, '-o',
             str(tmp_path / 'fitted.yaml'), '--servo-topic', '/plant/worm_angle_reference',
             '--measured-topic', '/plant/joint_states', '--serial', '--no-plot', '--yes'],
            env=ros_subprocess_env, capture_output=True, text=True, timeout=300)
        assert run.returncode == 0, run.stdout + run.stderr
        assert 'applied to /worm_gear_sim in one atomic set' in run.stdout
        radius, viscous = _get(ros_dds_context, names)
    finally:
        rcs = [stop_and_read(p, log)[0] for p, log in (plant, target)]
    assert rcs == [0, 0]
    assert radius == pytest.approx(0.115, rel=2e-3)
    assert viscous == pytest.approx(5.0, rel=2e-2)
    held = [line for line in run.stdout.splitlines() if line.startswith('held-out')]
    rel_after = float(held[0].split('->')[1].split('%')[0])
    assert rel_after < 3.0, held                     # % of the held-out move's amplitude
    assert (tmp_path / 'fitted.yaml').is_file() and (tmp_path / 'fitted.json').is_file()


def test_measured_samples_out_of_order_or_repeated_are_dropped_not_fatal():
    """A record holds the encoder samples whose stamps increase strictly: one delivered
    late or twice (seen once in CI: the sample stamped at the move's first instant came
    again as the 17th, and the calibration stopped on "decreasing time") is dropped, the
    rest kept in arrival order."""
    from worm_gear_sim.ros.calibrate import _increasing
    v = {'theta4': 0.0}
    got = _increasing([(10, v), (11, v), (12, v), (10, v), (13, v), (13, v), (12, v), (14, v)])
    assert [s for s, _ in got] == [10, 11, 12, 13, 14]
    assert _increasing([]) == []
