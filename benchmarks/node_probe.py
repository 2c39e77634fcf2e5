# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""What the node benchmarks (bench_node.py, bench_soak.py) share: the node as a child process
(started with its log in a file and stopped with a signal by the tests' helpers,
test/processes.py), the probe's measuring phases with the node's CPU over the measured
span, the slew command, and ticks lost between JointState stamps."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import IO, Any

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / 'test'))
from processes import start_logged, stop_and_read  # noqa: E402

PARAMS_FILE = ROOT / 'config' / 'worm_gear_sim.yaml'
#: seconds the probe waits for the node's first JointState (the first start compiles numba)
ANSWER_TIMEOUT = 120.0


def proc_cpu_seconds(pid: int) -> float:
    """utime + stime of a process (all threads) in seconds."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def slew(t: float, rate: float = 0.5, amplitude: float = 0.5) -> float:
    """Triangle: constant rate back and forth between +-amplitude [rad of worm]."""
    period = 4.0 * amplitude / rate
    x = (t % period) / period
    return amplitude * (4.0 * x - 1.0 if x < 0.5 else 3.0 - 4.0 * x)


def start_node(log_path: Path, *, executor: str | None = None, log_level: str = 'warn',
               ros_args: Sequence[str] = ()) -> tuple[subprocess.Popen, IO[str]]:
    """``python -m worm_gear_sim.ros`` with the package's params file (and ``ros_args``
    after it), stdout and stderr in ``log_path``."""
    cmd = [sys.executable, '-m', 'worm_gear_sim.ros']
    if executor:
        cmd += ['--executor', executor]
    cmd += ['--ros-args', '--params-file', str(PARAMS_FILE), *ros_args,
            '--log-level', log_level]
    return start_logged(cmd, dict(os.environ), log_path)


def stop_node(proc: subprocess.Popen, log: IO[str], sig: int = signal.SIGINT,
              timeout: float = 20.0) -> tuple[int | None, str]:
    """Signal the node, wait (kill after ``timeout`` s): (exit code or None, its log)."""
    return stop_and_read(proc, log, sig, timeout)


def spin_until_done(executor: Any, done: Any, linger: float = 0.0) -> None:
    """Spin the probe's executor until the future ``done`` completes, then ``linger`` s more
    (answers and diagnostics still on their way)."""
    from rclpy.task import Future
    while not done.done():
        executor.spin_until_future_complete(done, timeout_sec=1.0)
    end = time.monotonic() + linger
    while time.monotonic() < end:
        executor.spin_until_future_complete(Future(), timeout_sec=0.1)


class Phases:
    """The probe's phases: ``wait`` for the node's first answer, ``warm`` for ``warmup`` s,
    ``measure`` for ``duration`` s (the node's CPU is read at both ends), then done.
    :meth:`update` from the probe's timer returns the event of that call: 'start' (measuring
    begins), 'end' (measured, or ``error`` set: the node exited or never answered) or ''."""

    def __init__(self, proc: subprocess.Popen, warmup: float, duration: float,
                 t_start: float) -> None:
        self.proc, self.warmup, self.duration, self.t_start = proc, warmup, duration, t_start
        self.phase = 'wait'
        self.error = ''
        self.t_warm = self.wall0 = self.wall1 = self.cpu0 = self.cpu1 = 0.0

    def update(self, now: float, answered: bool) -> str:
        if self.proc.poll() is not None:
            self.error = f'node process exited with {self.proc.returncode}'
            return 'end'
        if self.phase == 'wait' and answered:
            self.phase, self.t_warm = 'warm', now
        elif self.phase == 'warm' and now - self.t_warm >= self.warmup:
            self.phase = 'measure'
            self.cpu0, self.wall0 = proc_cpu_seconds(self.proc.pid), now
            return 'start'
        elif self.phase == 'measure' and now - self.wall0 >= self.duration:
            self.cpu1, self.wall1 = proc_cpu_seconds(self.proc.pid), now
            self.phase = 'done'
            return 'end'
        elif self.phase == 'wait' and now - self.t_start > ANSWER_TIMEOUT:
            self.error = f'no JointState from the node within {ANSWER_TIMEOUT:g} s'
            return 'end'
        return ''

    @property
    def wall(self) -> float:
        """Measured span [s]."""
        return self.wall1 - self.wall0

    @property
    def cores(self) -> float:
        """CPU of the node over the measured span [cores]."""
        return (self.cpu1 - self.cpu0) / self.wall


def lost_periods(stamps_ns: Sequence[int] | np.ndarray, period_ns: float,
                 max_gap: float = np.inf) -> int:
    """Periods lost between consecutive stamps: a gap of g periods (g > 1.5) loses
    round(g) - 1; gaps of ``max_gap`` periods or more (an input path switched) are not
    counted."""
    gaps = np.diff(np.asarray(stamps_ns, dtype=np.int64)) / period_ns
    return int(np.sum(np.round(gaps[(gaps > 1.5) & (gaps < max_gap)]) - 1))
