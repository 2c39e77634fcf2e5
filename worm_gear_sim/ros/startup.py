# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The one start-up path of the node's entry points: signals first, then the heavy imports.

``worm_gear_sim_node`` (console script) and ``python -m worm_gear_sim.node`` call
:func:`node_main`, which installs the start-up signal handlers BEFORE numpy, scipy, numba and
rclpy are imported (that takes seconds), so Ctrl-C or SIGTERM at any moment of the start-up
ends the process quietly with exit code 0.  Every configuration error (broken, missing or
unreadable params file, malformed ``-p``, unknown or misspelt parameter, invalid or unusable
value) ends it with one line on stderr naming the cause, and exit code
:data:`EXIT_CONFIG_ERROR` (2).  This module imports only the standard library.

Phases of the signal handler (SIGINT and SIGTERM):

* ``starting`` (before ``rclpy.init``): raise ``SystemExit(0)``: unwinds the imports quietly;
* ``ros`` (from ``rclpy.init`` on): nothing here.  rclpy's own handler, installed by
  ``rclpy.init`` in front of this one, shuts the context down; parameter declaration and
  the spin loop end on that (an exception raised here could cross a C++ frame of rclpy's
  executor, which aborts the process);
* ``stopping``: ignored (a second Ctrl-C must not interrupt the clean-up).
"""

from __future__ import annotations

import os
import re
import signal
import sys
from typing import Any

__all__ = ['EXIT_CONFIG_ERROR', 'node_main', 'install_signal_handlers', 'set_phase',
           'phase', 'signalled', 'config_error', 'clean_rcl_message', 'check_params_files']

EXIT_CONFIG_ERROR = 2
PROGRAM = 'worm_gear_sim_node'

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


_RCL_LOCATION = re.compile(r',? at [^,]*\.c(pp)?:\d+')


def clean_rcl_message(text: str) -> str:
    """An rcl error on one line, without the C source locations
    (``..., at /project/src/rcl/arguments.c:352``) and rcl's generic prefixes."""
    text = _RCL_LOCATION.sub('', str(text))
    for prefix in ('failed to initialize rcl: ', 'Failed to parse ROS arguments: '):
        text = text.replace(prefix, '')
    return ' '.join(text.split())


def check_params_files(argv: list[str]) -> str:
    """'' if every ``--params-file`` in ``argv`` is a readable regular file, else the
    reason (rcl's own message for these cases is "Error opening YAML file" or a parse
    error at line 0)."""
    for flag, path in zip(argv, argv[1:]):
        if flag != '--params-file':
            continue
        if not os.path.exists(path):
            return f'params file {path}: no such file'
        if not os.path.isfile(path):
            return f'params file {path}: not a regular file'
        if not os.access(path, os.R_OK):
            return f'params file {path}: not readable (permission denied)'
    return ''


def config_error(text: str) -> int:
    """Print the one-line start-up error and return :data:`EXIT_CONFIG_ERROR`."""
    print(f'{PROGRAM}: error: {" ".join(str(text).split())}', file=sys.stderr, flush=True)
    return EXIT_CONFIG_ERROR


def node_main(args: list[str] | None = None) -> int:
    """Entry point of ``worm_gear_sim_node``: handlers first, then import and run the node."""
    install_signal_handlers()
    try:
        from .run import main  # numpy, scipy, numba, rclpy: seconds on a loaded machine
    except BaseException:
        # The handler's SystemExit can reach us wrapped by the import machinery: as
        # "ImportError: initialization failed" from a C extension's module initialisation
        # (rclpy's pybind11 module) or as a RuntimeError from a class's __set_name__.
        if _state.get('signalled'):
            return 0
        raise
    return main(args)


if __name__ == '__main__':  # pragma: no cover - python -m worm_gear_sim.ros.startup
    sys.exit(node_main())
