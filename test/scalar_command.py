# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A command of time evaluated at one instant, fast, for the Radau references' right-hand
sides (which scipy calls ~10^5 times per reference: the profiles' array methods cost ~25 us a
call there, most of the references' time).

The commands the references use are polynomials of degree <= 2 between their kinks
(trapezoidal moves, piecewise-linear samples).  :func:`piecewise_quadratic` takes the exact
quadratic of each piece from three of the profile's own values and checks it against the
profile on a dense grid before it is used, so a command that is not piecewise quadratic
between the given kinks is refused, never approximated."""

from __future__ import annotations

from bisect import bisect_right
from collections.abc import Callable, Sequence

import numpy as np


def piecewise_quadratic(fn: Callable[[np.ndarray], np.ndarray],
                        breaks: Sequence[float]) -> Callable[[float], float]:
    """``fn`` (a vectorised function of time) as a scalar function, exact to rounding on
    [breaks[0], breaks[-1]] (held at the end values outside) when ``fn`` is a polynomial of
    degree <= 2 on each interval between consecutive ``breaks``; raises otherwise."""
    starts, coeffs = [], []
    for a, b in zip(breaks[:-1], breaks[1:]):
        # three interior points: a derivative jumps at the kinks, whose value is the next piece's
        h = 0.25 * (b - a)
        v0, v1, v2 = (float(v) for v in fn(np.array([a + h, a + 2 * h, a + 3 * h])))
        c2 = (v2 - 2.0 * v1 + v0) / (2.0 * h * h)
        c1 = (v1 - v0) / h - c2 * (3 * h)
        c0 = v0 - h * (c1 + h * c2)
        starts.append(a)
        coeffs.append((c0, c1, c2))
    lo, hi = breaks[0], breaks[-1]

    def at(t: float) -> float:
        i = max(bisect_right(starts, t) - 1, 0)
        s = min(max(t, lo), hi) - starts[i]
        c0, c1, c2 = coeffs[i]
        return c0 + s * (c1 + s * c2)

    grid = np.unique(np.r_[np.linspace(lo, hi, 100 * len(breaks) + 1), breaks])
    exact = np.asarray(fn(grid), float)
    mine = np.array([at(t) for t in grid])
    scale = max(float(np.abs(exact).max()), float(np.abs(np.diff(exact)).max()), 1e-300)
    err = np.abs(mine - exact)
    if err.max() > 1e-12 * scale:
        t = grid[int(err.argmax())]
        raise ValueError(f'the command is not quadratic between the kinks near t = {t} '
                         f'(off by {err.max():.3g})')
    return at
