# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The node process's signal handling in phases (SIGINT and SIGTERM); standard library only,
so that :func:`worm_gear_sim.ros.startup.node_main` installs it before the heavy imports.

* ``starting`` (imports, argument and params-file checks, before ``rclpy.init``): flush
  stdout/stderr and end the process at once with exit code 0 (``os._exit``).  Nothing needs
  cleaning up yet, and unwinding instead (raising ``SystemExit``) can interrupt the
  initialisation of a C extension module (numba, llvmlite, rclpy's pybind11 module) whose
  half-built state the interpreter then frees at exit: "free(): double free detected",
  SIGABRT, seen once in 30 signals during the imports under CI load;
* ``init`` (``rclpy.init`` and the node's construction): record the signal only.  rclpy is
  initialised without its signal handlers, so nothing shuts the context down under the
  construction; :mod:`.run` checks :func:`signalled` when the node is built and ends with
  exit code 0 (node destroyed, ``rclpy.try_shutdown``);
* ``ros`` (the node is built; :mod:`.run` then installs rclpy's handlers in front of this
  one): nothing here.  rclpy's handler shuts the context down and wakes the executor; the
  spin loop ends on that (an exception raised here could cross a C++ frame of rclpy's
  executor, which aborts the process);
* ``stopping``: ignored (a second Ctrl-C must not interrupt the clean-up).

:mod:`.startup` installs the handlers, :mod:`.run` moves the phase on.
"""

from __future__ import annotations

import os
import signal
import sys
from typing import Any

__all__ = ['install_signal_handlers', 'set_phase', 'phase', 'signalled']

PHASES = ('starting', 'init', 'ros', 'stopping')

_state = {'phase': 'starting', 'signalled': ''}


def _exit_now() -> None:
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:  # noqa: BLE001 - a closed or broken pipe: exit regardless
            pass
    os._exit(0)


def _on_signal(signum: int, frame: Any) -> None:
    current = _state['phase']
    if current in ('starting', 'init'):
        _state['signalled'] = 'yes'
    if current == 'starting':
        _exit_now()


def install_signal_handlers() -> None:
    """SIGINT and SIGTERM -> :func:`_on_signal` (phase ``starting``).  Idempotent."""
    _state['phase'] = 'starting'
    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)


def set_phase(name: str) -> None:
    """``starting`` | ``init`` | ``ros`` | ``stopping`` (see the module docstring)."""
    if name not in PHASES:
        raise ValueError(f'unknown phase {name!r}')
    _state['phase'] = name


def phase() -> str:
    return _state['phase']


def signalled() -> bool:
    """True once SIGINT/SIGTERM arrived before the ``ros`` phase (during ``rclpy.init``)."""
    return bool(_state.get('signalled'))
