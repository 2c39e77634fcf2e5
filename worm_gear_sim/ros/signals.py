# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The node process's signal handling in phases (SIGINT and SIGTERM); standard library only,
so that :func:`worm_gear_sim.ros.startup.node_main` installs it before the heavy imports.

* ``starting`` (before ``rclpy.init``): raise ``SystemExit(0)``: unwinds the imports quietly;
* ``ros`` (from ``rclpy.init`` on): nothing here.  rclpy's own handler, installed by
  ``rclpy.init`` in front of this one, shuts the context down; parameter declaration and
  the spin loop end on that (an exception raised here could cross a C++ frame of rclpy's
  executor, which aborts the process);
* ``stopping``: ignored (a second Ctrl-C must not interrupt the clean-up).

:mod:`.startup` installs the handlers, :mod:`.run` moves the phase on.
"""

from __future__ import annotations

import signal
from typing import Any

__all__ = ['install_signal_handlers', 'set_phase', 'phase', 'signalled']

_state = {'phase': 'starting', 'signalled': ''}


def _on_signal(signum: int, frame: Any) -> None:
    if _state['phase'] == 'starting':
        _state['signalled'] = 'yes'
        raise SystemExit(0)


def install_signal_handlers() -> None:
    """SIGINT and SIGTERM -> :func:`_on_signal` (phase ``starting``).  Idempotent."""
    _state['phase'] = 'starting'
    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)


def set_phase(name: str) -> None:
    """``starting`` | ``ros`` | ``stopping`` (see the module docstring)."""
    if name not in ('starting', 'ros', 'stopping'):
        raise ValueError(f'unknown phase {name!r}')
    _state['phase'] = name


def phase() -> str:
    return _state['phase']


def signalled() -> bool:
    """True once SIGINT/SIGTERM arrived during the ``starting`` phase: the SystemExit the
    handler raised may have been swallowed by a library's broad ``except`` on the way, so the
    start-up checks this before it goes on to spin."""
    return bool(_state.get('signalled'))
