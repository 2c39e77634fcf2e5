# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Start-up of the node as a process (``python -m worm_gear_sim.node``): every configuration
error gives one line naming the cause and exit code 2, never a traceback; Ctrl-C or SIGTERM
at any moment of the start-up (imports of numpy/scipy/numba/rclpy, rclpy.init, parameter
declaration) ends it quietly."""

from __future__ import annotations

import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip('rclpy')

pytestmark = pytest.mark.ros

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / 'config' / 'worm_gear_sim.yaml'
ERROR_PREFIX = 'worm_gear_sim_node: error: '


def _file(tmp_path: Path, name: str, text: str) -> str:
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def _cases(tmp_path: Path) -> list[tuple[list[str], list[str]]]:
    """(ROS arguments, words the one error line must contain)."""
    cfg = CONFIG.read_text()
    misspelt = cfg.replace('    module:', '    modulee:', 1)
    assert misspelt != cfg
    kinetic = cfg.replace('mu_kinetic:', 'mu_kinectic:', 1)
    assert kinetic != cfg
    d = tmp_path / 'a_directory.yaml'
    d.mkdir()
    return [
        (['--params-file', str(tmp_path / 'missing.yaml')], ['missing.yaml', 'no such file']),
        (['--params-file', str(d)], ['a_directory.yaml', 'not a regular file']),
        (['--params-file', _file(tmp_path, 'broken.yaml', 'worm_gear_sim:\n  ros__parameters:'
                                 '\n    geometry:\n      module: [3.0\n')],
         ['broken.yaml', 'line']),
        (['--params-file', _file(tmp_path, 'noros.yaml', 'worm_gear_sim:\n  params:\n    x: 1\n')],
         ['noros.yaml', 'ros__parameters']),
        (['--params-file', _file(tmp_path, 'misspelt.yaml', misspelt)],
         ['geometry.modulee', 'did you mean geometry.module?']),
        (['--params-file', _file(tmp_path, 'kinetic.yaml', kinetic)],
         ['friction.mu_kinectic', 'did you mean friction.mu_kinetic?']),
        (['--params-file', str(CONFIG), '-p', 'friction.mu_kinectic:=0.05'],
         ['friction.mu_kinectic', 'did you mean friction.mu_kinetic?']),
        (['-p', 'qos_overrides./worm_angle_comand.subscription.reliability:=reliable'],
         ['worm_angle_comand', 'did you mean qos_overrides./worm_angle_command.subscription'
                               '.reliability?']),
        (['-p', 'friction.mu_kinetic'], ["'-p friction.mu_kinetic'"]),
        (['-p', 'friction.mu_kinetic:=[1,'], ["'-p friction.mu_kinetic:=[1,'"]),
        (['-p', 'friction.mu_kinetic:=7.0'], ['friction.mu_kinetic', 'range']),
        (['-p', 'friction.mu_kinetic:=5'], ['friction.mu_kinetic', 'INTEGER', 'DOUBLE']),
        (['-p', 'friction.model:=coulomb'], ['friction.model', 'coulomb']),
        (['-p', 'input.accel_time:=0.5'], ['input.accel_time', 'move_time']),
    ]


def test_every_configuration_error_is_one_line_and_exit_code_2(tmp_path, ros_subprocess_env):
    cases = _cases(tmp_path)
    procs = []
    for i, (ros_args, _) in enumerate(cases):   # all at once: each start costs seconds
        out = open(tmp_path / f'out{i}.txt', 'w+')
        procs.append((subprocess.Popen(
            [sys.executable, '-m', 'worm_gear_sim.node', '--ros-args', *ros_args],
            cwd=ROOT, env=ros_subprocess_env, stdout=out, stderr=subprocess.STDOUT), out))
        if i % 4 == 3:
            procs[-1][0].wait(timeout=180)
    failures = []
    for (proc, out), (ros_args, words) in zip(procs, cases):
        try:
            rc = proc.wait(timeout=180)
        except subprocess.TimeoutExpired:
            proc.kill()
            rc = 'timeout (the node started: the error was not detected)'
        out.seek(0)
        text = out.read()
        out.close()
        lines = [ln for ln in text.splitlines() if ln.strip()]
        ok = (rc == 2 and len(lines) == 1 and lines[0].startswith(ERROR_PREFIX)
              and all(w in lines[0] for w in words) and 'Traceback' not in text)
        if not ok:
            failures.append(f'{ros_args}: rc {rc}, expected words {words}:\n{text}')
    assert not failures, '\n\n'.join(failures)


def _catches_sigterm(pid: int) -> bool:
    """The process has a handler for SIGTERM (/proc SigCgt): the entry point has started.
    Python itself catches only SIGINT; before the entry point runs, the interpreter is
    still starting up (site, encodings: ~30 ms) and no code of the package can act."""
    try:
        for line in Path(f'/proc/{pid}/status').read_text().splitlines():
            if line.startswith('SigCgt:'):
                return bool(int(line.split()[1], 16) >> (signal.SIGTERM - 1) & 1)
    except OSError:
        pass
    return False


def test_early_signals_end_the_start_up_quietly(ros_subprocess_env):
    """30 SIGINT/SIGTERM at random moments of the start-up (imports of numpy, scipy, numba
    and rclpy, rclpy.init, parameter declaration, first spin), counted from the moment the
    entry point has installed its handlers: never a traceback, never a hang, exit code 0."""
    rng = random.Random(20261123)
    plan = [((signal.SIGINT, signal.SIGTERM)[i % 2], rng.uniform(0.0, 2.5)) for i in range(30)]
    failures = []
    for batch in range(0, len(plan), 5):            # 5 at a time: bounded wall time
        procs = []
        t0 = time.monotonic()
        for sig, delay in plan[batch:batch + 5]:
            procs.append((sig, delay, subprocess.Popen(
                [sys.executable, '-m', 'worm_gear_sim.node', '--ros-args', '--params-file',
                 str(CONFIG)], cwd=ROOT, env=ros_subprocess_env, stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT, text=True)))
        started = {}
        while len(started) < len(procs) and time.monotonic() - t0 < 60.0:
            for _, _, p in procs:
                if p.pid not in started and _catches_sigterm(p.pid):
                    started[p.pid] = time.monotonic()
            time.sleep(0.0005)
        for sig, delay, p in sorted(procs, key=lambda x: started.get(x[2].pid, t0) + x[1]):
            time.sleep(max(0.0, started.get(p.pid, t0) + delay - time.monotonic()))
            p.send_signal(sig)
        for sig, delay, p in procs:
            try:
                text, _ = p.communicate(timeout=60)
            except subprocess.TimeoutExpired:
                p.kill()
                text = p.communicate()[0]
                failures.append(f'{sig.name} after {delay:.3f} s: hang\n{text}')
                continue
            if p.returncode != 0 or 'Traceback' in text or 'Fatal' in text:
                failures.append(f'{sig.name} after {delay:.3f} s: rc {p.returncode}\n{text}')
    assert not failures, '\n\n'.join(failures)
