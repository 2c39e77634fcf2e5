# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Child processes of the tests (the node, the demo, an installed executable): started with
stdout and stderr in one log file, stopped with a signal (killed if it does not end in
time), their log read back."""

from __future__ import annotations

import signal
import subprocess
from collections.abc import Sequence
from pathlib import Path
from typing import IO

ROOT = Path(__file__).resolve().parent.parent


def start_logged(args: Sequence[str], env: dict[str, str], log_path: Path,
                 cwd: Path = ROOT) -> tuple[subprocess.Popen, IO[str]]:
    """Start ``args`` with stdout and stderr going to ``log_path``."""
    log = open(log_path, 'w+')
    proc = subprocess.Popen(list(args), cwd=cwd, env=env, stdout=log,
                            stderr=subprocess.STDOUT)
    return proc, log


def stop_and_read(proc: subprocess.Popen, log: IO[str], sig: int = signal.SIGTERM,
                  timeout: float = 30.0) -> tuple[int | None, str]:
    """Send ``sig`` (if still running) and wait; kill after ``timeout`` s.  Returns the exit
    code (None if it had to be killed) and the whole log."""
    if proc.poll() is None:
        proc.send_signal(sig)
    try:
        rc: int | None = proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        rc = None
    log.seek(0)
    text = log.read()
    log.close()
    return rc, text


def cli_in_process(*args: object) -> subprocess.CompletedProcess:
    """``worm-gear-sim ARGS`` through its whole entry point (``cli.main``: parsing, the run,
    the one-line errors and exit codes) in this process: what a process would show, without
    the interpreter's start (~3 s a call).  test/cli/test_cli.py runs the executable itself."""
    import contextlib
    import io

    from worm_gear_sim import cli
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = cli.main([str(a) for a in args])
    return subprocess.CompletedProcess([str(a) for a in args], status, out.getvalue(),
                                       err.getvalue())
