# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Many simulations in one call on threads of this process: :func:`simulate_batch` (N
parameter sets and/or N commands, each run as ``simulate``) and :func:`map_batch` (any
per-item function whose time is in the ``nogil`` kernel), with :class:`BatchError` and
:class:`BatchFailure` for bad items.

Item i is exactly the serial call, so a batch equals N serial calls bit for bit.  Why
threads, and the ``errors`` rules: docs/performance.md ("Sweeps and batches").
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor, as_completed
from dataclasses import dataclass
from numbers import Real
from typing import TYPE_CHECKING, Any, TypeVar, cast

import numpy as np

from ..dynamics.load import LoadSignal
from ..dynamics.model import DriveModel
from ..dynamics.profiles import Profile, make_profile
from ..dynamics.simulation import simulate
from ..dynamics.stepping import RUN_MEMORY_LIMIT, SimulationError
from ..dynamics.trajectory import ROW_BYTES, Trajectory
from ..dynamics.usability import check_usable
from ..schema.parameters import Parameters
from ..schema.validation import ConfigError

if TYPE_CHECKING:
    from ..config.usable import Config

__all__ = ['simulate_batch', 'map_batch', 'map_like_serial', 'BatchFailure', 'BatchError',
           'default_workers', 'ITEM_ERRORS']

T = TypeVar('T')
R = TypeVar('R')

#: What makes one item unusable or its run fail (a bad value, an unusable set, a failed
#: integration, a numeric domain error).  Any other exception is a bug: it stops the batch
#: and propagates unchanged, whatever ``errors`` says.
ITEM_ERRORS: tuple[type[BaseException], ...] = (ConfigError, SimulationError, ValueError,
                                                ArithmeticError)

#: A parameter set: a validated Config, a built model, or overrides (dotted keys) on ``base``.
SetLike = Parameters | DriveModel | Mapping[str, Any]


@dataclass(frozen=True)
class BatchFailure:
    """Item ``index`` of a batch could not be used or run: ``error`` says why, ``keys`` the
    parameters it blames (a :class:`ConfigError`'s keys; empty for a failed run)."""

    index: int
    error: BaseException

    @property
    def keys(self) -> tuple[str, ...]:
        return tuple(getattr(self.error, 'keys', ()) or ())

    def __str__(self) -> str:
        return f'set {self.index}: {self.error}'


class BatchError(ValueError):
    """A batch refused (``errors='raise'``): ``failures`` lists every bad item found
    (:class:`BatchFailure`: index, keys, error); ``indices`` and ``keys`` summarise them."""

    def __init__(self, failures: Sequence[BatchFailure], total: int) -> None:
        self.failures: tuple[BatchFailure, ...] = tuple(sorted(failures, key=lambda f: f.index))
        self.indices: tuple[int, ...] = tuple(f.index for f in self.failures)
        self.keys: tuple[str, ...] = tuple(dict.fromkeys(k for f in self.failures
                                                         for k in f.keys))
        shown = '; '.join(str(f) for f in self.failures[:5])
        more = len(self.failures) - 5
        if more > 0:
            shown += f'; and {more} more'
        super().__init__(f'batch of {total} refused, {len(self.failures)} bad: {shown}')


def default_workers() -> int:
    """Threads of a batch by default: the cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:          # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


def _check_errors(errors: str) -> None:
    if errors not in ('raise', 'collect'):
        raise ValueError(f"errors={errors!r}: 'raise' (refuse the batch) or 'collect' "
                         '(a BatchFailure in the bad item\'s place)')


def map_batch(fn: Callable[[T], R], items: Iterable[T], *, workers: int | None = None,
              errors: str = 'raise',
              on_result: Callable[[int, R | BatchFailure], None] | None = None,
              ) -> list[R | BatchFailure]:
    """``[fn(x) for x in items]`` on ``workers`` threads (default :func:`default_workers`;
    1 runs in the calling thread), results in item order, each equal bit for bit to the
    serial call's.  Worth it when ``fn`` spends its time in the compiled kernel (which
    releases the interpreter lock), e.g. a simulation or a fit's cost of one candidate.

    An item whose call raises one of :data:`ITEM_ERRORS`: with ``errors='raise'`` no new item
    starts, the running ones finish, and :class:`BatchError` names every failed index; with
    ``'collect'`` its place holds a :class:`BatchFailure` and the others run.  Any other
    exception propagates at once (pending items cancelled).  ``on_result(index, result)`` is
    called in the calling thread as each item completes (progress bars, streaming)."""
    _check_errors(errors)
    seq = list(items)
    n = len(seq)
    w = default_workers() if workers is None else int(workers)
    if w < 1:
        raise ValueError(f'workers = {workers!r}: must be >= 1')
    out: list[Any] = [None] * n
    failures: list[BatchFailure] = []

    def settle(i: int, result: Any) -> None:
        out[i] = result
        if isinstance(result, BatchFailure):
            failures.append(result)
        if on_result is not None:
            on_result(i, result)

    if w == 1 or n <= 1:
        for i, x in enumerate(seq):
            try:
                r: Any = fn(x)
            except ITEM_ERRORS as exc:
                r = BatchFailure(i, exc)
                if errors == 'raise':
                    failures.append(r)
                    raise BatchError(failures, n) from exc
            settle(i, r)
        return out

    def call(i: int) -> Any:
        try:
            return fn(seq[i])
        except ITEM_ERRORS as exc:
            return BatchFailure(i, exc)

    with ThreadPoolExecutor(max_workers=min(w, n), thread_name_prefix='wgs-batch') as ex:
        futures: dict[Future, int] = {ex.submit(call, i): i for i in range(n)}
        try:
            for fut in as_completed(futures):
                settle(futures[fut], fut.result())      # a bug (not an ITEM_ERROR) raises
                if failures and errors == 'raise':
                    break
        finally:
            for fut in futures:
                fut.cancel()                # no new item starts; the running ones finish
        if failures and errors == 'raise':
            for fut, i in futures.items():
                if out[i] is None and not fut.cancelled():
                    r = fut.result()
                    if isinstance(r, BatchFailure):
                        failures.append(r)
            raise BatchError(failures, n)
    return out


def map_like_serial(fn: Callable[[T], R], items: Iterable[T], *, workers: int | None = None,
                    on_result: Callable[[int, R], None] | None = None) -> list[R]:
    """:func:`map_batch` with a serial loop's contract, for code that replaces one (the
    studies): the results, or the failed item's own exception (of the lowest failed index
    found; no :class:`BatchError`).  ``on_result`` sees the successful items only."""
    def told(i: int, r: R | BatchFailure) -> None:
        if on_result is not None and not isinstance(r, BatchFailure):
            on_result(i, r)

    try:
        out = map_batch(fn, items, workers=workers, on_result=told)
    except BatchError as exc:
        raise exc.failures[0].error from None
    return cast(list[R], out)         # errors='raise': no BatchFailure in it


def _per_item(name: str, value: Any, single: Callable[[Any], bool]) -> Sequence[Any] | None:
    """``value`` as a per-item sequence, or None when it is one value for every item."""
    if single(value):
        return None
    if isinstance(value, np.ndarray) and value.ndim == 1:
        return value.tolist()
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
        raise TypeError(f'{name}: one value or a sequence of one per item, got '
                        f'{type(value).__name__}')
    return value


def simulate_batch(sets: SetLike | Sequence[SetLike], profiles: Profile | Sequence[Profile]
                   | None = None, t_end: float | Sequence[float] | None = None,
                   record_every: int = 1, *, base: Config | None = None,
                   loads: LoadSignal | Sequence[LoadSignal | None] | None = None,
                   workers: int | None = None, errors: str = 'raise',
                   max_bytes: float | None = None) -> list[Trajectory | BatchFailure]:
    """N runs from rest, ``simulate(set_i, profile_i, t_end_i, record_every, load=load_i)``
    each, on ``workers`` threads (:func:`map_batch`); the i-th Trajectory equals that serial
    call's bit for bit.

    ``sets``: one parameter set or a sequence, each a Config, a :class:`DriveModel` or a
    mapping of dotted-key overrides on ``base`` (``{'friction.mu_kinetic': 0.06}``).
    ``profiles`` (None: each set's own ``input`` section), ``t_end`` (None: its
    ``input.end_time``) and ``loads`` (None: the constant ``load.output_torque``): one for
    all or one per item.  Every sequence given has the batch's length N.

    Every set and argument is checked before anything runs (a bad override or an unusable set
    is a :class:`ConfigError` naming its keys); with ``errors='raise'`` a bad item refuses
    the batch (:class:`BatchError` with the indices and keys), with ``'collect'`` its place
    holds a :class:`BatchFailure` and the others run.  ``max_bytes``: the limit on the rows of
    the whole batch, which are all in memory (default ``RUN_MEMORY_LIMIT``): raise
    ``record_every``, or reduce each run inside ``fn`` with :func:`map_batch`."""
    _check_errors(errors)
    items = _BatchItems.of(sets, profiles, t_end, loads)
    n = items.n
    stride = int(record_every)
    if stride < 1:
        raise ValueError(f'record_every must be >= 1, got {record_every!r}')
    # 1. every item checked before any run: model, profile, duration, memory
    jobs, failures, total_bytes = _checked_jobs(items, base, stride)
    if failures and errors == 'raise':
        raise BatchError(failures, n)
    limit = RUN_MEMORY_LIMIT if max_bytes is None else float(max_bytes)
    if total_bytes > limit:
        raise ValueError(
            f'the batch records {total_bytes / 1e9:.3g} GB, above max_bytes = '
            f'{limit / 1e9:.3g} GB: raise record_every, shorten t_end, pass max_bytes=..., '
            'or reduce each run inside map_batch')

    # 2. the runs
    def run(i: int) -> Trajectory | BatchFailure:
        job = jobs[i]
        if job is None:     # failed its check ('collect')
            return next(f for f in failures if f.index == i)
        model, profile, te, load = job
        try:
            return simulate(model, profile, te, stride, max_bytes=limit, load=load)
        except ITEM_ERRORS as exc:
            return BatchFailure(i, exc)

    res = map_batch(run, range(n), workers=workers, errors='collect')
    if errors == 'raise':
        bad = [r for r in res if isinstance(r, BatchFailure)]
        if bad:
            raise BatchError(bad, n)
    return res


@dataclass
class _BatchItems:
    """:func:`simulate_batch`'s arguments, each one for all (its ``*_seq`` None) or one
    per item; ``n`` items."""

    sets: Any
    profiles: Any
    t_end: Any
    loads: Any
    set_seq: Sequence[Any] | None
    prof_seq: Sequence[Any] | None
    tend_seq: Sequence[Any] | None
    load_seq: Sequence[Any] | None
    n: int

    @classmethod
    def of(cls, sets: Any, profiles: Any, t_end: Any, loads: Any) -> _BatchItems:
        set_seq = _per_item('sets', sets,
                            lambda v: isinstance(v, (Parameters, DriveModel, Mapping)))
        prof_seq = _per_item('profiles', profiles,
                             lambda v: v is None or isinstance(v, Profile))
        tend_seq = _per_item('t_end', t_end, lambda v: v is None or isinstance(v, Real))
        load_seq = _per_item('loads', loads, lambda v: v is None or isinstance(v, LoadSignal))
        lengths = {name: len(s) for name, s in (('sets', set_seq), ('profiles', prof_seq),
                                                 ('t_end', tend_seq), ('loads', load_seq))
                   if s is not None}
        if len(set(lengths.values())) > 1:
            raise ValueError('batch lengths differ: ' + ', '.join(f'{k} {v}' for k, v in
                                                                  lengths.items()))
        n = next(iter(lengths.values())) if lengths else 1
        return cls(sets, profiles, t_end, loads, set_seq, prof_seq, tend_seq, load_seq, n)

    def item(self, i: int) -> tuple[Any, Any, Any, Any]:
        """The i-th (set, profile, t_end, load) as given."""
        def pick(seq: Sequence[Any] | None, one: Any) -> Any:
            return one if seq is None else seq[i]
        return (pick(self.set_seq, self.sets), pick(self.prof_seq, self.profiles),
                pick(self.tend_seq, self.t_end), pick(self.load_seq, self.loads))


def _checked_jobs(items: _BatchItems, base: Config | None, stride: int
                  ) -> tuple[list[tuple[DriveModel, Profile, float, LoadSignal | None] | None],
                             list[BatchFailure], float]:
    """Each item as a run (model, profile, t_end, load) or, failing its check, None with a
    :class:`BatchFailure`; and the bytes the runs record."""
    jobs: list[tuple[DriveModel, Profile, float, LoadSignal | None] | None] = [None] * items.n
    failures: list[BatchFailure] = []
    total_bytes = 0.0
    for i in range(items.n):
        the_set, profile, te, load = items.item(i)
        try:
            model = _model_of(the_set, base)
            profile = make_profile(model.config.input) if profile is None else profile
            te = model.config.input.end_time if te is None else float(te)
            dt = model.config.integrator.time_step
            if not (math.isfinite(te) and te >= 0.0):
                raise ValueError(f't_end = {te!r} s: must be finite and >= 0')
            total_bytes += (math.floor(te / dt + 1e-9) // stride + 1) * ROW_BYTES
            jobs[i] = (model, profile, te, load)
        except ITEM_ERRORS as exc:
            failures.append(BatchFailure(i, exc))
    return jobs, failures, total_bytes


def _model_of(s: SetLike, base: Config | None) -> DriveModel:
    """The set's model, proven usable (ConfigError naming the keys otherwise)."""
    if isinstance(s, DriveModel):
        check_usable(s.config)
        return s
    if isinstance(s, Parameters):
        check_usable(s)
        return DriveModel(s)
    if base is None:
        raise ValueError('a set given as overrides needs base= (the Config they change)')
    cfg = base.replace(dict(s))       # ConfigError naming a bad key; checks usability
    check_usable(cfg)
    return DriveModel(cfg)
