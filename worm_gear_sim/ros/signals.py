# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The node process's signal handling in phases (SIGINT and SIGTERM); standard library only,
so that ``startup.node_main`` installs it before the heavy imports.

The phases: ``starting`` (exit 0 at once, no unwinding through half-imported extension
modules), ``init`` (the signal recorded, :func:`signalled`), ``ros`` (rclpy's handlers in
front), ``stopping`` (ignored).  :mod:`.startup` installs the handlers, :mod:`.run` moves
the phase on.
"""

from __future__ import annotations

import os
import signal
import sys
from typing import Any

__all__ = ['install_signal_handlers', 'set_phase', 'phase', 'signalled', 'ignore_from_now']

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


def ignore_from_now() -> None:
    """The process is ending (rclpy shut down): SIGINT and SIGTERM ignored from now on, by
    the OS, through the interpreter's exit."""
    _state['phase'] = 'stopping'
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
