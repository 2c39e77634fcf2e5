# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Newmark-beta + Newton-Raphson integrator: compiled hot loop, many steps per call.

The unknown of each step is the end-of-step position u_{n+1}; acceleration and velocity
follow from the Newmark relations

    a_{n+1} = (u_{n+1} - u_n - dt v_n - dt^2 (1/2 - beta) a_n) / (beta dt^2)
    v_{n+1} = v_n + dt ((1 - gamma) a_n + gamma a_{n+1})

and Newton solves  R(u) = M a + C (v - r theta1') - Q(u, v, theta1) = 0  with the analytic
Jacobian  M/(beta dt^2) + (C - dQ/dv) gamma/(beta dt) - dQ/du.

Convergence: the residual is measured as an acceleration error, |R_i| / J_ii <= atol +
rtol |a_i| (rad/s^2) plus a round-off floor, so that the accepted position error per step
shrinks like dt^2 and the method keeps its order at any dt.  At least one Newton solve is
made every step.  Early exit: after the first solve the remaining residual is predicted
from the contraction rho = |R_1| / |R_0| measured on the last verified step (as Radau
carries its Newton rate); when rho |R_0| is far below tolerance and the step is smooth (the
sliding speed stays outside 10 v_eps on one side, the mesh force keeps its sign, no tooth
hand-over) the step is accepted without a second force evaluation.  Every 8th step, and
every non-smooth step, is verified with a fresh residual.

Robustness: when the residual grows the update is halved (damped Newton); an update that
would carry the sliding speed across zero from outside the friction zone is shortened to
land on zero; a step that still fails is repeated in 2, 4, ... 2^max_subdivision_level
sub-steps (theta1 interpolated linearly), each such event counted.
"""

from __future__ import annotations

import math

from numba import njit

from .model import (
    N_AUX,
    P_ATOL,
    P_BETA,
    P_COSL,
    P_COUT,
    P_FRIC_MODEL,
    P_FRIC_SET_VALUED,
    P_GAMMA,
    P_GAP_HALF,
    P_J4,
    P_JG,
    P_JW_STEP,
    P_KG,
    P_MAXIT,
    P_MAXSUB,
    P_MESH_COSINE,
    P_MESH_LINEAR,
    P_MU_STATIC,
    P_OUTPUT_PER_INPUT,
    P_PHASE0,
    P_RG,
    P_RTOL,
    P_RW,
    P_SINL,
    P_TLOAD,
    P_VCUSP,
    P_VEPS,
    P_ZG,
    mesh_approach,
    mesh_forces,
    mesh_forces_mu,
    slip_coefficient,
)

# stats vector layout (int64, cumulative)
S_STEPS, S_SOLVES, S_EVALS, S_SUBDIV_EVENTS, S_SUBSTEPS, S_MAX_SOLVES, S_FAILED = range(7)
S_VERIFIED = 7
S_CONTACT_EVENTS = 8          # steps split at a contact event of the mesh clearance
N_STATS = 9

# controller state (float64, carried between calls): contraction estimate, steps since verify
C_RHO, C_SINCE = 0, 1
C_MODE, C_MU = 2, 3        # set-valued friction: +1/-1 slipping, 0 stuck; last mu_eff
C_DA = 4                   # 4..6: change of the acceleration over the last whole step
N_CTL = 7
VERIFY_EVERY = 8
SMOOTH_ZONE = 10.0          # |v_s| > SMOOTH_ZONE * v_eps counts as clear of the stick zone
EXIT_EDGE_MARGIN = 1e-3     # a stick step's early exit keeps |mu_eff| this far inside the cone
SLIP_EDGE_SOLVES = 4        # a slip trial at |v_s| <= SLIP_EDGE_CUSPS v_c after this many
SLIP_EDGE_CUSPS = 10.0      # solves is given up (no slip solution: the edge fallback)

STATUS_OK = 0
STATUS_FAILED = 1          # Newton did not converge even at the finest subdivision
STATUS_NONFINITE = 2       # NaN/inf input or state

_EPS = 2.220446049250313e-16
ZERO3 = (0.0, 0.0, 0.0)


@njit(cache=True, error_model='numpy')
def _solve3(j00, j01, j02, j10, j11, j12, j20, j21, j22, b0, b1, b2):
    """(ok, x) with J x = b for a 3x3 system by cofactors; ok False if singular."""
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
def _residual_jacobian(p, C, c_a, c_v, x0, x1, x2, w0, w1, w2, a_0, a_1, a_2, th1dot, f,
                       g20, g21, g30, g31):
    """Newton residual R = M a + C (v - r theta1') - Q, its Jacobian
    M c_a + (C - dQ/dv) c_v - dQ/du (dQ/dv of the mesh given as g20 = dQ2/dv2, g21 = dQ2/dv3,
    g30 = dQ3/dv2, g31 = dQ3/dv3) and the residual's norm as an acceleration error:
    |R_i| / M_ii against atol + rtol |a_i| with a round-off floor of a few ulps of u_i seen
    through the Jacobian (a massless degree of freedom, J_4 = 0 without flywheel, is
    algebraic: its residual is scaled by j22 beta dt^2, the same acceleration-error measure).
    Returns (finite, R0, R1, R2, j00, ..., j22, r_norm); finite False (r_norm 0) if R is
    not finite."""
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


@njit(cache=True, error_model='numpy')
def _newmark_step(p, C, u0, v0, a0, th1, th1dot, dt, rho, since, da):
    """One Newmark step from (u0, v0, a0) (3-tuples).  Returns
    (ok, u, v, a, rho, since, n_solves, n_evals, verified)."""
    maxit = int(p[P_MAXIT])
    k_vs2, k_vs3 = p[P_RW] * p[P_COSL], p[P_RG] * p[P_SINL]
    veps = p[P_VEPS]
    friction_on = p[P_FRIC_MODEL] != 0.0
    gap = p[P_GAP_HALF]
    c_a, c_v, gdt, (us0, us1, us2), (vs0, vs1, vs2), (x0, x1, x2) = _newmark_start(
        p, u0, v0, a0, dt, da)
    vs_start = k_vs2 * v0[0] + k_vs3 * v0[1]
    q_start = mesh_approach(p, u0[0], u0[1])
    cycle_start = _phase_cycle(p, u0[0], u0[1])
    n_solves = 0
    n_evals = 0
    alpha = 1.0
    r_prev = 0.0
    r0 = 0.0
    d0 = d1 = d2 = 0.0
    p0 = p1 = p2 = 0.0
    while True:
        a_0, a_1, a_2, w0, w1, w2 = _newmark_av(x0, x1, x2, us0, us1, us2, vs0, vs1, vs2,
                                                 c_a, gdt)
        f = mesh_forces(p, x0, x1, x2, w0, w1, w2, th1)
        n_evals += 1
        (finite, R0, R1, R2, j00, j01, j02, j10, j11, j12, j20, j21, j22,
         r_norm) = _residual_jacobian(p, C, c_a, c_v, x0, x1, x2, w0, w1, w2, a_0, a_1, a_2,
                                      th1dot, f, f[7], f[8], f[9], f[10])
        if not finite:
            break
        if n_solves == 0:
            r0 = r_norm
        elif r_norm <= 1.0:
            rho = (r_norm / r0 if r0 > 0.0 else 0.0) if n_solves == 1 else 1.0
            return (True, (x0, x1, x2), (w0, w1, w2), (a_0, a_1, a_2), rho, 0.0,
                    n_solves, n_evals, True)
        if n_solves > 0 and r_norm > r_prev and alpha > 1.0 / 64.0:
            alpha *= 0.5            # damped Newton: backtrack along the last update
            x0 = p0 + alpha * d0
            x1 = p1 + alpha * d1
            x2 = p2 + alpha * d2
            continue
        if n_solves >= maxit:
            break
        ok, d0, d1, d2 = _solve3(j00, j01, j02, j10, j11, j12, j20, j21, j22, -R0, -R1, -R2)
        if not ok:
            break
        # Sliding-reversal limiter (like SPICE's junction limiting): an update that carries
        # the sliding speed from outside the friction zone across zero is shortened to land
        # on zero, where tanh is steep and its linearisation accurate.
        vs_old = k_vs2 * w0 + k_vs3 * w1
        dvs = c_v * (k_vs2 * d0 + k_vs3 * d1)
        if friction_on and abs(vs_old) > veps and vs_old * (vs_old + dvs) < 0.0:
            fr = -vs_old / dvs
            d0 *= fr
            d1 *= fr
            d2 *= fr
        p0, p1, p2 = x0, x1, x2
        x0 += d0
        x1 += d1
        x2 += d2
        r_prev = r_norm
        alpha = 1.0
        n_solves += 1
        if n_solves == 1 and since < VERIFY_EVERY and rho * r0 <= 0.25:
            # early exit without a second force evaluation if the step is smooth
            a_0, a_1, a_2, w0, w1, w2 = _newmark_av(x0, x1, x2, us0, us1, us2, vs0, vs1, vs2,
                                                     c_a, gdt)
            vs_end = k_vs2 * w0 + k_vs3 * w1
            q_end = mesh_approach(p, x0, x1)
            clear_of_stick = (vs_start * vs_end > 0.0 and abs(vs_start) > SMOOTH_ZONE * veps
                              and abs(vs_end) > SMOOTH_ZONE * veps)
            if gap > 0.0:       # with play: no contact event (loss, impact) in the step
                same_contact = _contact_region(gap, q_start) == _contact_region(gap, q_end)
            else:
                same_contact = q_start * q_end > 0.0
            if ((clear_of_stick or not friction_on) and same_contact
                    and _phase_cycle(p, x0, x1) == cycle_start):
                return (True, (x0, x1, x2), (w0, w1, w2), (a_0, a_1, a_2), rho, since + 1.0,
                        n_solves, n_evals, False)
    return (False, (x0, x1, x2), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 1.0, since, n_solves,
            n_evals, False)


@njit(cache=True, error_model='numpy')
def _sv_trial(p, C, u0, v0, a0, th1, th1dot, dt, mode, lam0, rho, exit_mode, da):
    """One Newmark step with the set-valued friction law in a fixed mode.

    mode 0, stick: the sliding speed at the end of the step is zero (a linear constraint on
    u) and mu_eff = lambda is an unknown solved with u in the same Newton iteration.  After a
    converged stick step the acceleration is replaced by the one consistent with the stuck
    contact (k . a = 0, with the multiplier lambda' that holds it): the trapezoidal rule
    would otherwise make the constrained acceleration alternate in sign from step to step,
    and lambda' is the force the cone test needs.
    mode +1/-1, slip in that direction: W_f = mode mu(mode v_s) |W_n| (mu_eff = sgn(q) mode
    mu), Eq. 18 with its cusp at v = 0 rounded below friction.cusp_velocity.
    Early exit (``exit_mode`` 2: the step's first trial, not due for verification; 1: the
    first trial, verified, measures ``rho``; 0: a later trial): after the first solve the
    remaining residual is predicted from the contraction ``rho`` = |R_1| / |R_0| of the
    last verified first trial (as in :func:`_newmark_step`); when rho |R_0| is far below
    tolerance the step is accepted without a second force evaluation: in stick if the
    multiplier is clear of the cone's edge (the forces at the update then agree with the
    Newmark acceleration to the predicted residual), in slip if the sliding speed keeps
    its direction clear of the stick zone (|v_s| > SMOOTH_ZONE v_eps at both ends) and
    the contact its flank.
    A slip trial whose iterates keep to the edge of its hypothesis (|v_s| within a few cusp
    speeds after 4 solves, no convergence) is given up: the sliding contact has no solution
    there (the stick trial's edge fallback ends the step).
    Returns (ok, u, v, a, mu_eff, n_solves, n_evals, da/dmu of theta2, theta3 (stick),
    rho, verified); ok False also when the slip hypothesis cannot hold (the speed would
    change sign)."""
    m0, m1, m2 = p[P_JW_STEP], p[P_JG], p[P_J4]   # worm: frequency-matched inertia
    r3 = p[P_OUTPUT_PER_INPUT]
    maxit = int(p[P_MAXIT])
    k2, k3 = p[P_RW] * p[P_COSL], p[P_RG] * p[P_SINL]
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = C
    c_a, c_v, gdt, (us0, us1, us2), (vs0, vs1, vs2), (x0, x1, x2) = _newmark_start(
        p, u0, v0, a0, dt, da)
    stick = mode == 0
    e = lam0 if stick else 0.0
    n_solves = 0
    n_evals = 0
    alpha = 1.0
    r_prev = 0.0
    d0 = d1 = d2 = de = 0.0
    p0 = p1 = p2 = pe = 0.0
    mu = 0.0
    r0 = 0.0
    mu_edge = p[P_MU_STATIC] * (1.0 - EXIT_EDGE_MARGIN)
    gap = p[P_GAP_HALF]
    q_start = mesh_approach(p, u0[0], u0[1])
    v_start = mode * (k2 * v0[0] + k3 * v0[1])
    while True:
        a_0, a_1, a_2, w0, w1, w2 = _newmark_av(x0, x1, x2, us0, us1, us2, vs0, vs1, vs2,
                                                 c_a, gdt)
        sq = 1.0 if mesh_approach(p, x0, x1) >= 0.0 else -1.0
        v_s = k2 * w0 + k3 * w1
        if stick:
            mu, dmu_dv = e, 0.0
        else:
            mag, dmag = slip_coefficient(p, mode * v_s)
            mu, dmu_dv = sq * mode * mag, sq * dmag
        f = mesh_forces_mu(p, x0, x1, x2, w2, th1, mu)
        n_evals += 1
        # dQ/dv through mu(v_s)
        (finite, R0, R1, R2, j00, j01, j02, j10, j11, j12, j20, j21, j22,
         r_norm) = _residual_jacobian(p, C, c_a, c_v, x0, x1, x2, w0, w1, w2, a_0, a_1, a_2,
                                      th1dot, f, f[7] * dmu_dv * k2, f[7] * dmu_dv * k3,
                                      f[8] * dmu_dv * k2, f[8] * dmu_dv * k3)
        if not finite:
            break
        if n_solves == 0:
            r0 = r_norm
        elif r_norm <= 1.0:
            if exit_mode > 0:
                rho = (r_norm / r0 if r0 > 0.0 else 0.0) if n_solves == 1 else 1.0
            if stick:
                rel0 = w0 - th1dot
                rel1 = w1 - r3 * th1dot
                rel2 = w2 - r3 * th1dot
                # acceleration consistent with the stuck contact and its multiplier
                af0 = (f[0] - c00 * rel0 - c01 * rel1 - c02 * rel2) / m0
                af1 = (f[1] - c10 * rel0 - c11 * rel1 - c12 * rel2) / m1
                s0, s1 = f[7] / m0, f[8] / m1
                den = k2 * s0 + k3 * s1
                if den == 0.0 or not math.isfinite(den):
                    break
                delta = -(k2 * af0 + k3 * af1) / den
                mu = e + delta
                a_0 = af0 + s0 * delta
                a_1 = af1 + s1 * delta
                if m2 > 0.0:
                    a_2 = (f[2] - c20 * rel0 - c21 * rel1 - c22 * rel2) / m2
                return (True, (x0, x1, x2), (w0, w1, w2), (a_0, a_1, a_2), mu, n_solves,
                        n_evals, s0, s1, rho, True)
            return (True, (x0, x1, x2), (w0, w1, w2), (a_0, a_1, a_2), mu, n_solves, n_evals,
                    0.0, 0.0, rho, True)
        elif (not stick and n_solves >= SLIP_EDGE_SOLVES
              and abs(v_s) <= SLIP_EDGE_CUSPS * p[P_VCUSP]):
            break               # iterating at the edge of the slip hypothesis: no solution
        if n_solves > 0 and r_norm > r_prev and alpha > 1.0 / 64.0:
            alpha *= 0.5            # damped Newton: backtrack along the last update
            x0 = p0 + alpha * d0
            x1 = p1 + alpha * d1
            x2 = p2 + alpha * d2
            e = pe + alpha * de
            continue
        if n_solves >= maxit:
            break
        ok, d0, d1, d2 = _solve3(j00, j01, j02, j10, j11, j12, j20, j21, j22, -R0, -R1, -R2)
        if not ok:
            break
        de = 0.0
        if stick:
            # J d - q_mu de = -R,  v_s(u + d) = 0:  d = y1 + y2 de
            ok, y0, y1, y2 = _solve3(j00, j01, j02, j10, j11, j12, j20, j21, j22,
                                     f[7], f[8], 0.0)
            den = k2 * y0 + k3 * y1
            if not ok or den == 0.0:
                break
            de = (-v_s / c_v - k2 * d0 - k3 * d1) / den
            d0 += y0 * de
            d1 += y1 * de
            d2 += y2 * de
        p0, p1, p2, pe = x0, x1, x2, e
        x0 += d0
        x1 += d1
        x2 += d2
        e += de
        r_prev = r_norm
        alpha = 1.0
        n_solves += 1
        if exit_mode == 2 and n_solves == 1 and rho * r0 <= 0.25 and not stick:
            a_0, a_1, a_2, w0, w1, w2 = _newmark_av(x0, x1, x2, us0, us1, us2, vs0, vs1, vs2,
                                                     c_a, gdt)
            v_end = mode * (k2 * w0 + k3 * w1)
            clear = SMOOTH_ZONE * p[P_VEPS]
            q_end = mesh_approach(p, x0, x1)
            if gap > 0.0:
                same_contact = _contact_region(gap, q_start) == _contact_region(gap, q_end)
            else:
                same_contact = q_start * q_end > 0.0
            if v_start > clear and v_end > clear and same_contact:
                mag, _ = slip_coefficient(p, v_end)
                return (True, (x0, x1, x2), (w0, w1, w2), (a_0, a_1, a_2),
                        (1.0 if q_end >= 0.0 else -1.0) * mode * mag, n_solves, n_evals,
                        0.0, 0.0, rho, False)
        if (stick and exit_mode == 2 and n_solves == 1 and rho * r0 <= 0.25
                and abs(e) <= mu_edge):
            # early exit: the forces at the update are those of the Newton model, so the
            # acceleration from them is the Newmark one up to the predicted residual
            a_0, a_1, a_2, w0, w1, w2 = _newmark_av(x0, x1, x2, us0, us1, us2, vs0, vs1, vs2,
                                                     c_a, gdt)
            s0, s1 = f[7] / m0, f[8] / m1
            den = k2 * s0 + k3 * s1
            if den != 0.0 and math.isfinite(den):
                delta = -(k2 * a_0 + k3 * a_1) / den
                if abs(e + delta) <= mu_edge:
                    if m2 > 0.0:        # Eq. 6 is linear: its force is exact
                        q4 = -p[P_KG] * (x2 - x1) - p[P_COUT] * w2 - p[P_TLOAD]
                        a_2 = (q4 - c20 * (w0 - th1dot) - c21 * (w1 - r3 * th1dot)
                               - c22 * (w2 - r3 * th1dot)) / m2
                    return (True, (x0, x1, x2), (w0, w1, w2),
                            (a_0 + s0 * delta, a_1 + s1 * delta, a_2), e + delta, n_solves,
                            n_evals, s0, s1, rho, False)
    return (False, (x0, x1, x2), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), mu, n_solves, n_evals,
            0.0, 0.0, rho, False)


@njit(cache=True, error_model='numpy')
def _step_set_valued(p, C, u0, v0, a0, th1, th1dot, dt, mode0, lam0, rho, since, da):
    """One step with exact stick-slip: the set-valued law W_f in mu(|v_s|) |W_n| Sgn(v_s)
    resolved by trials (as a return mapping): a slipping contact first tries to keep
    slipping; if its sliding speed would reverse, or the contact was stuck, it tries to
    stick, accepted when the holding force fits inside the cone |W_f| <= mu(0) |W_n|;
    otherwise it slips in the direction of the force the cone cannot hold (then the other
    one).  A contact that stays stuck may end its step without verifying it (early exit of
    :func:`_sv_trial`, every VERIFY_EVERY-th step verified).  Returns (ok, u, v, a, n_solves,
    n_evals, mode, mu_eff, rho, since, verified)."""
    mu_s = p[P_MU_STATIC] * (1.0 + 1e-12)
    k2, k3 = p[P_RW] * p[P_COSL], p[P_RG] * p[P_SINL]
    ns = 0
    ne = 0
    if mode0 != 0:
        ok, u, v, a, mu, n1, e1, _, _, rho, ver = _sv_trial(
            p, C, u0, v0, a0, th1, th1dot, dt, mode0, lam0, rho,
            2 if since < VERIFY_EVERY else 1, da)
        ns += n1
        ne += e1
        since = 0.0 if ver else since + 1.0
        if ok and (mode0 * (k2 * v[0] + k3 * v[1]) >= 0.0 or _in_play(p, u)):
            # (in the play: no friction to slip)
            return True, u, v, a, ns, ne, mode0, mu, rho, since, ver
    ok_st, u_st, v_st, a_st, lam, n1, e1, s0, s1, rho, ver = _sv_trial(
        p, C, u0, v0, a0, th1, th1dot, dt, 0, lam0, rho,
        0 if mode0 != 0 else 2 if since < VERIFY_EVERY else 1, da)
    ns += n1
    ne += e1
    if mode0 == 0:
        since = 0.0 if ver else since + 1.0
    if ok_st and abs(lam) <= mu_s:
        return True, u_st, v_st, a_st, ns, ne, 0, lam, rho, since, ver
    if ok_st:
        sq = 1.0 if mesh_approach(p, u_st[0], u_st[1]) >= 0.0 else -1.0
        s = 1 if lam * sq > 0.0 else -1
    else:
        # no stick solution (no normal force to hold it): slip the way the drive moves
        vs_pred = k2 * (v0[0] + dt * a0[0]) + k3 * (v0[1] + dt * a0[1])
        s = 1 if vs_pred >= 0.0 else -1
    for s_try in (s, -s):
        if s_try == mode0:
            continue            # tried first
        ok, u, v, a, mu, n1, e1, _, _, _, _ = _sv_trial(p, C, u0, v0, a0, th1, th1dot, dt,
                                                        s_try, lam0, rho, 0, da)
        ns += n1
        ne += e1
        if ok and (s_try * (k2 * v[0] + k3 * v[1]) >= 0.0 or _in_play(p, u)):
            return True, u, v, a, ns, ne, s_try, mu, rho, since, True
    if ok_st:
        # No mode is consistent over the whole step: the trapezoidal rule carries the old
        # friction in a_n, so a contact that stops inside the step reverses in both slip
        # trials while the cone cannot hold it.  The step ends stopped (v_s = 0) with the
        # friction at the edge of the cone and the acceleration that friction leaves: the
        # next step starts from rest and slips (or sticks) without the old memory.
        lam_edge = mu_s if lam > 0.0 else -mu_s
        dl = lam_edge - lam
        a_edge = (a_st[0] + s0 * dl, a_st[1] + s1 * dl, a_st[2])
        return True, u_st, v_st, a_edge, ns, ne, 0, lam_edge, rho, since, ver
    return False, u0, v0, a0, ns, ne, mode0, lam0, rho, since, False


@njit(cache=True, error_model='numpy')
def _step(p, Ct, u0, v0, a0, th1, th1dot, dt, rho, since, mode, mu, da):
    """One step with the configured friction law: (ok, u, v, a, rho, since, n_solves,
    n_evals, verified, mode, mu_eff)."""
    if p[P_FRIC_SET_VALUED] != 0.0:
        ok, u, v, a, ns, ne, mode, mu, rho, since, ver = _step_set_valued(
            p, Ct, u0, v0, a0, th1, th1dot, dt, mode, mu, rho, since, da)
        return ok, u, v, a, rho, since, ns, ne, ver, mode, mu
    ok, u, v, a, rho, since, ns, ne, ver = _newmark_step(p, Ct, u0, v0, a0, th1, th1dot, dt,
                                                         rho, since, da)
    return ok, u, v, a, rho, since, ns, ne, ver, mode, mu


def sliding_speed(p, v) -> float:
    """v_s = r_w cos(lam) theta2' + r_g sin(lam) theta3' [m/s]."""
    return float(p[P_RW] * p[P_COSL] * v[0] + p[P_RG] * p[P_SINL] * v[1])


@njit(cache=True, error_model='numpy')
def record_aux(p, u, v, theta1, mu, out):
    """Mesh quantities (W_n, mu, cwkw, cgkg, v_s, F_X, F_Y, q) at a state; with the
    set-valued law from the friction coefficient the integrator used (in stick the
    multiplier, which the state alone does not determine)."""
    if p[P_FRIC_SET_VALUED] != 0.0:
        r = mesh_forces_mu(p, u[0], u[1], u[2], v[2], theta1, mu)
        out[0], out[1], out[2], out[3] = r[9], mu, r[10], r[11]
        out[4] = p[P_RW] * p[P_COSL] * v[0] + p[P_RG] * p[P_SINL] * v[1]
        out[5], out[6], out[7] = r[12], r[13], r[14]
        return
    f = mesh_forces(p, u[0], u[1], u[2], v[0], v[1], v[2], theta1)
    for i in range(N_AUX):
        out[i] = f[11 + i]


@njit(cache=True, error_model='numpy')
def _split_at_contact(p, Ct, Cb, u0, v0, a0, th_a, th_b, td_a, td_b, dt, rho, since, mode,
                      mu, gap, qa, qb):
    """Redo a step whose approach q crosses an edge of the clearance (+-gap) as two parts
    split where it crosses: the crossing fraction by secant iterations on q (q at the end of
    a part of length f dt), then the rest of the step (with the damping ``Cb`` of the
    region the step ends in; ``Ct`` that of its start).  Returns (ok, u, v, a, rho, since,
    mode, mu, n_solves, n_evals); ok False leaves the caller's whole step in force."""
    ra = _contact_region(gap, qa)
    if ra != 0:
        edge = gap if ra > 0 else -gap          # leaving a flank
    else:
        edge = gap if qb > 0.0 else -gap        # reaching one
    ns = 0
    ne = 0
    f_lo, g_lo = 0.0, qa - edge
    f_hi, g_hi = 1.0, qb - edge
    f = f_lo - g_lo * (f_hi - f_lo) / (g_hi - g_lo)
    u1, v1, a1 = u0, v0, a0
    rho1, since1, mode1, mu1 = rho, since, mode, mu
    found = False
    for _ in range(6):
        f = min(max(f, 1e-6), 1.0 - 1e-6)
        ok, u1, v1, a1, rho1, since1, n1, e1, _, mode1, mu1 = _step(
            p, Ct, u0, v0, a0, th_a + f * (th_b - th_a), td_a + f * (td_b - td_a), f * dt,
            rho, since, mode, mu, ZERO3)
        ns += n1
        ne += e1
        if not ok:
            return False, u0, v0, a0, rho, since, mode, mu, ns, ne
        g = mesh_approach(p, u1[0], u1[1]) - edge
        found = True
        if abs(g) <= 1e-6 * gap:
            break
        if (g < 0.0) == (g_lo < 0.0):
            f_lo, g_lo = f, g
        else:
            f_hi, g_hi = f, g
        f = f_lo - g_lo * (f_hi - f_lo) / (g_hi - g_lo)
    if not found:
        return False, u0, v0, a0, rho, since, mode, mu, ns, ne
    ok, u2, v2, a2, rho2, since2, n2, e2, _, mode2, mu2 = _step(
        p, Cb, u1, v1, a1, th_b, td_b, (1.0 - f) * dt, rho1, since1, mode1, mu1, ZERO3)
    ns += n2
    ne += e2
    if not ok:
        return False, u0, v0, a0, rho, since, mode, mu, ns, ne
    return True, u2, v2, a2, rho2, since2, mode2, mu2, ns, ne


@njit(cache=True, error_model='numpy', nogil=True)   # batch.py runs it on threads
def advance(p, C, u, v, a, theta1, theta1_dot, dt, record_stride, rec_u, rec_v, rec_a,
            rec_aux, stats, ctl, load):
    """Advance len(theta1)-1 steps of size dt; theta1[k] is the command at the start of
    step k and theta1[k+1] at its end (theta1_dot likewise).  ``load``: the load torque on
    the antenna [N m] on the same grid (load[k+1] at the end of step k, linear within it),
    or an empty array for the constant ``p[P_TLOAD]``.  ``C``: the damping, 3 x 3, or 6 x 3
    with the damping of the open mesh in rows 3..5 (:func:`~worm_gear_sim.dynamics.modal.
    stepping_damping`: taken by the steps that start inside the play, so no structural
    damping acts across it).  Updates u, v, a in place and only
    with fully converged steps.  Every ``record_stride`` steps (if > 0) the end state is
    written to rec_* (row j after step (j+1)*stride).  ``ctl`` carries the Newton
    controller state between calls.  Returns (steps done, status)."""
    n_steps = theta1.shape[0] - 1
    varying = load.shape[0] > 0
    if varying:
        p = p.copy()                 # the caller's vector keeps its constant load
        if load.shape[0] < n_steps + 1:
            return 0, STATUS_NONFINITE
    Ct = (C[0, 0], C[0, 1], C[0, 2], C[1, 0], C[1, 1], C[1, 2], C[2, 0], C[2, 1], C[2, 2])
    Co = Ct
    if C.shape[0] == 6:
        Co = (C[3, 0], C[3, 1], C[3, 2], C[4, 0], C[4, 1], C[4, 2], C[5, 0], C[5, 1], C[5, 2])
    max_level = int(p[P_MAXSUB])
    gap = p[P_GAP_HALF]
    uu = (u[0], u[1], u[2])
    vv = (v[0], v[1], v[2])
    aa = (a[0], a[1], a[2])
    rho, since = ctl[C_RHO], ctl[C_SINCE]
    mode, mu = int(ctl[C_MODE]), ctl[C_MU]
    da = (ctl[C_DA], ctl[C_DA + 1], ctl[C_DA + 2])
    for i in range(3):
        if not (math.isfinite(u[i]) and math.isfinite(v[i]) and math.isfinite(a[i])):
            return 0, STATUS_NONFINITE
    n_solves = 0
    n_evals = 0
    n_verified = 0
    max_solves = stats[S_MAX_SOLVES]
    status = STATUS_OK
    done = 0
    for k in range(n_steps):
        th_a, th_b = theta1[k], theta1[k + 1]
        td_a, td_b = theta1_dot[k], theta1_dot[k + 1]
        if not (math.isfinite(th_b) and math.isfinite(td_b)):
            status = STATUS_NONFINITE
            break
        if varying:
            ld_a, ld_b = load[k], load[k + 1]
            if not math.isfinite(ld_b):
                status = STATUS_NONFINITE
                break
            p[P_TLOAD] = ld_b                                      # Eq. 6 (+ load), at t_k+1
        Cs = Ct
        if gap > 0.0 and abs(mesh_approach(p, uu[0], uu[1])) < gap:
            Cs = Co                              # the step starts inside the play
        ok, un, vn, an, rho, since, ns, ne, ver, mode_n, mu_n = _step(
            p, Cs, uu, vv, aa, th_b, td_b, dt, rho, since, mode, mu, da)
        n_solves += ns
        n_evals += ne
        n_verified += ver
        max_solves = max(max_solves, ns)
        level = 1
        while not ok and level <= max_level:
            n_sub = 1 << level
            stats[S_SUBDIV_EVENTS] += 1
            h = dt / n_sub
            us, vs, as_ = uu, vv, aa
            mode_n, mu_n = mode, mu
            ok = True
            for j in range(n_sub):
                f = (j + 1.0) / n_sub
                if varying:
                    p[P_TLOAD] = ld_a + f * (ld_b - ld_a)
                ok, us, vs, as_, rho, since, ns, ne, ver, mode_n, mu_n = _step(
                    p, Cs, us, vs, as_, th_a + f * (th_b - th_a), td_a + f * (td_b - td_a),
                    h, rho, since, mode_n, mu_n, ZERO3)
                n_solves += ns
                n_evals += ne
                n_verified += ver
                if not ok:
                    break
                stats[S_SUBSTEPS] += 1
            un, vn, an = us, vs, as_
            level += 1
        whole = level == 1
        if varying:
            p[P_TLOAD] = ld_b
        if not ok:
            stats[S_FAILED] += 1
            status = STATUS_FAILED
            break
        if gap > 0.0 and level == 1:
            qa = mesh_approach(p, uu[0], uu[1])
            qb = mesh_approach(p, un[0], un[1])
            rb = _contact_region(gap, qb)
            if _contact_region(gap, qa) != rb:
                # a contact event (loss, impact, re-engagement) inside the step: split the
                # step where q crosses the flank's edge, so that each part is smooth (the
                # trapezoidal rule then neither gains nor loses the contact's energy)
                ok_e, ue, ve, ae, rho_e, since_e, mode_e, mu_e, ns, ne = _split_at_contact(
                    p, Cs, Co if rb == 0 else Ct, uu, vv, aa, th_a, th_b, td_a, td_b, dt,
                    rho, since, mode, mu, gap, qa, qb)
                n_solves += ns
                n_evals += ne
                if ok_e:
                    un, vn, an, rho, since, mode_n, mu_n = ue, ve, ae, rho_e, since_e, \
                        mode_e, mu_e
                    whole = False
                    stats[S_CONTACT_EVENTS] += 1
        # a whole step (not subdivided, not split at a contact event) extrapolates the
        # acceleration into the next step's predictor; not with play, where the contact
        # events make the acceleration jump
        da = (an[0] - aa[0], an[1] - aa[1], an[2] - aa[2]) if whole and gap == 0.0 else ZERO3
        uu, vv, aa = un, vn, an
        mode, mu = mode_n, mu_n
        done += 1
        if record_stride > 0 and done % record_stride == 0:
            j = done // record_stride - 1
            for i in range(3):
                rec_u[j, i] = uu[i]
                rec_v[j, i] = vv[i]
                rec_a[j, i] = aa[i]
            record_aux(p, uu, vv, th_b, mu, rec_aux[j])
    for i in range(3):
        u[i] = uu[i]
        v[i] = vv[i]
        a[i] = aa[i]
    ctl[C_RHO] = rho
    ctl[C_SINCE] = since
    ctl[C_MODE] = mode
    ctl[C_MU] = mu
    ctl[C_DA], ctl[C_DA + 1], ctl[C_DA + 2] = da
    stats[S_STEPS] += done
    stats[S_SOLVES] += n_solves
    stats[S_EVALS] += n_evals
    stats[S_VERIFIED] += n_verified
    stats[S_MAX_SOLVES] = max_solves
    return done, status


@njit(cache=True, error_model='numpy')
def consistent_acceleration(p, C, u, v, theta1, theta1_dot, a):
    """a = M^{-1} (Q - C (v - r theta1')) at a given state (initial condition); ``C`` as
    :func:`advance` takes it (rows 3..5 inside the play)."""
    o = 3 if C.shape[0] == 6 and _in_play(p, u) else 0
    C = C[o:o + 3]
    f = mesh_forces(p, u[0], u[1], u[2], v[0], v[1], v[2], theta1)
    r3 = p[P_OUTPUT_PER_INPUT]
    rel0 = v[0] - theta1_dot
    rel1 = v[1] - r3 * theta1_dot
    rel2 = v[2] - r3 * theta1_dot
    m = (p[P_JW_STEP], p[P_JG], p[P_J4])
    for i in range(2):
        a[i] = (f[i] - C[i, 0] * rel0 - C[i, 1] * rel1 - C[i, 2] * rel2) / m[i]
    if m[2] > 0.0:
        a[2] = (f[2] - C[2, 0] * rel0 - C[2, 1] * rel1 - C[2, 2] * rel2) / m[2]
    else:
        # massless shaft end: 0 = Q4 - C (v - r th1'), differentiated in time
        c_end = C[2, 2] + p[P_COUT]
        if c_end > 0.0:
            a[2] = (p[P_KG] * (v[1] - v[2]) - C[2, 0] * a[0] - C[2, 1] * a[1]) / c_end
        else:
            a[2] = a[1]

