# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Packaging for a real ROS 2 install: ``colcon build`` (colcon-core + colcon-ros from PyPI,
no ROS install needed for an ament_python package) into a temporary workspace, then what
``ros2 run worm_gear_sim worm_gear_sim_node`` resolves (ament index marker -> prefix ->
``lib/worm_gear_sim/worm_gear_sim_node``), the installed config and package.xml, and the
installed executable run with the installed config, publishing JointState over DDS."""

from __future__ import annotations

import math
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from worm_gear_sim.params import load_config

ROOT = Path(__file__).resolve().parent.parent
PKG = 'worm_gear_sim'
EXE = 'worm_gear_sim_node'
PY = f'python{sys.version_info.major}.{sys.version_info.minor}'


def _colcon() -> str | None:
    here = Path(sys.executable).parent / 'colcon'
    return str(here) if here.exists() else shutil.which('colcon')


@pytest.fixture(scope='module')
def colcon_install(tmp_path_factory) -> Path:
    """A workspace with only what the package needs, built by colcon; returns the
    install base (isolated layout: <install>/worm_gear_sim/...)."""
    colcon = _colcon()
    if colcon is None:
        pytest.skip('colcon is not installed (pip install colcon-core colcon-ros '
                    'colcon-python-setup-py)')
    ws = tmp_path_factory.mktemp('colcon_ws')
    src = ws / 'src' / PKG
    src.mkdir(parents=True)
    for name in ('setup.py', 'setup.cfg', 'package.xml'):
        shutil.copy2(ROOT / name, src / name)
    for name in ('resource', 'config'):
        shutil.copytree(ROOT / name, src / name)
    shutil.copytree(ROOT / PKG, src / PKG,
                    ignore=shutil.ignore_patterns('__pycache__', '*.pyc', '*.nbi', '*.nbc'))
    env = dict(os.environ)
    env.pop('AMENT_PREFIX_PATH', None)
    env.pop('COLCON_PREFIX_PATH', None)
    proc = subprocess.run(
        [colcon, '--log-base', str(ws / 'log'), 'build', '--base-paths', str(ws / 'src'),
         '--build-base', str(ws / 'build'), '--install-base', str(ws / 'install')],
        cwd=ws, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return ws / 'install'


def _ros_env(install: Path, base: dict[str, str]) -> dict[str, str]:
    """What sourcing install/setup.sh sets for this package."""
    prefix = install / PKG
    env = dict(base)
    env['AMENT_PREFIX_PATH'] = str(prefix)
    site = prefix / 'lib' / PY / 'site-packages'
    env['PYTHONPATH'] = os.pathsep.join([str(site)] + ([env['PYTHONPATH']]
                                                        if env.get('PYTHONPATH') else []))
    return env


def test_colcon_install_layout_resolves_like_ros2_run(colcon_install, monkeypatch):
    prefix = colcon_install / PKG
    marker = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / PKG
    assert marker.is_file()
    # `ros2 run` = ament index prefix of the package + lib/<package>/<executable>
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(prefix))
    ament = pytest.importorskip('ament_index_python.packages')
    assert Path(ament.get_package_prefix(PKG)) == prefix
    share = Path(ament.get_package_share_directory(PKG))
    exe = prefix / 'lib' / PKG / EXE
    assert exe.is_file() and os.access(exe, os.X_OK)
    demo = prefix / 'lib' / PKG / 'worm_gear_sim_demo'
    assert demo.is_file() and os.access(demo, os.X_OK)
    assert (share / 'package.xml').read_text() == (ROOT / 'package.xml').read_text()
    installed_cfg = share / 'config' / 'worm_gear_sim.yaml'
    assert installed_cfg.is_file()
    assert load_config(installed_cfg) == load_config(ROOT / 'config' / 'worm_gear_sim.yaml')
    assert (prefix / 'lib' / PY / 'site-packages' / PKG / 'node.py').is_file()
    assert not (prefix / 'bin' / EXE).exists()       # setup.cfg puts scripts in lib/<pkg>


@pytest.mark.ros
def test_installed_executable_publishes_joint_states(colcon_install, ros_dds_context,
                                                     ros_subprocess_env, tmp_path):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64
    prefix = colcon_install / PKG
    exe = prefix / 'lib' / PKG / EXE
    cfg = prefix / 'share' / PKG / 'config' / 'worm_gear_sim.yaml'
    env = _ros_env(colcon_install, ros_subprocess_env)
    log = open(tmp_path / 'node.log', 'w+')
    proc = subprocess.Popen([str(exe), '--ros-args', '--params-file', str(cfg)],
                            cwd=tmp_path, env=env, stdout=log, stderr=subprocess.STDOUT)
    node = rclpy.create_node('packaging_probe', context=ros_dds_context)
    ex = SingleThreadedExecutor(context=ros_dds_context)
    ex.add_node(node)
    got: list = []
    node.create_subscription(JointState, 'joint_states', got.append, 20)
    pub = node.create_publisher(Float64, 'worm_angle_command', 10)
    try:
        t0 = time.monotonic()
        while len(got) < 5 and proc.poll() is None and time.monotonic() - t0 < 120.0:
            pub.publish(Float64(data=0.1))
            ex.spin_once(timeout_sec=0.005)
    finally:
        ex.shutdown()
        node.destroy_node()
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
        try:
            rc = proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            rc = proc.wait()
        log.seek(0)
        text = log.read()
        log.close()
    assert len(got) >= 5, f'no JointState from the installed executable (rc {rc}):\n{text}'
    assert got[-1].position[0] == pytest.approx(0.1)
    assert all(math.isfinite(x) for x in got[-1].position)
    assert rc == 0, text
    assert 'Traceback' not in text, text
    # it ran the installed copy, not the source tree
    assert str(prefix / 'lib' / PY / 'site-packages') in subprocess.run(
        [sys.executable, '-c', 'import worm_gear_sim, sys; print(worm_gear_sim.__file__)'],
        env=env, capture_output=True, text=True, cwd=tmp_path).stdout
