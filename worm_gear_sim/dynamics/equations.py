# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Equations of motion of the worm-gear drive (Chung & Shaw 2007, Eqs. 1-18), written once.

This module contains the compiled equations on the packed parameter vector (layout:
:mod:`.layout`) for the degrees of freedom ``u = (theta2, theta3, theta4)`` (worm body,
worm-gear body, flywheel/antenna) driven by the commanded worm-shaft angle ``theta1``: the
mesh approach with the periodic transmission error (Eq. 8), the tooth stiffness over the
mesh cycle (Eqs. 16-17), the friction coefficient (Eq. 18), the play, the mesh compliance
(Eqs. 7, 10), the generalized forces with their analytic Jacobians (Eqs. 4-15), the energy
and the linearised matrices.  They are the single source of truth for the physics; the
integrator, the node, the CLI, the studies and the compensation all call them.  The
equations as the code writes them, and the decisions where the paper is ambiguous:
docs/model-notes.md.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import ArrayLike

from .layout import (
    FRICTION_CONSTANT,
    FRICTION_OFF,
    FRICTION_STRIBECK,
    N_AUX,
    N_OUT,
    O_AUX,
    O_DQDU,
    O_DQDV,
    O_Q,
    P_CGKG_LIN,
    P_COSL,
    P_COSPHI,
    P_COUT,
    P_CWKW_LIN,
    P_FRIC_IN_COMPLIANCE,
    P_FRIC_MODEL,
    P_FRIC_PAPER,
    P_FRIC_SET_VALUED,
    P_GAP_HALF,
    P_GEAR_B,
    P_GEAR_SCALE,
    P_GEAR_X0,
    P_INV_KGS,
    P_INV_KWS,
    P_INV_SQRT_VS,
    P_INV_VEPS,
    P_J4,
    P_JG,
    P_JW,
    P_KG,
    P_KGS,
    P_KW,
    P_KWS,
    P_LIN_COMPLIANCE,
    P_LW,
    P_MESH_COSINE,
    P_MESH_LINEAR,
    P_MU_CONST,
    P_MU_DROP,
    P_MU_K,
    P_OUTPUT_PER_INPUT,
    P_PE_GEAR,
    P_PE_NG,
    P_PE_NW,
    P_PE_WORM,
    P_PHASE0,
    P_RG,
    P_RW,
    P_SINL,
    P_TEETH_TABLE,
    P_TLOAD,
    P_VCUSP,
    P_VS,
    P_WORM_B,
    P_WORM_SCALE,
    P_WORM_X0,
    P_ZG,
)
from .periodic import harmonic_sum, table_lookup

DEG_PER_RAD = 180.0 / math.pi

TWO_PI = 2.0 * math.pi



# ---- the periodic transmission error and the mesh approach (Eq. 8 + r_g e) -----------------
@njit(cache=True, error_model='numpy', inline='always')
def transmission_error(p, th2, th3):
    """(e, de/dth2, de/dth3, d2e/dth2^2, d2e/dth3^2) of the periodic transmission error
    e = sum_k s_k sin k th2 + c_k cos k th2 + sum_m S_m sin m th3 + C_m cos m th3 [rad at the
    gear]; all 0.0 without harmonics."""
    e = e2 = e22 = e3 = e33 = 0.0
    nw, ng = int(p[P_PE_NW]), int(p[P_PE_NG])
    if nw > 0:
        e, e2, e22 = harmonic_sum(p, P_PE_WORM, nw, th2)
    if ng > 0:
        f, e3, e33 = harmonic_sum(p, P_PE_GEAR, ng, th3)
        e += f
    return e, e2, e3, e22, e33



@njit(cache=True, error_model='numpy', inline='always')
def mesh_approach(p, th2, th3):
    """q = l_w th2 - r_g th3 + r_g e(th2, th3): the mesh approach along Y (Eq. 8 with the
    periodic transmission error; exactly Eq. 8 without harmonics)."""
    q = p[P_LW] * th2 - p[P_RG] * th3
    if p[P_PE_NW] > 0.0 or p[P_PE_NG] > 0.0:
        q += p[P_RG] * transmission_error(p, th2, th3)[0]
    return q



# ---- Eqs. 16-17: tooth stiffness over the mesh cycle ----------------------------------------
@njit(cache=True, error_model='numpy', inline='always')
def tooth_stiffness(p, theta2, theta3):
    """Return (c_w k_w, c_g k_g, d(c_w k_w)/d(phase), d(c_g k_g)/d(phase)); phase in rad."""
    if p[P_MESH_LINEAR] != 0.0:
        return p[P_CWKW_LIN], p[P_CGKG_LIN], 0.0, 0.0
    phase = 0.5 * (theta2 + p[P_ZG] * theta3) + p[P_PHASE0]
    bw, bg = p[P_WORM_B], p[P_GEAR_B]
    if p[P_MESH_COSINE] != 0.0:
        # x = x0 + 180 (1 - cos s) deg: out along the fitted range and back over one cycle,
        # continuous and smooth through the tooth hand-over
        c, sn = math.cos(phase), math.sin(phase)
        cwkw = p[P_WORM_SCALE] * math.exp(bw * (p[P_WORM_X0] + 180.0 * (1.0 - c)))
        cgkg = p[P_GEAR_SCALE] * math.exp(bg * (p[P_GEAR_X0] + 180.0 * (1.0 - c)))
        return cwkw, cgkg, cwkw * bw * 180.0 * sn, cgkg * bg * 180.0 * sn
    # sawtooth: x = x0 + s, s in [0, 360) deg; jumps by e^{360 b} at each hand-over
    s_deg = (phase - TWO_PI * math.floor(phase / TWO_PI)) * DEG_PER_RAD   # in [0, 360)
    # Eq. 16 / 17: M e^a (e^{b x_i} + e^{b x_j}), x_j = x_i + 360; (1 + e^{360 b}) in SCALE
    cwkw = p[P_WORM_SCALE] * math.exp(bw * (p[P_WORM_X0] + s_deg))
    cgkg = p[P_GEAR_SCALE] * math.exp(bg * (p[P_GEAR_X0] + s_deg))
    return cwkw, cgkg, cwkw * bw * DEG_PER_RAD, cgkg * bg * DEG_PER_RAD



# ---- Eq. 18: friction coefficient and its direction ---------------------------------------
@njit(cache=True, error_model='numpy', inline='always')
def slip_coefficient(p, v):
    """Friction coefficient of the set-valued law while slipping at speed v = |v_s| (v < 0:
    the slip hypothesis is violated; mu(0), slope 0), and d mu / d v.  Eq. 18 with the
    square root rounded at the cusp: sqrt(v) -> v / sqrt(v + v_c), equal to sqrt(v) for
    v >> v_c, finite slope 1/sqrt(v_c) at 0 (Newton converges), mu(0) unchanged."""
    if p[P_FRIC_MODEL] != FRICTION_STRIBECK:
        return p[P_MU_CONST], 0.0
    if v <= 0.0:
        return p[P_MU_K] + p[P_MU_DROP], 0.0
    vc = p[P_VCUSP]
    r = math.sqrt(v + vc)
    sroot = v / r
    dsroot = (v + 2.0 * vc) / (2.0 * r * r * r)
    isv = p[P_INV_SQRT_VS]
    ex = math.exp(-sroot * isv)
    return p[P_MU_K] + p[P_MU_DROP] * ex, -p[P_MU_DROP] * isv * ex * dsroot



@njit(cache=True, error_model='numpy')
def friction_coefficient(p, v_s, q):
    """Return (mu_eff, d mu_eff / d v_s): signed coefficient entering Eqs. 1-2, 10, 12, 14."""
    model = p[P_FRIC_MODEL]
    if model == FRICTION_OFF:
        return 0.0, 0.0
    av = abs(v_s)
    if model == FRICTION_CONSTANT:
        mu, dmu = p[P_MU_CONST], 0.0
    else:
        sv = math.sqrt(av)
        ex = math.exp(-sv * p[P_INV_SQRT_VS])
        mu = p[P_MU_K] + p[P_MU_DROP] * ex
        dmu = 0.0  # d mu / d|v|; singular at 0, handled below
        if av > 0.0:
            dmu = -0.5 * p[P_MU_DROP] * p[P_INV_SQRT_VS] * ex / sv
    if p[P_FRIC_SET_VALUED] != 0.0:
        # set-valued law, slip branch: W_f = mu(|v_s|) |W_n| sgn(v_s).  Below the cusp
        # velocity the contact counts as stuck and the friction as 0 here: the stick force
        # is a multiplier the integrator solves for, the state alone does not fix it
        if av < p[P_VCUSP]:
            return 0.0, 0.0
        sq = 1.0 if q >= 0.0 else -1.0
        sg = 1.0 if v_s > 0.0 else -1.0
        mag, dmag = slip_coefficient(p, av)
        return sq * sg * mag, sq * dmag
    if p[P_FRIC_PAPER] != 0.0:
        # fixed sign as printed; derivative floored to stay finite at rest
        if model == FRICTION_STRIBECK:
            avf = max(av, 1e-9)
            dmu = -p[P_MU_DROP] * math.exp(-math.sqrt(avf / p[P_VS])) \
                / (2.0 * math.sqrt(avf * p[P_VS]))
        sgn_v = 1.0 if v_s >= 0.0 else -1.0
        return mu, dmu * sgn_v
    sq = 1.0 if q >= 0.0 else -1.0       # flank in contact: friction ~ |W_n|
    # tanh(x) = -expm1(-2|x|) / (2 + expm1(-2|x|)) sgn(x): one exponential, exact near 0
    e = math.expm1(-2.0 * av * p[P_INV_VEPS])
    t = -e / (2.0 + e)
    if v_s < 0.0:
        t = -t
    # d/dv [mu(|v|) tanh(v/eps)] = mu'(|v|) sgn(v) t + mu (1 - t^2)/eps ; sgn(v) t = |t|
    # 1 - t^2 = 4 e^{-2|x|} / (1 + e^{-2|x|})^2, written without cancellation
    one_minus_t2 = 4.0 * (1.0 + e) / ((2.0 + e) * (2.0 + e))
    d = dmu * abs(t) + mu * one_minus_t2 * p[P_INV_VEPS]
    return sq * mu * t, sq * d



# ---- the mesh clearance: penetration of the flank in contact --------------------------------
@njit(cache=True, error_model='numpy', inline='always')
def penetration(p, q):
    """(q_e, dq_e/dq): the approach q = l_w theta2 - r_g theta3 less half the play h =
    r_g b / 2 on the flank in contact (q - h for q > h, q + h for q < -h), 0 inside the
    play (no tooth force, no friction).  Without play q_e = q exactly."""
    h = p[P_GAP_HALF]
    if h > 0.0:
        if q > h:
            return q - h, 1.0
        if q < -h:
            return q + h, 1.0
        return 0.0, 0.0
    return q, 1.0



# ---- Eqs. 7 and 10: compliance of the mesh along the contact normal -----------------------
@njit(cache=True, error_model='numpy', inline='always')
def mesh_compliance(p, th2, th3, mu):
    """KGWS of Eq. 10 at a mesh position and signed friction coefficient mu:
    (KGWS, dKGWS/dphase, dKGWS/dmu, c_w k_w, c_g k_g).  The friction terms are kept only
    with ``friction.in_compliance``."""
    sl, cl, cphi = p[P_SINL], p[P_COSL], p[P_COSPHI]
    inv_kgs, inv_kws = p[P_INV_KGS], p[P_INV_KWS]
    if p[P_FRIC_IN_COMPLIANCE] != 0.0:
        Ac, Bc, dK_dmu = cphi * sl + mu * cl, cphi * cl - mu * sl, cl * sl * (inv_kgs - inv_kws)
    else:
        Ac, Bc, dK_dmu = cphi * sl, cphi * cl, 0.0
    if p[P_MESH_LINEAR] != 0.0:
        teeth, dK_dphase = p[P_LIN_COMPLIANCE], 0.0
        cwkw, cgkg = p[P_CWKW_LIN], p[P_CGKG_LIN]
    elif p[P_TEETH_TABLE] != 0.0:
        teeth, dK_dphase = table_lookup(p, 0.5 * (th2 + p[P_ZG] * th3) + p[P_PHASE0])
        cwkw, cgkg, _, _ = tooth_stiffness(p, th2, th3)     # (unused in the hot path)
    else:
        cwkw, cgkg, dcw, dcg = tooth_stiffness(p, th2, th3)
        icw, icg = 1.0 / cwkw, 1.0 / cgkg
        teeth = icw + icg                                            # Eq. 7
        dK_dphase = -dcw * icw * icw - dcg * icg * icg
    kgws = teeth + Ac * sl * inv_kgs + Bc * cl * inv_kws             # Eq. 10
    return kgws, dK_dphase, dK_dmu, cwkw, cgkg



# ---- Eqs. 4-15: generalized forces with their analytic Jacobians ---------------------------
@njit(cache=True, error_model='numpy', inline='always')
def mesh_forces_mu(p, th2, th3, th4, w4, theta1, mu):
    """Generalized forces of Eqs. 11, 13 and 6 for a given signed friction coefficient mu
    (W_f = mu W_n): the slip law's value or, in stick, the multiplier the integrator solves
    for.  Returns (Q2, Q3, Q4, dQ2/dth2, dQ2/dth3, dQ3/dth2, dQ3/dth3, dQ2/dmu, dQ3/dmu, W_n,
    c_w k_w, c_g k_g, F_X, F_Y, q)."""
    lw, rw, rg = p[P_LW], p[P_RW], p[P_RG]
    sl, cl, cphi = p[P_SINL], p[P_COSL], p[P_COSPHI]
    q = lw * th2 - rg * th3                                          # Eq. 8 right side
    dq2, dq3 = lw, -rg
    g2 = g3 = 1.0                   # normal-force torque factors (dq/dth2)/l_w, -(dq/dth3)/r_g
    dg2 = dg3 = 0.0                 # their derivatives in th2, th3 (e is separable)
    if p[P_PE_NW] > 0.0 or p[P_PE_NG] > 0.0:
        # periodic transmission error: q += r_g e; the normal force acts through dq/dtheta
        # (virtual work), friction stays along the thread (docs/model-notes.md)
        e, e2, e3, e22, e33 = transmission_error(p, th2, th3)
        q += rg * e
        dq2 += rg * e2
        dq3 += rg * e3
        g2, g3 = dq2 / lw, 1.0 - e3
        dg2, dg3 = rg * e22 / lw, -e33
    A = cphi * sl * g2 + mu * cl                                     # F_X / W_n, Eq. 1
    B = cphi * cl * g3 - mu * sl                                     # F_Y / W_n, Eq. 2
    kgws, dK_dphase, dK_dmu, cwkw, cgkg = mesh_compliance(p, th2, th3, mu)
    ikg = 1.0 / kgws
    qe, dqe = penetration(p, q)                                      # the play
    Wn = qe * cl * ikg                                               # Eq. 9
    dWn_dq = cl * ikg * dqe
    dWn_dK = -Wn * ikg
    dWn_dth2 = dWn_dq * dq2 + dWn_dK * dK_dphase * 0.5
    dWn_dth3 = dWn_dq * dq3 + dWn_dK * dK_dphase * 0.5 * p[P_ZG]
    dWn_dmu = dWn_dK * dK_dmu
    Kw, Kg = p[P_KW], p[P_KG]
    Q2 = -rw * A * Wn - Kw * (th2 - theta1)                          # Eq. 11
    Q3 = rg * B * Wn - Kg * (th3 - th4)                              # Eq. 13
    Q4 = -Kg * (th4 - th3) - p[P_COUT] * w4 - p[P_TLOAD]             # Eq. 6 (+ load)
    return (Q2, Q3, Q4,
            -rw * (A * dWn_dth2 + cphi * sl * dg2 * Wn) - Kw, -rw * A * dWn_dth3,
            rg * B * dWn_dth2, rg * (B * dWn_dth3 + cphi * cl * dg3 * Wn) - Kg,
            -rw * (cl * Wn + A * dWn_dmu), rg * (-sl * Wn + B * dWn_dmu),
            Wn, cwkw, cgkg, A * Wn, B * Wn, q)



@njit(cache=True, error_model='numpy')
def mesh_forces(p, th2, th3, th4, w2, w3, w4, theta1):
    """Generalized forces Q (= M u'' without structural damping) of Eqs. 11, 13 and 6, the
    non-constant entries of their analytic Jacobians and the mesh quantities, as a tuple:

    (Q2, Q3, Q4, dQ2/dth2, dQ2/dth3, dQ3/dth2, dQ3/dth3, dQ2/dw2, dQ2/dw3, dQ3/dw2, dQ3/dw3,
     W_n, mu_eff, c_w k_w, c_g k_g, v_s, F_X, F_Y, q).

    The constant entries are dQ3/dth4 = dQ4/dth3 = K_g, dQ4/dth4 = -K_g, dQ4/dw4 = -c_out.
    Friction follows the law of the state (with the set-valued law: the slip branch, zero
    friction at exactly zero sliding speed).  Scalars in, scalars out: the hot path."""
    rw, rg = p[P_RW], p[P_RG]
    sl, cl = p[P_SINL], p[P_COSL]
    q = mesh_approach(p, th2, th3)
    v_s = rw * cl * w2 + rg * sl * w3                                # sliding speed
    mu, dmu_dvs = friction_coefficient(p, v_s, q)
    r = mesh_forces_mu(p, th2, th3, th4, w4, theta1, mu)
    dmu_dw2 = dmu_dvs * rw * cl
    dmu_dw3 = dmu_dvs * rg * sl
    return (r[0], r[1], r[2], r[3], r[4], r[5], r[6],
            r[7] * dmu_dw2, r[7] * dmu_dw3, r[8] * dmu_dw2, r[8] * dmu_dw3,
            r[9], mu, r[10], r[11], v_s, r[12], r[13], r[14])



@njit(cache=True, error_model='numpy')
def mesh_eval(p, th2, th3, th4, w2, w3, w4, theta1, out):
    """:func:`mesh_forces` written to a flat array (layout O_Q, O_DQDU, O_DQDV, O_AUX)."""
    r = mesh_forces(p, th2, th3, th4, w2, w3, w4, theta1)
    Kg = p[P_KG]
    out[0], out[1], out[2] = r[0], r[1], r[2]
    out[3], out[4], out[5] = r[3], r[4], 0.0
    out[6], out[7], out[8] = r[5], r[6], Kg
    out[9], out[10], out[11] = 0.0, Kg, -Kg
    out[12], out[13], out[14] = r[7], r[8], 0.0
    out[15], out[16], out[17] = r[9], r[10], 0.0
    out[18], out[19], out[20] = 0.0, 0.0, -p[P_COUT]
    for i in range(N_AUX):
        out[O_AUX + i] = r[11 + i]



@njit(cache=True, error_model='numpy')
def generalized_forces(p, u, v, theta1, Q, dQdu, dQdv, aux):
    """Array form of :func:`mesh_eval`: fill Q, dQ/du, dQ/dv (3x3) and aux (8)."""
    out = np.empty(N_OUT)
    mesh_eval(p, u[0], u[1], u[2], v[0], v[1], v[2], theta1, out)
    for i in range(3):
        Q[i] = out[O_Q + i]
        for k in range(3):
            dQdu[i, k] = out[O_DQDU + 3 * i + k]
            dQdv[i, k] = out[O_DQDV + 3 * i + k]
    for i in range(N_AUX):
        aux[i] = out[O_AUX + i]



@njit(cache=True, error_model='numpy')
def mesh_stiffness_y(p, theta2, theta3):
    """Frictionless mesh stiffness along Y, k_Y = cos(phi) cos^2(lam) / KGWS0 [N/m]."""
    sl, cl, cphi = p[P_SINL], p[P_COSL], p[P_COSPHI]
    cwkw, cgkg, _, _ = tooth_stiffness(p, theta2, theta3)
    kgws0 = 1.0 / cwkw + 1.0 / cgkg + cphi * sl * sl / p[P_KGS] + cphi * cl * cl / p[P_KWS]
    return cphi * cl * cl / kgws0



@njit(cache=True, error_model='numpy')
def mechanical_energy(p, u, v, theta1):
    """Kinetic + shaft torsion + mesh energy 0.5 k_Y q^2 [J] (exact invariant of the
    frictionless linear model)."""
    q, _ = penetration(p, mesh_approach(p, u[0], u[1]))
    kin = 0.5 * (p[P_JW] * v[0] ** 2 + p[P_JG] * v[1] ** 2 + p[P_J4] * v[2] ** 2)
    shaft = 0.5 * p[P_KW] * (u[0] - theta1) ** 2 + 0.5 * p[P_KG] * (u[1] - u[2]) ** 2
    return kin + shaft + 0.5 * mesh_stiffness_y(p, u[0], u[1]) * q * q



@njit(cache=True, error_model='numpy')
def energy_series(p, theta, omega, theta1):
    """mechanical_energy along a trajectory (rows of theta, omega; theta1 per row)."""
    out = np.empty(theta.shape[0])
    for i in range(theta.shape[0]):
        out[i] = mechanical_energy(p, theta[i], omega[i], theta1[i])
    return out



def mass_matrix(p: np.ndarray) -> np.ndarray:
    """Diagonal inertia matrix diag(J_w, J_g, J_4) of Eq. 15."""
    return np.diag([p[P_JW], p[P_JG], p[P_J4]])



def linear_stiffness(p: np.ndarray, theta2: float = 0.0, theta3: float = 0.0) -> np.ndarray:
    """Frictionless stiffness matrix of Eq. 15 (motor end held) at a mesh position."""
    kY = mesh_stiffness_y(p, theta2, theta3)
    lw, rg, Kw, Kg = p[P_LW], p[P_RG], p[P_KW], p[P_KG]
    return np.array([[Kw + lw * lw * kY, -lw * rg * kY, 0.0],
                     [-lw * rg * kY, rg * rg * kY + Kg, -Kg],
                     [0.0, -Kg, Kg]])



def rigid_motion_vector(p: np.ndarray) -> np.ndarray:
    """u of the undeformed drive per unit theta1: (1, l_w/r_g, l_w/r_g)."""
    return np.array([1.0, p[P_OUTPUT_PER_INPUT], p[P_OUTPUT_PER_INPUT]])



def forces(p: np.ndarray, u: ArrayLike, v: ArrayLike,
           theta1: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, float]]:
    """Python convenience wrapper: returns (Q, dQ/du, dQ/dv, aux dict)."""
    Q, dQdu, dQdv, aux = np.zeros(3), np.zeros((3, 3)), np.zeros((3, 3)), np.zeros(N_AUX)
    generalized_forces(p, np.asarray(u, float), np.asarray(v, float), float(theta1),
                       Q, dQdu, dQdv, aux)
    names = ('W_n', 'mu', 'cwkw', 'cgkg', 'v_s', 'F_X', 'F_Y', 'q')
    return Q, dQdu, dQdv, dict(zip(names, aux))
