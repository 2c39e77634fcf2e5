# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A soft crossing of the mesh play on a known trajectory (pure core, no rclpy).

The streaming feed-forward (:class:`~worm_gear_sim.compensation.Compensator`) takes up half
the play on the flank the move's mesh torque demand needs; when the demand changes sign it
steps the correction by the whole play, so the worm crosses the play in one command period
and strikes the new flank at the crossing speed (2 h in 1 ms): the antenna mode rings after
the impact.  Offline, the whole trajectory is known: the crossing can be planned.

Physics.  While the worm is inside the play the mesh carries no force: the gear and the
antenna coast under their own inertia, drag and load, while the antenna path wants the mesh
torque demand D(t) = (J_g + J_4) y'' + c y' + T_load (:func:`~worm_gear_sim.dynamics.model.
gear_torque_demand`).  Near the instant t0 where D changes sign it is small, D ~ D'(t0)
(t - t0): the torque missing during a crossing [a, a + T] is D itself, and a window
centred on t0 misses a torque of zero mean, so the antenna's error is of order
D' T^3 / J (nanoradians for the sector scans of docs/compensation.md).  The worm, on the
other hand, must reach the new flank with the gear's velocity (no impact): its offset
moves from one flank to the other along a smooth step whose velocity and acceleration are
zero at both ends (:func:`smooth_step`), so the approach q closes onto the elastic approach
q_e of the inverse with zero relative velocity.  Where the demand is held at zero (a drive
at rest, a move from rest without load) the window is placed where the demand is smallest
(:func:`plan_crossings`: the window of the given duration, containing t0, that minimises the
integral of D^2), so a move from rest crosses the play before the move starts.

The correction is the streaming compensator's (the same history, the centring preview of a
known trajectory) with its flank term flank(t) h / l_w replaced by the planned one; away
from the crossings both are bit for bit the same, and at rest the worm still takes up
exactly half the play.  The causal path for live streams (the node's ``worm_angle_command``)
cannot know a reversal before it happens; where the demand passes zero slowly it predicts
the zero from the demand's trend and crosses softly itself (``compensation.soft_crossing``;
:func:`flank_series` runs it with the step crossing, which the plans here replace).
Measured in docs/compensation.md, "A soft crossing of the play".

The crossing's step reaches the drive sampled and joined by straight lines: while the mesh
is open the worm rings on its shaft with the kinks, so two samples of each crossing are
moved to land it without that ringing (:func:`worm_ringing_cancel`).

The start of a known move from rest (a step in its acceleration that the drive cannot
follow) leaves the drive's undamped modes ringing for ever, and near a sign change of a
small demand that ringing lifts the teeth off their flank.  :func:`trajectory_feedforward`
therefore also cancels, at every start from rest (the first sample or after a rest,
:func:`rest_starts`), the free vibration the start leaves in each engaged mode (the
antenna mode unless the drag damps it out within the start transient), the
modes taken where the move starts and as it slides (:func:`start_modes`;
:func:`start_ringing_cancel`: a one-period pulse at the antenna mode and two moved samples
per faster mode, sized from the command's own slope changes, :func:`free_vibration`), and,
where the start parts the teeth (no load, no drag: no tooth force at rest), the free
vibration of that open interval, simulated (:func:`open_mesh_cancel`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
from numpy.typing import ArrayLike

from .compensation import (
    SOFT_PERIODS,
    SOFT_SHORTEST,
    SOFT_TOLERANCE,
    Compensator,
    smootherstep,
)
from .dynamics.inverse import gear_torque_demand
from .dynamics.modal import modes, open_mesh_damping_matrix, static_equilibrium
from .dynamics.model import (
    AUX_Q,
    DriveModel,
    has_play,
    linear_stiffness,
    mass_matrix,
)
from .dynamics.profiles import SampledProfile
from .dynamics.simulation import Simulator
from .params import Config

__all__ = ['trajectory_feedforward', 'CrossingPlan', 'FlankSeries', 'smooth_step',
           'flank_series', 'plan_crossings', 'coast_error', 'flank_offset',
           'soft_feedforward_series', 'crossing_time', 'CROSSING_PERIODS', 'SHORTEST_PERIODS',
           'CROSSING_TOLERANCE', 'free_vibration', 'start_ringing_cancel', 'START_WINDOW_PERIODS',
           'open_mesh_cancel', 'OPEN_MESH_FIRST_SAMPLE', 'OPEN_MESH_PROBE', 'start_modes',
           'open_worm_rate', 'worm_ringing_cancel', 'rest_starts', 'REST_TOLERANCE',
           'START_MODE_DECAY']

#: The longest crossing in antenna-mode periods (:func:`crossing_time`); the same bounds as
#: the streaming soft crossing's (one rule: :mod:`worm_gear_sim.compensation`).
CROSSING_PERIODS = SOFT_PERIODS
#: The shortest crossing in command periods (a gentler approach needs more samples).
SHORTEST_PERIODS = SOFT_SHORTEST
#: The antenna's stray while the mesh is free, as a share of half the play.
CROSSING_TOLERANCE = SOFT_TOLERANCE
#: The start transient whose free vibration :func:`start_ringing_cancel` cancels, in
#: antenna-mode periods (the cancelling pulse lasts one period within it).
START_WINDOW_PERIODS = 3.0
#: The share of the antenna mode's free vibration left after the start transient below
#: which :func:`start_modes` leaves that mode out (it has died out: nothing rings on).
START_MODE_DECAY = 1e-2
#: The first command sample :func:`open_mesh_cancel` moves: the first segment, where a start
#: from rest without preload opens the mesh, is left as it is.
OPEN_MESH_FIRST_SAMPLE = 2
#: Two command samples closer than this [rad of worm angle] are at rest (:func:`rest_starts`).
REST_TOLERANCE = 1e-12
#: The size of the command changes [rad] whose effect :func:`open_mesh_cancel` simulates
#: (the drive without play is linear at this scale).
OPEN_MESH_PROBE = 1e-7


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
    step = 0.5 * m.config.mesh.backlash / m.output_per_input if comp.backlash_inverse \
        else 0.0
    return FlankSeries(t_out, delta, flank, demand, step, rest)


def _seconds(t: ArrayLike) -> np.ndarray:
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
    half_play = 0.5 * m.config.mesh.backlash
    plans = plan_crossings(fs, T, Tmin, m.derived.J_g + m.derived.J_4,
                           m.config.load.output_viscous_coefficient,
                           2.0 * math.pi * Compensator(m).mode_frequency_hz,
                           tolerance * half_play)
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


def free_vibration(t: np.ndarray, u: np.ndarray, omega: complex, window: float) -> complex:
    """The free vibration a command u (samples at ``t``, joined by straight lines, at rest
    before ``t[0]``) leaves in a mode driven by its acceleration (q ~ u''), the mode's
    free motion being exp(i omega t) (``omega`` = w_d + i zeta w_n [rad/s]: undamped when
    real): sum of u'' = the slope changes m_k at t_k, weighted by
    exp(-i omega (t_k - t_w)), over ``window`` [s] from the start (t_w its end: a mode
    damped out within the window counts for nothing); past it the
    acceleration is taken as slowly varying, and its (geometric, Abel-summed) tail is the
    forced, quasi-static response, not free vibration.  The free part of q is then
    Im(exp(i omega (t - t_w)) F) / |omega| (scaled by the mode's participation)."""
    slope = np.diff(u) / np.diff(t)
    m = np.diff(np.concatenate(([0.0], slope)))       # u'' = sum m_k delta(t - t_k)
    k = min(int(np.searchsorted(t, t[0] + window)), m.size - 1)
    z = np.exp(-1j * omega * (t[:k] - t[k]))      # (referred to the window's end)
    f = complex(np.sum(m[:k] * z))
    dt = float(t[k + 1] - t[k])
    f += complex(m[k] / (1.0 - np.exp(-1j * omega * dt)))
    return f


def _start_basis(t: np.ndarray, slow: complex | None, n_fast: int, first: int
                 ) -> list[np.ndarray]:
    """The corrections a start cancels its free vibration with (:func:`start_ringing_cancel`):
    a one-period Hann-windowed oscillation at the ``slow`` mode (cosine and sine; none for
    None), then ``2 n_fast`` single moved samples from sample ``first`` on."""
    s = t - t[0]
    basis = []
    if slow is not None:
        w0 = complex(slow).real
        tau = 2.0 * math.pi / w0
        hann = np.where(s < tau, np.sin(math.pi * s / tau) ** 2, 0.0)
        basis += [hann * np.cos(w0 * s), hann * np.sin(w0 * s)]
    for k in range(2 * n_fast):
        hat = np.zeros_like(s)
        hat[first + k] = 1.0
        basis.append(hat)
    return basis


def start_ringing_cancel(t: ArrayLike, command: ArrayLike, slow: complex | None,
                         fast: Sequence[complex], window: float) -> np.ndarray:
    """A correction (added to ``command``, samples at ``t`` from rest) that leaves the modes
    ``slow`` and ``fast`` (their rates as in :func:`free_vibration`) at rest after the start
    transient: the start of a move (a step in its acceleration that the drive cannot
    follow) rings an undamped mode for ever.  The correction is, for the ``slow`` mode (the
    antenna's; None: none), a one-period Hann-windowed oscillation at its frequency from
    ``t[0]`` (zero value and slope at both ends; of the order of the acceleration step /
    omega^2) and, for each ``fast`` mode, two samples moved (the 2nd and 3rd, 4th and 5th,
    ...: a mode faster than the command rate is reached only through the kinks of the
    command), chosen together so every free vibration (over ``window`` s) cancels; zero
    when the samples span less than ``window`` (and the pulse) + 2 samples."""
    tq = np.asarray(t, float)
    u = np.asarray(command, float)
    out = np.zeros_like(u)
    rates = ([] if slow is None else [complex(slow)]) + [complex(w) for w in fast]
    if not rates or tq.size < 3 + 2 * len(fast):
        return out
    tau = 0.0 if slow is None else 2.0 * math.pi / complex(slow).real
    if tq[-1] - tq[0] < max(window, tau) + 2.0 * (tq[1] - tq[0]):
        return out
    basis = _start_basis(tq, slow, len(fast), 1)
    rows = []
    rhs = []
    for w in rates:
        fb = [free_vibration(tq, b, w, window) for b in basis]
        f = free_vibration(tq, u, w, window)
        rows += [[z.real for z in fb], [z.imag for z in fb]]
        rhs += [-f.real, -f.imag]
    # least squares on scaled columns: two fast modes that alias to close frequencies at
    # the command rate cannot be told apart by moved samples (cancelled in part, not blown up)
    mat = np.array(rows)
    scale = np.linalg.norm(mat, axis=0)
    scale[scale == 0.0] = 1.0
    a = np.linalg.lstsq(mat / scale, np.array(rhs), rcond=1e-6)[0] / scale
    return np.asarray(sum(ak * bk for ak, bk in zip(a, basis)))


def _mode_rate(f_hz: float, zeta: float) -> complex:
    """w_d + i zeta w_n [rad/s] of a mode of damped frequency ``f_hz`` and ratio ``zeta``."""
    w_d = 2.0 * math.pi * f_hz
    return complex(w_d, w_d * zeta / math.sqrt(max(1.0 - zeta * zeta, 1e-12)))


def _window_end(t: np.ndarray, window: float) -> int:
    """The sample a start transient of ``window`` s is referred to (:func:`free_vibration`)."""
    return min(int(np.searchsorted(t, t[0] + window)), t.size - 2)


def _rigid_mesh(m: DriveModel) -> DriveModel:
    """The drive without play (the teeth in contact both ways): linear about a move."""
    cfg = m.config
    return DriveModel(dataclasses.replace(cfg, mesh=dataclasses.replace(cfg.mesh,
                                                                         backlash=0.0)))


def _start_state(m: DriveModel, s: np.ndarray, u: np.ndarray, n: int
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Run ``m`` from rest on the command ``u`` (straight lines between the samples at
    ``s`` [s from 0], as the node applies commands) to ``s[n]``: (the state there, the
    angles (theta2, theta3, theta4) from the rest and the rates, as one 6-vector; the
    approach q at every step)."""
    # (the model is the compensator's, already in use: no usability check, no warnings)
    tr = Simulator(m, theta1=float(u[0]), check=False).run(SampledProfile(s, u), float(s[n]))
    return np.concatenate([tr.theta[-1] - tr.theta[0], tr.omega[-1]]), tr.aux[:, AUX_Q]


def open_mesh_cancel(model: DriveModel | Config, t: ArrayLike, command: ArrayLike,
                     slow: complex | None, n_fast: int, window: float) -> np.ndarray:
    """A correction (added to ``command``, samples at ``t`` from rest, already corrected by
    :func:`start_ringing_cancel`) that cancels the free vibration the start leaves because
    the mesh opens during it.  A drive at rest without load or drag has no tooth force, and
    the first segment of a command from rest is a velocity step: each engaged mode answers
    it with a sine, and the gear mode's (1.55 kHz) takes the tooth force below zero within
    the first millisecond whatever the segment's slope, so the teeth part for a moment and
    the linear cancellation misses the free vibration of that interval.  The drive is
    simulated over the start transient (``window`` s) with the play and without it (the
    rigid mesh, where the linear cancellation holds); their difference at the window's end
    is the free vibration to remove.  It is cancelled with the same kind of correction
    (the Hann pulse at ``slow`` unless None, 2 ``n_fast`` moved samples, here from sample
    OPEN_MESH_FIRST_SAMPLE on: after the mesh has closed again, where the drive is linear),
    each correction's effect simulated on the rigid mesh, solved in the modes' energy
    coordinates.  Zero when the mesh stays closed over the window (then the linear
    cancellation is all there is) or when the samples span less than it."""
    m = DriveModel.of(model)
    tq = np.asarray(t, float)
    u = np.asarray(command, float)
    out = np.zeros_like(u)
    first = OPEN_MESH_FIRST_SAMPLE
    tau = 0.0 if slow is None else 2.0 * math.pi / complex(slow).real
    if not has_play(m.p) or tq.size < first + 2 * n_fast + 2 \
            or tq[-1] - tq[0] < max(window, tau) + 2.0 * (tq[1] - tq[0]):
        return out
    s = tq - tq[0]
    n = _window_end(s, window)
    played, q = _start_state(m, s, u, n)
    half_play = 0.5 * m.config.mesh.backlash * m.config.geometry.gear_pitch_radius  # r_g b/2
    if not np.any(np.abs(q[1:]) <= half_play):
        return out                                # the mesh stayed closed
    rigid = _rigid_mesh(m)
    base, _ = _start_state(rigid, s, u, n)
    basis = _start_basis(s, slow, n_fast, first)
    jac = np.column_stack([(_start_state(rigid, s, u + OPEN_MESH_PROBE * b, n)[0] - base)
                           / OPEN_MESH_PROBE for b in basis])
    # energy coordinates of the contact modes at the start: omega_i phi_i' M x, phi_i' M v
    rest = static_equilibrium(rigid, float(u[0]))
    mass = mass_matrix(rigid.p)
    w2, phi = sla.eigh(linear_stiffness(rigid.p, float(rest[0]), float(rest[1])), mass)
    proj = phi.T @ mass
    energy = np.block([[np.sqrt(np.maximum(w2, 0.0))[:, None] * proj, np.zeros_like(proj)],
                       [np.zeros_like(proj), proj]])
    mat = energy @ jac
    scale = np.linalg.norm(mat, axis=0)
    scale[scale == 0.0] = 1.0
    a = np.linalg.lstsq(mat / scale, -energy @ (played - base), rcond=1e-9)[0] / scale
    return np.asarray(sum(ak * bk for ak, bk in zip(a, basis)))


def start_modes(model: DriveModel | Config, t: ArrayLike, command: ArrayLike
                ) -> tuple[complex | None, list[complex], float]:
    """The modes a start from rest rings, as the drive has them while it moves: (the
    antenna mode's rate (the compensator's, with the drag's damping), or None where that
    damping leaves less than START_MODE_DECAY of its free vibration after the start
    transient; the faster ones', teeth in contact; the start transient [s]:
    START_WINDOW_PERIODS antenna periods).  A mode so damped does not ring on: it has died
    out within the transient, and a pulse in the transient's first period could cancel
    what is left at its end only with an amplitude growing as the inverse of that decay
    (on the sector scan with 86 N m s/rad of drag, damping ratio 0.95: 0.35 rad of worm
    angle).  The faster modes are those of the drive without play linearised where the
    move starts (worm angle ``command[0]``) and sliding at the command's rate at the
    transient's end: the teeth's compliance varies along the worm, and sliding friction
    moves the gear mode (1 559 Hz at rest at 0 rad, 1 545 Hz sliding forward at the sector
    scan's start), enough to undo a cancellation spread over a few milliseconds."""
    m = DriveModel.of(model)
    tq = np.asarray(t, float)
    u = np.asarray(command, float)
    comp = Compensator(m)
    f0 = comp.mode_frequency_hz
    window = START_WINDOW_PERIODS / f0
    n = _window_end(tq, window)
    rate = float((u[n + 1] - u[n]) / (tq[n + 1] - tq[n]))
    res = modes(_rigid_mesh(m), float(u[0]), rate)
    fast = [_mode_rate(float(f), float(z)) for f, z in sorted(zip(
        res.frequencies_hz, np.maximum(res.damping_ratios, 0.0))) if f > 1.5 * f0]
    slow = _mode_rate(f0, comp.mode_damping_ratio)
    if math.exp(-slow.imag * window) < START_MODE_DECAY:
        return None, fast, window
    return slow, fast, window


def rest_starts(theta1_ref: ArrayLike, command: ArrayLike, tolerance: float = REST_TOLERANCE
                ) -> list[tuple[int, int]]:
    """The starts from rest of a known trajectory: for each sample k where the reference
    ``theta1_ref`` leaves a rest (x[k+1] != x[k], and k = 0 or x[k-1] == x[k]), (the first
    sample of that rest, the last sample j <= k where the corrected ``command`` is still at
    rest: |u[j] - u[j-1]| <= ``tolerance``, the centring preview moving the command a few
    samples ahead of the reference).  Sample 0 counts as at rest (the drive rests before
    the first sample); a start whose command never rests within the reference's rest (a
    one-sample stop) is left out."""
    x = np.asarray(theta1_ref, float).reshape(-1)
    u = np.asarray(command, float).reshape(-1)
    out = []
    moving = np.diff(x) != 0.0
    # a move's first segment, and the first sample of the rest before it (after the last
    # moving segment; 0 for the first rest)
    first = np.flatnonzero(moving & ~np.concatenate(([False], moving[:-1])))
    last = np.flatnonzero(moving)
    for k in first.tolist():
        i = int(np.searchsorted(last, k))
        r = int(last[i - 1]) + 1 if i else 0
        j = k
        while j > r and abs(u[j] - u[j - 1]) > tolerance:
            j -= 1
        if j > r or r == 0:
            out.append((r, j))
    return out


def trajectory_feedforward(model: DriveModel | Config, t: ArrayLike, theta1_ref: ArrayLike
                           ) -> np.ndarray:
    """The correction of a known trajectory (``compensate_trajectory``, the trajectory
    bridge): with play and the backlash inverse, :func:`soft_feedforward_series` with the
    free vibration of every start from rest cancelled (:func:`rest_starts`,
    :func:`start_ringing_cancel`, :func:`open_mesh_cancel`); else
    :func:`~worm_gear_sim.realtime.feedforward_series` (the same corrections without play)."""
    m = DriveModel.of(model)
    cs = m.config.compensation
    if has_play(m.p) and cs.backlash_inverse and cs.quasi_static and cs.enabled:
        delta, plans = soft_feedforward_series(m, t, theta1_ref)
        delta = np.array(delta, float)
        # the modes left at rest after each start (docs/compensation.md): unless the play
        # is crossed during the rest before it or the start transient (not linear then)
        fs_t = _seconds(t)
        x = np.asarray(theta1_ref, float).reshape(-1)
        window = START_WINDOW_PERIODS / Compensator(m).mode_frequency_hz
        for r, k in rest_starts(x, x + delta):
            if x.size - k < 3 or any(p.start < fs_t[k] + window and p.end >= fs_t[r]
                                     for p in plans):
                continue
            tk = fs_t[k:]
            slow, fast, window_k = start_modes(m, tk, x[k:] + delta[k:])
            delta[k:] += start_ringing_cancel(tk, x[k:] + delta[k:], slow, fast, window_k)
            delta[k:] += open_mesh_cancel(m, tk, x[k:] + delta[k:], slow, len(fast),
                                          window_k)
        return delta
    from .realtime import feedforward_series
    return feedforward_series(m, t, theta1_ref)
