# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The adapter's per-sample work, compiled (:class:`~.estimator.Adapter`): the regressors,
the Kalman step, the window (:func:`_window_step`) and an encoder sample in one call
(:func:`sample_head`, ending with :func:`sample_tail`) or in two with the adapter's Python
between them (a flank-change event, a detected step: a few per scan period).

The per-sample scalars live in float arrays (``Adapter._st``, indices ``S_*`` and ``X_*``;
the flank timing's ``_ts``, ``T_*``), read as attributes through :class:`~.slots.Slot`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from .flank_timing import STEP_STRIDE, T_EVENT_DUE, T_LAST_STEP, T_N, T_NEXT_LOOK, detect_core

# Adapter._st: per-sample state, then constants set at a rebase
(S_LAST_T, S_RATES, S_TH4, S_W4, S_A4, S_RATE, S_FLANK, S_FLANK_T, S_CROSS_T, S_FLANK_M,
 S_HOLD_UNTIL, S_W_MAX, S_A_MAX, S_FIRST_T, S_USED, S_SKIPPED,
 S_INERTIA, S_LOAD0, S_DRAG0, S_PLAY0, S_C_POS, S_C_NEG, S_WINDOW, S_MEMORY, S_NOISE2,
 S_MAX_GAP, S_ACCEL_TC, S_HOLD_OFF, S_HUBER, S_NOISE, S_MODEL_FLANK_T, S_APPLIED_T,
 S_APPLIED_BOUND,
 # the head's values for the tail
 X_DT, X_LOAD, X_DRAG, X_TORQUE, X_DRAG_M, X_TORQUE_M, X_OLD_FLANK_M, N_ST) = range(41)
# what sample_head asks of its caller
SKIPPED, USED, NEED_ROOM, PYTHON, CROSSED = range(5)
# Adapter._lay: the layout's indices
L_LOAD, L_DRAG, L_PLAY, L_WORM0, L_NW, L_GEAR0, L_NG, N_LAY = range(8)


class Estimate(NamedTuple):
    """The arrays one sample writes in place: the estimate ``theta``, its covariance ``P``
    (each variance capped at ``std2``), the regressor's scratch ``phi``, the window's
    triangular factor ``R`` and its sum of weights ``sc`` (:func:`_window_step`)."""
    theta: np.ndarray
    P: np.ndarray
    std2: np.ndarray
    phi: np.ndarray
    R: np.ndarray
    sc: np.ndarray


class Reading(NamedTuple):
    """One sample as the filter takes it: the prediction's angles theta2, theta3, the rate
    omega4, the flank of the estimate and of the model in use, the estimate's torque
    demand, the compliance on the present flank and the residual (measured - predicted
    theta4)."""
    th2: float
    th3: float
    w4: float
    flank: float
    flank_m: float
    torque: float
    compliance: float
    resid: float


class Weighing(NamedTuple):
    """How a sample is weighed: the random walk's share ``forget`` of each variance, the
    window's weight ``lam`` of the rows so far, the measurement's variance ``r_var``, the
    Huber bound (in predicted standard deviations) and whether the flank is sure."""
    forget: float
    lam: float
    r_var: float
    huber: float
    sure: bool


@njit(cache=True)
def _regressor(phi, lay, th2, th3, w4, flank, compliance):
    """The regressors of a sample into ``phi`` (``lay``: the layout, indices ``L_*``)."""
    i_load, i_drag, i_play = lay[L_LOAD], lay[L_DRAG], lay[L_PLAY]
    worm0, nw, gear0, ng = lay[L_WORM0], lay[L_NW], lay[L_GEAR0], lay[L_NG]
    phi[:] = 0.0
    if i_load >= 0:
        phi[i_load] = -compliance
    if i_drag >= 0:
        phi[i_drag] = -compliance * w4
    if i_play >= 0:
        phi[i_play] = -0.5 * flank
    for k in range(nw):
        phi[worm0 + 2 * k] = math.sin((k + 1) * th2)
        phi[worm0 + 2 * k + 1] = math.cos((k + 1) * th2)
    for m in range(ng):
        phi[gear0 + 2 * m] = math.sin((m + 1) * th3)
        phi[gear0 + 2 * m + 1] = math.cos((m + 1) * th3)


@njit(cache=True)
def _kalman_step(theta, P, q, p_max, phi, y, r_var, huber):
    """Random walk (P += q, each variance capped at its prior) then the measurement
    y = phi^T theta + noise(r_var).  An innovation beyond ``huber`` times its predicted
    standard deviation sqrt(phi^T P phi + r_var) is down-weighted (its noise variance
    inflated by |nu| / huber, Huber's weight): mean and covariance stay consistent.  Returns
    the normalised innovation nu."""
    n = theta.size
    for i in range(n):
        P[i, i] += q[i]
    for i in range(n):
        if P[i, i] > p_max[i]:
            s = math.sqrt(p_max[i] / P[i, i])
            for j in range(n):
                P[i, j] *= s
                P[j, i] *= s
    Pphi = P @ phi
    pp = 0.0
    innov = y
    for i in range(n):
        pp += phi[i] * Pphi[i]
        innov -= phi[i] * theta[i]
    nu = innov / math.sqrt(pp + r_var)
    r_eff = r_var
    if abs(nu) > huber:
        r_eff = (pp + r_var) * abs(nu) / huber - pp
        if r_eff < r_var:
            r_eff = r_var
    s = pp + r_eff
    for i in range(n):
        theta[i] += Pphi[i] / s * innov
    for i in range(n):
        for j in range(i, n):
            v = P[i, j] - Pphi[i] * Pphi[j] / s
            P[i, j] = v
            P[j, i] = v
    return nu


@njit(cache=True)
def _sample_step(est, applied, lay, rd, wg):
    """One encoder sample (:class:`Reading` ``rd``, weighed as :class:`Weighing` ``wg``)
    into the estimate and the window (:class:`Estimate` ``est``; module docstring): the
    soft flank from the estimate's covariance, the regressors, y = r + phi^T theta_model
    (the model's play on its own flank), forgetting, the Kalman step; the window's row with
    the estimate's hard flank (where it agrees with the model's, the model in use's
    linearised residual is the residual itself)."""
    th, P, phi = est.theta, est.P, est.phi
    i_load, i_drag, i_play = lay[L_LOAD], lay[L_DRAG], lay[L_PLAY]
    w4, flank, torque = rd.w4, rd.flank, rd.torque
    r_var = wg.r_var
    soft = flank
    if i_play >= 0 and not wg.sure:
        var = 0.0
        if i_load >= 0:
            var += P[i_load, i_load]
        if i_drag >= 0:
            var += w4 * w4 * P[i_drag, i_drag]
            if i_load >= 0:
                var += 2.0 * w4 * P[i_load, i_drag]
        if var > 0.0:
            soft = math.erf(torque / math.sqrt(2.0 * var))
            bp = th[i_play]
            r_var += 0.25 * (1.0 - soft * soft) * (bp * bp + P[i_play, i_play])
    _regressor(phi, lay, rd.th2, rd.th3, w4, soft, rd.compliance)
    y = rd.resid
    for i in range(phi.size):
        y += phi[i] * applied[i]
    if i_play >= 0:
        y += (0.5 * soft - 0.5 * rd.flank_m) * applied[i_play]
    q = np.empty(phi.size)
    for i in range(phi.size):
        q[i] = P[i, i] * wg.forget
    _kalman_step(th, P, q, est.std2, phi, y, r_var, wg.huber)
    # the window judges sets by the hard flank: for the model in use (same flank)
    # y - phi x is r itself
    if i_play >= 0:
        phi[i_play] = -0.5 * flank
    _window_step(est.R, est.sc, phi, y, wg.lam)


@njit(cache=True)
def _window_step(R, sc, phi, y, lam):
    """The exponentially weighted window of the rows [phi, y] (a row of age k weighs lam^k)
    as its triangular factor: R[:m] (m = n + 1, upper triangular) with R^T R = sum w [phi,
    y]^T [phi, y]; the rows so far scaled by sqrt(lam), then the new row rotated in (Givens,
    R[m] its scratch).  The windowed residual of a set x is |R[:m] [x, -1]|
    (:func:`window_norm`): no square expanded, so no cancellation between large terms, and
    no square formed, so no overflow (the mean square from sums of phi phi^T, phi y and y^2
    lost what a large y ever brought, and an infinite one for ever).  sc[0] = sum w."""
    n = phi.size
    m = n + 1
    g = math.sqrt(lam)
    for i in range(m):
        for j in range(i, m):
            R[i, j] *= g
    row = R[m]
    for j in range(n):
        row[j] = phi[j]
    row[n] = y
    for i in range(m):
        bi = row[i]
        if bi == 0.0:
            continue
        a = R[i, i]
        r = math.hypot(a, bi)
        c = a / r
        s = bi / r
        R[i, i] = r
        for j in range(i + 1, m):
            rij = R[i, j]
            xj = row[j]
            R[i, j] = c * rij + s * xj
            row[j] = c * xj - s * rij
        row[i] = 0.0
    sc[0] = lam * sc[0] + 1.0


@njit(cache=True)
def window_norm(R, x):
    """|R[:m] [x, -1]| (m = x.size + 1): the root of the window's weighted sum of squared
    residuals y - phi^T x (:func:`_window_step`), scaled by its largest entry (no
    overflow)."""
    n = x.size
    m = n + 1
    z = np.empty(m)
    big = 0.0
    for i in range(m):
        v = -R[i, n]
        for j in range(i, n):
            v += R[i, j] * x[j]
        z[i] = v
        big = max(big, abs(v))
    if big == 0.0 or not math.isfinite(big):
        return big
    acc = 0.0
    for i in range(m):
        q = z[i] / big
        acc += q * q
    return big * math.sqrt(acc)


@njit(cache=True)
def least_step(theta, P, lay, play0):
    """The smallest step the detector takes for the drive's crossing [rad]: half the play
    once it is known (the estimate's, beyond 3 sd; or the model's fixed play), else 0."""
    i_play = lay[L_PLAY]
    if i_play >= 0:
        bp = theta[i_play]
        if bp * bp > 9.0 * P[i_play, i_play]:
            return 0.5 * bp
        return 0.0
    return 0.5 * play0 if play0 > 0.0 else 0.0


@njit(cache=True)
def sample_head(st, ts, ta, theta, P, theta_d, P_d, std2, phi, applied, R, sc, lay, t, meas,
                th2, th3, th4):
    """An encoder sample at ``t`` (measured theta4 ``meas``, the prediction theta2..theta4
    of that instant), up to the flank-change events: the rates (alpha4 low-passed), the
    flanks of the estimate and of the model in use, the sample into the record, the step
    detector's look (judged by ``theta_d``, ``P_d``: the estimate from before its window).
    Returns SKIPPED or USED (the sample is done: :func:`sample_tail` ran),
    NEED_ROOM (the record is full: nothing changed), or PYTHON / CROSSED (the caller's
    Python work first: a flank-change event is due or the detector found a step; CROSSED:
    the model in use crossed its play, from ``st[X_OLD_FLANK_M]``; then the tail)."""
    i_load, i_drag, i_play = lay[L_LOAD], lay[L_DRAG], lay[L_PLAY]
    dt = t - st[S_LAST_T]
    rates = st[S_RATES]
    if not dt <= st[S_MAX_GAP]:                  # first sample, or after a pause
        rates = 0.0
    if rates == 0.0:
        w4 = 0.0
        a4 = 0.0
    else:
        w4 = (th4 - st[S_TH4]) / dt
        a_raw = (w4 - st[S_W4]) / dt if rates > 1.0 else 0.0
        g = dt / (st[S_ACCEL_TC] + dt)
        a4 = st[S_A4] + g * (a_raw - st[S_A4])
    if rates >= 2.0 and ts[T_N] == ta.shape[0]:
        return NEED_ROOM
    st[S_LAST_T] = t
    st[S_TH4] = th4
    st[S_W4] = w4
    st[S_A4] = a4
    if rates > 0.0:
        st[S_RATE] = 1.0 / dt
    rates += 1.0
    st[S_RATES] = rates
    if rates < 3.0:
        st[S_SKIPPED] += 1.0
        return SKIPPED
    inertia = st[S_INERTIA]
    load = theta[i_load] if i_load >= 0 else st[S_LOAD0]
    drag = theta[i_drag] if i_drag >= 0 else st[S_DRAG0]
    torque = inertia * a4 + drag * w4 + load
    flank = 1.0 if torque > 0.0 else -1.0 if torque < 0.0 else st[S_FLANK]
    if flank != st[S_FLANK]:
        st[S_FLANK] = flank
        st[S_FLANK_T] = t
        st[S_CROSS_T] = max(st[S_CROSS_T], t)     # (the estimate's crossing)
    # the flank of the model in use: where it differs, one of the two is wrong and the
    # residual holds a flank error the linear picture does not have
    drag_m = applied[i_drag] if i_drag >= 0 else st[S_DRAG0]
    torque_m = inertia * a4 + drag_m * w4 + (applied[i_load] if i_load >= 0
                                             else st[S_LOAD0])
    flank_m = 1.0 if torque_m > 0.0 else -1.0 if torque_m < 0.0 else st[S_FLANK_M]
    n = int(ts[T_N])
    ta[n, 0] = t
    ta[n, 1] = meas - th4
    ta[n, 2] = w4
    ta[n, 3] = a4
    ta[n, 4] = th2
    ta[n, 5] = th3
    ts[T_N] = n + 1.0
    crossed = False
    if flank_m != st[S_FLANK_M]:
        if i_play < 0 and st[S_PLAY0] > 0.0 or i_play >= 0 and applied[i_play] > 0.0:
            crossed = True                      # the model crosses its play here
            st[X_OLD_FLANK_M] = st[S_FLANK_M]
            st[S_MODEL_FLANK_T] = t
        st[S_FLANK_M] = flank_m
        st[S_FLANK_T] = max(st[S_FLANK_T], t)
    st[X_DT] = dt
    st[X_LOAD] = load
    st[X_DRAG] = drag
    st[X_TORQUE] = torque
    st[X_DRAG_M] = drag_m
    st[X_TORQUE_M] = torque_m
    if crossed:
        return CROSSED
    if t >= ts[T_EVENT_DUE]:                    # a flank-change event to measure
        return PYTHON
    if t >= ts[T_NEXT_LOOK]:                    # the step detector's look
        least = least_step(theta_d, P_d, lay, st[S_PLAY0])
        if detect_core(ta, n + 1, t, st[S_NOISE], st[S_MODEL_FLANK_T], ts[T_LAST_STEP],
                       least, theta_d, applied, P_d, lay, st[S_APPLIED_T],
                       st[S_APPLIED_BOUND])[0]:
            return PYTHON                       # found: the caller measures with it
        ts[T_NEXT_LOOK] = t + STEP_STRIDE
    return sample_tail(st, theta, P, std2, phi, applied, R, sc, lay, t, meas, th2, th3, th4)


@njit(cache=True)
def sample_tail(st, theta, P, std2, phi, applied, R, sc, lay, t, meas, th2, th3, th4):
    """The rest of :func:`sample_head`'s sample (its values in ``st[X_*]``): skipped near a
    flank change (past, ahead, or a step of the model's hold-off), else into the filter
    and the window.  Returns USED or SKIPPED."""
    i_play = lay[L_PLAY]
    w4, a4 = st[S_W4], st[S_A4]
    load, drag, torque = st[X_LOAD], st[X_DRAG], st[X_TORQUE]
    drag_m, torque_m = st[X_DRAG_M], st[X_TORQUE_M]
    # a flank change within the hold-off ahead (the torques' rates: c alpha4)
    hold = st[S_HOLD_OFF]
    ahead = hold * a4
    soon = torque * (torque + drag * ahead) < 0.0 or \
        torque_m * (torque_m + drag_m * ahead) < 0.0
    if soon or t - st[S_FLANK_T] < hold or t < st[S_HOLD_UNTIL]:
        st[S_SKIPPED] += 1.0
        return SKIPPED
    c_pos, c_neg = st[S_C_POS], st[S_C_NEG]
    compliance = c_pos if w4 > 0.0 else c_neg if w4 < 0.0 else 0.5 * (c_pos + c_neg)
    window = st[S_WINDOW]
    dt = st[X_DT]
    lam = math.exp(-dt / window)
    # the flank is sure when the drive stays on one: no crossing measured or estimated for
    # a window (the model in use's do not count) and the load outweighs twice the recent
    # drag and inertia torques.  Else load and play, one offset on such a drive, leave the
    # load's own uncertainty wide and the soft flank the play a noise for ever
    sure = i_play >= 0 and t - st[S_CROSS_T] > window and abs(load) > 2.0 * (
        max(drag, 0.0) * st[S_W_MAX] + st[S_INERTIA] * st[S_A_MAX])
    _sample_step(Estimate(theta, P, std2, phi, R, sc), applied, lay,
                 Reading(th2, th3, w4, st[S_FLANK], st[S_FLANK_M], torque, compliance,
                         meas - th4),
                 Weighing(dt / st[S_MEMORY], lam, st[S_NOISE2], st[S_HUBER], sure))
    st[S_W_MAX] = max(abs(w4), st[S_W_MAX] * lam)
    st[S_A_MAX] = max(abs(a4), st[S_A_MAX] * lam)
    if math.isnan(st[S_FIRST_T]):
        st[S_FIRST_T] = t
    st[S_USED] += 1.0
    return USED
