# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Worker processes forked from this one: :class:`ForkedWorkers` maps a function over items
on N processes that each hold a copy of one object (the *state*, e.g. a fit's problem) as it
was when they were forked.  The process backend of :mod:`.batch`, for work whose Python holds
the interpreter lock: a fit's candidate sets (building the set, its usability check with its
eigen-solves, packing) are Python, only the kernel releases the lock, so two threads reach
~1.5 cores (docs/performance.md).

**Same numbers.** A child is a copy of the parent: the same compiled kernels (no
recompilation), the same records and state (no re-reading, no pickled copy), so
``workers.map(fn, items)`` equals ``[fn(state, x) for x in items]`` bit for bit on one
machine.  Only the items and the results cross the pipes (pickled).

**Why fork, and when.** A spawned (or forkserver) pool would import numpy, scipy and numba and
load the kernels in every child (1-4 s for two, :mod:`.batch`) and receive the state pickled;
forking copies the process in milliseconds, so a pool per fit costs nothing that shows.  But
fork copies only the calling thread: a lock that another thread holds at that moment stays
held in the child.  :func:`fork_is_safe` is true only on Linux in a process with one Python
thread (a CLI, a benchmark, not the ROS node): the default of the fit's ``processes``
(:class:`~worm_gear_sim.identification.fit.FitOptions`) uses processes only then, threads
otherwise.  The package's own locks are taken around every fork (``os.register_at_fork``).

**Errors.** ``map`` raises the exception of the lowest failing item, as a serial loop does: the
item's own type, message and attributes, rebuilt in the parent (the child's traceback as a
note).  Children ignore SIGINT: the parent's ``KeyboardInterrupt`` closes the pool (pending
items cancelled, running ones finish); children die with the parent (``PR_SET_PDEATHSIG``). A
child that dies raises ``BrokenProcessPool``.
"""

from __future__ import annotations

import itertools
import multiprocessing
import os
import pickle
import signal
import sys
import threading
import traceback
from collections.abc import Callable, Iterable
from concurrent.futures import ProcessPoolExecutor
from typing import Any, Generic, TypeVar

__all__ = ['ForkedWorkers', 'fork_is_safe', 'can_fork']

S = TypeVar('S')
T = TypeVar('T')
R = TypeVar('R')

_STATES: dict[int, Any] = {}         # token -> state, read by the children after the fork
_TOKENS = itertools.count()


def can_fork() -> bool:
    """This platform forks processes the pool can use (Linux)."""
    return sys.platform.startswith('linux') and 'fork' in multiprocessing.get_all_start_methods()


def fork_is_safe() -> bool:
    """Forking now copies a consistent process: :func:`can_fork`, and this process runs one
    Python thread (no other thread can hold a lock the child would need)."""
    return can_fork() and threading.active_count() == 1


def _child_init(parent: int) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)      # the parent handles Ctrl-C
    try:                                              # die with the parent
        import ctypes
        ctypes.CDLL(None).prctl(1, signal.SIGTERM)    # PR_SET_PDEATHSIG
    except (OSError, AttributeError):                 # pragma: no cover - not on Linux
        pass
    if os.getppid() != parent:                        # the parent died before the prctl
        os._exit(1)


class _Raised:
    """An exception sent from a child: its class, args and attributes (rebuilt without its
    ``__init__``, whose signature may differ from its args) and the child's traceback."""

    def __init__(self, exc: BaseException) -> None:
        self.cls: type[BaseException] = type(exc)
        self.args = exc.args
        self.attrs = dict(getattr(exc, '__dict__', {}))
        self.trace = ''.join(traceback.format_exception(exc))
        try:
            pickle.dumps(self)
        except Exception:                             # unpicklable parts: the text only
            self.cls, self.args, self.attrs = RuntimeError, (f'{type(exc).__name__}: {exc}',), {}

    def rebuilt(self) -> BaseException:
        exc = self.cls.__new__(self.cls)
        exc.args = self.args
        exc.__dict__.update(self.attrs)
        exc.add_note('raised in a forked worker process:\n' + self.trace)
        return exc


def _run(token: int, fn: Callable[[Any, Any], Any], item: Any) -> tuple[bool, Any]:
    try:
        return True, fn(_STATES[token], item)
    except Exception as exc:
        return False, _Raised(exc)


class ForkedWorkers(Generic[S]):
    """``workers`` processes forked now, each with ``state`` as it is now; use as a context
    manager (or :meth:`close`).  ``fn`` given to :meth:`map` must be a module-level function
    (it is sent by name) taking ``(state, item)``."""

    def __init__(self, state: S, workers: int) -> None:
        n = int(workers)
        if n < 1:
            raise ValueError(f'workers = {workers!r}: must be >= 1')
        if not can_fork():
            raise RuntimeError('forked worker processes need Linux (fork)')
        self.workers = n
        self._token = next(_TOKENS)
        _STATES[self._token] = state
        try:
            self._pool: ProcessPoolExecutor | None = ProcessPoolExecutor(
                n, mp_context=multiprocessing.get_context('fork'), initializer=_child_init,
                initargs=(os.getpid(),))
            # every child forked here, in the calling thread, before the pool's own threads
            for f in [self._pool.submit(os.getpid) for _ in range(n)]:
                f.result()
        except BaseException:
            self.close()
            raise
        finally:
            _STATES.pop(self._token, None)             # the children hold their copy

    def map(self, fn: Callable[[S, T], R], items: Iterable[T]) -> list[R]:
        """``[fn(state, x) for x in items]`` on the children, in item order; the exception of
        the lowest failing item, as the serial loop raises it.  Safe to call from several
        threads at once."""
        if self._pool is None:
            raise RuntimeError('the worker processes are closed')
        futures = [self._pool.submit(_run, self._token, fn, x) for x in items]
        out: list[R] = []
        try:
            for f in futures:
                ok, value = f.result()
                if not ok:
                    raise value.rebuilt()
                out.append(value)
        finally:
            for f in futures:
                f.cancel()
        return out

    def close(self) -> None:
        """Stop the children: pending items cancelled, running ones finish."""
        pool, self._pool = getattr(self, '_pool', None), None
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> ForkedWorkers[S]:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
