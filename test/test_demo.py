# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The demo of README command #1 (worm_gear_sim.ros.demo_commander): its patterns, its move
summaries against a direct computation, lines that fit 80 columns, and the demo with the
node as two processes (bounded in time; assertions on what was computed, never on how fast):
one updating line in an 80-column pseudo-terminal, one line per move otherwise, and the
stamped interface with the feed-forward applied showing its benefit in numbers."""

from __future__ import annotations

import math
import os
import re
import select
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from processes import start_logged, stop_and_read

pytest.importorskip('rclpy')

from worm_gear_sim import Config  # noqa: E402
from worm_gear_sim.ros.demo_report import LINE_WIDTH, MOVE_HEADER, format_move, format_status
from worm_gear_sim.studies.compensation_eval import SETTLE_TOLERANCE  # noqa: E402
from worm_gear_sim.studies.demo_moves import (
    MoveSummary,
    MoveTracker,
    command_pattern,
    pattern_segments,
)

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / 'config' / 'worm_gear_sim.yaml'
MODE_HZ = 94.51
# The uncompensated stamped test streams at 250 Hz (the demo's default is 1 kHz): the same
# stamped path, a quarter of the messages, so that a machine busy with other work keeps up.
# The feed-forward is designed for the 1 kHz command period (at 250 Hz it makes the ringing
# worse, 817 urad against 242 urad without, measured): its test streams at 1 kHz.
LIGHT = ('--rate', '250')


def test_demo_patterns():
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
    seg = pattern_segments('paper', cfg)
    # each segment holds exactly one move, which starts at the segment's start
    for k in range(4):
        a = seg.first + k * seg.period
        assert paper(a) == paper(a - 1e-3) and paper(a + seg.motion) != paper(a)


def _ringing(t: np.ndarray, start: float, motion: float, amp: float, tau: float):
    """A move's error: a lag during the motion, then a decaying ring at the antenna mode."""
    s = t - start - motion
    during = (t >= start) & (s < 0)
    return np.where(during, 2 * amp, np.where(s >= 0, amp * np.exp(-s / tau)
                                              * np.cos(2 * np.pi * MODE_HZ * s), 0.0))


def test_move_tracker_against_a_direct_computation():
    cfg = Config()
    seg = pattern_segments('paper', cfg)
    t = np.arange(0.0, 2.0, 1e-3)
    taus = [0.01, 0.02, 0.004, 1.0]          # one move per segment, different decay
    e = np.zeros_like(t)
    for k, tau in enumerate(taus):
        a = seg.first + k * seg.period
        inside = (t >= a) & (t < a + seg.period)
        e[inside] = _ringing(t[inside], a, seg.motion, 300e-6, tau)
    tracker = MoveTracker(seg, MODE_HZ)
    done = [m for ti, ei in zip(t, e) if (m := tracker.add(float(ti), float(ei)))]
    assert [m.index for m in done] == [0, 1, 2]        # move 3 is cut by the end of data
    for m, tau in zip(done, taus):
        a = seg.first + m.index * seg.period
        inside = (t >= a) & (t < a + seg.period)
        tm, em = t[inside] - a, e[inside]
        assert m.peak == pytest.approx(600e-6)
        after = tm >= seg.motion
        assert m.ringing == pytest.approx(np.max(np.abs(em[after])), rel=1e-3)
        out = np.nonzero(after & (np.abs(em) > SETTLE_TOLERANCE))[0]
        settle = tm[out[-1] + 1] - seg.motion
        assert m.settling == pytest.approx(settle, abs=1e-9)
        # the envelope crosses the band at tau ln(30), within one period of the ring
        assert settle == pytest.approx(tau * math.log(300 / 10), abs=1 / MODE_HZ)
        assert m.label == ('fwd', 'back')[m.index % 2]
    # a move that never leaves the band is settled at once; a gap drops the move
    tracker = MoveTracker(seg, MODE_HZ)
    for ti in t:
        if not 0.7 < ti < 0.75:                 # 50 ms gap in move 1
            tracker.add(float(ti), 1e-6)
    assert [m.index for m in tracker.moves] == [0, 2]
    assert tracker.moves[0].settling == 0.0 and tracker.incomplete == 1


def test_lines_fit_80_columns():
    worst = MoveSummary(12345, 'back', 12345.678, 1.0, 123.0, math.inf, 0.5, 10)
    assert len(format_move(worst)) <= LINE_WIDTH
    # realistic moves fit without being cut
    slew = MoveSummary(9999, 'down', 9999.5, 1234.5e-6, 999.99e-6, math.inf, 123.45e-6, 500)
    paper = MoveSummary(3, 'fwd', 1.55, 400e-6, 320e-6, 3.4e-3, math.nan, 500)
    for m in (slew, paper):
        line = format_move(m)
        assert len(line) <= LINE_WIDTH and not line.endswith('>'), line
    assert len(MOVE_HEADER) <= LINE_WIDTH
    assert '320.00' in format_move(paper) and '3.4 ms' in format_move(paper)
    assert ' 123.45 ' in format_move(slew) and 'never' in format_move(slew)
    # the columns line up under the header
    for m in (slew, paper):
        assert len(format_move(m)) == len(MOVE_HEADER)
    for e in (0.0, -3e-4, 2.5e-4, 1.0, -1e9, math.nan, math.inf):
        for last in (None, worst, slew, paper):
            s = format_status(99999.9, e, 50e-6, last, extra=' ff  +12.34')
            assert len(s) < LINE_WIDTH, s
            assert '\n' not in s and '\r' not in s
    s = format_status(1234.5, -12.3e-6, 50e-6, slew, extra=' ff  +12.34')
    assert not s.endswith('>'), s


# ---- the demo and the node as processes ----------------------------------------------------
def _start_node(env: dict[str, str], log_path: Path, *extra: str) -> tuple:
    return start_logged([sys.executable, '-m', 'worm_gear_sim.ros', '--ros-args',
                         '--params-file', str(CONFIG), '--log-level', 'warn', *extra],
                        env, log_path)


def _demo(node: subprocess.Popen, env: dict[str, str], *args: str,
          timeout: float = 240.0) -> subprocess.CompletedProcess:
    """Run the demo to its end; stop it at once if the node dies first (bounded)."""
    demo = subprocess.Popen([sys.executable, '-m', 'worm_gear_sim.ros.demo_commander', *args],
                            cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + timeout
    while demo.poll() is None and node.poll() is None and time.monotonic() < deadline:
        time.sleep(0.2)
    if demo.poll() is None:
        demo.kill()
    out, err = demo.communicate(timeout=30)
    if node.poll() is not None and demo.returncode != 0:
        err += f'\n[the node exited with {node.returncode} before the demo ended]'
    return subprocess.CompletedProcess(demo.args, demo.returncode, out, err)


@pytest.mark.ros
def test_demo_float64_one_line_per_move(ros_subprocess_env, tmp_path):
    node, log = _start_node(ros_subprocess_env, tmp_path / 'node.log')
    try:
        demo = _demo(node, ros_subprocess_env, '--interface', 'float64', '--duration', '2')
    finally:
        node_rc, node_text = stop_and_read(node, log)
    out = demo.stdout + demo.stderr
    assert demo.returncode == 0, out + node_text
    lines = demo.stdout.splitlines()
    assert all(len(ln) <= LINE_WIDTH for ln in lines), out
    i = lines.index(MOVE_HEADER)
    moves = [ln for ln in lines[i + 1:] if re.match(r' +\d+ (fwd|back) ', ln)]
    assert len(moves) >= 1, out                    # 2 s of paper moves, one every 0.5 s
    assert 'feed-forward not applied' in out
    m = re.search(r'(\d+) moves without feed-forward: ringing median ([0-9.]+), max '
                  r'([0-9.]+) urad', out)
    assert m and int(m.group(1)) == len(moves), out
    assert 10.0 < float(m.group(2)) < 1e4          # the 18-step move rings the antenna
    assert node_rc == 0 and 'Traceback' not in node_text, node_text


@pytest.mark.ros
def test_demo_on_a_terminal_is_one_updating_line(ros_subprocess_env, tmp_path):
    import fcntl
    import pty
    import struct
    import termios
    node, log = _start_node(ros_subprocess_env, tmp_path / 'node.log')
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack('HHHH', 24, 80, 0, 0))
    chunks: list[bytes] = []
    try:
        demo = subprocess.Popen([sys.executable, '-m', 'worm_gear_sim.ros.demo_commander',
                                 '--interface', 'float64', '--duration', '2'], cwd=ROOT,
                                env=ros_subprocess_env, stdout=slave, stderr=slave,
                                stdin=subprocess.DEVNULL)
        os.close(slave)
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline and node.poll() is None:
            if not select.select([master], [], [], 0.2)[0]:
                continue
            try:
                data = os.read(master, 65536)
            except OSError:                         # EIO: the demo closed the terminal
                break
            if not data:
                break
            chunks.append(data)
        if demo.poll() is None:
            demo.kill()                             # the node died: stop now
        rc = demo.wait(timeout=30)
    finally:
        os.close(master)
        node_rc, node_text = stop_and_read(node, log)
    text = b''.join(chunks).decode(errors='replace').replace('\r\n', '\n')
    assert rc == 0, text + node_text
    head, sep, rest = text.partition('\r')          # banner, then the status line
    assert sep, text
    status, _, summary = rest.partition('\n')       # ONE line until the summary
    refreshes = status.split('\r')
    assert len(refreshes) >= 5, text                # refreshed while streaming
    for r in refreshes:
        assert len(r.replace('\x1b[K', '')) < 80, repr(r)
    assert re.search(r'e +[-+][0-9.]+ urad', status), text
    assert 'demo done' in summary and len(head.splitlines()) == 2, text
    assert all(len(ln) <= LINE_WIDTH for ln in head.splitlines() + summary.splitlines())
    assert node_rc == 0, node_text





def _numbers(pattern: str, text: str) -> tuple[float, ...]:
    m = re.search(pattern, text)
    assert m, text
    return tuple(float(g) for g in m.groups())


def _stamped_run(env: dict[str, str], tmp_path: Path, node_args: tuple, demo_args: tuple
                 ) -> tuple[str, str]:
    """Node + stamped demo; returns (demo stdout+stderr, node log).  The stamped results
    do not depend on timing unless the stream was interrupted: this process or the node
    starved of CPU for longer than the lead (a machine busy with other work), so that the
    node saw a paused stream.  The demo shows that as unanswered references or moves with
    gaps; then the run is repeated once, and the test skipped if it happens again."""
    for attempt in (1, 2):
        node, log = _start_node(env, tmp_path / f'node{attempt}.log', *node_args)
        try:
            demo = _demo(node, env, '--interface', 'stamped', *demo_args)
        finally:
            node_rc, node_text = stop_and_read(node, log)
        out = demo.stdout + demo.stderr
        assert demo.returncode == 0, out + node_text
        assert node_rc == 0 and 'Traceback' not in node_text, node_text
        sent, answered = _numbers(r'references (\d+), compensated commands (\d+)', out)
        if answered >= sent - 60 and 'moves with gaps' not in out:
            return out, node_text
    pytest.skip(f'the stream was interrupted twice (machine too busy): {out}')


@pytest.mark.ros
def test_demo_stamped_with_feedforward_shows_its_benefit(ros_subprocess_env, tmp_path):
    """The servo bridge (stamped mode) with the feed-forward applied: the live antenna error
    after each move is a small fraction of the model's without feed-forward (same moves,
    offline), and equals the offline compensated run (the stamped pipeline does not depend
    on arrival times)."""
    out, _ = _stamped_run(ros_subprocess_env, tmp_path,
                          ('-p', 'node.compensation_applied:=true'), ('--duration', '2.5'))
    assert all(len(ln) <= LINE_WIDTH for ln in out.splitlines()), out
    assert 'feed-forward applied' in out, out
    n, live, _ = _numbers(r'(\d+) moves with feed-forward: ringing median ([0-9.]+), '
                          r'max ([0-9.]+) urad', out)
    assert n >= 3, out
    without, with_ff = _numbers(r'offline, same moves: ringing ([0-9.]+) urad without, '
                                r'([0-9.]+) with feed-forward', out)
    assert without > 50.0                   # urad: the paper move rings the antenna
    assert live < 0.1 * without, out        # the benefit the compensated mode claims
    assert with_ff < 0.1 * without
    (dev,) = _numbers(r'live vs offline \(with feed-forward\): ringing differs by at most '
                      r'([0-9.e+-]+) rad', out)
    assert dev < 0.5e-6, out
    assert '=> ~/compensated_command applied' in out


@pytest.mark.ros
def test_demo_stamped_slew_matches_the_offline_model(ros_subprocess_env, tmp_path):
    out, _ = _stamped_run(ros_subprocess_env, tmp_path, (),
                          ('--pattern', 'slew', '--slew-period', '0.5', '--duration', '2.2',
                           *LIGHT))
    legs = [ln for ln in out.splitlines() if re.match(r' +\d+ (up|down) ', ln)]
    assert len(legs) >= 3, out
    for leg in legs:                        # t, peak, ringing, rms
        assert len(re.findall(r"\d+\.\d\d", leg)) == 4, leg
    assert 'feed-forward not applied' in out, out
    (dev,) = _numbers(r'live vs offline \(without feed-forward\): ringing differs by at '
                      r'most ([0-9.e+-]+) rad', out)
    assert dev < 0.5e-6, out


SCRIPT = Path(__file__).resolve().parents[1] / 'scripts' / 'run_demo.sh'


def test_run_demo_script_help_and_bad_arguments_before_any_set_up(tmp_path):
    """README command #1: --help prints the usage, a bad duration or pattern is one line on
    stderr and exit 2, checked before the venv set-up (VENV points at an empty directory,
    which the set-up would fill: it must stay empty)."""
    env = {**os.environ, 'VENV': str(tmp_path / 'venv')}
    out = subprocess.run(['bash', str(SCRIPT), '--help'], capture_output=True, text=True,
                         env=env, timeout=30)
    assert out.returncode == 0 and 'scripts/run_demo.sh [DURATION_S] [paper|slew]' in out.stdout
    for args, word in ((['abc'], "'abc'"), (['5', 'zigzag'], "'zigzag'"), (['-3'], "'-3'")):
        r = subprocess.run(['bash', str(SCRIPT), *args], capture_output=True, text=True,
                           env=env, timeout=30)
        assert r.returncode == 2, (args, r.stdout, r.stderr)
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and word in lines[0] and 'run_demo.sh' in lines[0], r.stderr
        assert 'Traceback' not in r.stderr and r.stdout == ''
    assert not (tmp_path / 'venv').exists()
