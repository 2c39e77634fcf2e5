# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Periodic functions of an angle for the compiled model, independent of its parameter
layout: a harmonic sum (the transmission error of Eq. 8's approach) and a table of a
smooth periodic function over one period, appended to a vector and interpolated by cubic
Hermite on value and slope (the tooth compliance of Eqs. 7, 16-17 over the mesh cycle).

A table is appended at the end of the vector it serves: the nodes (value, slope times
the interval) at phase 0, h, ..., 2 pi, then the number of intervals and the intervals per
radian, so that the lookup finds it from the vector's end."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numba import njit

TWO_PI = 2.0 * math.pi


@njit(cache=True, error_model='numpy', inline='always')
def harmonic_sum(p, at, n, theta):
    """(f, f', f'') of f = sum_k s_k sin(k theta) + c_k cos(k theta), k = 1..n, the pairs
    (s_k, c_k) from p[at]; sin/cos of k theta by the angle-addition recurrence."""
    s1, c1 = math.sin(theta), math.cos(theta)
    sk, ck = s1, c1
    f = df = d2f = 0.0
    for j in range(n):
        k = j + 1.0
        a, b = p[at + 2 * j], p[at + 2 * j + 1]
        f += a * sk + b * ck
        df += k * (a * ck - b * sk)
        d2f -= k * k * (a * sk + b * ck)
        sk, ck = sk * c1 + ck * s1, ck * c1 - sk * s1
    return f, df, d2f


@njit(cache=True, error_model='numpy', inline='always')
def table_lookup(p, phase):
    """(value, slope in the phase) of the periodic table at the end of ``p``."""
    m = p.shape[0]
    n = p[m - 2]
    scale = p[m - 1]
    x = (phase - TWO_PI * math.floor(phase / TWO_PI)) * scale      # in [0, n]
    i = min(int(x), int(n) - 1)
    t = x - i
    j = m - 2 - 2 * (int(n) + 1) + 2 * i
    y0, m0, y1, m1 = p[j], p[j + 1], p[j + 2], p[j + 3]
    t2 = t * t
    dy = y1 - y0
    val = y0 + t * m0 + t2 * (3.0 * dy - 2.0 * m0 - m1) + t2 * t * (m0 + m1 - 2.0 * dy)
    slope = m0 + t * (6.0 * dy - 4.0 * m0 - 2.0 * m1) + 3.0 * t2 * (m0 + m1 - 2.0 * dy)
    return val, slope * scale


@njit(cache=True, error_model='numpy')
def _lookup_many(p, phase):
    """:func:`table_lookup` at an array of phases: (values, slopes)."""
    val = np.empty(phase.shape[0])
    slope = np.empty(phase.shape[0])
    for i in range(phase.shape[0]):
        val[i], slope[i] = table_lookup(p, phase[i])
    return val, slope


def with_table(p: np.ndarray, f: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
               intervals: int, rtol: float, slope_rtol: float,
               key: bytes | None = None) -> np.ndarray | None:
    """``p`` with the table of ``f`` (phases -> (values, slopes), exact) over one period
    appended, or None if the interpolant misses f by more than ``rtol`` of |f| (value) or
    ``slope_rtol`` of max |f| (slope) at the quarter and mid points of its intervals (the
    mid point is the worst place of a cubic Hermite interpolant).  ``key``: the bytes of
    everything ``f`` depends on; the last tables accepted are kept by it (with intervals and
    tolerances), and a later call with an equal key appends the kept table (the same
    numbers) instead of building it again."""
    memo = None if key is None else (key, intervals, rtol, slope_rtol)
    table = None if memo is None else _TABLES.get(memo)
    if table is not None:
        return np.concatenate((p, table)) if np.all(np.isfinite(p)) else None
    h = TWO_PI / intervals
    s = np.arange(intervals + 1) * h
    with np.errstate(all='ignore'):
        val, slope = f(s)
        q = np.concatenate((p, np.ravel(np.column_stack((val, slope * h))),
                            [intervals, intervals / TWO_PI]))
        mid = np.concatenate([s[:-1] + k * h for k in (0.25, 0.5, 0.75)])
        exact, exact_slope = f(mid)
        got, got_slope = _lookup_many(q, mid)
        err = np.abs(got - exact) / np.abs(exact)
        err_slope = np.abs(got_slope - exact_slope) / np.abs(exact).max()
    if not (np.all(np.isfinite(q)) and err.max() <= rtol and err_slope.max() <= slope_rtol):
        return None
    if memo is not None:
        if len(_TABLES) >= 8:
            _TABLES.pop(next(iter(_TABLES)), None)
        _TABLES[memo] = q[p.size:].copy()
    return q


#: The last tables :func:`with_table` accepted, by key (a fit's candidates share one).
_TABLES: dict[tuple[bytes, int, float, float], np.ndarray] = {}
