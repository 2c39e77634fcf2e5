# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The reference filter of the feed-forward compensation (pure core, no rclpy).

This module contains the filter's design (input shapers, the B-spline kernel with its lead,
the quadrature weights of the filtered reference and its derivatives) and its compiled
per-sample evaluation (:func:`compensation_kernel`: the filter, the flank the backlash
inverse takes and the model inverse).  The streaming
:class:`~worm_gear_sim.compensation.streaming.Compensator` designs and runs it; its module
docstring explains the design.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np
from numba import njit

from .._support.stepwise import Steps, run_steps
from ..dynamics.inverse import gear_torque_demand, inverse_theta1

__all__ = ['FilterDesign', 'Shaper', 'design_shaper', 'design_filter', 'design_filter_steps',
           'SHAPERS', 'compensation_kernel']

SHAPERS = ('none', 'zv', 'zvd', 'ei')
NODES_PER_KNOT = 24      # quadrature nodes per B-spline knot interval
FLANK_TORQUE = 1e-6      # N m: |mesh torque demand| above which the flank in contact changes
#: The streaming soft crossing (``compensation.soft_crossing``): at most this many antenna-mode
#: periods long, at least SOFT_SHORTEST command periods, the antenna's stray while coasting
#: within SOFT_TOLERANCE of half the play (:mod:`worm_gear_sim.compensation.play_crossing` plans
#: the known trajectory's crossings within the same bounds)
SOFT_PERIODS = 1.0
SOFT_SHORTEST = 3.0
SOFT_TOLERANCE = 1e-2
# the kernel's flank state: [flank in contact, backlash inverse on, soft crossing on, longest
# crossing [s], shortest [s], 12 J tol [kg m^2 rad] (J = J_g + J_4, tol: the stray allowed),
# previous demand [N m], its time [s], crossing start [s], end [s], from flank, to flank]
_F_ON, _F_SOFT, _F_LONG, _F_SHORT, _F_COEF, _F_DPREV, _F_TPREV = 1, 2, 3, 4, 5, 6, 7
_F_START, _F_END, _F_FROM, _F_TO = 8, 9, 10, 11
_F_STATE = slice(6, 12)          # what a redesign carries over (with the flank in contact)
MIN_DEGREE = 4           # >= 5-fold spectral zeros at the command rate (anti-aliasing)


# ---- input shapers -------------------------------------------------------------------------
@dataclass(frozen=True)
class Shaper:
    """Impulse sequence sum_i A_i delta(t - t_i) (sum A_i = 1) tuned to one mode."""

    kind: str
    frequency_hz: float
    damping_ratio: float
    times: np.ndarray
    amplitudes: np.ndarray

    @property
    def duration(self) -> float:
        return float(self.times[-1])


def design_shaper(kind: str, frequency_hz: float, damping_ratio: float = 0.0,
                  ei_tolerance: float = 0.05) -> Shaper:
    """ZV, ZVD or EI (Singer-Seering) shaper for a mode of damped frequency ``frequency_hz``.

    EI uses the closed-form design for a vibration tolerance V (residual allowed at the
    design frequency) with its first-order damping correction.
    """
    if kind not in SHAPERS:
        raise ValueError(f'shaper must be one of {", ".join(SHAPERS)}, got {kind!r}')
    if kind == 'none':
        return Shaper('none', float(frequency_hz), float(damping_ratio), np.zeros(1),
                      np.ones(1))
    if not (math.isfinite(frequency_hz) and frequency_hz > 0.0):
        raise ValueError(f'shaper frequency must be > 0, got {frequency_hz!r}')
    z = float(min(max(damping_ratio, 0.0), 0.99))
    T = 1.0 / frequency_hz                      # damped period
    K = math.exp(-z * math.pi / math.sqrt(1.0 - z * z))
    if kind == 'zv':
        amps = np.array([1.0, K]) / (1.0 + K)
        times = np.array([0.0, 0.5 * T])
    elif kind == 'zvd':
        amps = np.array([1.0, 2.0 * K, K * K]) / (1.0 + K) ** 2
        times = np.array([0.0, 0.5 * T, T])
    else:
        V = ei_tolerance
        a1 = 0.25 * (1.0 + V) + z * (0.24968 + 0.80008 * V)   # Singer & Seering (1990) fits
        a3 = 0.25 * (1.0 + V) + z * (-0.24968 - 0.80008 * V)
        a2 = 1.0 - a1 - a3
        t2 = (0.5 + z * (0.4616 * V + 0.24056) + z * z * (0.9 * V + 0.26)) * T
        amps = np.array([a1, a2, a3])
        times = np.array([0.0, t2, T])
    return Shaper(kind, float(frequency_hz), z, times, amps / amps.sum())


# ---- reference filter ----------------------------------------------------------------------
@dataclass(frozen=True)
class FilterDesign:
    """Quadrature of the reference filter: r^(m)(t) = weights[m] @ x(t - tau)."""

    tau: np.ndarray          # lags of the quadrature nodes [s] (negative: preview)
    weights: np.ndarray      # (n_deriv, n) weights for r, r', r'', ...
    shaper: Shaper
    knot_spacing: float      # B-spline knot spacing [s]
    degree: int              # B-spline degree
    lead: tuple              # (p1, p2) of P(s) = 1 + p1 s + p2 s^2
    shift: float             # how much earlier the kernel was moved (preview) [s]

    @property
    def smoothing_time(self) -> float:
        """Width of the B-spline [s]."""
        return self.knot_spacing * (self.degree + 1)

    @property
    def lag_span(self) -> float:
        """Longest lag of the kernel [s]: the history needed, and how long after a feature
        of the reference the filter still acts on it."""
        return float(self.tau[-1])


@functools.cache
def _cardinal_pieces(degree: int, order: int) -> np.ndarray:
    """Coefficients c[i, p] of u**p of the ``order``-th derivative of the cardinal B-spline of
    ``degree`` (knots 0, 1, ..., degree + 1; unit area) on its piece i, x = i + u, 0 <= u < 1:
    the truncated powers M(x) = sum_k (-1)^k C(n+1, k) (x - k)_+^n / n!, expanded exactly in
    integers (no cancellation left for the floats: each piece is evaluated by Horner in u).
    Kept per (degree, order), read-only: the exact fractions were two thirds of a design."""
    n, m = degree, order
    out = np.zeros((n + 1, n - m + 1))
    for i in range(n + 1):
        acc = [Fraction(0)] * (n - m + 1)
        for k in range(i + 1):
            w = Fraction((-1) ** k * math.comb(n + 1, k), math.factorial(n - m))
            for p in range(n - m + 1):         # (u + i - k)^(n-m), binomial in u
                acc[p] += w * math.comb(n - m, p) * (i - k) ** (n - m - p)
        out[i] = [float(a) for a in acc]
    out.flags.writeable = False
    return out


def _spline_derivs(width: float, degree: int, orders: int):
    """Cardinal B-spline on [0, width] (unit area) and its derivatives as callables, zero
    outside [0, width]; a piecewise-constant derivative takes the value of the interval to
    the right of a knot (of the left one at ``width``), as scipy's BSpline does."""
    knots = np.linspace(0.0, width, degree + 2)
    hk = width / (degree + 1)

    def make(m: int):
        coef = _cardinal_pieces(degree, m) / hk ** (m + 1)     # B = M(x/hk)/hk: unit area

        def f(tt: np.ndarray) -> np.ndarray:
            x = np.asarray(tt, dtype=float)
            i = np.clip(np.searchsorted(knots, x, side='right') - 1, 0, degree)
            u = (x - knots[i]) / hk
            c = coef[i]
            val = c[..., -1]
            for p in range(c.shape[-1] - 2, -1, -1):
                val = val * u + c[..., p]
            return np.where((x >= 0.0) & (x <= knots[-1]), val, 0.0)
        return f
    return [make(m) for m in range(orders + 1)]


def design_filter(shaper: Shaper, knot_spacing: float, degree: int = 4, lag_order: int = 2,
                  preview: float = 0.0, n_deriv: int = 3) -> FilterDesign:
    """Quadrature weights for the filtered reference r and its first ``n_deriv - 1``
    derivatives (:func:`design_filter_steps`, run through)."""
    return run_steps(design_filter_steps(shaper, knot_spacing, degree, lag_order, preview,
                                         n_deriv))


def design_filter_steps(shaper: Shaper, knot_spacing: float, degree: int = 4,
                        lag_order: int = 2, preview: float = 0.0, n_deriv: int = 3
                        ) -> Steps[FilterDesign]:
    """Quadrature weights for the filtered reference r and its first ``n_deriv - 1``
    derivatives, in steps (:mod:`worm_gear_sim._support.stepwise`).

    Kernel g = shaper * B-spline (``degree``, uniform knots ``knot_spacing`` apart);
    F = g * (1 + p1 d/dt + p2 d2/dt2) with p chosen so that F reproduces polynomials up to
    degree ``lag_order`` (no lag at constant rate / acceleration); the kernel is moved
    earlier by min(preview, mean delay of g).  The highest derivative of the spline used is
    n_deriv - 1 + lag_order, which must not exceed ``degree``.
    """
    if not (knot_spacing > 0.0 and math.isfinite(knot_spacing)):
        raise ValueError(f'knot_spacing must be > 0, got {knot_spacing!r}')
    if lag_order not in (0, 1, 2):
        raise ValueError(f'lag_order must be 0, 1 or 2, got {lag_order!r}')
    if not (1 <= n_deriv <= 5):
        raise ValueError(f'n_deriv must be 1..5, got {n_deriv!r}')
    d = int(degree)
    need = n_deriv - 1 + lag_order               # highest derivative of the spline used
    if d < max(need, 1) or d > 12:
        raise ValueError(f'degree {d} cannot give {n_deriv - 1} derivatives with lead order '
                         f'{lag_order} (need {max(need, 1)}..12)')
    h = float(knot_spacing) * (d + 1)
    bders = _spline_derivs(h, d, need)
    # moments of g: spline moments (symmetric about h/2) combined with the impulses
    A, ti = shaper.amplitudes, shaper.times
    mean_b = 0.5 * h
    var_b = (d + 1) * knot_spacing ** 2 / 12.0    # d+1 uniform boxes of width knot_spacing
    mA = float(np.sum(A * ti))
    mu1 = mA + mean_b
    mu2 = float(np.sum(A * ti ** 2)) + 2.0 * mean_b * mA + var_b + mean_b ** 2
    shift = min(max(preview, 0.0), mu1)
    mu1s = mu1 - shift
    mu2s = mu2 - 2.0 * shift * mu1 + shift ** 2
    # G(s) = 1 - mu1 s + mu2 s^2 / 2 + ...;  P = 1/G to order lag_order
    p1 = mu1s if lag_order >= 1 else 0.0
    p2 = (mu1s ** 2 - 0.5 * mu2s) if lag_order >= 2 else 0.0
    # quadrature nodes covering every shifted spline copy, NODES_PER_KNOT per knot interval
    span = float(ti[-1]) + h
    n = int(math.ceil(span / knot_spacing * NODES_PER_KNOT)) + 1
    tau = np.linspace(0.0, span, n)
    dtau = tau[1] - tau[0]
    wq = np.full(n, dtau)
    wq[0] = wq[-1] = 0.5 * dtau
    gder = np.zeros((need + 1, n))
    for m in range(need + 1):
        yield
        for a, t0 in zip(A, ti):
            gder[m] += a * bders[m](tau - t0)
    coef = (1.0, p1, p2)
    W = np.zeros((n_deriv, n))
    for m in range(n_deriv):
        for k in range(lag_order + 1):
            W[m] += coef[k] * gder[m + k]
        W[m] *= wq
    tau_s = tau - shift
    yield
    # exact moments: polynomial references of low degree are filtered exactly
    W = _enforce_moments(W, tau_s, lag_order)
    return FilterDesign(tau=tau_s, weights=W, shaper=shaper, knot_spacing=float(knot_spacing),
                        degree=d, lead=(p1, p2), shift=shift)


def _enforce_moments(W: np.ndarray, tau: np.ndarray, lag_order: int) -> np.ndarray:
    """Minimum-norm correction of quadrature weights so that polynomial references of degree
    up to m + lag_order are differentiated exactly (r^(m) of x = t^k at t = 0)."""
    W = W.copy()
    s = tau / max(abs(tau).max(), 1e-12)            # scaled for conditioning
    scale = max(abs(tau).max(), 1e-12)
    for m in range(W.shape[0]):
        kmax = m + lag_order
        rows, rhs = [], []
        for k in range(kmax + 1):
            rows.append((-s) ** k)
            # d^m/dt^m t^k at t = 0 is k! if m == k else 0; in scaled units
            rhs.append(math.factorial(k) / scale ** m if k == m else 0.0)
        Amat = np.array(rows)
        r = np.array(rhs) - Amat @ W[m]
        W[m] += Amat.T @ np.linalg.solve(Amat @ Amat.T, r)
    return W


@njit(cache=True, error_model='numpy')
def _interp_at(s, ht, hx, lo, hi, j):
    """x(s) of the piecewise-linear history (ht, hx)[lo:hi] (held beyond its ends, as
    np.interp), searching down from index j; returns (value, index)."""
    while j > lo and ht[j] > s:
        j -= 1
    if s <= ht[lo]:
        return hx[lo], lo
    if j >= hi - 1:
        return hx[hi - 1], hi - 1
    return hx[j] + (hx[j + 1] - hx[j]) / (ht[j + 1] - ht[j]) * (s - ht[j]), j


@njit(cache=True, error_model='numpy')
def compensation_kernel(te, tau, W, ht, hx, lo, hi, p, out_per_in, quasi_static, dynamic,
                        enabled, r, flank):
    """One evaluation of the compensator at time ``te`` (the compiled per-sample update):
    r[m] = sum_k W[m, k] x(te - tau_k) (the filtered reference and its derivatives), then
    the model inverse.  ``flank`` = [flank in contact, backlash inverse on]: when on, the
    last two rows of W are the lead-free r', r'' whose mesh torque demand decides the flank
    (kept while |demand| <= FLANK_TORQUE), updated in place.  Returns (delta, x(te))."""
    ref = _interp_at(te, ht, hx, lo, hi, hi - 1)[0]
    if not enabled:
        return 0.0, ref
    nd = W.shape[0]
    for m in range(nd):
        r[m] = 0.0
    j = hi - 1
    for k in range(tau.size):           # tau increases: te - tau decreases
        v, j = _interp_at(te - tau[k], ht, hx, lo, hi, j)
        for m in range(nd):
            r[m] += W[m, k] * v
    if not quasi_static:
        return r[0] - ref, ref          # shaping (filtering) only
    c = out_per_in
    f = flank[0]
    if flank[_F_ON] > 0.0:              # the backlash inverse: which flank must carry the load
        nd -= 2
        demand = gear_torque_demand(p, r[nd] * c, r[nd + 1] * c, 0.0, 0.0, False)
        f = _flank_at(te, demand, flank)
    if nd == 5:
        th1 = inverse_theta1(p, r[0] * c, r[1] * c, r[2] * c, r[3] * c, r[4] * c, dynamic, f)
    else:
        th1 = inverse_theta1(p, r[0] * c, r[1] * c, r[2] * c, 0.0, 0.0, np.bool_(False), f)
    return th1 - ref, ref


@njit(cache=True, error_model='numpy')
def smootherstep(v):
    """The degree-7 smooth step on v in [0, 1] (a float or an array, not clipped): 0 -> 1
    with zero first, second and third derivatives at both ends; the crossings of the play
    follow it (:func:`_flank_at`, :func:`worm_gear_sim.compensation.play_crossing.smooth_step`)."""
    return v ** 4 * (35.0 + v * (-84.0 + v * (70.0 - 20.0 * v)))


@njit(cache=True, error_model='numpy')
def _flank_at(te, demand, flank):
    """The flank term at ``te`` from the mesh torque ``demand`` (updates ``flank``, the
    state described at _F_*): the sign of a demand beyond FLANK_TORQUE (a change is a step),
    or, with the soft crossing on, a smooth step across the play planned when the demand,
    extrapolated from its last two values, will change sign within half a crossing:
    centred on that zero, as long as the antenna's stray while it coasts (a linear demand
    missed over a window W strays |D'| W^3 / (12 J)) stays within tolerance."""
    start, end = flank[_F_START], flank[_F_END]
    if end > start:
        if te < end:                    # crossing: the degree-7 smooth step (play_crossing)
            s = smootherstep(min(max((te - start) / (end - start), 0.0), 1.0))
            flank[_F_DPREV], flank[_F_TPREV] = demand, te
            return flank[_F_FROM] + (flank[_F_TO] - flank[_F_FROM]) * s
        flank[0] = flank[_F_TO]         # crossed
        flank[_F_START] = flank[_F_END] = 0.0
    f = flank[0]
    if demand > FLANK_TORQUE:
        f = 1.0
    elif demand < -FLANK_TORQUE:
        f = -1.0
    flank[0] = f
    t_prev, d_prev = flank[_F_TPREV], flank[_F_DPREV]
    flank[_F_DPREV], flank[_F_TPREV] = demand, te
    if flank[_F_SOFT] > 0.0 and te > t_prev and abs(demand) > FLANK_TORQUE \
            and demand * f > 0.0:
        rate = (demand - d_prev) / (te - t_prev)
        if demand * rate < 0.0:         # heading for zero
            tau = -demand / rate
            w = min(flank[_F_LONG], (flank[_F_COEF] / abs(rate)) ** (1.0 / 3.0))
            if tau <= 0.5 * w and 2.0 * tau >= flank[_F_SHORT]:
                flank[_F_START], flank[_F_END] = te, te + 2.0 * tau
                flank[_F_FROM], flank[_F_TO] = f, -f
    return f
