# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Newmark-beta + Newton-Raphson integrator: the compiled hot loop, many steps per call
(:func:`advance`).

Newton solves each step's residual with the analytic Jacobian (a damped update, early exit
on a predicted contraction, every 8th and every non-smooth step verified) and repeats a
failed step in 2, 4, ... sub-steps, counted.  The set-valued friction trials are in
:mod:`.set_valued`, the step's shared pieces in :mod:`.newmark`, the variable step in
:mod:`.adaptive`; the method: docs/model-notes.md.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from numba import njit

from .equations import mesh_approach, mesh_forces, mesh_forces_mu
from .layout import (
    N_AUX,
    P_COSL,
    P_COUT,
    P_FRIC_MODEL,
    P_FRIC_SET_VALUED,
    P_GAP_HALF,
    P_J4,
    P_JG,
    P_JW_STEP,
    P_KG,
    P_MAXIT,
    P_MAXSUB,
    P_OUTPUT_PER_INPUT,
    P_RG,
    P_RW,
    P_SINL,
    P_TLOAD,
    P_VEPS,
)
from .newmark import (
    SMOOTH_ZONE,
    VERIFY_EVERY,
    ZERO3,
    Control,
    State,
    Target,
    _contact_region,
    _in_play,
    _newmark_av,
    _newmark_start,
    _phase_cycle,
    _residual_jacobian,
    _solve3,
)
from .set_valued import step_set_valued

# stats vector layout (int64, cumulative)
S_STEPS, S_SOLVES, S_EVALS, S_SUBDIV_EVENTS, S_SUBSTEPS, S_MAX_SOLVES, S_FAILED = range(7)
S_VERIFIED = 7
S_CONTACT_EVENTS = 8          # steps split at a contact event of the mesh clearance
# the variable step (dynamics/adaptive.py): accepted and rejected steps, located events, rows
# of its step log written
S_ADAPTIVE_STEPS, S_REJECTED, S_EVENTS, S_LOGGED = 9, 10, 11, 12
N_STATS = 13

# controller state (float64, carried between calls): contraction estimate, steps since verify
C_RHO, C_SINCE = 0, 1
C_MODE, C_MU = 2, 3        # set-valued friction: +1/-1 slipping, 0 stuck; last mu_eff
C_DA = 4                   # 4..6: change of the acceleration over the last whole step
C_RHO2 = 7                 # contraction of a second Newton solve (set-valued slip)
# the variable step: the next step, the last accepted one [s], its error estimate, and the
# inertia factors of worm and antenna the carried acceleration belongs to (0: not yet), and
# whether the last step slid (its worm velocity is then in the matched representation)
C_H, C_HLAST, C_ERR, C_FW, C_FA, C_RING = 8, 9, 10, 11, 12, 13
N_CTL = 14

STATUS_OK = 0
STATUS_FAILED = 1          # Newton did not converge even at the finest subdivision
STATUS_NONFINITE = 2       # NaN/inf input or state


class Span(NamedTuple):
    """The command over a step of ``dt``: theta1 and its rate at its start and its end."""
    th_a: float
    th_b: float
    td_a: float
    td_b: float
    dt: float


@njit(cache=True, error_model='numpy')
def _newmark_step(p, C, s, to, ctl):
    """One Newmark step from :class:`State` ``s`` to :class:`Target` ``to`` (``ctl``: the
    :class:`Control` carried in; its friction mode unused).  Returns (ok, u, v, a, rho,
    since, n_solves, n_evals, verified)."""
    u0, v0, a0 = s
    th1, th1dot, dt = to
    rho, since, _, _, da = ctl
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
         r_norm) = _residual_jacobian(p, C, c_a, c_v, (x0, x1, x2), (w0, w1, w2),
                                      (a_0, a_1, a_2), th1dot, f, (f[7], f[8], f[9], f[10]))
        if not finite:
            break
        if n_solves == 0:
            r0 = r_norm
        elif r_norm <= 1.0:
            rho = ((r_norm / r0 if r0 > 0.0 else 0.0) if n_solves == 1 else 1.0, rho[1])
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
        ok, d0, d1, d2 = _solve3((j00, j01, j02, j10, j11, j12, j20, j21, j22),
                                 (-R0, -R1, -R2))
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
        if n_solves == 1 and since < VERIFY_EVERY and rho[0] * r0 <= 0.25:
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
    return (False, (x0, x1, x2), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (1.0, rho[1]), since,
            n_solves, n_evals, False)


@njit(cache=True, error_model='numpy')
def _step(p, Ct, s, to, ctl):
    """One step from :class:`State` ``s`` to :class:`Target` ``to`` with the configured
    friction law (:class:`Control` ``ctl``): (ok, u, v, a, rho, since, n_solves, n_evals,
    verified, mode, mu_eff)."""
    if p[P_FRIC_SET_VALUED] != 0.0:
        ok, u, v, a, ns, ne, mode, mu, rho, since, ver = step_set_valued(p, Ct, s, to, ctl)
        return ok, u, v, a, rho, since, ns, ne, ver, mode, mu
    ok, u, v, a, rho, since, ns, ne, ver = _newmark_step(p, Ct, s, to, ctl)
    return ok, u, v, a, rho, since, ns, ne, ver, ctl.mode, ctl.mu


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
def _split_at_contact(p, Ct, Cb, s, span, ctl, gap, qa, qb):
    """Redo a step (:class:`State` ``s``, :class:`Span` ``span``, :class:`Control` ``ctl``)
    whose approach q crosses an edge of the clearance (+-gap; q from ``qa`` to ``qb``) as
    two parts split where it crosses: the crossing fraction by secant iterations on q (q at
    the end of a part of length f dt), then the rest of the step (with the damping ``Cb`` of
    the region the step ends in; ``Ct`` that of its start).  Returns (ok, u, v, a, rho,
    since, mode, mu, n_solves, n_evals); ok False leaves the caller's whole step in force."""
    u0, v0, a0 = s
    th_a, th_b, td_a, td_b, dt = span
    rho, since, mode, mu, _ = ctl
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
            p, Ct, s, Target(th_a + f * (th_b - th_a), td_a + f * (td_b - td_a), f * dt),
            Control(rho, since, mode, mu, ZERO3))
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
        p, Cb, State(u1, v1, a1), Target(th_b, td_b, (1.0 - f) * dt),
        Control(rho1, since1, mode1, mu1, ZERO3))
    ns += n2
    ne += e2
    if not ok:
        return False, u0, v0, a0, rho, since, mode, mu, ns, ne
    return True, u2, v2, a2, rho2, since2, mode2, mu2, ns, ne


@njit(cache=True, error_model='numpy', inline='always')
def _same(x, y):
    """The same double: equal, and zeros of the same sign (NaN is never the same)."""
    return x == y and math.copysign(1.0, x) == math.copysign(1.0, y)


@njit(cache=True, error_model='numpy', inline='always')
def _same3(x, y):
    return _same(x[0], y[0]) and _same(x[1], y[1]) and _same(x[2], y[2])


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
    rho, since = (ctl[C_RHO], ctl[C_RHO2]), ctl[C_SINCE]
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
    # the last step repeated itself (a drive at rest under a constant command): its
    # command, load and counts; the step is a pure function of the state, its control and
    # the command, so the same inputs give the same step, without computing it
    rep, rep_th, rep_td, rep_ld, rep_ns, rep_ne, rep_ver = False, 0.0, 0.0, 0.0, 0, 0, 0
    ld_a = ld_b = 0.0
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
        rho_in, since_in, da_in = rho, since, da
        if rep and th_b == rep_th and td_b == rep_td and ld_b == rep_ld:
            ok, un, vn, an, ns, ne, ver, mode_n, mu_n = (True, uu, vv, aa, rep_ns, rep_ne,
                                                         rep_ver, mode, mu)
        else:
            ok, un, vn, an, rho, since, ns, ne, ver, mode_n, mu_n = _step(
                p, Cs, State(uu, vv, aa), Target(th_b, td_b, dt),
                Control(rho, since, mode, mu, da))
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
                    p, Cs, State(us, vs, as_),
                    Target(th_a + f * (th_b - th_a), td_a + f * (td_b - td_a), h),
                    Control(rho, since, mode_n, mu_n, ZERO3))
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
                    p, Cs, Co if rb == 0 else Ct, State(uu, vv, aa),
                    Span(th_a, th_b, td_a, td_b, dt), Control(rho, since, mode, mu, ZERO3),
                    gap, qa, qb)
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
        rep = (whole and th_a == th_b and td_a == td_b and ld_a == ld_b and mode_n == mode
               and _same3(un, uu) and _same3(vn, vv) and _same3(an, aa) and _same3(da, da_in)
               and _same(rho[0], rho_in[0]) and _same(rho[1], rho_in[1])
               and _same(since, since_in) and _same(mu_n, mu))
        if rep:
            rep_th, rep_td, rep_ld, rep_ns, rep_ne, rep_ver = th_b, td_b, ld_b, ns, ne, ver
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
    ctl[C_RHO], ctl[C_RHO2] = rho
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

