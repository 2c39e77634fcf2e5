# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The pieces of one Newmark-Newton step shared by the integrator's kernels
(:mod:`~worm_gear_sim.dynamics.integrator` and the set-valued friction trials of
:mod:`~worm_gear_sim.dynamics.set_valued`): the step's set-up and predictor, the Newmark
relations, the residual with its Jacobian and its norm, the 3 x 3 solve, and the contact
regions of the mesh clearance."""

from __future__ import annotations

import math
from typing import NamedTuple

from numba import njit

from .equations import mesh_approach
from .layout import (
    P_ATOL,
    P_BETA,
    P_COUT,
    P_GAMMA,
    P_GAP_HALF,
    P_J4,
    P_JG,
    P_JW_STEP,
    P_KG,
    P_MESH_COSINE,
    P_MESH_LINEAR,
    P_OUTPUT_PER_INPUT,
    P_PHASE0,
    P_RTOL,
    P_ZG,
)

VERIFY_EVERY = 8            # an early-exiting step is verified at least this often
SMOOTH_ZONE = 10.0          # |v_s| > SMOOTH_ZONE * v_eps counts as clear of the stick zone
ZERO3 = (0.0, 0.0, 0.0)
_EPS = 2.220446049250313e-16


class State(NamedTuple):
    """The state a step starts from: angles, rates, accelerations (3-tuples)."""
    u: tuple
    v: tuple
    a: tuple


class Target(NamedTuple):
    """Where a step goes: the command theta1 and its rate at its end, and its size."""
    th1: float
    th1dot: float
    dt: float


class Control(NamedTuple):
    """The step's controller, carried from step to step: the Newton contractions ``rho``
    (first and second solve), the steps ``since`` the last verified one, the set-valued
    friction's ``mode`` (+1/-1 slipping, 0 stuck) and coefficient ``mu``, and the
    acceleration's change ``da`` over the last whole step (the predictor's)."""
    rho: tuple
    since: float
    mode: int
    mu: float
    da: tuple


@njit(cache=True, error_model='numpy')
def _solve3(J, b):
    """(ok, x) with J x = b for a 3x3 system by cofactors (``J``: its 9 entries row by row,
    ``b``: 3); ok False if singular."""
    j00, j01, j02, j10, j11, j12, j20, j21, j22 = J
    b0, b1, b2 = b
    c00 = j11 * j22 - j12 * j21
    c01 = j12 * j20 - j10 * j22
    c02 = j10 * j21 - j11 * j20
    det = j00 * c00 + j01 * c01 + j02 * c02
    if det == 0.0 or not math.isfinite(det):
        return False, 0.0, 0.0, 0.0
    inv = 1.0 / det
    c10 = j02 * j21 - j01 * j22
    c11 = j00 * j22 - j02 * j20
    c12 = j01 * j20 - j00 * j21
    c20 = j01 * j12 - j02 * j11
    c21 = j02 * j10 - j00 * j12
    c22 = j00 * j11 - j01 * j10
    return (True, (c00 * b0 + c10 * b1 + c20 * b2) * inv, (c01 * b0 + c11 * b1 + c21 * b2) * inv,
            (c02 * b0 + c12 * b1 + c22 * b2) * inv)


@njit(cache=True, error_model='numpy')
def _phase_cycle(p, th2, th3):
    """Index of the mesh cycle (tooth hand-over count) at a position."""
    if p[P_MESH_LINEAR] != 0.0 or p[P_MESH_COSINE] != 0.0:
        return 0.0          # no hand-over discontinuity
    return math.floor((0.5 * (th2 + p[P_ZG] * th3) + p[P_PHASE0]) / (2.0 * math.pi))


@njit(cache=True, error_model='numpy')
def _newmark_av(x0, x1, x2, us0, us1, us2, vs0, vs1, vs2, c_a, gdt):
    """Newmark relations: a = (u - u*) / (beta dt^2), v = v* + gamma dt a."""
    a0 = c_a * (x0 - us0)
    a1 = c_a * (x1 - us1)
    a2 = c_a * (x2 - us2)
    return a0, a1, a2, vs0 + gdt * a0, vs1 + gdt * a1, vs2 + gdt * a2


@njit(cache=True, error_model='numpy', inline='always')
def _newmark_start(p, u0, v0, a0, dt, da):
    """Set-up of one Newmark step from (u0, v0, a0) (3-tuples), shared by both Newton kernels:
    c_a = 1/(beta dt^2), c_v = gamma/(beta dt), gamma dt, the known parts u*, v* of
    a = c_a (u - u*), v = v* + gamma dt a, and the predictor of u: the acceleration
    extrapolated linearly by ``da`` (its change over the last step; zeros: constant)."""
    beta, gamma = p[P_BETA], p[P_GAMMA]
    c_a = 1.0 / (beta * dt * dt)
    c_v = gamma / (beta * dt)
    h2 = dt * dt * (0.5 - beta)
    us = (u0[0] + dt * v0[0] + h2 * a0[0], u0[1] + dt * v0[1] + h2 * a0[1],
          u0[2] + dt * v0[2] + h2 * a0[2])
    g1 = dt * (1.0 - gamma)
    vs = (v0[0] + g1 * a0[0], v0[1] + g1 * a0[1], v0[2] + g1 * a0[2])
    h = dt * dt / 6.0
    x = (u0[0] + dt * v0[0] + h * (3.0 * a0[0] + da[0]),
         u0[1] + dt * v0[1] + h * (3.0 * a0[1] + da[1]),
         u0[2] + dt * v0[2] + h * (3.0 * a0[2] + da[2]))
    return c_a, c_v, gamma * dt, us, vs, x


@njit(cache=True, error_model='numpy', inline='always')
def _residual_jacobian(p, C, c_a, c_v, x, w, acc, th1dot, f, g):
    """Newton residual R = M a + C (v - r theta1') - Q at the iterate ``x`` (its velocity
    ``w`` and acceleration ``acc``: 3-tuples), its Jacobian
    M c_a + (C - dQ/dv) c_v - dQ/du (dQ/dv of the mesh given as ``g`` = (dQ2/dv2, dQ2/dv3,
    dQ3/dv2, dQ3/dv3)) and the residual's norm as an acceleration error:
    |R_i| / M_ii against atol + rtol |a_i| with a round-off floor of a few ulps of u_i seen
    through the Jacobian (a massless degree of freedom, J_4 = 0 without flywheel, is
    algebraic: its residual is scaled by j22 beta dt^2, the same acceleration-error measure).
    Returns (finite, R0, R1, R2, j00, ..., j22, r_norm); finite False (r_norm 0) if R is
    not finite."""
    x0, x1, x2 = x
    w0, w1, w2 = w
    a_0, a_1, a_2 = acc
    g20, g21, g30, g31 = g
    m0, m1, m2 = p[P_JW_STEP], p[P_JG], p[P_J4]   # worm: frequency-matched inertia
    r3 = p[P_OUTPUT_PER_INPUT]
    Kg, cout = p[P_KG], p[P_COUT]
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = C
    rel0 = w0 - th1dot
    rel1 = w1 - r3 * th1dot
    rel2 = w2 - r3 * th1dot
    R0 = m0 * a_0 + c00 * rel0 + c01 * rel1 + c02 * rel2 - f[0]
    R1 = m1 * a_1 + c10 * rel0 + c11 * rel1 + c12 * rel2 - f[1]
    R2 = m2 * a_2 + c20 * rel0 + c21 * rel1 + c22 * rel2 - f[2]
    j00 = m0 * c_a + (c00 - g20) * c_v - f[3]
    j01 = (c01 - g21) * c_v - f[4]
    j02 = c02 * c_v
    j10 = (c10 - g30) * c_v - f[5]
    j11 = m1 * c_a + (c11 - g31) * c_v - f[6]
    j12 = c12 * c_v - Kg
    j20 = c20 * c_v
    j21 = c21 * c_v - Kg
    j22 = m2 * c_a + (c22 + cout) * c_v + Kg
    if not (math.isfinite(R0) and math.isfinite(R1) and math.isfinite(R2)):
        return False, R0, R1, R2, j00, j01, j02, j10, j11, j12, j20, j21, j22, 0.0
    rtol, atol = p[P_RTOL], p[P_ATOL]
    t0 = m0 * (atol + rtol * abs(a_0)) + 8.0 * _EPS * abs(x0) * abs(j00)
    t1 = m1 * (atol + rtol * abs(a_1)) + 8.0 * _EPS * abs(x1) * abs(j11)
    m2t = m2 if m2 > 0.0 else j22 / c_a
    t2 = m2t * (atol + rtol * abs(a_2)) + 8.0 * _EPS * abs(x2) * abs(j22)
    r_norm = max(abs(R0) / t0, abs(R1) / t1, abs(R2) / t2)
    return True, R0, R1, R2, j00, j01, j02, j10, j11, j12, j20, j21, j22, r_norm


@njit(cache=True, error_model='numpy')
def _contact_region(gap, q):
    """+1 on the drive flank (q > gap), -1 on the coast flank, 0 inside the play."""
    if q > gap:
        return 1
    if q < -gap:
        return -1
    return 0


@njit(cache=True, error_model='numpy')
def _in_play(p, u):
    """Inside the mesh clearance (no tooth force, no friction): never without play."""
    return abs(mesh_approach(p, u[0], u[1])) < p[P_GAP_HALF]
