# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The demo of README command #1: the demo commander streaming to the node (two processes,
domain 43, discovery LOCALHOST) for a short bounded time, both ending with exit code 0."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent


def test_demo_patterns():
    pytest.importorskip('rclpy')
    from worm_gear_sim import Config
    from worm_gear_sim.ros.demo_commander import command_pattern
    cfg = Config()
    paper = command_pattern('paper', cfg)
    target = cfg.input.target_angle
    # rest, forward move done after 20 ms, back move 0.5 s later, forward again
    np.testing.assert_allclose(paper([0.0, 0.05, 0.07, 0.3, 0.57, 0.9, 1.07]),
                               [0.0, 0.0, target, target, 0.0, 0.0, target], atol=1e-15)
    slew = command_pattern('slew', cfg, slew_rate=2.0, slew_period=2.0)
    np.testing.assert_allclose(slew([0.0, 1.0, 2.0, 3.0, 4.0]), [0.0, 2.0, 4.0, 2.0, 0.0])
    with pytest.raises(ValueError):
        command_pattern('zigzag', cfg)


@pytest.mark.ros
def test_demo_commander_with_node(ros_subprocess_env, tmp_path):
    pytest.importorskip('rclpy')
    cfg = ROOT / 'config' / 'worm_gear_sim.yaml'
    log = open(tmp_path / 'node.log', 'w+')
    node = subprocess.Popen([sys.executable, '-m', 'worm_gear_sim.node', '--ros-args',
                             '--params-file', str(cfg), '--log-level', 'warn'], cwd=ROOT,
                            env=ros_subprocess_env, stdout=log, stderr=subprocess.STDOUT)
    try:
        demo = subprocess.run([sys.executable, '-m', 'worm_gear_sim.demo_commander',
                               '--duration', '2', '--pattern', 'paper'], cwd=ROOT,
                              env=ros_subprocess_env, capture_output=True, text=True,
                              timeout=180)
    finally:
        node.send_signal(signal.SIGTERM)
        try:
            node_rc = node.wait(timeout=30)
        except subprocess.TimeoutExpired:
            node.kill()
            node_rc = node.wait()
        log.seek(0)
        node_text = log.read()
        log.close()
    out = demo.stdout + demo.stderr
    assert demo.returncode == 0, out + node_text
    m = re.search(r'demo done: (\d+) commands sent, (\d+) joint_states received, largest '
                  r'antenna error ([0-9.]+) urad', out)
    assert m, out
    assert int(m.group(1)) > 500 and int(m.group(2)) > 500
    assert 10.0 < float(m.group(3)) < 1e4          # the 18-step move rings the antenna
    assert re.search(r'error +[-+][0-9.]+ urad', out), out
    assert node_rc == 0 and 'Traceback' not in node_text, node_text
