# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The least-squares problem: records + base config + fitted keys -> the noise-weighted
residual vector r(x) and its finite-difference Jacobian (:class:`Problem`).

The Jacobian's step (:data:`DIFF_STEP`) is large on purpose: the set-valued friction law
makes a residual's last bits noise.  Its columns run on threads or, inside
:meth:`Problem.on_processes`, on forked workers: the same numbers either way.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import replace
from typing import Any

import numpy as np

from ..config.usable import Config
from ..dynamics.modal import modes
from ..dynamics.model import DriveModel
from ..dynamics.stepping import SimulationError
from ..dynamics.usability import usable_model
from ..parallel.processes import ForkedWorkers
from ..parallel.threads import map_like_serial
from ..records import Record
from ..schema.validation import ConfigError
from .data import (
    OUTPUTS,
    IdentificationError,
    measured_frequencies,
    motion_times,
    normalised,
    predict,
    rigid_motion,
)
from .observability import sampling_check
from .parameters import FitParameter, apply_values

__all__ = ['DIFF_STEP', 'Problem', 'jacobian']

#: Finite-difference step in the fitted coordinate x (see the module docstring).
DIFF_STEP = 1e-3

_COUNT_LOCK = threading.Lock()     # Problem.n_evals when the Jacobian runs on threads
os.register_at_fork(before=_COUNT_LOCK.acquire, after_in_parent=_COUNT_LOCK.release,
                    after_in_child=_COUNT_LOCK.release)


class Problem:
    """Records + base config + fitted keys -> weighted residual vector r(x)."""

    #: threads of the Jacobian's columns (1: in the calling thread; a fit running on several
    #: processes keeps 1 in each)
    threads: int = 1
    #: the forked worker processes of every evaluation inside :meth:`on_processes`
    _workers: ForkedWorkers[Problem] | None = None

    def __init__(self, base: Config, params: Sequence[FitParameter],
                 records: Sequence[Record], outputs: Sequence[str] | None = None):
        """``outputs``: the measured outputs to fit (None: every measured output that is
        observable at its sampling, :mod:`.observability`)."""
        if not records:
            raise IdentificationError('no records to fit')
        self.base = base
        self.params = list(params)
        self.records = [normalised(r, i) for i, r in enumerate(records)]
        rigid = rigid_motion(base)
        measured = [o for o in OUTPUTS if any(o in r.measured for r in self.records)]
        self.sampling = sampling_check(base, self.records)
        #: outputs measured but not fitted, with the reason
        self.left_out: dict[str, str] = {}
        if outputs is None:
            self.outputs = [o for o in measured if self.sampling[o].observable]
            self.left_out = {o: self.sampling[o].describe() for o in measured
                             if not self.sampling[o].observable}
            if not self.outputs:
                raise IdentificationError(
                    'no measured output is observable at its sampling: '
                    + '; '.join(self.left_out.values())
                    + ' (--outputs fits them anyway)')
        else:
            chosen = list(dict.fromkeys(str(o).strip() for o in outputs))
            unknown = [o for o in chosen if o not in OUTPUTS]
            if unknown or not chosen:
                raise IdentificationError(f'outputs {", ".join(unknown) or "(none)"}: choose '
                                          f'among {", ".join(OUTPUTS)}')
            missing = [o for o in chosen if o not in measured]
            if missing:
                raise IdentificationError(f'outputs {", ".join(missing)}: not measured in the '
                                          f'records (measured: {", ".join(measured)})')
            self.outputs = [o for o in OUTPUTS if o in chosen]
            self.left_out = {o: f'{o}: not fitted (not among the chosen outputs)'
                             for o in measured if o not in chosen}
        # the records as the fit sees them: the fitted outputs only (an aliased output would
        # also mislead the frequency start and the time windows)
        self.records = [replace(r, measured={o: v for o, v in r.measured.items()
                                             if o in self.outputs})
                        for r in self.records]
        self.records = [r for r in self.records if r.measured]
        self.scale: dict[str, float] = {}
        for o in self.outputs:
            j = OUTPUTS.index(o)
            dev = np.concatenate([r.measured[o] - rigid[j] * r.theta1
                                  for r in self.records if o in r.measured])
            s = float(np.sqrt(np.mean((dev - dev.mean()) ** 2)))
            if not s > 0:
                raise IdentificationError(f'{o}: the measured angle follows the command '
                                          'exactly; nothing to fit')
            self.scale[o] = s
        # white-noise level of each output from 4th differences (a 100 Hz mode sampled at
        # 10 kHz contributes (2 pi f dt)^4 = 2e-5 of its amplitude): var(d4 x) = 70 sigma^2
        self.noise: dict[str, float] = {}
        for o in self.outputs:
            d4 = np.concatenate([np.diff(r.measured[o], 4) for r in self.records
                                 if o in r.measured])
            self.noise[o] = float(np.sqrt(np.mean(d4 ** 2) / 70.0)) if d4.size else 0.0
        # residual weights: 1 / noise level (maximum likelihood for white Gaussian noise; a
        # noisy output such as a worm encoder that hardly sees the mesh wind-up cannot drown
        # the antenna's), at most 1000 / scale for noise-free data
        self.sigma = {o: max(self.noise[o], 1e-3 * self.scale[o]) for o in self.outputs}
        self.period = self.dominant_period()
        self.n_evals = 0
        self._memos: list[dict[float | None, Any]] = [{} for _ in self.records]  # predict's
        self._last: tuple[bytes, float | None, np.ndarray] | None = None

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state.pop('_workers', None)        # a pool stays with the process that forked it
        return state

    @contextmanager
    def on_processes(self, workers: int) -> Iterator[None]:
        """Inside the block, every evaluation (:meth:`residuals`, the Jacobian's columns)
        runs on ``workers`` processes forked now (each a copy of this problem; the calling
        threads wait), not in the calling thread or on :attr:`threads` threads; the pool is
        closed on leaving.  Fork from a single-threaded process
        (:func:`~worm_gear_sim.parallel.processes.fork_is_safe`)."""
        if self._workers is not None:
            raise RuntimeError('the evaluations already run on worker processes')
        with ForkedWorkers(self, workers) as pool:
            self._workers = pool
            try:
                yield
            finally:
                self._workers = None

    def on_processes_now(self) -> bool:
        """The evaluations run on worker processes (inside :meth:`on_processes`)."""
        return self._workers is not None

    def dominant_period(self) -> float:
        """Period [s] of the lowest measured oscillation (for time windows)."""
        freqs = [f for f, _, _, fs in measured_frequencies(self.base, self.records)
                 if f < 0.4 * fs]
        if freqs:
            return 1.0 / min(freqs)
        return 1.0 / float(modes(self.base).frequencies_hz[0] or 1.0)

    @property
    def n(self) -> int:
        return len(self.params)

    @property
    def x_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of x."""
        lo, hi = zip(*[p.x_bounds for p in self.params])
        return np.array(lo, float), np.array(hi, float)

    def config(self, x: np.ndarray) -> Config:
        return apply_values(self.base, self.params, [p.from_x(v) for p, v in zip(self.params, x)])

    def windows(self, n_periods: Sequence[float] = (4.0, 10.0, 25.0)) -> list[float | None]:
        """Growing window lengths after the start of motion (None: whole records)."""
        start = min(motion_times(r.t, r.theta1)[0] - r.t[0] for r in self.records)
        longest = max(r.t[-1] - r.t[0] for r in self.records)
        out: list[float | None] = [start + k * self.period for k in n_periods
                                   if start + k * self.period < 0.8 * longest]
        return out + [None]

    def residuals(self, x: np.ndarray, window: float | None = None) -> np.ndarray:
        """Weighted residuals (predicted - measured) / sigma over every record and output
        (the records cut ``window`` seconds after their start; None: whole records)."""
        x = np.asarray(x, float)
        key = x.tobytes()
        last = self._last       # one tuple, swapped whole: safe when threads share the cache
        if last is not None and last[0] == key and last[1] == window:
            return last[2].copy()
        with _COUNT_LOCK:
            self.n_evals += 1
        pool = self._workers
        out = (self.computed(x, window) if pool is None
               else pool.map(_computed, [(x, window)])[0])
        self._last = (key, window, out)
        return out.copy()

    def computed(self, x: np.ndarray, window: float | None = None) -> np.ndarray:
        """:meth:`residuals` computed here, without its cache."""
        parts = []
        try:   # the model the usability check of the new set built (built once)
            model: DriveModel | None = usable_model(self.config(x))
        except ConfigError:
            model = None
        for r, memo in zip(self.records, self._memos):
            t_end = None if window is None else r.t[0] + window
            n = r.t.size if t_end is None else max(2, int(np.searchsorted(r.t, t_end,
                                                                          side='right')))
            pred = None
            if model is not None:
                try:
                    pred = predict(model, r, t_end, memo)
                except (SimulationError, ValueError):
                    pred = None
            for o in self.outputs:
                if o not in r.measured:
                    continue
                meas = r.measured[o][:n]
                if pred is None:   # failed run: a large, smooth penalty
                    parts.append(np.full(n, 10.0 * self.scale[o] / self.sigma[o]))
                else:
                    parts.append((pred[o][:n] - meas) / self.sigma[o])
        return np.concatenate(parts)

    def cost(self, x: np.ndarray, window: float | None = None) -> float:
        r = self.residuals(x, window)
        return 0.5 * float(r @ r)

    def jacobian(self, x: np.ndarray, window: float | None = None, h: float = DIFF_STEP,
                 central: bool = False, columns: Sequence[int] | None = None) -> np.ndarray:
        """d residuals / dx by finite differences with the absolute step ``h`` in x: forward
        (n evaluations; backward next to an upper bound) or ``central`` (2 n; one-sided next
        to a bound); only ``columns`` if given (the others are NaN)."""
        x = np.asarray(x, float)
        lo, hi = self.x_bounds
        r0 = self.residuals(x, window)
        J = np.full((r0.size, x.size), np.nan)
        plan = []          # per column: the points to evaluate and how to combine them
        for i in range(x.size) if columns is None else columns:
            e = np.zeros_like(x)
            e[i] = h
            up, down = x[i] + h <= hi[i], x[i] - h >= lo[i]
            if central and up and down:
                plan.append((i, [x + e, x - e], 2 * h))
            elif up:
                plan.append((i, [x + e, None], h))
            else:
                plan.append((i, [None, x - e], h))
        points = [p for _, pts, _ in plan for p in pts if p is not None]
        pool = self._workers
        if pool is None:
            done = iter(map_like_serial(lambda xp: self.residuals(xp, window), points,
                                        workers=self.threads))
        else:
            with _COUNT_LOCK:
                self.n_evals += len(points)
            done = iter(pool.map(_computed, [(xp, window) for xp in points]))
        for i, (fwd, back), step in plan:
            rf = r0 if fwd is None else next(done)
            rb = r0 if back is None else next(done)
            J[:, i] = (rf - rb) / step
        return J


def _computed(problem: Problem, point: tuple[np.ndarray, float | None]) -> np.ndarray:
    """One evaluation in a worker process (its copy of the problem)."""
    return problem.computed(*point)


def jacobian(problem: Problem, x: np.ndarray, h: float = DIFF_STEP,
             columns: Sequence[int] | None = None) -> np.ndarray:
    """d residuals / dx over the whole records by central differences with step ``h`` in the
    fitted coordinate (one-sided next to a bound)."""
    return problem.jacobian(x, None, h, central=True, columns=columns)
