# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Equations of motion of the worm-gear drive (Chung & Shaw 2007, Eqs. 1-18), written once.

Degrees of freedom ``u = (theta2, theta3, theta4)``: worm body, worm-gear body, flywheel
(antenna).  ``theta1`` is the commanded worm-shaft angle (input).  The compiled functions
below are the single source of truth for the physics; the integrator, the ROS node, the
CLI, the studies and the compensation all call them.

Mesh (Eqs. 7-10, derived from Fig. 3; the printed form is kept):

    q      = l_w*theta2 - r_g*theta3                      mesh approach along Y    (Eq. 8)
    A      = cos(phi_n) sin(lam) + mu cos(lam)             F_X / W_n                (Eq. 1)
    B      = cos(phi_n) cos(lam) - mu sin(lam)             F_Y / W_n                (Eq. 2)
    KGWS   = 1/c_w k_w + 1/c_g k_g + A sin(lam)/k_gs + B cos(lam)/k_ws             (Eq. 10)
    W_n    = q cos(lam) / KGWS                                                      (Eq. 9)
    J_w th2'' = -r_w A W_n - K_w (th2 - th1)                                       (Eq. 11)
    J_g th3'' =  r_g B W_n - K_g (th3 - th4)                                       (Eq. 13)
    J_4 th4'' = -K_g (th4 - th3) [- c_out th4' - T_load]                            (Eq. 6)

cos(pi/2 - lam) = sin(lam) and sin(pi/2 - lam) = cos(lam) are written out.  With
tan(lam) = l_w / r_w the frictionless mesh force is conservative (r_w A = l_w B/cos..., the
stiffness matrix is symmetric) with potential 0.5 k_Y q^2, k_Y = cos(phi_n) cos^2(lam)/KGWS0.

Friction (Eq. 18 in SI, MODEL-NOTES): sliding speed along the thread
v_s = r_w cos(lam) th2' + r_g sin(lam) th3'; mu(v) = mu_k + drop*exp(-sqrt(|v|/v_S));
the effective signed coefficient is mu_eff = mu(|v_s|) tanh(v_s/v_eps) sgn(q), so that
W_f = mu |W_n| sgn(v_s) always opposes sliding; ``direction: paper`` keeps mu_eff = mu(|v_s|).

Mesh stiffness (Eqs. 16-17): two tooth pairs one axial pitch apart share the load.  The
contact position x is in degrees of worm-thread phase: x_i = x0 + s, x_j = x_i + 360 with
s = mesh phase in [0, 360) deg, phase = (theta2 + z_g theta3)/2 + phase_offset, so x moves
through one mesh cycle per axial pitch (one worm revolution, one gear tooth).  x0 is
calibrated so that the cycle mean equals the linear values (3.5e8 / 2.5e8 N/m).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .params import Config, derive

# ---- packed parameter vector layout (compile-time constants for numba) -------------------
P_JW, P_JG, P_J4 = 0, 1, 2
P_KW, P_KG, P_KWS, P_KGS = 3, 4, 5, 6
P_LW, P_RW, P_RG, P_SINL, P_COSL, P_COSPHI = 7, 8, 9, 10, 11, 12
P_MESH_LINEAR, P_CWKW_LIN, P_CGKG_LIN = 13, 14, 15
P_WORM_SCALE, P_WORM_B, P_WORM_X0 = 16, 17, 18      # M e^{a_w} * multiplier, b_w, x0_w
P_GEAR_SCALE, P_GEAR_B, P_GEAR_X0 = 19, 20, 21
P_ZG, P_PHASE0 = 22, 23
P_FRIC_MODEL, P_FRIC_PAPER, P_MU_CONST, P_MU_K, P_MU_DROP, P_VS, P_VEPS = (
    24, 25, 26, 27, 28, 29, 30)
P_FRIC_IN_COMPLIANCE = 31
P_COUT, P_TLOAD = 32, 33
P_BETA, P_GAMMA, P_RTOL, P_ATOL, P_MAXIT, P_MAXSUB = 34, 35, 36, 37, 38, 39
P_RIGID3 = 40                                        # theta3/theta1 of the rigid motion
N_PARAMS = 41

FRICTION_OFF, FRICTION_CONSTANT, FRICTION_STRIBECK = 0, 1, 2

# aux outputs of generalized_forces
AUX_WN, AUX_MU, AUX_CWKW, AUX_CGKG, AUX_VS, AUX_FX, AUX_FY, AUX_Q = range(8)
N_AUX = 8

DEG_PER_RAD = 180.0 / math.pi
TWO_PI = 2.0 * math.pi


def _calibrated_origin(scale: float, b: float, target_mean: float) -> float:
    """x0 [deg] such that mean over s in [0,360) of scale*(e^{b(x0+s)} + e^{b(x0+s+360)})
    equals ``target_mean`` (the linear tooth stiffness)."""
    if b == 0.0:
        return 0.0
    e = math.exp(360.0 * b)
    cycle_mean_factor = (1.0 + e) * (e - 1.0) / (360.0 * b)
    return math.log(target_mean / (scale * cycle_mean_factor)) / b


def pack_parameters(cfg: Config) -> np.ndarray:
    """Flatten a Config (plus derived quantities) into the kernel's parameter vector."""
    d = derive(cfg)
    g, mesh, fr, integ = cfg.geometry, cfg.mesh, cfg.friction, cfg.integrator
    p = np.zeros(N_PARAMS)
    p[P_JW], p[P_JG], p[P_J4] = d.J_w, d.J_g, d.J_4
    p[P_KW], p[P_KG], p[P_KWS], p[P_KGS] = d.K_w, d.K_g, d.k_ws, d.k_gs
    p[P_LW], p[P_RW], p[P_RG] = d.l_w, g.worm_pitch_radius, g.gear_pitch_radius
    p[P_SINL], p[P_COSL] = math.sin(d.lead_angle), math.cos(d.lead_angle)
    p[P_COSPHI] = math.cos(g.pressure_angle)
    p[P_MESH_LINEAR] = 1.0 if mesh.stiffness_model == 'linear' else 0.0
    p[P_CWKW_LIN] = mesh.worm_tooth_stiffness_linear * mesh.worm_tooth_stiffness_multiplier
    p[P_CGKG_LIN] = mesh.gear_tooth_stiffness_linear * mesh.gear_tooth_stiffness_multiplier
    worm_raw = g.module * math.exp(mesh.worm_fit_a)          # Eq. 16: M e^{a_w}
    gear_raw = g.module * math.exp(mesh.gear_fit_a)          # Eq. 17: M e^{a_g}
    if mesh.calibrate_to_linear_mean:
        x0w = _calibrated_origin(worm_raw, mesh.worm_fit_b, mesh.worm_tooth_stiffness_linear)
        x0g = _calibrated_origin(gear_raw, mesh.gear_fit_b, mesh.gear_tooth_stiffness_linear)
    else:
        x0w = x0g = 0.0
    p[P_WORM_SCALE] = worm_raw * mesh.worm_tooth_stiffness_multiplier
    p[P_GEAR_SCALE] = gear_raw * mesh.gear_tooth_stiffness_multiplier
    p[P_WORM_B], p[P_WORM_X0] = mesh.worm_fit_b, x0w
    p[P_GEAR_B], p[P_GEAR_X0] = mesh.gear_fit_b, x0g
    p[P_ZG], p[P_PHASE0] = d.gear_teeth, mesh.phase_offset
    p[P_FRIC_MODEL] = {'off': FRICTION_OFF, 'constant': FRICTION_CONSTANT,
                       'stribeck': FRICTION_STRIBECK}[fr.model]
    p[P_FRIC_PAPER] = 1.0 if fr.direction == 'paper' else 0.0
    p[P_MU_CONST], p[P_MU_K], p[P_MU_DROP] = (fr.constant_coefficient, fr.mu_kinetic,
                                              fr.mu_stribeck_drop)
    p[P_VS], p[P_VEPS] = fr.stribeck_velocity, fr.regularization_velocity
    p[P_FRIC_IN_COMPLIANCE] = 1.0 if fr.in_compliance else 0.0
    p[P_COUT], p[P_TLOAD] = cfg.load.output_viscous_coefficient, cfg.load.output_torque
    p[P_BETA], p[P_GAMMA] = integ.newmark_beta, integ.newmark_gamma
    p[P_RTOL], p[P_ATOL] = integ.newton_rtol, integ.newton_atol
    p[P_MAXIT], p[P_MAXSUB] = integ.newton_max_iterations, integ.max_subdivision_level
    p[P_RIGID3] = d.l_w / g.gear_pitch_radius
    return p


# ---- Eqs. 16-17: tooth stiffness over the mesh cycle ----------------------------------------
@njit(cache=True)
def tooth_stiffness(p, theta2, theta3):
    """Return (c_w k_w, c_g k_g, d(c_w k_w)/d(phase), d(c_g k_g)/d(phase)); phase in rad."""
    if p[P_MESH_LINEAR] != 0.0:
        return p[P_CWKW_LIN], p[P_CGKG_LIN], 0.0, 0.0
    phase = 0.5 * (theta2 + p[P_ZG] * theta3) + p[P_PHASE0]
    s_deg = (phase - TWO_PI * math.floor(phase / TWO_PI)) * DEG_PER_RAD   # in [0, 360)
    bw, bg = p[P_WORM_B], p[P_GEAR_B]
    ew = math.exp(bw * (p[P_WORM_X0] + s_deg))
    eg = math.exp(bg * (p[P_GEAR_X0] + s_deg))
    # second pair one axial pitch (360 deg) further: e^{b(x+360)} = e^{bx} e^{360 b}
    cwkw = p[P_WORM_SCALE] * ew * (1.0 + math.exp(360.0 * bw))                    # Eq. 16
    cgkg = p[P_GEAR_SCALE] * eg * (1.0 + math.exp(360.0 * bg))                    # Eq. 17
    return cwkw, cgkg, cwkw * bw * DEG_PER_RAD, cgkg * bg * DEG_PER_RAD


# ---- Eq. 18: friction coefficient and its direction ---------------------------------------
@njit(cache=True)
def friction_coefficient(p, v_s, q):
    """Return (mu_eff, d mu_eff / d v_s): signed coefficient entering Eqs. 1-2, 10, 12, 14."""
    model = p[P_FRIC_MODEL]
    if model == FRICTION_OFF:
        return 0.0, 0.0
    av = abs(v_s)
    if model == FRICTION_CONSTANT:
        mu, dmu = p[P_MU_CONST], 0.0
    else:
        ex = math.exp(-math.sqrt(av / p[P_VS]))
        mu = p[P_MU_K] + p[P_MU_DROP] * ex
        dmu = 0.0  # d mu / d|v|; singular at 0, handled below
        if av > 0.0:
            dmu = -p[P_MU_DROP] * ex / (2.0 * math.sqrt(av * p[P_VS]))
    if p[P_FRIC_PAPER] != 0.0:
        # fixed sign as printed; derivative floored to stay finite at rest
        if model == FRICTION_STRIBECK:
            avf = max(av, 1e-9)
            dmu = -p[P_MU_DROP] * math.exp(-math.sqrt(avf / p[P_VS])) \
                / (2.0 * math.sqrt(avf * p[P_VS]))
        sgn_v = 1.0 if v_s >= 0.0 else -1.0
        return mu, dmu * sgn_v
    sq = 1.0 if q >= 0.0 else -1.0       # flank in contact: friction ~ |W_n|
    t = math.tanh(v_s / p[P_VEPS])
    # d/dv [mu(|v|) tanh(v/eps)] = mu'(|v|) sgn(v) t + mu (1 - t^2)/eps ; sgn(v) t = |t|
    d = dmu * abs(t) + mu * (1.0 - t * t) / p[P_VEPS]
    return sq * mu * t, sq * d


# ---- Eqs. 4-15: generalized forces with their analytic Jacobians ---------------------------
@njit(cache=True)
def generalized_forces(p, u, v, theta1, Q, dQdu, dQdv, aux):
    """Fill Q (= M u'' without damping), dQ/du, dQ/dv and aux for state (u, v) at theta1."""
    lw, rw, rg = p[P_LW], p[P_RW], p[P_RG]
    sl, cl, cphi = p[P_SINL], p[P_COSL], p[P_COSPHI]
    th2, th3, th4 = u[0], u[1], u[2]
    q = lw * th2 - rg * th3                                          # Eq. 8 right side
    v_s = rw * cl * v[0] + rg * sl * v[1]                            # sliding speed
    mu, dmu_dvs = friction_coefficient(p, v_s, q)
    cwkw, cgkg, dcw, dcg = tooth_stiffness(p, th2, th3)
    A = cphi * sl + mu * cl                                          # F_X / W_n, Eq. 1
    B = cphi * cl - mu * sl                                          # F_Y / W_n, Eq. 2
    if p[P_FRIC_IN_COMPLIANCE] != 0.0:
        Ac, Bc, dK_dmu = A, B, cl * sl / p[P_KGS] - sl * cl / p[P_KWS]
    else:
        Ac, Bc, dK_dmu = cphi * sl, cphi * cl, 0.0
    kgws = 1.0 / cwkw + 1.0 / cgkg + Ac * sl / p[P_KGS] + Bc * cl / p[P_KWS]   # Eq. 10
    Wn = q * cl / kgws                                               # Eq. 9
    # derivatives of W_n
    dWn_dq = cl / kgws
    dWn_dK = -Wn / kgws
    dK_dphase = -dcw / (cwkw * cwkw) - dcg / (cgkg * cgkg)
    dWn_dth2 = dWn_dq * lw + dWn_dK * dK_dphase * 0.5
    dWn_dth3 = -dWn_dq * rg + dWn_dK * dK_dphase * 0.5 * p[P_ZG]
    dWn_dmu = dWn_dK * dK_dmu
    # Eqs. 11, 13, 6
    Kw, Kg = p[P_KW], p[P_KG]
    Q[0] = -rw * A * Wn - Kw * (th2 - theta1)
    Q[1] = rg * B * Wn - Kg * (th3 - th4)
    Q[2] = -Kg * (th4 - th3) - p[P_COUT] * v[2] - p[P_TLOAD]
    dQdu[0, 0] = -rw * A * dWn_dth2 - Kw
    dQdu[0, 1] = -rw * A * dWn_dth3
    dQdu[0, 2] = 0.0
    dQdu[1, 0] = rg * B * dWn_dth2
    dQdu[1, 1] = rg * B * dWn_dth3 - Kg
    dQdu[1, 2] = Kg
    dQdu[2, 0] = 0.0
    dQdu[2, 1] = Kg
    dQdu[2, 2] = -Kg
    dQ0_dmu = -rw * (cl * Wn + A * dWn_dmu)
    dQ1_dmu = rg * (-sl * Wn + B * dWn_dmu)
    dmu_dw2 = dmu_dvs * rw * cl
    dmu_dw3 = dmu_dvs * rg * sl
    dQdv[0, 0] = dQ0_dmu * dmu_dw2
    dQdv[0, 1] = dQ0_dmu * dmu_dw3
    dQdv[0, 2] = 0.0
    dQdv[1, 0] = dQ1_dmu * dmu_dw2
    dQdv[1, 1] = dQ1_dmu * dmu_dw3
    dQdv[1, 2] = 0.0
    dQdv[2, 0] = 0.0
    dQdv[2, 1] = 0.0
    dQdv[2, 2] = -p[P_COUT]
    aux[AUX_WN] = Wn
    aux[AUX_MU] = mu
    aux[AUX_CWKW] = cwkw
    aux[AUX_CGKG] = cgkg
    aux[AUX_VS] = v_s
    aux[AUX_FX] = A * Wn
    aux[AUX_FY] = B * Wn
    aux[AUX_Q] = q


@njit(cache=True)
def mesh_stiffness_y(p, theta2, theta3):
    """Frictionless mesh stiffness along Y, k_Y = cos(phi) cos^2(lam) / KGWS0 [N/m]."""
    sl, cl, cphi = p[P_SINL], p[P_COSL], p[P_COSPHI]
    cwkw, cgkg, _, _ = tooth_stiffness(p, theta2, theta3)
    kgws0 = 1.0 / cwkw + 1.0 / cgkg + cphi * sl * sl / p[P_KGS] + cphi * cl * cl / p[P_KWS]
    return cphi * cl * cl / kgws0


@njit(cache=True)
def mechanical_energy(p, u, v, theta1):
    """Kinetic + shaft torsion + mesh energy 0.5 k_Y q^2 [J] (exact invariant of the
    frictionless linear model)."""
    q = p[P_LW] * u[0] - p[P_RG] * u[1]
    kin = 0.5 * (p[P_JW] * v[0] ** 2 + p[P_JG] * v[1] ** 2 + p[P_J4] * v[2] ** 2)
    shaft = 0.5 * p[P_KW] * (u[0] - theta1) ** 2 + 0.5 * p[P_KG] * (u[1] - u[2]) ** 2
    return kin + shaft + 0.5 * mesh_stiffness_y(p, u[0], u[1]) * q * q


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
    return np.array([1.0, p[P_RIGID3], p[P_RIGID3]])


def forces(p: np.ndarray, u, v, theta1: float):
    """Python convenience wrapper: returns (Q, dQ/du, dQ/dv, aux dict)."""
    Q, dQdu, dQdv, aux = np.zeros(3), np.zeros((3, 3)), np.zeros((3, 3)), np.zeros(N_AUX)
    generalized_forces(p, np.asarray(u, float), np.asarray(v, float), float(theta1),
                       Q, dQdu, dQdv, aux)
    names = ('W_n', 'mu', 'cwkw', 'cgkg', 'v_s', 'F_X', 'F_Y', 'q')
    return Q, dQdu, dQdv, dict(zip(names, aux))
