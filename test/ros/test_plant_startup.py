# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The plant node (``python -m worm_gear_sim.ros.plant``) as a process: a plant file the core
refuses, an encoder noise that is not a number >= 0, a record path where no file can be
written and a malformed option each end the start-up with one line and exit code 2, before
any reference comes (a broken file was a traceback, ``--noise nan`` a crash at the first
reference, ``--record /proc/x.npz`` a traceback at the exit)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip('rclpy')

pytestmark = pytest.mark.ros

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / 'config' / 'worm_gear_sim.yaml'
PREFIX = 'worm_gear_sim.ros.plant: error: '


def _cases(tmp_path: Path) -> list[tuple[list[str], list[str]]]:
    broken = tmp_path / 'broken.yaml'
    broken.write_text('worm_gear_sim:\n  ros__parameters:\n    geometry:\n      module: [3.0\n')
    unusable = tmp_path / 'unusable.yaml'
    unusable.write_text(CONFIG.read_text().replace('mu_kinetic: 0.0470713',
                                                   'mu_kinetic: -1.0'))
    return [
        (['--plant', str(broken)], ['--plant', 'broken.yaml', 'line']),
        (['--plant', str(unusable)], ['--plant', 'friction.mu_kinetic']),
        (['--plant', str(tmp_path / 'missing.yaml')], ['--plant', 'not found']),
        (['--plant', str(CONFIG), '--noise', 'nan'], ['noise nan', 'must be >= 0']),
        (['--plant', str(CONFIG), '--noise=-1e-6'], ['noise -1e-06']),
        (['--plant', str(CONFIG), '--encoder-bits', '99'], ['encoder_bits 99']),
        (['--plant', str(CONFIG), '--record', '/proc/x.npz'], ['--record /proc/x.npz']),
        (['--plant', str(CONFIG), '--record', str(tmp_path)], ['--record', 'is a directory']),
        (['--plant', str(CONFIG), '--noise', 'abc'], ['--noise', "'abc'"]),
    ]


def test_bad_plant_options_are_one_line_and_exit_code_2(tmp_path, ros_subprocess_env):
    cases = _cases(tmp_path)
    procs = []
    for i, (args, _) in enumerate(cases):      # started together: each start costs seconds
        out = open(tmp_path / f'out{i}.txt', 'w+')
        procs.append((subprocess.Popen([sys.executable, '-m', 'worm_gear_sim.ros.plant', *args],
                                       cwd=ROOT, env=ros_subprocess_env, stdout=out,
                                       stderr=subprocess.STDOUT), out))
        if i % 3 == 2:
            procs[-1][0].wait(timeout=120)
    failures = []
    for (proc, out), (args, words) in zip(procs, cases):
        try:
            rc = proc.wait(timeout=120)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
            rc = 'timeout (the plant started: the error was not detected)'
        out.seek(0)
        text = out.read()
        out.close()
        lines = [ln for ln in text.splitlines() if ln.strip()]
        ok = (rc == 2 and len(lines) == 1 and lines[0].startswith(PREFIX)
              and all(w in lines[0] for w in words) and 'Traceback' not in text)
        if not ok:
            failures.append(f'{args}: rc {rc}, expected words {words}:\n{text}')
    assert not failures, '\n\n'.join(failures)
