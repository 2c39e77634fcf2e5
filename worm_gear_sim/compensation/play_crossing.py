# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A soft crossing of the mesh play on a known trajectory (pure core, no rclpy).

The streaming feed-forward (:class:`~worm_gear_sim.compensation.streaming.Compensator`) steps
its correction by the whole play when the mesh torque demand changes sign, so the worm strikes
the new flank; offline, the whole trajectory is known and the crossing can be planned.  This
module contains :func:`flank_series` (the streaming compensator run on a sampled trajectory,
with its flanks and torque demands), :func:`plan_crossings` (each crossing's window, the
antenna's stray while coasting, :func:`coast_error`, within tolerance), :func:`flank_offset`
(the planned flank along a :func:`smooth_step`), :func:`worm_ringing_cancel` (two samples of
each crossing moved so the worm lands without ringing on its shaft) and
:func:`soft_feedforward_series` (the feed-forward with all of it).  The physics and the
measurements: docs/compensation.md, "Crossing the play on a known trajectory".
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..config.usable import Config
from ..dynamics.inverse import gear_torque_demand
from ..dynamics.modal import open_mesh_damping_matrix
from ..dynamics.model import DriveModel, has_play
from .filters import SOFT_PERIODS, SOFT_SHORTEST, SOFT_TOLERANCE, smootherstep
from .start_from_rest import free_vibration
from .streaming import Compensator

__all__ = ['seconds_of', 'CrossingPlan', 'FlankSeries', 'smooth_step',
           'flank_series', 'plan_crossings', 'coast_error', 'flank_offset',
           'soft_feedforward_series', 'crossing_time', 'CROSSING_PERIODS', 'SHORTEST_PERIODS',
           'CROSSING_TOLERANCE', 'open_worm_rate', 'worm_ringing_cancel']

#: The longest crossing in antenna-mode periods (:func:`crossing_time`); the same bounds as
#: the streaming soft crossing's (one rule: :mod:`worm_gear_sim.compensation.filters`).
CROSSING_PERIODS = SOFT_PERIODS
#: The shortest crossing in command periods (a gentler approach needs more samples).
SHORTEST_PERIODS = SOFT_SHORTEST
#: The antenna's stray while the mesh is free, as a share of half the play.
CROSSING_TOLERANCE = SOFT_TOLERANCE


def smooth_step(u: ArrayLike) -> np.ndarray:
    """0 -> 1 on u in [0, 1] with zero first, second and third derivatives at both ends
    (the degree-7 'smootherstep'); 0 before, 1 after."""
    v: np.ndarray = np.clip(np.asarray(u, float), 0.0, 1.0)
    return np.asarray(smootherstep(v)) if v.ndim else np.asarray(smootherstep(float(v)))


@dataclass(frozen=True)
class CrossingPlan:
    """One crossing of the play: the worm leaves flank ``start_flank`` at ``start`` [s] and
    reaches ``end_flank`` at ``end``; ``zero`` is where the torque demand changes sign (or
    where the streaming compensator changed flank, for a demand held at zero)."""

    start: float
    end: float
    zero: float
    start_flank: float
    end_flank: float


@dataclass
class FlankSeries:
    """The streaming compensator run on a sampled trajectory: its corrections ``delta``,
    the flank it chose and the mesh torque demand [N m] it chose it from, at ``t``."""

    t: np.ndarray
    delta: np.ndarray
    flank: np.ndarray
    demand: np.ndarray
    flank_step: float          # the correction per unit of flank: h / l_w [rad]
    rest_flank: float          # the flank before the first sample


def flank_series(model: DriveModel | Config, t: ArrayLike, theta1_ref: ArrayLike
                 ) -> FlankSeries:
    """Run :class:`Compensator` on the samples as the real-time pipeline does (each sample's
    correction evaluated once the samples up to its time plus ``preview_time`` are in; the
    reference rests at its ends) with the step crossings (``compensation.soft_crossing``
    off: the crossings are planned on the whole path from these): its corrections (those
    of :func:`~worm_gear_sim.realtime.feedforward_series` with the soft crossing off, bit
    for bit), flanks and torque demands.  ``t``: float seconds, or integer nanoseconds
    (then ``FlankSeries.t`` is in seconds from the first sample)."""
    m = DriveModel.of(model)
    t_in = np.asarray(t).reshape(-1)
    x = np.asarray(theta1_ref, float).reshape(-1)
    if t_in.size == 0 or t_in.shape != x.shape:
        raise ValueError('t and theta1_ref must be equal-length, non-empty 1-D arrays')
    # the pipeline's clock: nanoseconds from the first sample (integer times: nanoseconds)
    if np.issubdtype(t_in.dtype, np.integer):
        rel = t_in.astype(np.int64) - np.int64(t_in[0])
        t_out = rel * 1e-9
    else:
        t_out = t_in.astype(float)
        rel = np.round((t_out - t_out[0]) * 1e9).astype(np.int64)
    if rel.size > 1 and not np.all(np.diff(rel) > 0):
        raise ValueError('times must be strictly increasing (to the nanosecond)')
    ts = rel * 1e-9
    comp = Compensator(m)
    comp.soft_crossing = False            # the crossings are planned here, on the whole path
    comp.reset(float(x[0]), float(ts[0]))
    rest = comp.flank
    n = ts.size
    delta, flank, demand = np.empty(n), np.empty(n), np.empty(n)
    preview_ns = int(round(comp.preview * 1e9))
    c = m.output_per_input
    j = 0
    for i in range(n):
        while j < n and (j <= i or rel[j - 1] < rel[i] + preview_ns):  # as the pipeline does
            comp.add_sample(float(ts[j]), float(x[j]))
            j += 1
        delta[i] = comp.evaluate(float(ts[i]))
        flank[i] = comp.flank
        if comp.backlash_inverse:
            r = comp._derivs                      # r..r'' (lead), then lead-free r', r''
            demand[i] = gear_torque_demand(m.p, r[-2] * c, r[-1] * c, 0.0, 0.0, False)
        else:
            demand[i] = 0.0
        comp.trim(float(ts[i]))
    # half the play along the mesh approach, r_g b / 2, in worm angle (q = l_w theta2 - ...)
    step = m.half_play / m.output_per_input if comp.backlash_inverse else 0.0
    return FlankSeries(t_out, delta, flank, demand, step, rest)


def seconds_of(t: ArrayLike) -> np.ndarray:
    """Sample times as float seconds (integer times: nanoseconds from the first sample)."""
    a = np.asarray(t).reshape(-1)
    if np.issubdtype(a.dtype, np.integer):
        return (a.astype(np.int64) - np.int64(a[0])) * 1e-9
    return a.astype(float)


def crossing_time(model: DriveModel | Config) -> float:
    """The longest crossing [s]: CROSSING_PERIODS periods of the antenna mode (a gentle
    approach on a 1 kHz command; :func:`plan_crossings` shortens it where the demand
    changes fast)."""
    m = DriveModel.of(model)
    return CROSSING_PERIODS / Compensator(m).mode_frequency_hz


def _zero_time(t: np.ndarray, d: np.ndarray, i: int, old: float) -> float:
    """Where the demand left the old flank's sign before sample i (the flank changes only
    once |demand| exceeds a threshold): interpolated between the last sample of the old
    sign and the next one; t[i] where the demand was held at zero."""
    j = i
    while j > 0 and not d[j - 1] * old > 0.0:
        j -= 1
    if j > 0 and d[j - 1] * old > 0.0 and d[j] * old <= 0.0 and d[j - 1] != d[j]:
        return float(t[j - 1] + (t[j] - t[j - 1]) * d[j - 1] / (d[j - 1] - d[j]))
    return float(t[i])


def coast_error(t: np.ndarray, d: np.ndarray, a: float, b: float, inertia: float,
                drag: float, mode_rate: float, n: int = 64) -> float:
    """How far the antenna strays while the mesh is free over [a, b]: the rigid gear and
    antenna (``inertia``, ``drag``) miss the torque demand d, J e'' + c e' = -d(t) from
    e = e' = 0 (trapezoidal rule on ``n`` steps, d interpolated from the samples); the
    stray at b as position and velocity, |e| + |e'| / ``mode_rate`` [rad] (a velocity
    error rings the antenna mode with amplitude e' / w)."""
    if b <= a:
        return 0.0
    tt = np.linspace(a, b, n + 1)
    dd = np.interp(tt, t, d)
    h = (b - a) / n
    k = drag / inertia
    e = v = 0.0
    den = 1.0 + 0.5 * h * k
    for i in range(n):
        v_new = (v * (1.0 - 0.5 * h * k) - 0.5 * h * (dd[i] + dd[i + 1]) / inertia) / den
        e += 0.5 * h * (v + v_new)
        v = v_new
    return abs(e) + abs(v) / mode_rate


def plan_crossings(fs: FlankSeries, longest: float, shortest: float, inertia: float,
                   drag: float, mode_rate: float, tolerance: float,
                   placements: int = 21, durations: int = 8) -> list[CrossingPlan]:
    """The crossings of the play (module docstring): one per change of flank of ``fs``.
    Each is the longest of ``durations`` geometric steps from ``longest`` down to
    ``shortest`` [s] whose best placement (``placements`` positions containing the sign
    change, within the samples and half-way to the neighbouring crossings) keeps the
    antenna's stray while coasting (:func:`coast_error`) within ``tolerance`` [rad]; where
    none does (a fast reversal: the demand changes sign within a few milliseconds), the
    streaming compensator's step at the sample where it changed flank (``start`` = ``end``).
    """
    t, f, d = fs.t, fs.flank, fs.demand
    prev = np.concatenate(([fs.rest_flank], f[:-1]))
    idx = np.flatnonzero(f != prev)
    if idx.size == 0 or longest <= 0.0:
        return [CrossingPlan(float(t[i]), float(t[i]), float(t[i]), float(prev[i]),
                             float(f[i])) for i in idx]
    zeros = [_zero_time(t, d, int(i), float(prev[i]) or -float(f[i])) for i in idx]
    shortest = min(shortest, longest)
    Ts = np.geomspace(longest, shortest, durations) if durations > 1 else [longest]
    plans = []
    for k, i in enumerate(idx):
        t0 = zeros[k]
        lo = float(t[0]) if k == 0 else 0.5 * (zeros[k - 1] + t0)
        hi = float(t[-1]) if k == len(idx) - 1 else 0.5 * (t0 + zeros[k + 1])
        plan = CrossingPlan(float(t[i]), float(t[i]), t0, float(prev[i]), float(f[i]))
        for T in Ts:                      # the longest crossing that strays little enough
            T = min(float(T), hi - lo)
            cand: tuple[tuple[float, float], float] | None = None
            for s in np.linspace(-T, 0.0, placements):
                a = min(max(t0 + s, lo), hi - T)
                err = coast_error(t, d, a, a + T, inertia, drag, mode_rate)
                key = (err, abs(a + 0.5 * T - t0))
                if cand is None or key < cand[0]:
                    cand = (key, a)
            assert cand is not None
            if cand[0][0] <= tolerance:
                plan = CrossingPlan(cand[1], cand[1] + T, t0, float(prev[i]), float(f[i]))
                break
        plans.append(plan)
    return plans


def flank_offset(t: ArrayLike, plans: list[CrossingPlan], first_flank: float) -> np.ndarray:
    """The planned flank at times ``t`` (-1 coast .. +1 drive): ``first_flank`` before the
    first crossing, a :func:`smooth_step` across each."""
    tq = np.asarray(t, float)
    out = np.full(tq.shape, float(first_flank))
    for p in plans:
        if p.end > p.start:
            s = smooth_step((tq - p.start) / (p.end - p.start))
        else:
            s = (tq >= p.start).astype(float)
        after = tq >= p.start
        out[after] = p.start_flank + (p.end_flank - p.start_flank) * s[after]
    return out


def soft_feedforward_series(model: DriveModel | Config, t: ArrayLike, theta1_ref: ArrayLike,
                            longest: float | None = None, shortest: float | None = None,
                            tolerance: float = CROSSING_TOLERANCE
                            ) -> tuple[np.ndarray, list[CrossingPlan]]:
    """The feed-forward of a known sampled trajectory with the soft crossing of the play:
    (delta [rad] at ``t``, the crossings).  Crossings last at most ``longest`` [s]
    (default :func:`crossing_time`; 0: the step of the streaming compensator) and at least
    ``shortest`` (default SHORTEST_PERIODS command periods), the antenna's stray while
    coasting kept within ``tolerance`` x half the play at the antenna.  Without play or
    with the backlash inverse off: the streaming corrections unchanged."""
    m = DriveModel.of(model)
    fs = flank_series(m, t, theta1_ref)
    if fs.flank_step == 0.0 or not has_play(m.p):
        return fs.delta, []
    T = crossing_time(m) if longest is None else float(longest)
    if not (math.isfinite(T) and T >= 0.0):
        raise ValueError(f'crossing duration {longest!r} s: must be >= 0')
    period = 1.0 / m.config.node.publish_rate_hz
    Tmin = SHORTEST_PERIODS * period if shortest is None else float(shortest)
    plans = plan_crossings(fs, T, Tmin, m.derived.J_g + m.derived.J_4,
                           m.config.load.output_viscous_coefficient,
                           2.0 * math.pi * Compensator(m).mode_frequency_hz,
                           tolerance * m.half_play)
    planned = flank_offset(fs.t, plans, fs.rest_flank)
    delta = fs.delta + (planned - fs.flank) * fs.flank_step
    return delta + worm_ringing_cancel(m, fs.t, plans, fs.flank_step), plans


def open_worm_rate(model: DriveModel | Config) -> complex:
    """The rate (as in :func:`free_vibration`) of the worm on its shaft while the mesh is
    open: J_w theta2'' = -K_w (theta2 - theta1) (Eq. 11 without tooth force), with the
    damping that still acts then (:func:`~worm_gear_sim.dynamics.modal.
    open_mesh_damping_matrix`)."""
    m = DriveModel.of(model)
    jw, kw = m.derived.J_w, m.derived.K_w
    w_n = math.sqrt(kw / jw)
    zeta = min(float(open_mesh_damping_matrix(m)[0, 0]) / (2.0 * jw * w_n), 0.999)
    return complex(w_n * math.sqrt(1.0 - zeta * zeta), zeta * w_n)


def worm_ringing_cancel(model: DriveModel | Config, t: np.ndarray,
                        plans: Sequence[CrossingPlan], flank_step: float) -> np.ndarray:
    """A correction that lands the worm on the new flank without ringing: while the mesh
    is open the worm is alone on its shaft (:func:`open_worm_rate`, 8.6 kHz on the default
    drive), and the crossing's smooth step, sampled and joined by straight lines, kinks
    at every sample, so the worm reaches the new flank oscillating on its shaft and the
    teeth chatter as the small tooth force builds up.  For each planned crossing (end >
    start, spanning at least 2 samples) the two samples nearest its middle (the worm
    half-way across the play, away from both flanks: a drag can make the gear meet the worm
    before the planned end) are moved so that the free vibration of the step
    (``flank_step`` per unit of flank, :func:`free_vibration` referred to the 2nd sample
    past the end) is zero."""
    tq = np.asarray(t, float)
    out = np.zeros_like(tq)
    live = [p for p in plans if p.end > p.start]
    if not live:
        return out
    rate = open_worm_rate(model)
    for p in live:
        k0 = max(int(np.searchsorted(tq, p.start)) - 1, 0)
        k1 = int(np.searchsorted(tq, p.end, side='right')) - 1
        if k1 - k0 < 2 or k1 + 4 > tq.size:
            continue
        # from the sample before the start to 2 past the end: every kink of the step is in
        # the sum, and the last slope change (the tail of free_vibration) is zero
        tt = tq[k0:k1 + 4]
        step = (flank_offset(tt, [p], p.start_flank) - p.start_flank) * flank_step
        span = float(tt[-2] - tt[0])
        f = free_vibration(tt, step, rate, span)
        mid = int(np.searchsorted(tq, 0.5 * (p.start + p.end)))
        moved = (mid - 1, mid)
        fb = []
        for j in moved:
            hat = np.zeros_like(tt)
            hat[j - k0] = 1.0
            fb.append(free_vibration(tt, hat, rate, span))
        mat = np.array([[z.real for z in fb], [z.imag for z in fb]])
        a = np.linalg.lstsq(mat, -np.array([f.real, f.imag]), rcond=1e-9)[0]
        out[moved[0]] += a[0]
        out[moved[1]] += a[1]
    return out
