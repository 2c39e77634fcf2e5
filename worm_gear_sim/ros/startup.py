# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The one start-up path of the node's entry points: signals first, then the heavy imports.

``worm_gear_sim_node`` (console script) and ``python -m worm_gear_sim.ros`` call
:func:`node_main`, which installs the start-up signal handlers (:mod:`.signals`) BEFORE
numpy, scipy, numba and rclpy are imported (that takes seconds), so Ctrl-C or SIGTERM at any
moment of the start-up ends the process quietly with exit code 0.  Then :mod:`.run` (the
process) takes over: every configuration error (broken, missing or unreadable params file,
malformed ``-p``, unknown or misspelt parameter, invalid or unusable value) ends it with one
line on stderr naming the cause, and exit code 2 (:mod:`.config_errors`).  This module
imports only the standard library and :mod:`.signals`; :mod:`.run` is imported by
:func:`node_main` after the handlers are in place, and never imports this module back.
"""

from __future__ import annotations

import sys

from .signals import install_signal_handlers

__all__ = ['node_main', 'pedestal_main']


def node_main(args: list[str] | None = None) -> int:
    """Entry point of ``worm_gear_sim_node``: handlers first, then import and run the node."""
    install_signal_handlers()
    # A signal during these imports ends the process at once (exit 0, see .signals): the
    # imports are never unwound half-way through a C extension's initialisation.
    from .run import main  # numpy, scipy, numba, rclpy: seconds on a loaded machine
    return main(args)


def pedestal_main(args: list[str] | None = None) -> int:
    """Entry point of ``worm_gear_sim_pedestal`` (:mod:`.pedestal`): the same start-up."""
    install_signal_handlers()
    from .run import main
    return main(args, pedestal=True)


if __name__ == '__main__':  # pragma: no cover - python -m worm_gear_sim.ros.startup
    sys.exit(node_main())
