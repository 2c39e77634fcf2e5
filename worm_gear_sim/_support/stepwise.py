# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Work cut into steps, run at once or a slice at a time between samples (pure core).

A *steps* generator does a piece of work between its ``yield``\\ s and ``return``\\ s its result
(``Generator[None, None, T]``).  :func:`run_steps` runs one through (the plain call:
``Compensator(model)``, ``RealtimePredictor.prepare``); :class:`Stepwise` is a future-like
handle (``done()``, ``result()``) whose :meth:`~Stepwise.advance` runs the steps until a
time budget is spent.  The node prepares an adapted step so (``adaptation.live``): a slice
after each sample, on the sample thread itself, never a second thread competing for the
interpreter (a worker thread preparing a step made the samples around it wait for the GIL:
2.4-6.7 ms per sample, p99, under load).  The result is the one :func:`run_steps` gives:
the same code on the same data, only cut differently in time.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Generator
from typing import Any, Generic, TypeVar

__all__ = ['Steps', 'run_steps', 'Stepwise', 'SLICE_BUDGET']

T = TypeVar('T')
#: Work that yields between its steps and returns its result.
Steps = Generator[None, None, T]
#: The time one :meth:`Stepwise.advance` may spend [s]: another step is started only while
#: the time spent plus the longest step so far stays within it (each step of a preparation
#: is ~0.01-0.3 ms on an idle core; at least one step runs per call).
SLICE_BUDGET = 0.0003


def run_steps(steps: Steps[T]) -> T:
    """Run ``steps`` through; its result."""
    while True:
        try:
            next(steps)
        except StopIteration as stop:
            return stop.value


class Stepwise(Generic[T]):
    """A future-like handle on ``steps``, run a slice at a time by :meth:`advance` (module
    docstring).  ``clock``: the time base of the budget (wall time: a slice bounds how long
    the caller is held)."""

    def __init__(self, steps: Steps[T], budget: float = SLICE_BUDGET,
                 clock: Callable[[], float] = time.perf_counter) -> None:
        self._steps: Steps[T] | None = steps
        self.budget = float(budget)
        self._clock = clock
        self._value: Any = None
        self._error: BaseException | None = None
        self.slices = 0              # calls of advance that ran a step
        self.longest = 0.0           # the longest slice [s]
        self.longest_step = 0.0      # the longest step [s]

    def done(self) -> bool:
        return self._steps is None

    def result(self) -> T:
        """The result (the exception the steps raised, re-raised); RuntimeError when not
        done."""
        if self._steps is not None:
            raise RuntimeError('Stepwise.result: not done (advance it)')
        if self._error is not None:
            raise self._error
        return self._value

    def advance(self, budget: float | None = None) -> bool:
        """Run steps until they are done or the next one might not end within ``budget``
        [s] (default :attr:`budget`; the longest step so far is the guess; at least one
        step); True when done."""
        steps = self._steps
        if steps is None:
            return True
        clock = self._clock
        t0 = t = clock()
        end = t0 + (self.budget if budget is None else budget)
        try:
            while True:
                next(steps)
                t1 = clock()
                self.longest_step = max(self.longest_step, t1 - t)
                if t1 + self.longest_step > end:
                    break
                t = t1
        except StopIteration as stop:
            self._value, self._steps = stop.value, None
        except Exception as exc:  # noqa: BLE001 - re-raised by result(), as a future does
            self._error, self._steps = exc, None
        self.slices += 1
        self.longest = max(self.longest, clock() - t0)
        return self._steps is None

    def cancel(self) -> None:
        """Drop the steps (nothing more runs; :meth:`result` then raises)."""
        if self._steps is not None:
            self._steps.close()
            self._steps = None
            self._error = RuntimeError('Stepwise: cancelled')
