# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The start of a known move from rest, landed without ringing (pure core, no rclpy).

A known move that starts from rest (a step in its acceleration that the drive cannot follow)
leaves the drive's undamped modes ringing for ever, and near a sign change of a small demand
that ringing lifts the teeth off their flank.  This module contains what
:func:`~worm_gear_sim.joint_trajectory.compensate.trajectory_feedforward` adds at every start
from rest (:func:`rest_starts`) to cancel the free vibration the start leaves in each engaged
mode (the antenna mode unless the drag damps it out within the start transient), the modes
taken where the move starts and as it slides (:func:`start_modes`;
:func:`start_ringing_cancel`: a one-period pulse at the antenna mode and two moved samples per
faster mode, sized from the command's own slope changes, :func:`free_vibration`), and, where
the start parts the teeth (no load, no drag: no tooth force at rest), the free vibration of
that open interval, simulated (:func:`open_mesh_cancel`).  docs/compensation.md, "Crossing
the play on a known trajectory".
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
import scipy.linalg as sla
from numpy.typing import ArrayLike

from ..config.usable import Config
from ..dynamics.equations import linear_stiffness, mass_matrix
from ..dynamics.layout import AUX_Q
from ..dynamics.modal import modes, static_equilibrium
from ..dynamics.model import DriveModel, has_play
from ..dynamics.profiles import SampledProfile
from ..dynamics.simulation import Simulator
from .streaming import Compensator

__all__ = ['free_vibration', 'start_ringing_cancel', 'START_WINDOW_PERIODS',
           'open_mesh_cancel', 'OPEN_MESH_FIRST_SAMPLE', 'OPEN_MESH_PROBE', 'start_modes',
           'rest_starts', 'REST_TOLERANCE', 'START_MODE_DECAY']

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
    gap = m.half_play * m.config.geometry.gear_pitch_radius     # along q: r_g b / 2
    if not np.any(np.abs(q[1:]) <= gap):
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
