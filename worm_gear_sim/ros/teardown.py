# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A bounded teardown: a process of the package ends within :data:`TEARDOWN_S` of starting
to tear rclpy down, even when DDS hangs there; standard library only.

rclpy's teardown (the executor, the nodes, the context) destroys the DDS participant. Fast DDS
2.14 (ROS 2 Jazzy's wheels) can deadlock there when another participant leaves at the same
moment: the main thread spins in ``DomainParticipant::set_listener`` for a discovery callback
that waits for a lock it holds, for ever, holding the GIL (seen with the demo's two nodes
stopped together on a loaded machine). No Python code runs then, so the deadline is native: a
POSIX timer whose own thread calls ``_exit(rc)`` (glibc's ``SIGEV_THREAD``), and half a second
before it ``faulthandler`` prints every thread's stack on stderr, naming where it hung.
Where no such timer exists, ``faulthandler`` ends the process itself (status 1).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import faulthandler
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ['TEARDOWN_S', 'teardown_deadline']

#: The teardown's deadline [s]: a node's takes well under a second on a loaded machine.
TEARDOWN_S = 6.0
#: The stacks are printed this long before the end [s].
DUMP_AHEAD_S = 0.5

_CLOCK_MONOTONIC = 1
_SIGEV_THREAD = 2


class _Sigval(ctypes.Union):
    _fields_ = [('sival_int', ctypes.c_int), ('sival_ptr', ctypes.c_void_p)]


class _SigevThread(ctypes.Structure):
    _fields_ = [('function', ctypes.c_void_p), ('attribute', ctypes.c_void_p)]


class _SigevUnion(ctypes.Union):
    _fields_ = [('pad', ctypes.c_int * 12), ('tid', ctypes.c_int), ('thread', _SigevThread)]


class _Sigevent(ctypes.Structure):
    """``struct sigevent`` of Linux (64 bytes on 64-bit machines)."""

    _fields_ = [('value', _Sigval), ('signo', ctypes.c_int), ('notify', ctypes.c_int),
                ('un', _SigevUnion)]


class _Timespec(ctypes.Structure):
    _fields_ = [('sec', ctypes.c_long), ('nsec', ctypes.c_long)]


class _Itimerspec(ctypes.Structure):
    _fields_ = [('interval', _Timespec), ('value', _Timespec)]


def _libc() -> Any | None:
    """The C library with ``timer_create`` (libc from glibc 2.34 on, librt before); None
    elsewhere."""
    for name in (None, ctypes.util.find_library('rt')):
        try:
            lib = ctypes.CDLL(name, use_errno=True)
        except (OSError, TypeError):
            continue
        if all(hasattr(lib, f) for f in ('timer_create', 'timer_settime', 'timer_delete',
                                          '_exit')):
            return lib
    return None


def _arm(seconds: float, rc: int) -> tuple[Any, ctypes.c_void_p] | None:
    """A one-shot timer calling ``_exit(rc)`` after ``seconds`` from a thread of the C
    library (no GIL needed); None when the platform offers none."""
    if not sys.platform.startswith('linux'):
        return None
    lib = _libc()
    if lib is None:
        return None
    event = _Sigevent()
    event.notify = _SIGEV_THREAD
    event.value.sival_int = rc                       # _exit's argument
    event.un.thread.function = ctypes.cast(lib._exit, ctypes.c_void_p)
    timer = ctypes.c_void_p()
    if lib.timer_create(_CLOCK_MONOTONIC, ctypes.byref(event), ctypes.byref(timer)) != 0:
        return None
    when = _Itimerspec()
    when.value.sec, frac = int(seconds), seconds - int(seconds)
    when.value.nsec = int(frac * 1e9)
    if lib.timer_settime(timer, 0, ctypes.byref(when), None) != 0:
        lib.timer_delete(timer)
        return None
    return lib, timer


def _status_now() -> int:
    """The process's status if it ended now: 1 while an error propagates, else 0 (a normal
    end, Ctrl-C and a ROS shutdown included)."""
    exc = sys.exc_info()[1]
    if exc is None or isinstance(exc, KeyboardInterrupt) or \
            type(exc).__name__ == 'ExternalShutdownException':
        return 0
    return 1


@contextmanager
def teardown_deadline(rc: int | None = None, seconds: float = TEARDOWN_S) -> Iterator[None]:
    """Around a process's rclpy teardown: if it has not ended after ``seconds``, the process
    ends with status ``rc`` (None: 0, or 1 while an error propagates), the threads' stacks
    printed on stderr just before.  Disarmed when the block ends, so a teardown in a process
    that goes on (a test calling an entry point) is safe."""
    status = _status_now() if rc is None else int(rc)
    armed = _arm(seconds, status)
    try:
        faulthandler.dump_traceback_later(max(seconds - DUMP_AHEAD_S, 0.05),
                                          exit=armed is None, file=sys.__stderr__)
        dumping = True
    except (AttributeError, ValueError, OSError, RuntimeError):   # no stderr file here
        dumping = False
    try:
        yield
    finally:
        if dumping:
            faulthandler.cancel_dump_traceback_later()
        if armed is not None:
            lib, timer = armed
            lib.timer_delete(timer)
