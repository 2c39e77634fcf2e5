# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``worm_gear_sim_calibrate`` under hostile use: options out of range refused in one
line before anything starts (a NaN settle timeout would wait forever); Ctrl-C, during the
start-up imports or while it waits for the node, ends the process with one line
"interrupted; nothing applied", exit 130, no traceback (as a process); it asks before it
moves the axis."""

from __future__ import annotations

import io
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from worm_gear_sim.ros.calibrate import EXIT_INTERRUPTED, INTERRUPTED, main

pytest.importorskip('rclpy')

pytestmark = pytest.mark.ros

ARGS = ['--fit', 'geometry.flywheel_radius', '--servo-topic', '/servo', '--serial']


@pytest.mark.parametrize('value', ['nan', 'inf', '-inf', '0', '-1'])
def test_a_settle_timeout_that_is_not_a_finite_positive_time_is_refused(value, tmp_path,
                                                                          capsys):
    assert main([*ARGS, '-o', str(tmp_path / 'f.yaml'), f'--settle-timeout={value}']) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f'worm_gear_sim_calibrate: --settle-timeout '
                                               f'{float(value)!r}'), err


class _Terminal(io.StringIO):
    """A stdin that is a terminal, with the user's answer typed in."""

    def isatty(self) -> bool:
        return True


@pytest.mark.parametrize('stdin, status, words', [
    (io.StringIO(''), 2, ['stdin is not a terminal', '--yes', 'nothing moved']),
    (_Terminal('n\n'), 1, ['not confirmed', 'nothing moved']),
    (_Terminal('\n'), 1, ['not confirmed']),
])
def test_it_asks_before_it_moves_the_axis(stdin, status, words, tmp_path, capsys,
                                          monkeypatch):
    """The live calibrator streamed the excitation to the servo without asking; now it asks
    (--yes skips it), and a stdin nobody can answer from is refused, before any ROS
    entity exists (the node named here does not exist: asked first, it would wait 30 s)."""
    monkeypatch.setattr(sys, 'stdin', stdin)
    t0 = time.monotonic()
    assert main([*ARGS, '-o', str(tmp_path / 'f.yaml'), '--node', '/no_such_node']) == status
    assert time.monotonic() - t0 < 20
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and all(w in lines[0] for w in words), err
    if isinstance(stdin, _Terminal):
        assert 'Move it? [y/N]' in out and '/servo' in out and '0.12 rad each way' in out


def test_a_yes_at_the_prompt_goes_on(tmp_path):
    from worm_gear_sim.ros.calibrate import _args, consent
    opts = _args([*ARGS, '-o', str(tmp_path / 'f.yaml')])
    assert consent(opts, _Terminal('y\n'), io.StringIO()) is None
    assert consent(opts, io.StringIO(''), io.StringIO())[0] == 2
    assert consent(_args([*ARGS, '-o', str(tmp_path / 'f.yaml'), '--yes']),
                   io.StringIO(''), io.StringIO()) is None


def _start(env, tmp_path: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, '-m', 'worm_gear_sim.ros.calibrate', *ARGS, '-o',
         str(tmp_path / 'f.yaml'), '--node', '/no_such_node', '--yes'],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _interrupted(proc: subprocess.Popen, tmp_path: Path) -> None:
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == EXIT_INTERRUPTED, (proc.returncode, out, err)
    assert err.strip().splitlines() == [INTERRUPTED], err
    assert not (tmp_path / 'f.yaml').exists()


def test_ctrl_c_while_starting_one_line_exit_130(ros_subprocess_env, tmp_path):
    proc = _start(ros_subprocess_env, tmp_path)
    try:
        maps = Path(f'/proc/{proc.pid}/maps')
        t0 = time.monotonic()
        while 'numpy' not in maps.read_text() and time.monotonic() - t0 < 60:
            time.sleep(0.005)                # its heavy imports have begun
        _interrupted(proc, tmp_path)
    finally:
        proc.kill()
        proc.wait()


def test_ctrl_c_while_waiting_for_the_node_one_line_exit_130(ros_dds_context,
                                                             ros_subprocess_env, tmp_path):
    import rclpy
    probe = rclpy.create_node('calibrator_watch', context=ros_dds_context)
    proc = _start(ros_subprocess_env, tmp_path)
    try:
        t0 = time.monotonic()
        while 'worm_gear_sim_calibrator' not in probe.get_node_names():
            assert proc.poll() is None and time.monotonic() - t0 < 60, proc.communicate()
            time.sleep(0.05)                 # it is on the graph, asking /no_such_node
        _interrupted(proc, tmp_path)
    finally:
        probe.destroy_node()
        proc.kill()
        proc.wait()
