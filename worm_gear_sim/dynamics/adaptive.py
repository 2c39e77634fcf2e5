# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The variable-step Newmark-beta + Newton integrator (``integrator.method: adaptive``).

Each step is the fixed kernel's step; this module sets its size: the local error estimate
and its PI step control, frequency matching at every step size, friction events located
(never stepped across) and steps ending on every record point.  The method:
docs/model-notes.md ("Integration: the variable step").
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from .equations import mesh_approach, mesh_forces_mu
from .integrator import (
    C_DA,
    C_ERR,
    C_FA,
    C_FW,
    C_H,
    C_HLAST,
    C_MODE,
    C_MU,
    C_RHO,
    C_RHO2,
    C_RING,
    C_SINCE,
    S_ADAPTIVE_STEPS,
    S_CONTACT_EVENTS,
    S_EVALS,
    S_EVENTS,
    S_FAILED,
    S_LOGGED,
    S_MAX_SOLVES,
    S_REJECTED,
    S_SOLVES,
    S_STEPS,
    S_VERIFIED,
    STATUS_FAILED,
    STATUS_NONFINITE,
    STATUS_OK,
    _step,
    record_aux,
)
from .layout import (
    P_BETA,
    P_COSL,
    P_FRIC_SET_VALUED,
    P_GAP_HALF,
    P_J4,
    P_JG,
    P_JW_STEP,
    P_MU_STATIC,
    P_OUTPUT_PER_INPUT,
    P_RG,
    P_RW,
    P_SINL,
    P_TLOAD,
    P_VCUSP,
)
from .newmark import VERIFY_EVERY, ZERO3, Control, State, Target, _contact_region
from .set_valued import _sv_trial
from .step_control import (
    A_H0,
    A_HMAX,
    A_HMIN,
    A_HREF,
    A_J4,
    A_JW,
    A_KI,
    A_KP,
    A_OMEGA_A,
    A_OMEGA_W,
    A_SAFETY,
    A_TOL2,
    A_TOL3,
    A_TOL4,
    CONE_LAND,
    EVENT_ITERATIONS,
    EVENT_SPEED,
    GROW_MAX,
    KIND_CONE,
    KIND_CONTACT,
    KIND_STEP,
    KIND_STOP,
    LOG_ERR,
    LOG_EVALS,
    LOG_H,
    LOG_KIND,
    LOG_MODE,
    LOG_ROW,
    LOG_T,
    LOG_U,
    SHRINK_MIN,
)


class Grid(NamedTuple):
    """The command on the run's grid: theta1, its rate and the load at the grid points
    (load empty: the model's constant), the last grid index and the grid's spacing."""
    theta1: np.ndarray
    theta1_dot: np.ndarray
    load: np.ndarray
    n_grid: int
    dt: float


class Carried(NamedTuple):
    """What the last accepted step leaves to the next: angles, rates, accelerations
    (3-tuples), the command theta1 there, whether it slid (``ring``), and the inertia
    factors of worm and antenna its acceleration belongs to."""
    u: tuple
    v: tuple
    a: tuple
    th: float
    ring: bool
    fw: float
    fa: float


class Bracket(NamedTuple):
    """An event inside a step of size ``h``: the event function at its start (``g0``) and
    its end (``g1``), the band [0, ``land``] to land in, the contact's ``edge``."""
    g0: float
    h: float
    g1: float
    land: float
    edge: float


@njit(cache=True, error_model='numpy', inline='always')
def _factor(omega, h):
    """(x / tan x)^2, x = omega h / 2: the inertia factor that gives the average-acceleration
    rule the exact frequency omega at step h (1: no matching, or a mode too coarse)."""
    x = 0.5 * omega * h
    if not 0.0 < x <= 1.2:
        return 1.0
    r = x / math.tan(x)
    return r * r


@njit(cache=True, error_model='numpy', inline='always')
def _command(theta1, theta1_dot, load, seg0, s, n_grid, dt):
    """theta1, its rate (the sample at the end of the grid interval) and the load (linear)
    at s grid units after the boundary at grid index seg0 (measured from the boundary, so
    that a run that records every tick and the node's tick-by-tick calls compute the same
    numbers).  theta1 between two grid samples: where the sampled rates at the two ends lie
    on either side of the chord's slope (the command bends one way), the parabola through
    both samples that takes the sampled rate at the end where it differs less from the
    chord's (minmod), so that a curved command (an accelerating move) is followed to second
    order; else the chord (a straight stretch, the kink of a sampled command, a step)."""
    k = int(math.floor(s))
    fr = s - k
    k += seg0
    if k >= n_grid:
        return (theta1[n_grid], theta1_dot[n_grid],
                load[n_grid] if load.shape[0] > 0 else 0.0)
    if fr == 0.0:
        return theta1[k], theta1_dot[k], load[k] if load.shape[0] > 0 else 0.0
    ld = 0.0
    if load.shape[0] > 0:
        ld = load[k] + fr * (load[k + 1] - load[k])
    d = theta1[k + 1] - theta1[k]
    c0 = d - dt * theta1_dot[k]
    c1 = dt * theta1_dot[k + 1] - d
    bow = 0.0
    if c0 * c1 > 0.0:
        bow = c0 if abs(c0) < abs(c1) else c1
    return theta1[k] + fr * d - fr * (1.0 - fr) * bow, theta1_dot[k + 1], ld


@njit(cache=True, error_model='numpy', inline='always')
def _setup(pl, ap, grid, seg0, s_end, h, cur, stuck):
    """A step of size h from ``cur`` (:class:`Carried`) ending s_end grid units after the
    boundary seg0 of the :class:`Grid`: the command there,
    the inertias matched to h (the worm's only while it slides) and the load written into
    ``pl``, and the carried state in the representation of those inertias: the acceleration
    for the same forces, and the velocity relative to the command's rigid motion of the
    antenna and (``ring``: the last step slid too) of the worm by sqrt(f_old / f_new).
    Returns (theta1, theta1_dot, load, f_w, f_a, a0, v0)."""
    theta1, theta1_dot, load, n_grid, _ = grid
    _, vv, aa, th_cur, ring, fw_cur, fa_cur = cur
    om_w = ap[A_OMEGA_W]
    th, td, ld = _command(theta1, theta1_dot, load, seg0, s_end, n_grid, grid.dt)
    fw = 1.0 if stuck else _factor(om_w, h)
    pl[P_JW_STEP] = ap[A_JW] * fw
    fa = 1.0
    if ap[A_J4] > 0.0:
        fa = _factor(ap[A_OMEGA_A], h)
        pl[P_J4] = ap[A_J4] * fa
    if load.shape[0] > 0:
        pl[P_TLOAD] = ld
    v0 = vv
    if fw != fw_cur or fa != fa_cur:
        rig = (th - th_cur) / h
        r3 = pl[P_OUTPUT_PER_INPUT]
        v_0 = vv[0]
        if ring and not stuck and fw != fw_cur:
            v_0 = rig + (vv[0] - rig) * math.sqrt(fw_cur / fw)
        v_2 = vv[2]
        if fa != fa_cur:
            v_2 = r3 * rig + (vv[2] - r3 * rig) * math.sqrt(fa_cur / fa)
        v0 = (v_0, vv[1], v_2)
    return th, td, ld, fw, fa, (aa[0] * fw_cur / fw, aa[1], aa[2] * fa_cur / fa), v0


@njit(cache=True, error_model='numpy')
def _locate(what, pl, ap, C, cur, grid, seg0, s, ctl, bracket):
    """The step size in (0, h) at which an event function g, positive at the step's start
    (g0) and negative at its end (g1), falls into [0, land] (:class:`Bracket`; Illinois'
    regula falsi on the step size, each evaluation a whole step from the same start
    :class:`Carried` ``cur``, s grid units after the boundary seg0 of the :class:`Grid`,
    with the :class:`~.newmark.Control` ``ctl``): ``what`` KIND_STOP, g =
    mode v_s of the slip trial; KIND_CONE, g = mu(0) - |lambda| of the stick trial;
    KIND_CONTACT, g = (edge - q) sgn(edge - q_start) of the step.  Returns (found, h, theta1,
    theta1_dot, load, f_w, f_a, a0, v0, u, v, a, mu, mode, rho, since, n_solves, n_evals)."""
    uu, vv, aa, _, _, fw_cur, fa_cur = cur
    dt = grid.dt
    rho, since, mode, mu, _ = ctl
    g0, h, g1, land, edge = bracket
    k2, k3 = pl[P_RW] * pl[P_COSL], pl[P_RG] * pl[P_SINL]
    mu_s = pl[P_MU_STATIC]
    sgn = 1.0 if g0 >= 0.0 else -1.0
    lo, f_lo, hi, f_hi = 0.0, g0, h, g1
    side = 0
    ns = 0
    ne = 0
    for _ in range(EVENT_ITERATIONS):
        hh = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
        if not (lo < hh < hi) or hh < ap[A_HMIN]:
            break
        th, td, ld, fw, fa, a0, v0 = _setup(pl, ap, grid, seg0, s + hh / dt, hh, cur,
                                            mode == 0)
        if what == KIND_CONTACT:
            ok, u, v, a, rho_e, since_e, n1, e1, _, mode_e, mu_e = _step(
                pl, C, State(uu, v0, a0), Target(th, td, hh),
                Control(rho, since, mode, mu, ZERO3))
            g = sgn * (edge - mesh_approach(pl, u[0], u[1]))
        else:
            m = mode if what == KIND_STOP else 0
            ok, u, v, a, mu_e, n1, e1, _, _, _, _ = _sv_trial(
                pl, C, State(uu, v0, a0), Target(th, td, hh), np.int64(m), mu, rho,
                np.int64(0), ZERO3)
            rho_e, since_e, mode_e = rho, since, m
            if what == KIND_STOP:
                g = mode * (k2 * v[0] + k3 * v[1])
            else:
                g = mu_s - abs(mu_e)
        ns += n1
        ne += e1
        if not ok:
            break
        if 0.0 <= g <= land:
            return (True, hh, th, td, ld, fw, fa, a0, v0, u, v, a, mu_e, mode_e, rho_e,
                    since_e, ns, ne)
        if g > 0.0:
            lo, f_lo = hh, g
            if side == 1:
                f_hi *= 0.5
            side = 1
        else:
            hi, f_hi = hh, g
            if side == -1:
                f_lo *= 0.5
            side = -1
    return (False, h, 0.0, 0.0, 0.0, 1.0, 1.0, aa, vv, uu, vv, aa, mu, mode, rho, since, ns,
            ne)


@njit(cache=True, error_model='numpy')
def _stop_transition(p, u, v, a, th1, mode, mu):
    """The contact has just stopped (a located stop, v_s within the landing tolerance of
    zero, which is removed: v projected on v_s = 0 along k = (r_w cos lam, r_g sin lam, 0)):
    it sticks if the multiplier that holds it fits the cone (the acceleration then the one
    consistent with the stuck contact), else it slips the other way from the cone's edge.
    Q is linear in mu (friction outside the compliance), so the acceleration changes by
    dQ/dmu / M times the change of mu.  Returns (mode, mu, v, a); one force evaluation."""
    k2, k3 = p[P_RW] * p[P_COSL], p[P_RG] * p[P_SINL]
    f = mesh_forces_mu(p, u[0], u[1], u[2], 0.0, th1, mu)
    s0, s1 = f[7] / p[P_JW_STEP], f[8] / p[P_JG]
    den = k2 * s0 + k3 * s1
    if den == 0.0 or not math.isfinite(den):
        return mode, mu, v, a
    lam = mu - (k2 * a[0] + k3 * a[1]) / den
    c = (k2 * v[0] + k3 * v[1]) / (k2 * k2 + k3 * k3)
    v = (v[0] - c * k2, v[1] - c * k3, v[2])
    if abs(lam) <= p[P_MU_STATIC] * (1.0 + 1e-12):
        new_mode, new_mu = 0, lam
    else:
        sq = 1.0 if mesh_approach(p, u[0], u[1]) >= 0.0 else -1.0
        new_mode = 1 if lam * sq > 0.0 else -1
        new_mu = sq * new_mode * p[P_MU_STATIC]
    dl = new_mu - mu
    return new_mode, new_mu, v, (a[0] + s0 * dl, a[1] + s1 * dl, a[2])


@njit(cache=True, error_model='numpy', nogil=True)
def advance_adaptive(p, ap, C, u, v, a, theta1, theta1_dot, dt, t_start, record_stride,
                     rec_u, rec_v, rec_a, rec_aux, stats, ctl, load, log):
    """Advance over len(theta1)-1 grid steps of dt (the command samples theta1, theta1_dot
    and the load on that grid, as for :func:`~worm_gear_sim.dynamics.integrator.advance`)
    in steps of any size: every ``record_stride`` grid steps (if > 0) and the end of the
    arrays are boundaries that a step ends on; the state is recorded at each record point
    (row j at grid step (j+1) stride).  ``ap``: :func:`adaptive_parameters`.  ``log`` (rows
    of N_LOG; empty: none) gets every accepted step from row ``stats[S_LOGGED]`` on while rows
    are left (time: t_start + grid position * dt).  Updates u, v, a, ctl and stats in place
    with accepted steps only.  Returns (grid steps done, status)."""
    n_grid = theta1.shape[0] - 1
    grid = Grid(theta1, theta1_dot, load, n_grid, dt)
    pl = p.copy()          # the step's inertias (matching) and load change per step
    if load.shape[0] > 0 and load.shape[0] < n_grid + 1:
        return 0, STATUS_NONFINITE
    Ct = (C[0, 0], C[0, 1], C[0, 2], C[1, 0], C[1, 1], C[1, 2], C[2, 0], C[2, 1], C[2, 2])
    Co = Ct
    if C.shape[0] == 6:
        Co = (C[3, 0], C[3, 1], C[3, 2], C[4, 0], C[4, 1], C[4, 2], C[5, 0], C[5, 1], C[5, 2])
    for i in range(3):
        if not (math.isfinite(u[i]) and math.isfinite(v[i]) and math.isfinite(a[i])):
            return 0, STATUS_NONFINITE
    set_valued = p[P_FRIC_SET_VALUED] != 0.0
    gap = p[P_GAP_HALF]
    k2, k3 = p[P_RW] * p[P_COSL], p[P_RG] * p[P_SINL]
    mu_s = p[P_MU_STATIC]
    vcusp = p[P_VCUSP]
    tol2, tol3, tol4 = ap[A_TOL2], ap[A_TOL3], ap[A_TOL4]
    h_max, h_min, safety = ap[A_HMAX], ap[A_HMIN], ap[A_SAFETY]
    c_err = abs(p[P_BETA] - 1.0 / 6.0)
    uu = (u[0], u[1], u[2])
    vv = (v[0], v[1], v[2])
    aa = (a[0], a[1], a[2])
    rho, since = (ctl[C_RHO], ctl[C_RHO2]), ctl[C_SINCE]
    mode, mu = int(ctl[C_MODE]), ctl[C_MU]
    da = (ctl[C_DA], ctl[C_DA + 1], ctl[C_DA + 2])
    h_next, h_last, err_last = ctl[C_H], ctl[C_HLAST], ctl[C_ERR]
    fw_cur = ctl[C_FW] if ctl[C_FW] > 0.0 else p[P_JW_STEP] / ap[A_JW]
    fa_cur = ctl[C_FA] if ctl[C_FA] > 0.0 else 1.0
    ring = ctl[C_RING] != 0.0
    th_cur = theta1[0]
    if h_next <= 0.0:
        h_next = ap[A_H0]
    log_err_last = math.log(max(err_last, 1e-10))
    stride = record_stride if record_stride > 0 else n_grid
    n_solves = 0
    n_evals = 0
    n_verified = 0
    n_acc = 0
    n_rej = 0
    n_ev = 0
    max_solves = stats[S_MAX_SOLVES]
    n_log = stats[S_LOGGED]
    status = STATUS_OK
    done = 0
    seg0 = 0
    while seg0 < n_grid:
        seg1 = min(seg0 + stride, n_grid)
        span = float(seg1 - seg0)
        s = 0.0
        while s < span:
            # ---- a step that does not cross the boundary --------------------------------
            h_prop = min(h_next, h_max)
            h = h_prop
            rem = (span - s) * dt
            if h >= rem * (1.0 - 1e-9):
                h = rem
            elif h > 0.5 * rem:
                h = 0.5 * rem               # two equal steps rather than one and a sliver
            accepted = False
            rejected = False
            evals_before = n_evals
            while not accepted:
                s_end = span if h == rem else s + h / dt
                cur = Carried(uu, vv, aa, th_cur, ring, fw_cur, fa_cur)
                th_b, td_b, ld_b, fw, fa, a0, v0 = _setup(pl, ap, grid, seg0, s_end, h, cur,
                                                          mode == 0)
                if not (math.isfinite(th_b) and math.isfinite(td_b) and math.isfinite(ld_b)):
                    status = STATUS_NONFINITE
                    break
                sc = h / h_last if h_last > 0.0 else 0.0
                da_s = (da[0] * sc, da[1] * sc, da[2] * sc)
                q0 = mesh_approach(pl, uu[0], uu[1])
                Cs = Co if gap > 0.0 and abs(q0) < gap else Ct
                kind = KIND_STEP
                ok = False
                ns = 0
                ne = 0
                ver = False
                ev = False
                g0 = g1 = land = 0.0
                un, vn, an = uu, v0, a0
                rho_n, since_n, mode_n, mu_n = rho, since, mode, mu
                # ---- the step in the current friction mode, its event located -----------
                vs0 = k2 * v0[0] + k3 * v0[1]
                if set_valued and (mode == 0 or mode * vs0 > vcusp):
                    ok, un, vn, an, mu_n, ns, ne, _, _, rho_n, ver = _sv_trial(
                        pl, Cs, State(uu, v0, a0), Target(th_b, td_b, h), np.int64(mode), mu,
                        rho, np.int64(2 if since < VERIFY_EVERY else 1), da_s)
                    n_solves += ns
                    n_evals += ne
                    since_n = 0.0 if ver else since + 1.0
                    mode_n = mode
                    if ok and mode != 0:
                        g1 = mode * (k2 * vn[0] + k3 * vn[1])
                        g0, land = mode * vs0, max(EVENT_SPEED * mode * vs0, vcusp)
                        if not (gap > 0.0 and abs(mesh_approach(pl, un[0], un[1])) < gap):
                            ev = g1 < 0.0           # reverses inside the step: find where
                            if 0.0 <= g1 <= land:
                                kind = KIND_STOP    # ends where it stops
                    elif ok:
                        g1 = mu_s - abs(mu_n)
                        g0, land = mu_s - abs(mu), CONE_LAND * mu_s
                        if g1 < -1e-12 * mu_s:
                            ev = g0 > 0.0       # leaves the cone inside the step
                            ok = ev
                            if not ev:
                                # already at the cone's edge: slip the way the force the cone
                                # cannot hold pushes (else the whole dispatch below decides)
                                sq = 1.0 if mesh_approach(pl, uu[0], uu[1]) >= 0.0 else -1.0
                                m_s = 1 if mu_n * sq > 0.0 else -1
                                ok, un, vn, an, mu_n, n1, e1, _, _, _, _ = _sv_trial(
                                    pl, Cs, State(uu, v0, a0), Target(th_b, td_b, h),
                                    np.int64(m_s), mu, rho, np.int64(0), da_s)
                                n_solves += n1
                                n_evals += e1
                                ok = ok and m_s * (k2 * vn[0] + k3 * vn[1]) >= 0.0
                                mode_n = m_s
                                since_n = since
                    if ok and ev:
                        what = KIND_STOP if mode != 0 else KIND_CONE
                        (found, he, th_e, td_e, ld_e, fwe, fae, ae, v0e, ue, ve, ane, mue, _, _,
                         _, n1, e1) = _locate(what, pl, ap, Cs, cur, grid, seg0, s,
                                              Control(rho, since, mode, mu, ZERO3),
                                              Bracket(g0, h, g1, land, 0.0))
                        n_solves += n1
                        n_evals += e1
                        if found:
                            h, s_end, th_b, td_b, ld_b, fw, fa, a0, v0 = (
                                he, s + he / dt, th_e, td_e, ld_e, fwe, fae, ae, v0e)
                            un, vn, an, mu_n, since_n, kind = ue, ve, ane, mue, since, what
                        else:
                            ok = False      # the whole dispatch below decides
                            th_b, td_b, ld_b, fw, fa, a0, v0 = _setup(
                                pl, ap, grid, seg0, s_end, h, cur, mode == 0)
                if not ok:
                    # the fixed kernel's step: the set-valued dispatch (slip, stick, slip,
                    # the cone's edge) or the smooth laws' Newton step
                    ok, un, vn, an, rho_n, since_n, ns, ne, ver, mode_n, mu_n = _step(
                        pl, Cs, State(uu, v0, a0), Target(th_b, td_b, h),
                        Control(rho, since, mode, mu, da_s))
                    n_solves += ns
                    n_evals += ne
                n_verified += ver
                max_solves = max(max_solves, ns)
                if ok and kind == KIND_STEP and gap > 0.0:
                    qb = mesh_approach(pl, un[0], un[1])
                    ra = _contact_region(gap, q0)
                    if ra != _contact_region(gap, qb):
                        # a contact event (loss, impact) in the step: end it at the edge
                        edge = (gap if ra > 0 else -gap) if ra != 0 else \
                            (gap if qb > 0.0 else -gap)
                        land_q = 1e-6 * gap
                        if abs(q0 - edge) > land_q:
                            sgn = 1.0 if edge - q0 > 0.0 else -1.0
                            (found, he, th_e, td_e, ld_e, fwe, fae, ae, v0e, ue, ve, ane, mue,
                             mode_e, rho_e, since_e, n1, e1) = _locate(
                                KIND_CONTACT, pl, ap, Cs, cur, grid, seg0, s,
                                Control(rho, since, mode, mu, ZERO3),
                                Bracket(abs(edge - q0), h, sgn * (edge - qb), land_q, edge))
                            n_solves += n1
                            n_evals += e1
                            if found:
                                h, s_end, th_b, td_b, ld_b, fw, fa, a0, v0 = (
                                    he, s + he / dt, th_e, td_e, ld_e, fwe, fae, ae, v0e)
                                un, vn, an, mu_n, mode_n, rho_n, since_n = (
                                    ue, ve, ane, mue, mode_e, rho_e, since_e)
                                kind = KIND_CONTACT
                if not ok:
                    # Newton failed at this size: a quarter of it
                    n_rej += 1
                    if h * 0.25 < h_min:
                        stats[S_FAILED] += 1
                        status = STATUS_FAILED
                        break
                    h *= 0.25
                    continue
                # ---- the local error (Zienkiewicz-Xie) ------------------------------------
                hh2 = c_err * h * h
                e_0 = abs(an[0] - a0[0]) * hh2 / tol2
                e_1 = abs(an[1] - a0[1]) * hh2 / tol3
                # (without flywheel theta4 = theta3 - T/K_g is algebraic: theta3's error)
                e_2 = abs(an[2] - a0[2]) * hh2 / tol4 if p[P_J4] > 0.0 else 0.0
                err = max(e_0, e_1, e_2)
                row = 0 if err == e_0 else 1 if err == e_1 else 2
                if not math.isfinite(err):
                    err = 1e300
                if err > 1.0 and h > h_min and not (mode_n != mode and kind == KIND_STEP
                                                    and h <= ap[A_HREF]):
                    # (a stick-slip transition the trials could not locate is taken at the
                    # fixed step's size, as the fixed kernel takes it)
                    n_rej += 1
                    rejected = True
                    h = max(h * max(SHRINK_MIN, safety * err ** (-1.0 / 3.0)), h_min)
                    continue
                accepted = True
            if status != STATUS_OK:
                break
            # ---- accepted ---------------------------------------------------------------
            whole = kind == KIND_STEP and mode_n == mode and gap == 0.0
            da = (an[0] - a0[0], an[1] - a0[1], an[2] - a0[2]) if whole else ZERO3
            if set_valued and mode_n == 0 and kind == KIND_STEP:
                # a stuck step: v_s = 0 exactly (its constraint holds to the round-off of
                # the Newmark velocity, which grows as 1/h on the short steps near events)
                c = (k2 * vn[0] + k3 * vn[1]) / (k2 * k2 + k3 * k3)
                vn = (vn[0] - c * k2, vn[1] - c * k3, vn[2])
            if kind == KIND_STOP:
                mode_n, mu_n, vn, an = _stop_transition(pl, un, vn, an, th_b, mode, mu_n)
            elif kind == KIND_CONE:
                sq = 1.0 if mesh_approach(pl, un[0], un[1]) >= 0.0 else -1.0
                mode_n = 1 if mu_n * sq > 0.0 else -1
            if kind != KIND_STEP:
                n_ev += 1
            if kind == KIND_CONTACT:
                stats[S_CONTACT_EVENTS] += 1
            # PI control of the step (Gustafsson): the error's trend damps the growth; no
            # growth right after a rejection
            le = math.log(max(err, 1e-10))
            grow = safety * math.exp(-ap[A_KI] * le + ap[A_KP] * (log_err_last - le))
            grow = min(1.0 if rejected else GROW_MAX, max(SHRINK_MIN, grow))
            if kind == KIND_STEP:
                h_next = max(h * grow, h_prop) if h < h_prop and grow >= 1.0 else h * grow
            elif grow < 1.0:
                h_next = min(h_next, h * grow)
            h_next = max(h_next, h_min)
            ring = mode != 0 and mode_n != 0 and kind == KIND_STEP    # a step that slid
            uu, vv, aa = un, vn, an
            mode, mu = mode_n, mu_n
            rho, since = rho_n, since_n
            fw_cur, fa_cur = fw, fa
            th_cur = th_b
            h_last = h
            err_last = err
            log_err_last = le
            n_acc += 1
            if n_log < log.shape[0]:
                log[n_log, LOG_T] = t_start + (seg0 + s_end) * dt
                log[n_log, LOG_H] = h
                log[n_log, LOG_MODE] = mode
                log[n_log, LOG_ERR] = err
                log[n_log, LOG_U] = uu[0]
                log[n_log, LOG_U + 1] = uu[1]
                log[n_log, LOG_U + 2] = uu[2]
                log[n_log, LOG_KIND] = kind
                log[n_log, LOG_ROW] = row
                log[n_log, LOG_EVALS] = n_evals - evals_before
                n_log += 1
            s = s_end
        if status != STATUS_OK:
            break
        done = seg1
        if record_stride > 0 and seg1 % record_stride == 0:
            j = seg1 // record_stride - 1
            for i in range(3):
                rec_u[j, i] = uu[i]
                rec_v[j, i] = vv[i]
                rec_a[j, i] = aa[i]
            record_aux(pl, uu, vv, theta1[seg1], mu, rec_aux[j])
        seg0 = seg1
    for i in range(3):
        u[i] = uu[i]
        v[i] = vv[i]
        a[i] = aa[i]
    ctl[C_RHO], ctl[C_RHO2] = rho
    ctl[C_SINCE] = since
    ctl[C_MODE] = mode
    ctl[C_MU] = mu
    ctl[C_DA], ctl[C_DA + 1], ctl[C_DA + 2] = da
    ctl[C_H], ctl[C_HLAST], ctl[C_ERR] = h_next, h_last, err_last
    ctl[C_FW], ctl[C_FA] = fw_cur, fa_cur
    ctl[C_RING] = 1.0 if ring else 0.0
    stats[S_STEPS] += done
    stats[S_SOLVES] += n_solves
    stats[S_EVALS] += n_evals
    stats[S_VERIFIED] += n_verified
    stats[S_MAX_SOLVES] = max_solves
    stats[S_ADAPTIVE_STEPS] += n_acc
    stats[S_REJECTED] += n_rej
    stats[S_EVENTS] += n_ev
    stats[S_LOGGED] = n_log
    return done, status
