# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Feed-forward compensation of the worm-gear drive's positioning error (pure core, no rclpy).

Given the servo's intended worm-angle command ``theta1_ref(t)``, streamed sample by sample,
:class:`Compensator` returns a correction ``delta`` so that, with ``theta1 = theta1_ref +
delta`` applied to the drive, the antenna angle ``theta4`` follows ``theta1_ref * l_w / r_g``.

Design (computed from the NOMINAL model at construction / :meth:`Compensator.reconfigure`):

1. Reference filter F (causal unless ``compensation.preview_time`` > 0).  The streamed
   reference (samples joined by straight lines, as the simulator and the node apply
   commands) is convolved with a short smooth kernel g: a B-spline whose knots are one
   command period apart (``node.publish_rate_hz``; degree 4, 5 ms at 1 kHz), optionally
   convolved with an input shaper (ZV / ZVD / EI impulses tuned to the antenna mode of
   :func:`worm_gear_sim.dynamics.modal.modes`).  The filtered reference r and its derivatives are
   quadratures of the stored history with precomputed weights (the derivatives of g are
   analytic), exact for polynomial references.  A lead P(s) = 1 + p1 s + p2 s^2 is folded
   in so that F = g P = 1 + O(s^(n+1)), n = ``compensation.lag_order``: the filter has no
   lag at constant rate (n >= 1) nor at constant acceleration (n = 2).  With a preview the
   kernel is moved earlier by up to its mean delay (centred: no lead needed).
   Knots one command period apart put (degree+1)-fold spectral zeros on the command rate
   and its harmonics: the correction, sampled at that rate and joined by straight lines,
   then does not alias into the antenna mode (at f_rate - f_mode).
2. Model inverse with theta4 as flat output.  The desired antenna path y = r l_w / r_g and
   its derivatives give, through the nominal model's equations (Eqs. 6, 9-13; Eq. 18
   friction at the rigid sliding speed, flank from the sign of the mesh torque; tooth
   stiffness of Eqs. 16-17 at the predicted mesh phase), the gear-shaft torque, the gear
   angle, the normal force, the mesh approach, the worm angle and the worm-shaft input
   theta1 that makes theta4 = y.  ``quasi_static`` keeps the terms up to y'': twist of
   both shafts, tooth and bearing deflection under the load torque, the bearing drag, the
   friction (efficiency) and the rigid-body inertia torques J y''.  Fed with a smooth and
   timely y'', the inertia terms cancel the 94.5 Hz antenna mode.  ``model_inverse`` adds
   the y''' / y'''' terms (gear- and worm-body inertia, drag rate); they need a degree-6
   kernel and measure worse at a 1 kHz command rate, so they are off by default.

3. Across the mesh play (``mesh.backlash`` > 0, ``compensation.backlash_inverse``): the
   inverse also takes up half the play on the flank the move needs, the sign of the mesh
   torque demand (:func:`worm_gear_sim.dynamics.inverse.gear_torque_demand`) of the filtered
   reference without the lead (two more rows of weights; the lead's overshoot at rate changes would
   flip the flank back and forth).  A change of flank steps the correction by the whole
   play, so the worm crosses it in one command period; it is timely only with a preview
   (:func:`centring_preview`).  Measured in docs/compensation.md, "Across the mesh play".
   With ``compensation.soft_crossing`` (the default) a zero of the demand predicted from
   its trend (its last two values) within half a crossing starts a smooth step across the
   play centred on that zero (:func:`_flank_at`): the sign changes in the middle of a move
   (a drag that outgrows a load), where the demand passes zero slowly; a fast reversal
   still takes the step.  A known trajectory plans its crossings on the whole path
   (:mod:`worm_gear_sim.play_crossing`: the new flank reached with the gear's velocity);
   the streaming path here is the one for live commands.

``delta = theta1_inverse(t) - theta1_ref(t)``.  Per call: one compiled kernel
(:func:`compensation_kernel`: an interpolation walk over the history at ~120 quadrature
nodes, the weights and the model inverse
:func:`worm_gear_sim.dynamics.inverse.inverse_theta1`), about 2 us with the Python call
(``benchmarks/bench_realtime.py``).  Structural damping (``damping.*``) is not in the
inverse (zero by default; it only makes the drive ring less).

Why no input shaper by default (see docs/compensation.md for the measurements): a
lag-free filter (needed for constant-rate tracking) that contains a shaper one antenna
period long overshoots at every rate change, which costs more than the shaper's
robustness gains; a plain shaper (``lag_order: 0``) delays the whole move, so its
constant-rate tracking error is many times the uncompensated one.  Shaping with
``lag_order: 0`` remains the robust choice for pure point-to-point moves.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np
from numba import njit

from .dynamics.inverse import gear_torque_demand, inverse_theta1
from .dynamics.modal import modes_steps
from .dynamics.model import DriveModel, has_play, rest_flank
from .params import Config
from .schema import Parameters
from .stepwise import Steps, run_steps

__all__ = ['Compensator', 'FilterDesign', 'Shaper', 'design_shaper', 'design_filter',
           'design_filter_steps',
           'SHAPERS', 'compensation_kernel', 'centring_preview', 'with_preview']

SHAPERS = ('none', 'zv', 'zvd', 'ei')
NODES_PER_KNOT = 24      # quadrature nodes per B-spline knot interval
FLANK_TORQUE = 1e-6      # N m: |mesh torque demand| above which the flank in contact changes
#: The streaming soft crossing (``compensation.soft_crossing``): at most this many antenna-mode
#: periods long, at least SOFT_SHORTEST command periods, the antenna's stray while coasting
#: within SOFT_TOLERANCE of half the play (:mod:`worm_gear_sim.play_crossing` plans the
#: known trajectory's crossings within the same bounds)
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
    derivatives, in steps (:mod:`worm_gear_sim.stepwise`).

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
    follow it (:func:`_flank_at`, :func:`worm_gear_sim.play_crossing.smooth_step`)."""
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


# ---- the streaming compensator -------------------------------------------------------------
class Compensator:
    """Streaming feed-forward: ``update(t, theta1_ref)`` returns delta to ADD to theta1.

    Causal: a call uses only the samples passed so far.  With ``preview_time`` P > 0 the
    caller streams the reference P ahead: ``update(t, theta1_ref(t))`` returns the delta for
    time ``t - P`` (the reference there is :attr:`reference`).  Samples are joined by
    straight lines, as the simulator interpolates commands.  Construction and
    :meth:`reconfigure` do the design work (modes, shaper, quadrature weights); a call
    costs tens of microseconds.
    """

    def __init__(self, model: DriveModel | Config) -> None:
        run_steps(self._init_steps(model))

    @classmethod
    def design_steps(cls, model: DriveModel | Config) -> Steps[Compensator]:
        """``Compensator(model)`` cut into steps (:mod:`worm_gear_sim.stepwise`): the same
        object, its design a piece at a time."""
        self = cls.__new__(cls)
        yield from self._init_steps(model)
        return self

    def _init_steps(self, model: DriveModel | Config) -> Steps[None]:
        self._derivs = np.zeros(0)       # r, r', ... of the filtered reference (reset fills it)
        self._flank = np.zeros(12)       # the kernel's flank state (_F_*)
        yield from self._reconfigure_steps(model)
        self.reset(0.0, 0.0)

    # ---- design ----------------------------------------------------------------------------
    def reconfigure(self, model: DriveModel | Config) -> None:
        """Redesign from a (nominal) model or configuration; keeps the stored reference
        history."""
        run_steps(self._reconfigure_steps(model))

    def _reconfigure_steps(self, model: DriveModel | Config) -> Steps[None]:
        """:meth:`reconfigure` in steps (each ~0.1-0.4 ms on an idle core)."""
        model = DriveModel.of(model)
        config = model.config
        cs = config.compensation
        self.model = model
        self.config = config
        self.enabled = bool(cs.enabled)
        self.quasi_static = bool(cs.quasi_static)
        self.dynamic = bool(cs.model_inverse) and self.quasi_static
        self.preview = float(cs.preview_time)
        # the antenna mode with the teeth in contact (with play, the modes of the linearised
        # model are those of a free mesh: a rigid antenna and the gear alone)
        linear = DriveModel(dataclasses.replace(
            config, mesh=dataclasses.replace(config.mesh, backlash=0.0))) \
            if has_play(model.p) else model
        yield
        res = yield from modes_steps(linear)
        yield
        # the antenna mode: largest theta4 participation (mode 1 for the default drive)
        k = int(np.argmax(np.abs(res.shapes[2, :])))
        self.mode_frequency_hz = float(res.frequencies_hz[k] or res.undamped_hz[k])
        self.mode_damping_ratio = float(max(res.damping_ratios[k], 0.0))
        shaper = design_shaper(cs.shaper, self.mode_frequency_hz, self.mode_damping_ratio)
        # derivatives the inverse needs (r..r'' or r..r''''), plus the lead order: the
        # B-spline degree is the lowest that keeps them bounded (at least MIN_DEGREE)
        n_deriv = 5 if self.dynamic else (3 if self.quasi_static else 1)
        lag = int(cs.lag_order)
        degree = max(n_deriv - 1 + lag, MIN_DEGREE)
        # knots one command period apart (by default): the kernel's spectrum then has
        # (degree+1)-fold zeros at the command rate and its harmonics, so the correction,
        # sampled at that rate and joined by straight lines, does not alias into the
        # antenna mode (at f_rate - f_mode)
        width = float(cs.smoothing_time) or (degree + 1) / config.node.publish_rate_hz
        self.filter = yield from design_filter_steps(shaper, width / (degree + 1), degree, lag,
                                                     self.preview, n_deriv)
        yield
        self._tau = np.ascontiguousarray(self.filter.tau)
        W = self.filter.weights
        # the backlash inverse decides the flank from the lead-free (lag 0) r', r'': the
        # lead makes r'' overshoot at every rate change, which would flip the flank back
        # and forth (same knots, same nodes: the rows stack)
        self.backlash_inverse = bool(cs.backlash_inverse) and self.quasi_static \
            and has_play(model.p)
        if self.backlash_inverse:
            plain = yield from design_filter_steps(shaper, width / (degree + 1), degree, 0,
                                                   self.preview, 3)
            yield
            if not np.array_equal(plain.tau, self.filter.tau):  # pragma: no cover
                raise RuntimeError('backlash inverse: filter nodes differ')
            W = np.vstack((W, plain.weights[1:3]))
        self._W = np.ascontiguousarray(W)
        if self._derivs.size != W.shape[0]:
            self._derivs = np.zeros(W.shape[0])
        self._flank[_F_ON] = 1.0 if self.backlash_inverse else 0.0
        self._rest_flank = rest_flank(model.p) if self.backlash_inverse else 0.0
        self.soft_crossing = bool(cs.soft_crossing)
        self._flank[_F_LONG] = SOFT_PERIODS / self.mode_frequency_hz \
            if self.mode_frequency_hz > 0.0 else 0.0
        self._flank[_F_SHORT] = SOFT_SHORTEST / config.node.publish_rate_hz
        d = model.derived
        self._flank[_F_COEF] = 12.0 * (d.J_g + d.J_4) * SOFT_TOLERANCE * 0.5 * \
            config.mesh.backlash
        self._n_deriv = n_deriv
        self._span = self.filter.lag_span + self.preview
        self._p, self._output_per_input = model.p, model.output_per_input   # per-sample use

    # ---- streaming -------------------------------------------------------------------------
    def reset(self, theta1_ref: float, t: float) -> None:
        """Forget the history: the reference has rested at ``theta1_ref`` until ``t``."""
        if not (math.isfinite(theta1_ref) and math.isfinite(t)):
            raise ValueError('reset: theta1_ref and t must be finite')
        self._ht = np.empty(64)          # history: times and values, [lo, hi) in use
        self._hx = np.empty(64)
        self._ht[0], self._hx[0] = float(t), float(theta1_ref)
        self._lo, self._hi = 0, 1
        self._last_delta = 0.0
        self._reference = float(theta1_ref)
        self._derivs = np.zeros(self._W.shape[0])
        self._derivs[0] = float(theta1_ref)
        self._flank[0] = self._rest_flank
        self._flank[_F_STATE] = 0.0
        self._flank[_F_TPREV] = -math.inf

    def update(self, t: float, theta1_ref: float) -> float:
        """Add the sample (t, theta1_ref) and return the correction delta [rad] for time
        t - preview_time.  Times must not decrease (an equal time replaces the sample)."""
        t = float(t)
        self.add_sample(t, theta1_ref)
        te = t - self.preview
        d = self.evaluate(te)
        self.trim(te)
        return d

    def add_sample(self, t: float, theta1_ref: float) -> None:
        """Append a sample to the history without evaluating (an equal time replaces the
        last sample; times must not decrease)."""
        t = float(t)
        x = float(theta1_ref)
        if not (math.isfinite(t) and math.isfinite(x)):
            raise ValueError('update: t and theta1_ref must be finite')
        hi = self._hi
        last = self._ht[hi - 1]
        if t < last:
            raise ValueError(f'update: time went backwards ({t!r} < {last!r})')
        if t == last:
            self._hx[hi - 1] = x
            return
        if hi == self._ht.size:          # full: compact, grow if still more than half used
            lo = self._lo
            n = hi - lo
            size = self._ht.size * 2 if n > self._ht.size // 2 else self._ht.size
            ht, hx = np.empty(size), np.empty(size)
            ht[:n], hx[:n] = self._ht[lo:hi], self._hx[lo:hi]
            self._ht, self._hx, self._lo, hi = ht, hx, 0, n
        self._ht[hi] = t
        self._hx[hi] = x
        self._hi = hi + 1

    def evaluate(self, te: float) -> float:
        """The correction for time ``te`` from the history so far (the reference at ``te``
        becomes :attr:`reference`); any ``te`` not before the last :meth:`trim`."""
        d, ref = compensation_kernel(float(te), self._tau, self._W, self._ht, self._hx,
                                     self._lo, self._hi, self._p, self._output_per_input,
                                     self.quasi_static, self.dynamic, self.enabled,
                                     self._derivs, self._flank)
        self._reference = ref
        self._last_delta = d
        return d

    def trim(self, te_min: float) -> None:
        """Forget the samples no evaluation at a time >= ``te_min`` needs (one before the
        filter window is kept for the interpolation)."""
        t_old = te_min - float(self._tau[-1])
        ht, lo, hi = self._ht, self._lo, self._hi
        while hi - lo > 2 and ht[lo + 1] <= t_old:
            lo += 1
        self._lo = lo

    def copy_history(self, other: Any) -> None:
        """Take over the reference history and last outputs of ``other`` (a redesign that
        keeps the stream; a Compensator, or a blend of two, whose new one's)."""
        self._ht, self._hx = other._ht.copy(), other._hx.copy()
        self._lo, self._hi = other._lo, other._hi
        self._last_delta, self._reference = other._last_delta, other._reference
        if self.backlash_inverse:    # the teeth stay where they are (none: the rest flank)
            self._flank[0] = other._flank[0] if other.backlash_inverse else self._rest_flank
            if other.backlash_inverse:          # and a crossing under way goes on
                self._flank[_F_STATE] = other._flank[_F_STATE]

    def __copy__(self) -> Compensator:
        """A copy that streams on its own: its history and kernel state are its own arrays
        (the design is shared)."""
        new = object.__new__(type(self))
        new.__dict__.update(self.__dict__)
        new._ht, new._hx = self._ht.copy(), self._hx.copy()
        new._derivs, new._flank = self._derivs.copy(), self._flank.copy()
        return new

    # ---- introspection ---------------------------------------------------------------------
    @property
    def reference(self) -> float:
        """theta1_ref at the time the last delta applies to (t - preview_time)."""
        return self._reference

    @property
    def delta(self) -> float:
        return self._last_delta

    @property
    def filtered_reference(self) -> np.ndarray:
        """Last filtered worm reference and its derivatives (r, r', r'' [, r''', r''''])."""
        return np.array(self._derivs[:self._n_deriv], float)

    @property
    def soft_crossing(self) -> bool:
        """Cross the play along a smooth step planned ahead (``compensation.soft_crossing``)
        rather than in one command period."""
        return bool(self._flank[_F_SOFT] > 0.0)

    @soft_crossing.setter
    def soft_crossing(self, on: bool) -> None:
        self._flank[_F_SOFT] = 1.0 if on else 0.0

    @property
    def flank(self) -> float:
        """The flank the backlash inverse has the worm on: +1 drive, -1 coast, 0 the centre
        of the play (always 0 without play or with ``compensation.backlash_inverse`` off)."""
        return float(self._flank[0])

    def describe(self) -> str:
        f = self.filter
        return (f'shaper {f.shaper.kind} at {self.mode_frequency_hz:.4g} Hz '
                f'(zeta {self.mode_damping_ratio:.3g}, {f.shaper.duration * 1e3:.3g} ms), '
                f'B-spline degree {f.degree} over {f.smoothing_time * 1e3:.3g} ms, '
                f'lead {f.lead[0]:.3g} s / '
                f'{f.lead[1]:.3g} s^2, preview {self.preview * 1e3:.3g} ms, '
                f'quasi_static {self.quasi_static}, model_inverse {self.dynamic}, '
                f'backlash_inverse {self.backlash_inverse}')


def centring_preview(model: DriveModel | Config) -> float:
    """The preview [s] that centres the reference filter's kernel on the present (its mean
    delay: 2.5 ms at a 1 kHz command rate).  With it the filtered reference is not late, so
    the backlash inverse changes flank when the move's torque changes sign rather than
    after (docs/compensation.md: 53-115x instead of 1.8-4x on fast reversals)."""
    config = DriveModel.of(model).config
    return float(Compensator(DriveModel(with_preview(config, 1.0))).filter.shift)


def with_preview(config: Parameters, preview: float) -> Parameters:
    """A copy of ``config`` (a Config stays a Config) with another
    ``compensation.preview_time`` [s]."""
    cs = dataclasses.replace(config.compensation, preview_time=float(preview))
    return dataclasses.replace(config, compensation=cs)
