# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Worker processes forked from this one: :class:`ForkedWorkers` maps a function over items
on N processes that each hold a copy of one state (e.g. a fit's problem), bit for bit the
serial loop; :func:`fork_is_safe` says when forking is allowed (Linux, one Python thread).

The backend for work whose Python, not its kernel, holds the interpreter lock (a fit's
candidate sets); why and when: docs/performance.md ("Sweeps and batches").
"""

from __future__ import annotations

import itertools
import multiprocessing
import os
import pickle
import queue
import signal
import sys
import threading
import traceback
from collections.abc import Callable, Iterable
from multiprocessing.connection import Connection, wait
from typing import Any, Generic, TypeVar, cast

__all__ = ['ForkedWorkers', 'WorkerDied', 'fork_is_safe', 'can_fork']

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
    return (can_fork() and threading.active_count() == 1
            and not multiprocessing.current_process().daemon)   # a daemon has no children


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


def _run(state: Any, fn: Callable[[Any, Any], Any], item: Any) -> tuple[bool, Any]:
    try:
        return True, fn(state, item)
    except Exception as exc:
        return False, _Raised(exc)


def _child_main(conn: Connection, token: int, parent: int, siblings: list[Connection]
                ) -> None:
    """A worker: ``(fn, item)`` in, ``(ok, result or _Raised)`` out, until None or EOF."""
    _child_init(parent)
    for other in siblings:           # the parent's ends of the earlier workers' pipes
        other.close()
    state = _STATES[token]
    while True:
        try:
            msg = conn.recv()
        except EOFError:
            return
        if msg is None:
            return
        conn.send(_run(state, *msg))


class WorkerDied(RuntimeError):
    """A worker process ended while it computed an item (killed, out of memory, a crash)."""


class ForkedWorkers(Generic[S]):
    """``workers`` processes forked now, each with ``state`` as it is now; use as a context
    manager (or :meth:`close`).  ``fn`` given to :meth:`map` must be a module-level function
    (it is sent by name) taking ``(state, item)``.  Each worker is a pipe: a calling thread
    takes an idle worker, sends it an item and waits for the result (no broker thread)."""

    def __init__(self, state: S, workers: int) -> None:
        n = int(workers)
        if n < 1:
            raise ValueError(f'workers = {workers!r}: must be >= 1')
        if not can_fork():
            raise RuntimeError('forked worker processes need Linux (fork)')
        self.workers = n
        self._idle: queue.SimpleQueue[Connection] = queue.SimpleQueue()
        self._procs: list[tuple[Any, Connection]] = []
        self._closed = False
        token = next(_TOKENS)
        _STATES[token] = state
        ctx = multiprocessing.get_context('fork')
        try:
            for _ in range(n):
                mine, theirs = ctx.Pipe()
                proc = ctx.Process(target=_child_main, args=(theirs, token, os.getpid(),
                                                             [c for _, c in self._procs]),
                                   daemon=True, name='wgs-forked')
                proc.start()
                theirs.close()
                self._procs.append((proc, mine))
                self._idle.put(mine)
        except BaseException:
            self.close(now=True)
            raise
        finally:
            _STATES.pop(token, None)             # the children hold their copy

    def map(self, fn: Callable[[S, T], R], items: Iterable[T]) -> list[R]:
        """``[fn(state, x) for x in items]`` on the children, in item order; the exception of
        the lowest failing item, as the serial loop raises it (no item after a failed one is
        started).  Safe to call from several threads at once."""
        seq = list(items)
        out: list[Any] = [None] * len(seq)
        failed: dict[int, _Raised] = {}
        pending: dict[Connection, int] = {}
        i = 0
        try:
            while i < len(seq) or pending:
                while i < len(seq) and not failed:
                    if self._closed:
                        raise RuntimeError('the worker processes are closed')
                    try:                 # block for a worker only when none works for us
                        conn = self._idle.get(block=not pending)
                    except queue.Empty:
                        break
                    pending[conn] = i
                    conn.send((fn, seq[i]))
                    i += 1
                if not pending:
                    break
                for ready in wait(list(pending)):
                    done = cast(Connection, ready)
                    k = pending.pop(done)
                    ok, value = self._received(done)
                    self._idle.put(done)
                    if ok:
                        out[k] = value
                    else:
                        failed[k] = value
        except BaseException:      # Ctrl-C, a dead worker: results may still be on the way
            self.close(now=True)
            raise
        if failed:
            raise failed[min(failed)].rebuilt()
        return out

    def _received(self, conn: Connection) -> tuple[bool, Any]:
        try:
            return conn.recv()
        except (EOFError, OSError):
            codes = [p.exitcode for p, _ in self._procs]
            raise WorkerDied(f'a forked worker process ended while computing an item '
                             f'(exit codes {codes})') from None

    def close(self, now: bool = False) -> None:
        """Stop the children (``now``: without waiting for the items they compute)."""
        if self._closed:
            return
        self._closed = True
        for proc, conn in self._procs:
            try:
                if now:
                    proc.terminate()
                else:
                    conn.send(None)
            except OSError:
                pass
        for proc, conn in self._procs:
            proc.join(timeout=None if now else 5.0)
            if proc.is_alive():                  # pragma: no cover - a stuck child
                proc.kill()
                proc.join()
            conn.close()

    def __enter__(self) -> ForkedWorkers[S]:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
