# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Feed-forward compensation of the worm-gear drive's positioning error (pure core, no rclpy).

Given the servo's intended worm-angle command ``theta1_ref(t)``, streamed sample by sample,
:class:`Compensator` returns a correction ``delta`` so that, with ``theta1 = theta1_ref +
delta`` applied to the drive, the antenna angle ``theta4`` follows ``theta1_ref * l_w / r_g``.

Design (everything is computed from the NOMINAL model at construction / reconfigure):

1. Reference filter F (causal unless ``compensation.preview_time`` > 0).  The streamed,
   piecewise-linear reference is convolved with a short smooth kernel g: an optional input
   shaper (ZV / ZVD / EI impulses tuned to the antenna mode given by
   :func:`worm_gear_sim.modal.modes` at the operating point) convolved with a B-spline of
   width ``compensation.smoothing_time``.  The filtered reference r and its time
   derivatives up to 4th order are exact quadratures of the stored history with
   precomputed weights (the derivatives of g are analytic).  A polynomial lead
   P(s) = 1 + p1 s + p2 s^2 is folded in so that F = G P = 1 + O(s^(n+1)),
   n = ``compensation.lag_order``: the filter then has no lag at constant rate (n >= 1) and
   none at constant acceleration (n = 2), so constant-rate tracking is not spoiled by the
   filter's delay.  With a preview the kernel is shifted earlier by up to the preview time.
2. Model inverse (flat output theta4).  The desired antenna path y = r l_w / r_g and its
   derivatives give, through the nominal model's equations (Eqs. 6, 9-13 with the Eq. 18
   friction of the rigid sliding speed and the mesh stiffness of Eqs. 16-17 at the
   predicted mesh phase), the gear-shaft torque, the gear angle, the mesh force, the mesh
   approach, the worm angle and finally the worm-shaft input theta1 that makes
   theta4 = y.  ``quasi_static`` keeps the terms up to y'' (compliance of gear shaft,
   teeth, bearings and worm shaft under load, viscous drag, friction and the rigid-body
   inertia torques: this alone cancels the antenna mode when y'' is smooth and timely);
   ``model_inverse`` adds the y''' / y'''' terms (gear-body and worm-body inertia,
   derivative of the drag), i.e. the full flat inverse of the 3-DOF chain.

``delta = theta1_inverse(t) - theta1_ref(t)``.  Per call: one ``np.interp`` of the history
at the quadrature nodes, one small matrix-vector product and ~60 float operations.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import BSpline

from .modal import modes
from .model import (
    P_COSL,
    P_COSPHI,
    P_COUT,
    P_FRIC_IN_COMPLIANCE,
    P_J4,
    P_JG,
    P_JW,
    P_KG,
    P_KGS,
    P_KW,
    P_KWS,
    P_LW,
    P_RG,
    P_RW,
    P_SINL,
    P_TLOAD,
    friction_coefficient,
    pack_parameters,
    tooth_stiffness,
)
from .params import Config

__all__ = ['Compensator', 'FilterDesign', 'Shaper', 'design_shaper', 'design_filter',
           'feedforward_series', 'SHAPERS']

SHAPERS = ('none', 'zv', 'zvd', 'ei')
N_DERIV = 5              # r, r', r'', r''', r''''
SPLINE_DEGREE = 7        # C^6 kernel: derivatives up to 4 plus a 2nd-order lead stay bounded
NODES_PER_SPLINE = 96    # quadrature nodes across one B-spline width


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
    weights: np.ndarray      # (N_DERIV, n) weights for r, r', ..., r''''
    shaper: Shaper
    smoothing_time: float
    lead: tuple              # (p1, p2) of P(s) = 1 + p1 s + p2 s^2
    shift: float             # how much earlier the kernel was moved (preview) [s]

    @property
    def lag_span(self) -> float:
        """Longest lag of the kernel [s] (history needed)."""
        return float(self.tau[-1])

    @property
    def settle_time(self) -> float:
        """Time after a reference feature during which the filter still acts on it."""
        return float(self.tau[-1])


def _spline_derivs(width: float, degree: int, orders: int):
    """Cardinal B-spline on [0, width] (unit area) and its derivatives as callables."""
    knots = np.linspace(0.0, width, degree + 2)
    b = BSpline.basis_element(knots, extrapolate=False)
    area = width / (degree + 1)      # integral of a basis element with uniform knots
    out = []
    for m in range(orders + 1):
        bm = b if m == 0 else b.derivative(m)
        out.append(lambda tt, f=bm: np.nan_to_num(f(tt), nan=0.0) / area)
    return out


def design_filter(shaper: Shaper, smoothing_time: float, lag_order: int = 2,
                  preview: float = 0.0, degree: int = SPLINE_DEGREE) -> FilterDesign:
    """Quadrature weights for the filtered reference and its first four derivatives.

    Kernel g = shaper * B-spline(width ``smoothing_time``); F = g * (1 + p1 d/dt + p2 d2/dt2)
    with p chosen so that F reproduces polynomials up to degree ``lag_order``; the kernel is
    moved earlier by min(preview, mean delay of g).
    """
    if not (smoothing_time > 0.0 and math.isfinite(smoothing_time)):
        raise ValueError(f'smoothing_time must be > 0, got {smoothing_time!r}')
    if lag_order not in (0, 1, 2):
        raise ValueError(f'lag_order must be 0, 1 or 2, got {lag_order!r}')
    h = float(smoothing_time)
    d = int(degree)
    need = N_DERIV - 1 + lag_order              # highest derivative of the spline used
    bders = _spline_derivs(h, d, min(need, d))
    # moments of g: spline moments (symmetric about h/2) combined with the impulses
    A, ti = shaper.amplitudes, shaper.times
    mean_b = 0.5 * h
    var_b = (d + 1) * (h / (d + 1)) ** 2 / 12.0   # sum of d+1 uniform boxes of width h/(d+1)
    mu1 = float(np.sum(A * ti)) + mean_b
    mu2 = float(np.sum(A * ti ** 2)) + 2.0 * mean_b * float(np.sum(A * ti)) + var_b + mean_b ** 2
    shift = min(max(preview, 0.0), mu1)
    mu1s = mu1 - shift
    mu2s = mu2 - 2.0 * shift * mu1 + shift ** 2
    # G(s) = 1 - mu1 s + mu2 s^2 / 2 + ...;  P = 1/G to order lag_order
    p1 = mu1s if lag_order >= 1 else 0.0
    p2 = (mu1s ** 2 - 0.5 * mu2s) if lag_order >= 2 else 0.0
    # quadrature nodes covering every shifted spline copy
    span = float(ti[-1]) + h
    n = int(math.ceil(span / h * NODES_PER_SPLINE)) + 1
    tau = np.linspace(0.0, span, n)
    dtau = tau[1] - tau[0]
    wq = np.full(n, dtau)
    wq[0] = wq[-1] = 0.5 * dtau
    gder = np.zeros((need + 1, n))
    for m in range(need + 1):
        for a, t0 in zip(A, ti):
            gder[m] += a * bders[m](tau - t0)
    coef = (1.0, p1, p2)
    W = np.zeros((N_DERIV, n))
    for m in range(N_DERIV):
        for k in range(lag_order + 1):
            if coef[k] != 0.0 or k == 0:
                W[m] += coef[k] * gder[m + k]
        W[m] *= wq
    tau_s = tau - shift
    # exact moments: sum_j W[m, j] (-tau_j)^k must equal d^m/dt^m (t^k) at t=0 for the
    # polynomial x(t) = t^k, k = 0..m+lag_order+1 (reproduction of low-degree references)
    W = _enforce_moments(W, tau_s, lag_order)
    return FilterDesign(tau=tau_s, weights=W, shaper=shaper, smoothing_time=h,
                        lead=(p1, p2), shift=shift)


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


# ---- model inverse -------------------------------------------------------------------------
class _Inverse:
    """Flat-output inverse of the nominal chain: theta1 needed for theta4 = y(t)."""

    def __init__(self, cfg: Config):
        p = pack_parameters(cfg)
        self.p = p
        self.Jw, self.Jg, self.J4 = p[P_JW], p[P_JG], p[P_J4]
        self.Kw, self.Kg, self.kws, self.kgs = p[P_KW], p[P_KG], p[P_KWS], p[P_KGS]
        self.lw, self.rw, self.rg = p[P_LW], p[P_RW], p[P_RG]
        self.sl, self.cl, self.cphi = p[P_SINL], p[P_COSL], p[P_COSPHI]
        self.cout, self.Tload = p[P_COUT], p[P_TLOAD]
        self.fric_compl = p[P_FRIC_IN_COMPLIANCE] != 0.0
        self.ratio = self.rg / self.lw       # theta1 per theta4

    def theta1(self, y0: float, y1: float, y2: float, y3: float, y4: float,
               dynamic: bool) -> float:
        """theta1 making theta4 = y; ``dynamic`` keeps the y''' and y'''' terms."""
        Kg, J4, Jg = self.Kg, self.J4, self.Jg
        if not dynamic:
            y3 = y4 = 0.0
        Ts = J4 * y2 + self.cout * y1 + self.Tload            # gear-shaft torque, Eq. 6
        th3 = y0 + Ts / Kg
        th3_1 = y1 + (J4 * y3 + self.cout * y2) / Kg
        th3_2 = y2 + (J4 * y4 + self.cout * y3) / Kg
        Tm = Jg * th3_2 + Ts if dynamic else (Jg + J4) * y2 + self.cout * y1 + self.Tload
        # friction of the rigid sliding speed, flank from the sign of the mesh torque
        th2_1 = th3_1 * self.ratio
        v_s = self.rw * self.cl * th2_1 + self.rg * self.sl * th3_1
        mu, _ = friction_coefficient(self.p, v_s, Tm)
        A = self.cphi * self.sl + mu * self.cl
        B = self.cphi * self.cl - mu * self.sl
        Wn = Tm / (self.rg * B)                               # Eq. 13 at the flat path
        th2_rigid = th3 * self.ratio
        cwkw, cgkg, _, _ = tooth_stiffness(self.p, th2_rigid, th3)
        if self.fric_compl:
            Ac, Bc = A, B
        else:
            Ac, Bc = self.cphi * self.sl, self.cphi * self.cl
        kgws = 1.0 / cwkw + 1.0 / cgkg + Ac * self.sl / self.kgs + Bc * self.cl / self.kws
        q = Wn * kgws / self.cl                               # Eq. 9
        th2 = (q + self.rg * th3) / self.lw                   # Eq. 8
        Tw = self.rw * A * Wn                                 # mesh torque on the worm
        if dynamic:
            Tw += self.Jw * th3_2 * self.ratio                # worm-body inertia (rigid)
        return th2 + Tw / self.Kw                             # Eq. 11


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

    def __init__(self, config: Config) -> None:
        self._hist_t: list[float] = []
        self._hist_x: list[float] = []
        self.reconfigure(config)
        self.reset(0.0, 0.0)

    # ---- design ----------------------------------------------------------------------------
    def reconfigure(self, config: Config) -> None:
        """Redesign from a (nominal) configuration; keeps the stored reference history."""
        cs = config.compensation
        self.config = config
        self.enabled = bool(cs.enabled)
        self.quasi_static = bool(cs.quasi_static)
        self.dynamic = bool(cs.model_inverse) and self.quasi_static
        self.preview = float(cs.preview_time)
        res = modes(config)
        # the antenna mode: largest theta4 participation (mode 1 for the default drive)
        k = int(np.argmax(np.abs(res.shapes[2, :])))
        self.mode_frequency_hz = float(res.frequencies_hz[k] or res.undamped_hz[k])
        self.mode_damping_ratio = float(max(res.damping_ratios[k], 0.0))
        shaper = design_shaper(cs.shaper, self.mode_frequency_hz, self.mode_damping_ratio,
                               0.05)
        self.filter = design_filter(shaper, float(cs.smoothing_time), int(cs.lag_order),
                                    self.preview)
        self._tau = np.ascontiguousarray(self.filter.tau)
        self._W = np.ascontiguousarray(self.filter.weights)
        self._inv = _Inverse(config)
        self._span = self.filter.lag_span + self.preview
        self._out_per_in = 1.0 / self._inv.ratio

    # ---- streaming -------------------------------------------------------------------------
    def reset(self, theta1_ref: float, t: float) -> None:
        """Forget the history: the reference has rested at ``theta1_ref`` until ``t``."""
        if not (math.isfinite(theta1_ref) and math.isfinite(t)):
            raise ValueError('reset: theta1_ref and t must be finite')
        self._hist_t = [float(t)]
        self._hist_x = [float(theta1_ref)]
        self._last_delta = 0.0
        self._reference = float(theta1_ref)
        self._derivs = np.array([float(theta1_ref), 0.0, 0.0, 0.0, 0.0])

    def update(self, t: float, theta1_ref: float) -> float:
        """Add the sample (t, theta1_ref) and return the correction delta [rad] for time
        t - preview_time.  Times must not decrease (an equal time replaces the sample)."""
        t = float(t)
        x = float(theta1_ref)
        if not (math.isfinite(t) and math.isfinite(x)):
            raise ValueError('update: t and theta1_ref must be finite')
        self._add_sample(t, x)
        return self._evaluate(t - self.preview)

    def _add_sample(self, t: float, x: float) -> None:
        ht, hx = self._hist_t, self._hist_x
        if t < ht[-1]:
            raise ValueError(f'update: time went backwards ({t!r} < {ht[-1]!r})')
        if t == ht[-1]:
            hx[-1] = x
        else:
            ht.append(t)
            hx.append(x)
        # drop samples older than needed (keep one before the window for interpolation)
        t_old = t - self._span
        while len(ht) > 2 and ht[1] <= t_old:
            del ht[0]
            del hx[0]

    def _evaluate(self, te: float) -> float:
        ht, hx = self._hist_t, self._hist_x
        self._reference = float(np.interp(te, ht, hx))
        if not self.enabled:
            self._last_delta = 0.0
            return 0.0
        r = self._W @ np.interp(te - self._tau, ht, hx)
        self._derivs = r
        if self.quasi_static:
            c = self._out_per_in
            th1 = self._inv.theta1(r[0] * c, r[1] * c, r[2] * c, r[3] * c, r[4] * c,
                                   self.dynamic)
        else:
            th1 = float(r[0])            # shaping (filtering) only
        self._last_delta = th1 - self._reference
        return self._last_delta

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
        """Last filtered worm reference r and its derivatives r' .. r'''' (copy)."""
        return np.array(self._derivs, float)

    def describe(self) -> str:
        f = self.filter
        return (f'shaper {f.shaper.kind} at {self.mode_frequency_hz:.4g} Hz '
                f'(zeta {self.mode_damping_ratio:.3g}, {f.shaper.duration * 1e3:.3g} ms), '
                f'smoothing {f.smoothing_time * 1e3:.3g} ms, lead {f.lead[0]:.3g} s / '
                f'{f.lead[1]:.3g} s^2, preview {self.preview * 1e3:.3g} ms, '
                f'quasi_static {self.quasi_static}, model_inverse {self.dynamic}')


def feedforward_series(config: Config, times, theta1_ref) -> np.ndarray:
    """Stream a sampled reference through a fresh :class:`Compensator` (batch helper).

    Returns the delta for each sample time (with a preview, the delta for ``times[i]`` is
    produced once the sample at ``times[i] + preview_time`` has been streamed; samples past
    the end hold the last value)."""
    t = np.asarray(times, float)
    x = np.asarray(theta1_ref, float)
    comp = Compensator(config)
    comp.reset(float(x[0]), float(t[0]))
    out = np.empty(t.size)
    P = comp.preview
    if P <= 0.0:
        for i in range(t.size):
            out[i] = comp.update(t[i], x[i])
        return out
    # the stream runs P ahead (past the end it holds the last value)
    j = 0
    for i in range(t.size):
        target = t[i] + P
        while j < t.size and t[j] <= target + 1e-12:
            comp._add_sample(float(t[j]), float(x[j]))
            j += 1
        if j == t.size and comp._hist_t[-1] < target:
            comp._add_sample(target, float(x[-1]))
        out[i] = comp._evaluate(float(t[i]))
    return out
