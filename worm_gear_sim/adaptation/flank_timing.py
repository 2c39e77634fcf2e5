# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""When did the drive change flank: the instant the real drive's mesh torque crossed zero,
measured from the residual around the model's own flank change (:class:`FlankTiming`).

At that instant T + c omega4 = -J alpha4, a measurement linear in load and drag that the
adapter's Kalman filter takes.  The instant comes from the residual's step area, the onset
of a floating gear (:func:`float_onset`) or the top of its arch (:func:`arch_top`); while
the model does not cross, :meth:`FlankTiming.detect` finds the drive's own steps (the
play).  The method: docs/adaptation.md ("What is estimated, from what").
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from .slots import Slot

__all__ = ['FlankTiming', 'WINDOW', 'LEVEL_WINDOW', 'STEP_SIDE', 'STEP_GAP', 'STEP_STRIDE',
           'STEP_NOISES', 'STEP_SIDE_WIDE', 'STEP_GAP_WIDE', 'ONSET_SHARE', 'SMOOTH_SIGMAS',
           'ONSET_NOISES', 'ONSET_SAMPLES', 'RATE_WINDOW', 'float_onset', 'arch_top',
           'path_rates', 'detect_core']

#: Half-width of the window over which the steps are integrated [s].
WINDOW = 0.3
#: Length of the windows giving the residual's level before and after [s].
LEVEL_WINDOW = 0.05


#: Step detector: fitted line length each side [s], the gap left for the transit [s], how
#: often it looks [s], and the smallest step in measurement noises.
STEP_SIDE = 0.04
STEP_GAP = 0.06
STEP_STRIDE = 0.01
STEP_NOISES = 15.0
#: The wide scale, for crossings that take longer than STEP_GAP (near the top speed the
#: gear floats across its play for ~0.1 s; measured 0.12-0.14 s on a drawn drive), and the
#: share of the step at which its float is taken to start.
STEP_SIDE_WIDE = 0.08
STEP_GAP_WIDE = 0.2
ONSET_SHARE = 0.05
#: A step within this many standard deviations of the periodic error not yet learnt is none.
SMOOTH_SIGMAS = 3.0
#: Half-width of the fit that gives the path's rates at a measured crossing [s].
RATE_WINDOW = 0.1

# FlankTiming._ts (read by the adapter's compiled sample, :mod:`.per_sample`): the rows in
# the record, the step detector's next look and last step, the open event's due time
T_N, T_NEXT_LOOK, T_LAST_STEP, T_EVENT_DUE, N_TS = range(5)


#: Float onset: the rise before the model's crossing counts from this many measurement
#: noises, over at least this many samples.
ONSET_NOISES = 5.0
ONSET_SAMPLES = 5
#: An arch's fitted curvature must be within this factor of the float's, |alpha4| / 2 (the
#: impact on the new flank leaves a transient ~2.5x as curved: docs/adaptation.md)
ARCH_CURVATURE = 2.0


def float_onset(ts: np.ndarray, dev: np.ndarray, threshold: float) -> float | None:
    """Where a parabolic rise dev = k (t - t0)^2 (dev >= 0 towards the step) starts: the
    zero of the least-squares line through sqrt(dev) over the run of samples above
    ``threshold`` that ends at the rise's peak (the last sample before the worm moves), or
    None (too few samples, no rise, a line that does not fit a parabola's root)."""
    if ts.size < ONSET_SAMPLES:
        return None
    k = int(np.argmax(dev))
    if dev[k] < 2.0 * threshold:
        return None
    j = k
    while j > 0 and dev[j - 1] > threshold:
        j -= 1
    if k - j + 1 < ONSET_SAMPLES:
        return None
    x, y = ts[j:k + 1], np.sqrt(dev[j:k + 1])
    slope, icpt = _line(x, y)
    if not slope > 0.0:
        return None
    fit = slope * x + icpt
    if float(np.sum((y - fit) ** 2)) > 0.05 * float(np.sum((y - y.mean()) ** 2)):
        return None                       # not a parabola's root: no onset
    return -icpt / slope


def arch_top(ts: np.ndarray, dev: np.ndarray, threshold: float,
             alpha: float = 0.0) -> float | None:
    """The top of an arch dev (>= 0 inside it): the vertex of the parabola fitted to the
    samples above half its peak, provided the peak exceeds twice ``threshold`` and the arch
    falls below half its peak on both sides inside the samples, and (``alpha`` > 0, the
    path's |alpha4|) its curvature is within ARCH_CURVATURE of the float's, alpha / 2;
    else None."""
    if ts.size < 2 * ONSET_SAMPLES:
        return None
    k = int(np.argmax(dev))
    top = float(dev[k])
    if top < 2.0 * threshold:
        return None
    i = k
    while i > 0 and dev[i - 1] > 0.5 * top:
        i -= 1
    j = k
    while j < dev.size - 1 and dev[j + 1] > 0.5 * top:
        j += 1
    if i == 0 or j == dev.size - 1 or j - i + 1 < ONSET_SAMPLES:
        return None
    x = ts[i:j + 1] - ts[k]
    c2, c1, _ = np.polyfit(x, dev[i:j + 1], 2)
    if not c2 < 0.0:
        return None
    if alpha > 0.0 and not alpha / ARCH_CURVATURE <= -2.0 * c2 <= alpha * ARCH_CURVATURE:
        return None                       # not the gear's float: its curvature is |alpha4|/2
    vertex = -c1 / (2.0 * c2)
    return float(ts[k] + vertex) if abs(vertex) <= x[-1] - x[0] else None


def path_rates(ts: np.ndarray, w4: np.ndarray, t_p: float) -> tuple[float, float]:
    """(omega4, alpha4) of the path at ``t_p``: the value and slope there of a parabola
    fitted to omega4 over ``RATE_WINDOW`` s each side.  Not the samples' own values: the
    model's crossing of the play, next to t_p, shakes the predicted antenna (alpha4 swung
    from 0.2 to -0.85 rad/s^2 and back within 30 ms on the sector scan, measured), and
    both the torque-zero measurement's noise and the cost of a mistimed crossing divide
    by alpha4."""
    m = np.abs(ts - t_p) <= RATE_WINDOW
    if np.count_nonzero(m) < 3:
        return float(np.interp(t_p, ts, w4)), 0.0
    _, c1, c0 = np.polyfit(ts[m] - t_p, w4[m], 2)
    return float(c0), float(c1)


def _line(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Least-squares line y = k x + d: (k, d)."""
    xm, ym = float(x.mean()), float(y.mean())
    dx = x - xm
    sxx = float(dx @ dx)
    k = float(dx @ (y - ym)) / sxx if sxx > 0.0 else 0.0
    return k, ym - k * xm


_NONE, _NONE2 = np.zeros(0), np.zeros((0, 0))
_NO_LAYOUT = np.array([-1, -1, -1, -1, 0, -1, 0], np.int64)   # no harmonics adapted


class FlankTiming:
    """Collects (t, r, omega4, alpha4) per sample; :meth:`model_flank_changed` opens an
    event at t_m; :meth:`ready` returns (t_p, omega4(t_p), alpha4(t_p)) once the window
    after it has passed, or None; :meth:`detect` finds the drive's own crossings.
    The record's length and the due times are in ``_ts``, which the adapter's compiled
    sample reads (:mod:`.per_sample`)."""

    _n = Slot('_ts', T_N, int)
    _next_look = Slot('_ts', T_NEXT_LOOK)
    _last_step = Slot('_ts', T_LAST_STEP)

    def __init__(self) -> None:
        self._ts = np.zeros(N_TS)
        self._a = np.zeros((4096, 6))  # rows (t, r, omega4, alpha4, theta2, theta3); [0, n)
        self._n = 0
        self._event = None
        self.events = 0
        self.measured = 0
        self.onsets = 0
        self.arches = 0
        self._next_look = -math.inf
        self._last_step = -math.inf

    def push(self, t: float, r: float, w4: float, a4: float, th2: float = 0.0,
             th3: float = 0.0) -> None:
        """A sample (t, residual, omega4, alpha4, theta2, theta3) into the record (the
        adapter's compiled sample writes its rows itself, after :meth:`make_room` when
        full)."""
        if self._n == self._a.shape[0]:
            self.make_room(t)
        n = self._n
        row = self._a[n]
        row[0], row[1], row[2], row[3], row[4], row[5] = t, r, w4, a4, th2, th3
        self._n = n + 1

    def make_room(self, t: float) -> None:
        """The record is full: drop what is older than any look at ``t`` needs (or, if
        nothing is, double it)."""
        a, n = self._a, self._n
        keep = max(2.0 * (WINDOW + LEVEL_WINDOW), 2 * STEP_SIDE_WIDE + STEP_GAP_WIDE) + 0.05
        k = int(np.searchsorted(a[:n, 0], t - keep))
        if k == 0:
            self._a = np.concatenate([a, np.zeros_like(a)])
        else:
            a[:n - k] = a[k:n]
            self._n = n - k

    @property
    def _event(self) -> tuple[float, float] | None:
        """The open event (t_m, s), or None."""
        return self._open

    @_event.setter
    def _event(self, ev: tuple[float, float] | None) -> None:
        self._open = ev
        self._ts[T_EVENT_DUE] = math.inf if ev is None else ev[0] + WINDOW + LEVEL_WINDOW

    def _since(self, t0: float) -> np.ndarray | None:
        """The rows from ``t0`` on (None if the record does not reach back that far)."""
        a = self._a[:self._n]
        if not self._n or a[0, 0] > t0 + 1e-9:
            return None
        return a[int(np.searchsorted(a[:, 0], t0)):]

    def clear(self) -> None:
        self._n = 0
        self._event = None

    def due(self, t: float) -> bool:
        """Whether :meth:`detect` would look at ``t`` (every STEP_STRIDE s)."""
        return t >= self._next_look

    def detect(self, t: float, noise: float, t_model: float, least: float = 0.0,
               theta: np.ndarray = _NONE, applied: np.ndarray = _NONE, P: np.ndarray = _NONE2,
               lay: np.ndarray = _NO_LAYOUT, t_applied: float = -math.inf,
               applied_bound: float = 0.0
               ) -> tuple[float, float, float, float, bool, float] | None:
        """A step of the drive's own in the residual (its crossing of the play while the
        model did not cross: no model crossing at ``t_model`` within the window): lines
        fitted to STEP_SIDE s of the residual each side of a STEP_GAP s gap, their values at
        the centre differ by more than STEP_NOISES ``noise``, than ``least`` (half the play
        once it is known) and than twice the lines' own change over the gap; a step
        applied to the model at ``t_applied`` within the window steps the residual too, by
        at most ``applied_bound`` [rad] (the change of the static correction it made): the
        step must then exceed those thresholds by that much; with the
        estimate (``theta``, its covariance ``P``, the model in use's ``applied``, the
        adapter's layout ``lay``: :mod:`.per_sample`'s L_* indices) the share of the step
        the periodic error not yet learnt makes is taken off, and the step must exceed
        SMOOTH_SIGMAS of its sd (module docstring).  Returns (t_p, omega4, alpha4, step
        [rad], wide, rise [s]), t_p where the step's float starts (:func:`detect_core`),
        rise the time from there to the step's middle, or None.  Looks every STEP_STRIDE s."""
        if t < self._next_look:
            return None
        self._next_look = t + STEP_STRIDE
        found, t_p, w_p, a_p, step, wide, rise = detect_core(
            self._a, self._n, t, noise, t_model, self._last_step, least, theta, applied, P,
            lay, t_applied, applied_bound)
        if not found:
            return None
        self._last_step = t_p + rise         # (the step's middle: the next looks pass it)
        return t_p, w_p, a_p, step, wide, rise

    def model_flank_changed(self, t: float, old: float, new: float) -> None:
        """The model's flank changed at ``t`` from ``old`` to ``new`` (+1 / -1; 0 unknown)."""
        if self._event is not None:          # another change inside the window: no event
            self._event = None
            return
        if old == 0.0 or new == 0.0 or old == new:
            return
        self.events += 1
        self._event = (t, -0.5 * (new - old))

    def event_spans(self, t: float) -> bool:
        """Whether ``t`` falls inside the open event's window (its levels included)."""
        ev = self._event
        return ev is not None and abs(t - ev[0]) <= WINDOW + LEVEL_WINDOW

    def drop_event(self) -> None:
        self._event = None

    def event_due(self, t: float) -> bool:
        """Whether :meth:`ready` would look at ``t`` (a model crossing past its window)."""
        ev = self._event
        return ev is not None and t >= ev[0] + WINDOW + LEVEL_WINDOW

    def ready(self, t: float, play: float, min_play: float, model_play: float,
              noise: float = 0.0, float_lag: float = 0.0
              ) -> tuple[float, float, float, str] | None:
        """The event's measurement (t_p, omega4, alpha4, how: 'onset', 'arch' or 'area')
        once ``t`` is past its window; ``play``: the drive's
        play (the estimate) [rad], at least ``min_play`` to be seen; ``model_play``: the
        model's.  The residual's net step must be the drive's crossing less the model's,
        s (play - model_play), within a third of the play (else the drive did not cross
        in the window: no measurement).  ``noise``: the measurement noise [rad];
        ``float_lag``: the gear's time constant J/c [s] (the float's parabola starts that
        much after the drive's crossing, module docstring)."""
        ev = self._event
        if ev is None or t < ev[0] + WINDOW + LEVEL_WINDOW:
            return None
        self._event = None
        t_m, s = ev
        if not play >= min_play:
            return None
        a = self._since(t_m - WINDOW - LEVEL_WINDOW)
        if a is None:
            return None                       # the record does not reach back far enough
        ts, r = a[:, 0], a[:, 1]
        pre = ts < t_m - WINDOW
        post = (ts >= t_m + WINDOW) & (ts < t_m + WINDOW + LEVEL_WINDOW)
        mid = (ts >= t_m - WINDOW) & (ts < t_m + WINDOW)
        if not (np.any(pre) and np.any(post) and np.count_nonzero(mid) > 2):
            return None
        r_pre, r_post = float(np.mean(r[pre])), float(np.mean(r[post]))
        if abs(r_post - r_pre - s * (play - model_play)) > play / 3.0:
            return None
        before = (ts >= t_m - WINDOW) & (ts < t_m)
        onset = float_onset(ts[before], s * (r[before] - r_pre),
                            ONSET_NOISES * noise)
        if onset is not None:                 # the drive crossed first: the gear floated
            t_p = onset - float_lag
            if not t_m - WINDOW < t_p < t_m:
                return None
            self.measured += 1
            self.onsets += 1
            return (t_p, *path_rates(ts, a[:, 2], t_p), 'onset')
        after = (ts >= t_m - 0.5 * LEVEL_WINDOW) & (ts < t_m + WINDOW)
        top = arch_top(ts[after], -s * (r[after] - r_pre), ONSET_NOISES * noise,
                       abs(float(np.mean(a[after, 3]))))
        if top is not None and t_m - 0.5 * LEVEL_WINDOW < top < t_m + WINDOW:
            self.measured += 1                # the model crossed first: the gear's arch
            self.arches += 1
            return (top, *path_rates(ts, a[:, 2], top), 'arch')
        tm, rm = ts[mid], r[mid] - r_pre
        integral = float(np.sum(0.5 * (rm[1:] + rm[:-1]) * np.diff(tm)))
        integral += float(rm[-1]) * (t_m + WINDOW - float(tm[-1]))
        shift = -(integral - (r_post - r_pre) * WINDOW) / (s * play)
        if not (math.isfinite(shift) and abs(shift) < WINDOW):
            return None
        t_p = t_m + shift
        self.measured += 1
        return (t_p, *path_rates(ts, a[:, 2], t_p), 'area')


class Look(NamedTuple):
    """When and against what the step detector looks: at ``t``, the encoder's noise, the
    model's last crossing ``t_model``, the last step found, the least step, and the last
    step applied to the model (at ``t_applied``, its bound ``applied_bound``)."""
    t: float
    noise: float
    t_model: float
    last_step: float
    least: float
    t_applied: float
    applied_bound: float


class Estimates(NamedTuple):
    """The estimate (``theta``, its covariance ``P``; empty: none) against the model in use
    (``applied``), on the adapter's layout ``lay``."""
    theta: np.ndarray
    P: np.ndarray
    applied: np.ndarray
    lay: np.ndarray


class Scale(NamedTuple):
    """A scale of the look: lines over ``side`` s each side of a ``gap`` s gap; ``onset``:
    t_p where the rise leaves the line before it (else where a cube through it starts)."""
    side: float
    gap: float
    onset: bool


@njit(cache=True)
def _crossing_at(a, k0, n, centre, half, dl, kl, level0):
    """Where the residual first crosses the left line + ``level0`` in the gap (time from
    ``centre``; NaN if it does not: the step was not made in the gap)."""
    prev_t = prev_l = 0.0
    seen = 0
    for i in range(k0, n):
        x = a[i, 0] - centre
        if -half <= x <= half:
            level = a[i, 1] - (dl + kl * x + level0)
            if seen and _sign(level) != _sign(prev_l):
                return prev_t - prev_l * (x - prev_t) / (level - prev_l)
            prev_t, prev_l = x, level
            seen += 1
    return np.nan


@njit(cache=True)
def _sign(x):
    return 1.0 if x > 0.0 else -1.0 if x < 0.0 else 0.0


@njit(cache=True)
def _harmonic_share(a, k0, n, centre, half, left, right, est):
    """(share, sd): what the step's statistic (the right line's value at the centre less
    the left one's, a weighted sum g . r of the rows; ``left``, ``right``: the lines of
    :func:`_side_line`) makes of the harmonics the estimate has and the model in use lacks
    (:class:`Estimates` ``est``), and its sd from the estimate's covariance."""
    ml, _, _, xl, sxxl = left
    mr, _, _, xr, sxxr = right
    theta, P, applied, lay = est
    nw, ng = lay[4], lay[6]
    nh = 2 * (nw + ng)
    if nh == 0 or theta.size == 0:
        return 0.0, 0.0
    i0 = lay[3] if lay[3] >= 0 else lay[5]          # (the two blocks adjoin)
    d = np.zeros(nh)
    for i in range(k0, n):
        x = a[i, 0] - centre
        if x < -half:
            g = -(1.0 / ml - xl * (x - xl) / sxxl)
        elif x > half:
            g = 1.0 / mr - xr * (x - xr) / sxxr
        else:
            continue
        for k in range(nw):
            d[2 * k] += g * math.sin((k + 1) * a[i, 4])
            d[2 * k + 1] += g * math.cos((k + 1) * a[i, 4])
        for m in range(ng):
            d[2 * nw + 2 * m] += g * math.sin((m + 1) * a[i, 5])
            d[2 * nw + 2 * m + 1] += g * math.cos((m + 1) * a[i, 5])
    share = 0.0
    var = 0.0
    for j in range(nh):
        share += d[j] * (theta[i0 + j] - applied[i0 + j])
        for k in range(nh):
            var += d[j] * P[i0 + j, i0 + k] * d[k]
    return share, math.sqrt(max(var, 0.0))


@njit(cache=True)
def _side_line(a, k0, n, centre, lo, hi):
    """Least-squares line r = k t + d through the rows k0..n-1 with lo < t - centre < hi:
    (count, k, d, mean t, centred sum of squares), as :func:`_line` (the means first, then
    the centred sums)."""
    m = 0
    sx = sy = 0.0
    for i in range(k0, n):
        x = a[i, 0] - centre
        if lo < x < hi:
            m += 1
            sx += x
            sy += a[i, 1]
    if m == 0:
        return 0, 0.0, 0.0, 0.0, 0.0
    xm, ym = sx / m, sy / m
    sxx = sxy = 0.0
    for i in range(k0, n):
        x = a[i, 0] - centre
        if lo < x < hi:
            dx = x - xm
            sxx += dx * dx
            sxy += dx * (a[i, 1] - ym)
    k = sxy / sxx if sxx > 0.0 else 0.0
    return m, k, ym - k * xm, xm, sxx


@njit(cache=True)
def detect_core(a, n, t, noise, t_model, last_step, least, theta, applied, P, lay,
                t_applied, applied_bound):
    """:meth:`FlankTiming.detect`'s look at ``t`` over the record's rows a[:n] (the
    estimate ``theta``, ``P``, ``applied`` and ``lay`` for the harmonics' share; empty:
    none; the last step applied to the model at ``t_applied``, its bound ``applied_bound``):
    (found, t_p, omega4, alpha4, step, wide, rise).  The steep scale (STEP_SIDE, STEP_GAP)
    first, t_p where a cube through the residual's ONSET_SHARE and middle crossings starts
    (the float starts where the mesh torque passes zero); else the wide one
    (STEP_SIDE_WIDE, STEP_GAP_WIDE: a drive that crosses near its top speed floats across
    its play for ~0.1 s, no cube), t_p where the residual leaves the line before it by
    ONSET_SHARE of the step.  ``rise``: from t_p to the step's middle."""
    look = Look(t, noise, t_model, last_step, least, t_applied, applied_bound)
    est = Estimates(theta, P, applied, lay)
    found, t_p, w_p, a_p, step, rise = _look(a, n, look, est,
                                             Scale(STEP_SIDE, STEP_GAP, False))
    if found:
        return True, t_p, w_p, a_p, step, False, rise
    found, t_p, w_p, a_p, step, rise = _look(a, n, look, est,
                                             Scale(STEP_SIDE_WIDE, STEP_GAP_WIDE, True))
    return found, t_p, w_p, a_p, step, found, rise


@njit(cache=True)
def _look(a, n, look, est, scale):
    """One :class:`Scale` of :func:`detect_core` (:class:`Look` ``look``,
    :class:`Estimates` ``est``): lines over ``side`` s each side of a ``gap`` s gap ending
    at ``t``; t_p where a cube through the step's rise starts, or (``onset``) where the
    rise leaves the line before it."""
    t, noise, t_model, last_step, least, t_applied, applied_bound = look
    side, gap, onset = scale
    nothing = (False, 0.0, 0.0, 0.0, 0.0, 0.0)
    span = 2 * side + gap
    centre = t - 0.5 * span
    if t_model > centre - span or centre - last_step < span:
        return nothing
    # a step applied inside the window moved the prediction by up to applied_bound
    extra = applied_bound if t_applied > centre - span else 0.0
    t0 = t - span
    if n == 0 or a[0, 0] > t0 + 1e-9:
        return nothing
    k0 = np.searchsorted(a[:n, 0], t0)
    half = 0.5 * gap
    left = _side_line(a, k0, n, centre, -np.inf, -half)
    right = _side_line(a, k0, n, centre, half, np.inf)
    ml, kl, dl, _, _ = left
    mr, kr, dr, _, _ = right
    if ml < 4 or mr < 4:
        return nothing
    step = dr - dl
    drift = max(abs(kl), abs(kr)) * gap
    if not (abs(step) > max(STEP_NOISES * noise, least) + extra
            and abs(step) > 2.0 * drift + extra):
        return nothing
    share, sd = _harmonic_share(a, k0, n, centre, half, left, right, est)
    step -= share
    if not (abs(step) > max(STEP_NOISES * noise, least, SMOOTH_SIGMAS * sd) + extra
            and abs(step) > 2.0 * drift + extra):
        return nothing
    t_c = _crossing_at(a, k0, n, centre, half, dl, kl, 0.5 * step)    # the middle
    # the whole float inside the gap on the wide scale (the look that has the step's
    # middle at or just before its centre)
    if math.isnan(t_c) or onset and not -0.25 * gap <= t_c <= 0.0:
        return nothing          # (NaN: the residual crosses no such level in the gap)
    if onset:
        # near the top speed the torque demand hardly passes zero, the float is no cube:
        # where the residual leaves the line before it by ONSET_SHARE of the step
        t_0 = _crossing_at(a, k0, n, centre, half, dl, kl, ONSET_SHARE * step)
        if math.isnan(t_0):
            return nothing
    else:
        # the float starts where the mesh torque passes zero: the gear's acceleration off
        # the path grows linearly from zero there (a cube), until with drag it coasts at
        # -T/c after J/c (a square): from the rise's ONSET_SHARE and middle crossings back
        # to where a cube starts (a square's start comes 0.2 of the float early; measured
        # on the drawn drives of benchmarks/bench_adaptation.py, RISE_TIME_SHARE)
        t_s = _rise_before(a, k0, n, centre, t_c, dl, kl, ONSET_SHARE * step)
        t_0 = t_s - (t_c - t_s) / _CUBE_SPAN if t_s > -np.inf else t_c
        t_0 = max(t_0, a[k0, 0] - centre)
    ts = a[k0:n, 0] - centre
    return (True, centre + t_0, np.interp(t_0, ts, a[k0:n, 2]),
            np.interp(t_0, ts, a[k0:n, 3]), step, t_c - t_0)


#: A cubic rise from t_0: (t_mid - t_0) / (t_s - t_0) - 1, t_s at ONSET_SHARE of the step and
#: t_mid at its middle: (0.5 / ONSET_SHARE)^(1/3) - 1
_CUBE_SPAN = (0.5 / ONSET_SHARE) ** (1.0 / 3.0) - 1.0


@njit(cache=True)
def _rise_before(a, k0, n, centre, t_mid, dl, kl, level0):
    """Where the residual, going back from ``t_mid`` (time from ``centre``), last crossed
    the left line + ``level0`` (time from ``centre``; -inf if it does not in the rows)."""
    i = k0 + np.searchsorted(a[k0:n, 0], centre + t_mid)
    if i >= n:
        i = n - 1
    s = _sign(level0)
    while i > k0:
        x1 = a[i, 0] - centre
        l1 = a[i, 1] - (dl + kl * x1 + level0)
        x0 = a[i - 1, 0] - centre
        l0 = a[i - 1, 1] - (dl + kl * x0 + level0)
        if _sign(l0) != s and _sign(l1) == s:
            return x0 - l0 * (x1 - x0) / (l1 - l0)
        i -= 1
    return -np.inf
