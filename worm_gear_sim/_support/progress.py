# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The package's progress bars (``sweep``, ``identify``, ``calibrate``): tqdm on stderr,
without tqdm's monitor thread.  That thread, started with the first bar and never ended,
made every later fit in the process run its evaluations on threads instead of forked worker
processes: forking is safe only while the process runs one thread
(:func:`worm_gear_sim.parallel.processes.fork_is_safe`)."""

from __future__ import annotations

import sys
from typing import Any

__all__ = ['progress_bar']


def progress_bar(total: int, desc: str, unit: str) -> Any:
    """A tqdm bar of ``total`` ``unit`` on stderr that starts no thread; None without tqdm
    (a declared dependency)."""
    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover - tqdm is a declared dependency
        return None

    class _Bar(tqdm):
        monitor_interval = 0    # no monitor thread (module docstring)

    return _Bar(total=total, desc=desc, unit=unit, file=sys.stderr, leave=True,
                dynamic_ncols=True)
