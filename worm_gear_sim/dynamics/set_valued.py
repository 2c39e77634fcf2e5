# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The set-valued friction law in the Newmark step: W_f in mu(|v_s|) |W_n| Sgn(v_s),
resolved by trials in a fixed mode (stick, slip either way) as a return mapping
(:func:`step_set_valued`; the integrator's :func:`~worm_gear_sim.dynamics.integrator.advance`
calls it through its per-step dispatch)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .equations import mesh_approach, mesh_forces_mu, slip_coefficient
from .layout import (
    P_COSL,
    P_COUT,
    P_GAP_HALF,
    P_J4,
    P_JG,
    P_JW_STEP,
    P_KG,
    P_MAXIT,
    P_MU_STATIC,
    P_OUTPUT_PER_INPUT,
    P_RG,
    P_RW,
    P_SINL,
    P_TLOAD,
    P_VCUSP,
    P_VEPS,
)
from .newmark import (
    SMOOTH_ZONE,
    VERIFY_EVERY,
    _contact_region,
    _in_play,
    _newmark_av,
    _newmark_start,
    _residual_jacobian,
    _solve3,
)

EXIT_EDGE_MARGIN = 1e-3     # a stick step's early exit keeps |mu_eff| this far inside the cone
SLIP_EDGE_SOLVES = 4        # a slip trial at |v_s| <= SLIP_EDGE_CUSPS v_c after this many
SLIP_EDGE_CUSPS = 10.0      # solves is given up (no slip solution: the edge fallback)


@njit(cache=True, error_model='numpy')
def _sv_trial(p, C, s, to, mode, lam0, rho, exit_mode, da):
    """One Newmark step (from :class:`~.newmark.State` ``s`` to
    :class:`~.newmark.Target` ``to``) with the set-valued friction law in a fixed mode.

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
    remaining residual is predicted from the contraction ``rho[0]`` = |R_1| / |R_0| of the
    last verified first trial that converged in one solve (as in :func:`_newmark_step`),
    after the second from ``rho[1]`` = |R_2| / |R_1| of the last one that needed two
    (undamped); when that prediction is far below tolerance the step is accepted without
    another force evaluation: in stick (after the first solve only) if the
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
    u0, v0, a0 = s
    th1, th1dot, dt = to
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
    damped = False
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
         r_norm) = _residual_jacobian(p, C, c_a, c_v, (x0, x1, x2), (w0, w1, w2),
                                      (a_0, a_1, a_2), th1dot, f,
                                      (f[7] * dmu_dv * k2, f[7] * dmu_dv * k3,
                                       f[8] * dmu_dv * k2, f[8] * dmu_dv * k3))
        if not finite:
            break
        if n_solves == 0:
            r0 = r_norm
        elif r_norm <= 1.0:
            if exit_mode > 0:
                if n_solves == 1:
                    rho = (r_norm / r0 if r0 > 0.0 else 0.0, rho[1])
                elif n_solves == 2 and not damped:
                    rho = (1.0, r_norm / r_prev if r_prev > 0.0 else 0.0)
                else:
                    rho = (1.0, 1.0)
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
            damped = True
            x0 = p0 + alpha * d0
            x1 = p1 + alpha * d1
            x2 = p2 + alpha * d2
            e = pe + alpha * de
            continue
        if n_solves >= maxit:
            break
        J = (j00, j01, j02, j10, j11, j12, j20, j21, j22)
        ok, d0, d1, d2 = _solve3(J, (-R0, -R1, -R2))
        if not ok:
            break
        de = 0.0
        if stick:
            # J d - q_mu de = -R,  v_s(u + d) = 0:  d = y1 + y2 de
            ok, y0, y1, y2 = _solve3(J, (f[7], f[8], 0.0))
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
        if (exit_mode == 2 and not stick and not damped
                and ((n_solves == 1 and rho[0] * r0 <= 0.25)
                     or (n_solves == 2 and rho[1] * r_prev <= 0.25))):
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
        if (stick and exit_mode == 2 and n_solves == 1 and rho[0] * r0 <= 0.25
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
def step_set_valued(p, C, s, to, ctl):
    """One step with exact stick-slip: the set-valued law W_f in mu(|v_s|) |W_n| Sgn(v_s)
    resolved by trials (as a return mapping): a slipping contact first tries to keep
    slipping; if its sliding speed would reverse, or the contact was stuck, it tries to
    stick, accepted when the holding force fits inside the cone |W_f| <= mu(0) |W_n|;
    otherwise it slips in the direction of the force the cone cannot hold (then the other
    one).  A contact that stays stuck may end its step without verifying it (early exit of
    :func:`_sv_trial`, every VERIFY_EVERY-th step verified).  Returns (ok, u, v, a, n_solves,
    n_evals, mode, mu_eff, rho, since, verified); ``s``, ``to``, ``ctl``: the
    :class:`~.newmark.State` it starts from, its :class:`~.newmark.Target` and the
    :class:`~.newmark.Control` carried in."""
    u0, v0, a0 = s
    dt = to.dt
    rho, since, mode0, lam0, da = ctl
    mu_s = p[P_MU_STATIC] * (1.0 + 1e-12)
    k2, k3 = p[P_RW] * p[P_COSL], p[P_RG] * p[P_SINL]
    ns = 0
    ne = 0
    if mode0 != 0:
        ok, u, v, a, mu, n1, e1, _, _, rho, ver = _sv_trial(
            p, C, s, to, mode0, lam0, rho, 2 if since < VERIFY_EVERY else 1, da)
        ns += n1
        ne += e1
        since = 0.0 if ver else since + 1.0
        if ok and (mode0 * (k2 * v[0] + k3 * v[1]) >= 0.0 or _in_play(p, u)):
            # (in the play: no friction to slip)
            return True, u, v, a, ns, ne, mode0, mu, rho, since, ver
    ok_st, u_st, v_st, a_st, lam, n1, e1, s0, s1, rho, ver = _sv_trial(
        p, C, s, to, np.int64(0), lam0, rho,
        0 if mode0 != 0 else 2 if since < VERIFY_EVERY else 1, da)
    ns += n1
    ne += e1
    if mode0 == 0:
        since = 0.0 if ver else since + 1.0
    if ok_st and abs(lam) <= mu_s:
        return True, u_st, v_st, a_st, ns, ne, 0, lam, rho, since, ver
    if ok_st:
        sq = 1.0 if mesh_approach(p, u_st[0], u_st[1]) >= 0.0 else -1.0
        s_dir = 1 if lam * sq > 0.0 else -1
    else:
        # no stick solution (no normal force to hold it): slip the way the drive moves
        vs_pred = k2 * (v0[0] + dt * a0[0]) + k3 * (v0[1] + dt * a0[1])
        s_dir = 1 if vs_pred >= 0.0 else -1
    for s_try in (s_dir, -s_dir):
        if s_try == mode0:
            continue            # tried first
        ok, u, v, a, mu, n1, e1, _, _, _, _ = _sv_trial(p, C, s, to, s_try, lam0, rho,
                                                        np.int64(0), da)
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
