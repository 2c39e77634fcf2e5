# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A shorter interpreter switch interval while a worker thread computes beside the 1 kHz
sample path.

A worker that holds the interpreter (a trajectory's compensation, an adapted model's
preparation) makes the sample callback wait up to the switch interval (5 ms by default)
for it; lowered to :data:`WORKER_SWITCH_INTERVAL` the callback waits at most that.  Several
workers may overlap (the trajectory worker and the adaptation's): the interval is lowered
when the first one starts and restored when the last one ends, so no interleaving of
starts and ends can leave it lowered (each saving and restoring on its own could).
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ['WORKER_SWITCH_INTERVAL', 'short_switch_interval']

#: The switch interval [s] while a worker computes beside the sample path.
WORKER_SWITCH_INTERVAL = 0.0005

_lock = threading.Lock()
_running = 0                 # workers inside short_switch_interval
_saved = 0.0                 # the interval before the first of them


@contextmanager
def short_switch_interval() -> Iterator[None]:
    """Run the block with the switch interval at most :data:`WORKER_SWITCH_INTERVAL`."""
    global _running, _saved
    with _lock:
        if _running == 0:
            _saved = sys.getswitchinterval()
            sys.setswitchinterval(min(_saved, WORKER_SWITCH_INTERVAL))
        _running += 1
    try:
        yield
    finally:
        with _lock:
            _running -= 1
            if _running == 0:
                sys.setswitchinterval(_saved)
