# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Newmark-beta + Newton-Raphson integrator: compiled hot loop, many steps per call.

The unknown of each step is the end-of-step position u_{n+1}; acceleration and velocity
follow from the Newmark relations

    a_{n+1} = (u_{n+1} - u_n - dt v_n - dt^2 (1/2 - beta) a_n) / (beta dt^2)
    v_{n+1} = v_n + dt ((1 - gamma) a_n + gamma a_{n+1})

and Newton solves  R(u) = M a + C (v - r theta1') - Q(u, v, theta1) = 0  with the analytic
Jacobian  M/(beta dt^2) + (C - dQ/dv) gamma/(beta dt) - dQ/du.  Convergence is tested on
the residual scaled to displacement units (|R_i| / J_ii against atol + rtol |du_i| plus a
round-off floor), with early exit.  When the residual grows the update is halved (damped
Newton); when a step still fails it is repeated in 2, 4, ... 2^max_subdivision_level
sub-steps (theta1 interpolated linearly), and each such event is counted.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .model import (
    N_AUX,
    P_ATOL,
    P_BETA,
    P_GAMMA,
    P_J4,
    P_JG,
    P_JW,
    P_MAXIT,
    P_MAXSUB,
    P_RIGID3,
    P_RTOL,
    generalized_forces,
)

# stats vector layout
S_STEPS, S_SOLVES, S_EVALS, S_SUBDIV_EVENTS, S_SUBSTEPS, S_MAX_SOLVES, S_FAILED = range(7)
N_STATS = 7

STATUS_OK = 0
STATUS_FAILED = 1          # Newton did not converge even at the finest subdivision
STATUS_NONFINITE = 2       # NaN/inf input or state

_EPS = 2.220446049250313e-16


@njit(cache=True)
def _solve3(J, b, x):
    """x = J^{-1} b for a 3x3 system (Gaussian elimination with partial pivoting)."""
    A = J.copy()
    y = b.copy()
    for c in range(3):
        piv = c
        best = abs(A[c, c])
        for r in range(c + 1, 3):
            if abs(A[r, c]) > best:
                best = abs(A[r, c])
                piv = r
        if best == 0.0:
            return False
        if piv != c:
            for k in range(3):
                tmp = A[c, k]
                A[c, k] = A[piv, k]
                A[piv, k] = tmp
            tmp = y[c]
            y[c] = y[piv]
            y[piv] = tmp
        for r in range(c + 1, 3):
            f = A[r, c] / A[c, c]
            for k in range(c, 3):
                A[r, k] -= f * A[c, k]
            y[r] -= f * y[c]
    for r in range(2, -1, -1):
        s = y[r]
        for k in range(r + 1, 3):
            s -= A[r, k] * x[k]
        x[r] = s / A[r, r]
    return True


@njit(cache=True)
def _newmark_step(p, C, u0, v0, a0, th1, th1dot, dt, u, v, a, work, J, stats):
    """One Newmark step from (u0, v0, a0) to (u, v, a). Returns True when converged."""
    Q = work[0]
    R = work[1]
    delta = work[2]
    u_prev = work[3]
    scale = work[4]
    aux = work[5]
    dQdu = J[1]
    dQdv = J[2]
    Jm = J[0]
    beta, gamma = p[P_BETA], p[P_GAMMA]
    m0, m1, m2 = p[P_JW], p[P_JG], p[P_J4]
    r3 = p[P_RIGID3]
    rtol, atol = p[P_RTOL], p[P_ATOL]
    maxit = int(p[P_MAXIT])
    c_a = 1.0 / (beta * dt * dt)
    c_v = gamma / (beta * dt)
    for i in range(3):      # predictor: constant acceleration
        u[i] = u0[i] + dt * v0[i] + 0.5 * dt * dt * a0[i]
    n_solves = 0
    n_evals = 0
    alpha = 1.0
    r_prev = 0.0
    have_scale = False
    while True:
        for i in range(3):
            a[i] = (u[i] - u0[i] - dt * v0[i] - dt * dt * (0.5 - beta) * a0[i]) * c_a
            v[i] = v0[i] + dt * ((1.0 - gamma) * a0[i] + gamma * a[i])
        generalized_forces(p, u, v, th1, Q, dQdu, dQdv, aux)
        n_evals += 1
        rel0 = v[0] - th1dot
        rel1 = v[1] - r3 * th1dot
        rel2 = v[2] - r3 * th1dot
        R[0] = m0 * a[0] + C[0, 0] * rel0 + C[0, 1] * rel1 + C[0, 2] * rel2 - Q[0]
        R[1] = m1 * a[1] + C[1, 0] * rel0 + C[1, 1] * rel1 + C[1, 2] * rel2 - Q[1]
        R[2] = m2 * a[2] + C[2, 0] * rel0 + C[2, 1] * rel1 + C[2, 2] * rel2 - Q[2]
        finite = True
        for i in range(3):
            if not math.isfinite(R[i]):
                finite = False
        if not finite:
            break
        for i in range(3):
            for k in range(3):
                Jm[i, k] = (C[i, k] - dQdv[i, k]) * c_v - dQdu[i, k]
        Jm[0, 0] += m0 * c_a
        Jm[1, 1] += m1 * c_a
        Jm[2, 2] += m2 * c_a
        if not have_scale:
            for i in range(3):
                scale[i] = abs(Jm[i, i]) if Jm[i, i] != 0.0 else 1.0
            have_scale = True
        converged = True
        r_norm = 0.0
        for i in range(3):
            err = abs(R[i]) / scale[i]
            tol = atol + rtol * abs(u[i] - u0[i]) + 8.0 * _EPS * abs(u[i])
            if err > tol:
                converged = False
            r_norm += (err / tol) ** 2
        if converged:
            stats[S_SOLVES] += n_solves
            stats[S_EVALS] += n_evals
            if n_solves > stats[S_MAX_SOLVES]:
                stats[S_MAX_SOLVES] = n_solves
            return True
        if n_solves > 0 and r_norm > r_prev and alpha > 1.0 / 64.0:
            alpha *= 0.5            # damped Newton: backtrack along the last update
            for i in range(3):
                u[i] = u_prev[i] + alpha * delta[i]
            continue
        if n_solves >= maxit:
            break
        for i in range(3):
            R[i] = -R[i]
        if not _solve3(Jm, R, delta):
            break
        for i in range(3):
            u_prev[i] = u[i]
            u[i] += delta[i]
        r_prev = r_norm
        alpha = 1.0
        n_solves += 1
    stats[S_SOLVES] += n_solves
    stats[S_EVALS] += n_evals
    return False


@njit(cache=True)
def advance(p, C, u, v, a, theta1, theta1_dot, dt, record_stride, rec_u, rec_v, rec_a,
            rec_aux, stats):
    """Advance len(theta1)-1 steps of size dt; theta1[k] is the command at the start of
    step k and theta1[k+1] at its end (theta1_dot likewise).  Updates u, v, a in place and
    only with fully converged steps.  Every ``record_stride`` steps (if > 0) the end state is
    written to rec_* (row j after step (j+1)*stride).  Returns (steps done, status)."""
    n_steps = theta1.shape[0] - 1
    u0 = u.copy()
    v0 = v.copy()
    a0 = a.copy()
    un = np.empty(3)
    vn = np.empty(3)
    an = np.empty(3)
    us = np.empty(3)
    vs = np.empty(3)
    as_ = np.empty(3)
    work = np.zeros((6, N_AUX))
    J = np.zeros((3, 3, 3))
    dQdu = np.zeros((3, 3))
    dQdv = np.zeros((3, 3))
    Qtmp = np.zeros(3)
    max_level = int(p[P_MAXSUB])
    for i in range(3):
        if not (math.isfinite(u0[i]) and math.isfinite(v0[i]) and math.isfinite(a0[i])):
            return 0, STATUS_NONFINITE
    for k in range(n_steps):
        th_a, th_b = theta1[k], theta1[k + 1]
        td_a, td_b = theta1_dot[k], theta1_dot[k + 1]
        if not (math.isfinite(th_b) and math.isfinite(td_b)):
            return k, STATUS_NONFINITE
        ok = _newmark_step(p, C, u0, v0, a0, th_b, td_b, dt, un, vn, an, work, J, stats)
        if not ok:
            level = 1
            while level <= max_level and not ok:
                n_sub = 1 << level
                stats[S_SUBDIV_EVENTS] += 1
                for i in range(3):
                    us[i] = u0[i]
                    vs[i] = v0[i]
                    as_[i] = a0[i]
                ok = True
                h = dt / n_sub
                for j in range(n_sub):
                    f = (j + 1.0) / n_sub
                    th = th_a + f * (th_b - th_a)
                    td = td_a + f * (td_b - td_a)
                    if not _newmark_step(p, C, us, vs, as_, th, td, h, un, vn, an, work, J,
                                         stats):
                        ok = False
                        break
                    stats[S_SUBSTEPS] += 1
                    for i in range(3):
                        us[i] = un[i]
                        vs[i] = vn[i]
                        as_[i] = an[i]
                level += 1
            if not ok:
                stats[S_FAILED] += 1
                for i in range(3):
                    u[i] = u0[i]
                    v[i] = v0[i]
                    a[i] = a0[i]
                return k, STATUS_FAILED
        for i in range(3):
            u0[i] = un[i]
            v0[i] = vn[i]
            a0[i] = an[i]
        stats[S_STEPS] += 1
        if record_stride > 0 and (k + 1) % record_stride == 0:
            j = (k + 1) // record_stride - 1
            for i in range(3):
                rec_u[j, i] = un[i]
                rec_v[j, i] = vn[i]
                rec_a[j, i] = an[i]
            generalized_forces(p, un, vn, th_b, Qtmp, dQdu, dQdv, rec_aux[j])
    for i in range(3):
        u[i] = u0[i]
        v[i] = v0[i]
        a[i] = a0[i]
    return n_steps, STATUS_OK


@njit(cache=True)
def consistent_acceleration(p, C, u, v, theta1, theta1_dot, a):
    """a = M^{-1} (Q - C (v - r theta1')) at a given state (initial condition)."""
    Q = np.zeros(3)
    dQdu = np.zeros((3, 3))
    dQdv = np.zeros((3, 3))
    aux = np.zeros(N_AUX)
    generalized_forces(p, u, v, theta1, Q, dQdu, dQdv, aux)
    r3 = p[P_RIGID3]
    rel = np.array([v[0] - theta1_dot, v[1] - r3 * theta1_dot, v[2] - r3 * theta1_dot])
    m = (p[P_JW], p[P_JG], p[P_J4])
    for i in range(3):
        f = Q[i]
        for k in range(3):
            f -= C[i, k] * rel[k]
        a[i] = f / m[i]
