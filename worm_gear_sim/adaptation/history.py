# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Copies of the estimate kept for a short while (:class:`.estimator.Adapter`): the one the
step detector judges a window by, from before the window, and the one a crossing found late
rolls the estimate back to, from before the crossing."""

from __future__ import annotations

import collections
import math
from collections.abc import Sequence

import numpy as np

__all__ = ['EVERY', 'SPAN', 'EstimateHistory']

#: A copy every EVERY s, each kept for SPAN s [s].
EVERY = 0.01
SPAN = 0.6


class EstimateHistory:
    """Copies of ``arrays`` (the estimate, its covariance, the window's sums: the live arrays,
    restored in place) taken by :meth:`keep`; :attr:`lagged`: the latest copy at least ``lag``
    s old (the oldest one while none is), its first two as :attr:`theta` and :attr:`P`."""

    def __init__(self, arrays: Sequence[np.ndarray], lag: float) -> None:
        self._arrays = tuple(arrays)
        self._lag = lag
        self._copies: collections.deque = collections.deque()
        self.next = -math.inf
        self.lagged: tuple[np.ndarray, ...] = tuple(a.copy() for a in self._arrays)
        self.theta, self.P = self.lagged[0], self.lagged[1]

    def keep(self, t: float) -> None:
        """Copy the arrays as of ``t`` (call when ``t >= next``)."""
        copies = self._copies
        while copies and t - copies[0][0] > SPAN:
            copies.popleft()
        copies.append((t, tuple(a.copy() for a in self._arrays)))
        self.next = t + EVERY
        lagged = copies[0]
        for c in copies:
            if c[0] > t - self._lag:
                break
            lagged = c
        self.lagged = lagged[1]
        self.theta, self.P = self.lagged[0], self.lagged[1]

    def before(self, t: float) -> tuple[np.ndarray, ...] | None:
        """The latest copy taken at or before ``t``, if one is kept."""
        out = None
        for c in self._copies:
            if c[0] > t:
                break
            out = c[1]
        return out

    def restore(self, copy: Sequence[np.ndarray]) -> None:
        """Put ``copy`` (from :meth:`before`) back into the live arrays."""
        for a, c in zip(self._arrays, copy):
            a[:] = c
