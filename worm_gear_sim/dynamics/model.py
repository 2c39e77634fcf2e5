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

Friction (Eq. 18 in SI, docs/model-notes.md): sliding speed along the thread
v_s = r_w cos(lam) th2' + r_g sin(lam) th3'; mu(v) = mu_k + drop*exp(-sqrt(|v|/v_S));
the effective signed coefficient is mu_eff = mu(|v_s|) tanh(v_s/v_eps) sgn(q), so that
W_f = mu |W_n| sgn(v_s) always opposes sliding; ``direction: paper`` keeps mu_eff = mu(|v_s|).

Mesh stiffness (Eqs. 16-17): two tooth pairs one axial pitch apart share the load.  The
contact position x is in degrees of worm-thread phase, x_j = x_i + 360, and moves through one
mesh cycle per axial pitch (one worm revolution, one gear tooth): phase s = (theta2 + z_g
theta3)/2 + phase_offset.  The paper does not define the mapping x(s).  Default (``cosine``):
x_i = x0 + 180 (1 - cos s): the contact runs out along the fitted range [x0, x0 + 360] and
back, so the stiffness is periodic, smooth and has no jump at the tooth hand-over.  With
``sawtooth`` (x_i = x0 + s) the sum of two exponentials jumps by e^{360 b} (27 % worm,
18 % gear) once per worm revolution.  x0 is calibrated so that the cycle mean equals the
linear values (3.5e8 / 2.5e8 N/m).
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit
from numpy.typing import ArrayLike

from ..derived import Derived, derive
from ..schema import MAX_ERROR_ORDERS, Parameters
from .periodic import harmonic_sum, table_lookup, with_table

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
P_OUTPUT_PER_INPUT = 40          # l_w / r_g: theta3, theta4 per theta1 in rigid motion
P_INV_KGS, P_INV_KWS, P_INV_VEPS, P_LIN_COMPLIANCE = 41, 42, 43, 44   # precomputed
P_INV_SQRT_VS = 45
P_MESH_COSINE = 46                                   # contact mapping: 1 cosine, 0 sawtooth
P_FRIC_SET_VALUED, P_MU_STATIC = 47, 48              # set-valued law; mu(0), the cone's edge
P_VCUSP = 49                                         # Stribeck cusp rounding speed
P_JW_STEP = 50                                       # worm inertia in the Newmark step
P_GAP_HALF, P_INIT_FLANK = 51, 52     # half the play along q, r_g b / 2 [m]; +1/-1/0 flank
# periodic transmission error e(theta2, theta3) [rad at the gear]: orders of the worm and of
# the gear harmonics in use, then [s1, c1, s2, c2, ...] of each (MAX_ERROR_ORDERS pairs)
P_PE_NW, P_PE_NG = 53, 54
P_PE_WORM = 55
P_PE_GEAR = P_PE_WORM + 2 * MAX_ERROR_ORDERS
# 1: the cosine mapping's tooth compliance tabulated at the vector's end (periodic.with_table:
# 1024 intervals, kept within 1e-12 of Eq. 7, its slope (Jacobian only) within 1e-9)
P_TEETH_TABLE = P_PE_GEAR + 2 * MAX_ERROR_ORDERS
N_PARAMS = P_TEETH_TABLE + 1

# layout of the flat output of mesh_eval: Q (3), dQ/du (3x3 row-major), dQ/dv (3x3), aux
O_Q, O_DQDU, O_DQDV, O_AUX = 0, 3, 12, 21
N_OUT = 21 + 8

FRICTION_OFF, FRICTION_CONSTANT, FRICTION_STRIBECK = 0, 1, 2

# aux outputs of generalized_forces
AUX_WN, AUX_MU, AUX_CWKW, AUX_CGKG, AUX_VS, AUX_FX, AUX_FY, AUX_Q = range(8)
N_AUX = 8

DEG_PER_RAD = 180.0 / math.pi
MODULE_OF_FIT = 2.0     # Eqs. 16-17 and the linear tooth stiffnesses are the paper's M2
TWO_PI = 2.0 * math.pi


@functools.lru_cache(maxsize=64)    # numpy's I0 costs more than the rest of a model's build
def _calibrated_origin(scale: float, b: float, target_mean: float,
                       cosine: bool = True) -> float:
    """x0 [deg] such that the mean over a mesh cycle of scale*(e^{b x} + e^{b(x+360)})
    equals ``target_mean`` (the linear tooth stiffness).  Sawtooth mapping x = x0 + s,
    s in [0, 360): mean factor (1 + e^{360b}) (e^{360b} - 1)/(360 b) e^{b x0}; cosine mapping
    x = x0 + 180 (1 - cos s): mean factor (1 + e^{360b}) e^{b(x0 + 180)} I0(180 b)."""
    if b == 0.0:
        return 0.0
    e = math.exp(360.0 * b)
    if cosine:
        factor = (1.0 + e) * float(np.i0(180.0 * b))
        return math.log(target_mean / (scale * factor)) / b - 180.0
    cycle_mean_factor = (1.0 + e) * (e - 1.0) / (360.0 * b)
    return math.log(target_mean / (scale * cycle_mean_factor)) / b


def pack_parameters(cfg: Parameters, derived: Derived | None = None) -> np.ndarray:
    """Flatten a Config (plus its derived quantities ``derived``, computed if not given)
    into the kernel's parameter vector (use :class:`DriveModel`: it does this once)."""
    d = derive(cfg) if derived is None else derived
    g, mesh, fr, integ = cfg.geometry, cfg.mesh, cfg.friction, cfg.integrator
    p = np.zeros(N_PARAMS)
    p[P_JW], p[P_JG], p[P_J4] = d.J_w, d.J_g, d.J_4
    p[P_KW], p[P_KG], p[P_KWS], p[P_KGS] = d.K_w, d.K_g, d.k_ws, d.k_gs
    p[P_LW], p[P_RW], p[P_RG] = d.l_w, g.worm_pitch_radius, g.gear_pitch_radius
    p[P_SINL], p[P_COSL] = math.sin(d.lead_angle), math.cos(d.lead_angle)
    p[P_COSPHI] = math.cos(g.pressure_angle)
    p[P_MESH_LINEAR] = 1.0 if mesh.stiffness_model == 'linear' else 0.0
    # Tooth stiffness scales with the module M (the M factor of Eqs. 16-17); the linear
    # values and the calibration of the contact-position origin refer to the paper's M2.
    m_scale = g.module / MODULE_OF_FIT
    lin_w, lin_g = mesh.worm_tooth_stiffness_linear, mesh.gear_tooth_stiffness_linear
    p[P_CWKW_LIN] = lin_w * mesh.worm_tooth_stiffness_multiplier * m_scale
    p[P_CGKG_LIN] = lin_g * mesh.gear_tooth_stiffness_multiplier * m_scale
    worm_raw = g.module * math.exp(mesh.worm_fit_a)          # Eq. 16: M e^{a_w}
    gear_raw = g.module * math.exp(mesh.gear_fit_a)          # Eq. 17: M e^{a_g}
    if mesh.calibrate_to_linear_mean:
        fit_w = MODULE_OF_FIT * math.exp(mesh.worm_fit_a)
        fit_g = MODULE_OF_FIT * math.exp(mesh.gear_fit_a)
        cosine = mesh.contact_mapping == 'cosine'
        x0w = _calibrated_origin(fit_w, mesh.worm_fit_b, lin_w, cosine)
        x0g = _calibrated_origin(fit_g, mesh.gear_fit_b, lin_g, cosine)
    else:
        x0w = x0g = 0.0
    # second pair one axial pitch (360 deg) further on: e^{b(x+360)} = e^{bx} e^{360 b}
    p[P_WORM_SCALE] = worm_raw * mesh.worm_tooth_stiffness_multiplier \
        * (1.0 + math.exp(360.0 * mesh.worm_fit_b))
    p[P_GEAR_SCALE] = gear_raw * mesh.gear_tooth_stiffness_multiplier \
        * (1.0 + math.exp(360.0 * mesh.gear_fit_b))
    p[P_WORM_B], p[P_WORM_X0] = mesh.worm_fit_b, x0w
    p[P_GEAR_B], p[P_GEAR_X0] = mesh.gear_fit_b, x0g
    p[P_ZG], p[P_PHASE0] = d.gear_teeth, mesh.phase_offset
    p[P_MESH_COSINE] = 1.0 if mesh.contact_mapping == 'cosine' else 0.0
    p[P_FRIC_MODEL] = {'off': FRICTION_OFF, 'constant': FRICTION_CONSTANT,
                       'stribeck': FRICTION_STRIBECK}[fr.model]
    p[P_FRIC_PAPER] = 1.0 if fr.direction == 'paper' else 0.0
    p[P_FRIC_SET_VALUED] = 1.0 if (fr.direction == 'set_valued' and fr.model != 'off') else 0.0
    p[P_MU_STATIC] = {'off': 0.0, 'constant': fr.constant_coefficient,
                      'stribeck': fr.mu_kinetic + fr.mu_stribeck_drop}[fr.model]
    p[P_VCUSP] = fr.cusp_velocity
    p[P_MU_CONST], p[P_MU_K], p[P_MU_DROP] = (fr.constant_coefficient, fr.mu_kinetic,
                                              fr.mu_stribeck_drop)
    p[P_VS], p[P_VEPS] = fr.stribeck_velocity, fr.regularization_velocity
    p[P_FRIC_IN_COMPLIANCE] = 1.0 if fr.in_compliance else 0.0
    p[P_COUT], p[P_TLOAD] = cfg.load.output_viscous_coefficient, cfg.load.output_torque
    p[P_BETA], p[P_GAMMA] = integ.newmark_beta, integ.newmark_gamma
    p[P_RTOL], p[P_ATOL] = integ.newton_rtol, integ.newton_atol
    p[P_MAXIT], p[P_MAXSUB] = integ.newton_max_iterations, integ.max_subdivision_level
    p[P_OUTPUT_PER_INPUT] = d.output_per_input
    p[P_INV_KGS], p[P_INV_KWS] = 1.0 / d.k_gs, 1.0 / d.k_ws
    p[P_INV_VEPS] = 1.0 / fr.regularization_velocity
    p[P_INV_SQRT_VS] = 1.0 / math.sqrt(fr.stribeck_velocity)
    p[P_LIN_COMPLIANCE] = 1.0 / p[P_CWKW_LIN] + 1.0 / p[P_CGKG_LIN]
    p[P_GAP_HALF] = 0.5 * g.gear_pitch_radius * mesh.backlash
    p[P_INIT_FLANK] = {'drive': 1.0, 'coast': -1.0, 'center': 0.0}[mesh.initial_flank]
    for n_at, at, coeffs in ((P_PE_NW, P_PE_WORM, mesh.worm_error_harmonics),
                             (P_PE_NG, P_PE_GEAR, mesh.gear_error_harmonics)):
        p[n_at] = len(coeffs) // 2
        p[at:at + len(coeffs)] = coeffs
    p[P_JW_STEP] = p[P_JW]
    if integ.worm_frequency_matching:
        p[P_JW_STEP] = p[P_JW] * worm_inertia_factor(p, integ.time_step)
    return _with_teeth_table(p)


@njit(cache=True, error_model='numpy')
def _teeth_exact(p, phase):
    """Eq. 7's 1/c_w k_w + 1/c_g k_g and its slope in the phase (Eqs. 16-17) at phases."""
    val, slope = np.empty(phase.shape[0]), np.empty(phase.shape[0])
    for i in range(phase.shape[0]):
        cw, cg, dcw, dcg = tooth_stiffness(p, 2.0 * (phase[i] - p[P_PHASE0]), 0.0)
        val[i] = 1.0 / cw + 1.0 / cg
        slope[i] = -dcw / (cw * cw) - dcg / (cg * cg)
    return val, slope


def _with_teeth_table(p: np.ndarray) -> np.ndarray:
    """``p`` with Eq. 7's 1/c_w k_w + 1/c_g k_g of the cosine mapping tabulated over the mesh
    cycle (the force evaluation interpolates instead of two exponentials and a sine/cosine
    pair) if within its tolerances of Eqs. 16-17 (otherwise they are evaluated directly)."""
    if p[P_MESH_LINEAR] != 0.0 or p[P_MESH_COSINE] == 0.0:
        return p
    key = p[np.r_[P_MESH_LINEAR:P_PHASE0 + 1, P_MESH_COSINE]].tobytes()  # all Eq. 7 reads
    q = with_table(p, lambda phase: _teeth_exact(p, phase), 1024, 1e-12, 1e-9, key)
    if q is not None:
        q[P_TEETH_TABLE] = 1.0
    return p if q is None else q


def worm_frequency(p: np.ndarray) -> float:
    """Highest linearised natural frequency [rad/s] (frictionless, at the mesh stiffness of
    theta = 0): the worm on its shaft, 8.6 kHz for Table 1."""
    import scipy.linalg as sla
    w2 = sla.eigvals(linear_stiffness(p), mass_matrix(p))
    w2 = w2[np.isfinite(w2) & (np.abs(w2) < 1e300)].real
    return float(np.sqrt(max(w2.max(), 0.0)))


def worm_inertia_factor(p: np.ndarray, dt: float) -> float:
    """(x / tan x)^2 with x = omega_w dt / 2: the average-acceleration rule integrates a mode
    of frequency omega at 2 atan(omega dt / 2) / dt; this factor on the worm inertia in the
    step's inertia term gives the worm mode its exact frequency (no period elongation).
    1 when the mode is too coarse to correct (x > 1.2, dt > 0.38 period)."""
    x = 0.5 * worm_frequency(p) * dt
    if not 0.0 < x <= 1.2:
        return 1.0
    return (x / math.tan(x)) ** 2


def holding_friction(p: np.ndarray, sliding_speed: float = 0.0) -> float:
    """The friction coefficient the mesh offers at a sliding speed [m/s]: mu(0), the edge
    of the stick cone, at rest; the law's mu(|v_s|) when sliding (Eq. 18 or constant; 0
    with friction off)."""
    model = p[P_FRIC_MODEL]
    if model == FRICTION_OFF:
        return 0.0
    if model == FRICTION_CONSTANT:
        return float(p[P_MU_CONST])
    return float(p[P_MU_K] + p[P_MU_DROP] * math.exp(-math.sqrt(abs(sliding_speed) / p[P_VS])))


def backdrive_friction(p: np.ndarray) -> float:
    """The friction coefficient that just holds the worm when the motor lets go: with the
    worm shaft torque gone, Eq. 11 leaves Q2 = -r_w (cos(phi_n) sin(lam) + mu cos(lam)) W_n,
    zero only for |mu| = cos(phi_n) tan(lam), whatever the load (W_n)."""
    return float(p[P_COSPHI] * p[P_SINL] / p[P_COSL])


def backdrive_margin(p: np.ndarray, sliding_speed: float = 0.0) -> float:
    """holding_friction / backdrive_friction: > 1 the worm holds the antenna if the motor
    lets go (self-locking), < 1 the load would turn the worm back.  With Coulomb friction
    it does not depend on the load's magnitude; it falls with the sliding speed on Eq. 18
    (mu_kinetic < mu(0))."""
    return holding_friction(p, sliding_speed) / backdrive_friction(p)


def sliding_speed_of(p: np.ndarray, omega: ArrayLike) -> float:
    """v_s = r_w cos(lam) theta2' + r_g sin(lam) theta3' [m/s] of a state's speeds."""
    w = np.asarray(omega, float)
    return float(p[P_RW] * p[P_COSL] * w[0] + p[P_RG] * p[P_SINL] * w[1])


def friction_is_set_valued(p: np.ndarray) -> bool:
    """True when the packed parameters select the set-valued (stick-slip) friction law."""
    return bool(p[P_FRIC_SET_VALUED] != 0.0)


class DriveModel:
    """The drive's model built once from a validated :class:`Config`: the Config, its
    derived quantities (:class:`Derived`: inertias, stiffnesses, l_w, ratio) and the packed
    parameter vector ``p`` of the compiled kernels, whose layout (``P_*``) is private to
    this module and the integrator.  Build it once and pass it to :class:`Simulator`,
    :class:`Compensator`, :func:`modes`, the studies and the real-time pipeline (each also
    accepts a Config and builds the model itself).  Treat it as immutable: ``p`` is shared
    by everyone holding the model (it stays a writeable array because the compiled kernels
    are specialised on that array type)."""

    __slots__ = ('config', 'derived', 'p', 'stepping_C', 'damping_C')

    def __init__(self, config: Parameters) -> None:
        self.config = config
        self.derived = derive(config)
        self.p = pack_parameters(config, self.derived)
        self.stepping_C: np.ndarray | None = None    # modal.stepping_damping's, kept
        self.damping_C: np.ndarray | None = None     # modal.damping_matrix's, kept

    @classmethod
    def of(cls, model: DriveModel | Parameters) -> DriveModel:
        """``model`` itself, or the model of a Config."""
        return model if isinstance(model, DriveModel) else cls(model)

    def __repr__(self) -> str:
        return f'DriveModel(output_per_input={self.output_per_input!r})'

    @property
    def output_per_input(self) -> float:
        """Rigid kinematic ratio theta4/theta1 = theta3/theta1 = l_w / r_g [rad/rad]."""
        return self.derived.output_per_input

    @property
    def rigid_motion(self) -> np.ndarray:
        """u = (theta2, theta3, theta4) of the undeformed drive per unit theta1."""
        return rigid_motion_vector(self.p)

    def backdrive_margin(self, omega: ArrayLike | None = None) -> float:
        """Back-drive margin (:func:`backdrive_margin`) at rest, or at the sliding speed of
        the speeds ``omega`` (theta2', theta3', theta4')."""
        v = 0.0 if omega is None else sliding_speed_of(self.p, omega)
        return backdrive_margin(self.p, v)

    @property
    def friction_is_set_valued(self) -> bool:
        """True with the set-valued (stick-slip) friction law."""
        return friction_is_set_valued(self.p)

    @property
    def contact_origins_deg(self) -> tuple[float, float]:
        """Calibrated origins x0 of the worm and gear contact positions of Eqs. 16-17 [deg]
        (cycle means equal to the linear tooth stiffnesses; see docs/model-notes.md)."""
        return float(self.p[P_WORM_X0]), float(self.p[P_GEAR_X0])

    @property
    def linear_tooth_stiffness(self) -> tuple[float, float]:
        """c_w k_w and c_g k_g of the linear mesh (multipliers and module applied) [N/m]."""
        return float(self.p[P_CWKW_LIN]), float(self.p[P_CGKG_LIN])

    @property
    def linear_mesh_compliance(self) -> float:
        """1/c_w k_w + 1/c_g k_g of the linear tooth stiffnesses (Eq. 10) [m/N]."""
        return float(self.p[P_LIN_COMPLIANCE])

    @property
    def mesh_is_linear(self) -> bool:
        """True when the tooth stiffnesses are constant (``mesh.stiffness_model: linear``)."""
        return bool(self.p[P_MESH_LINEAR] != 0.0)

    def worm_frequency(self) -> float:
        """Highest linearised natural frequency [rad/s] (see :func:`worm_frequency`)."""
        return worm_frequency(self.p)


# ---- the periodic transmission error and the mesh approach (Eq. 8 + r_g e) -----------------
def has_periodic_error(p: np.ndarray) -> bool:
    """The model has a periodic transmission error (``mesh.*_error_harmonics``)."""
    return bool(p[P_PE_NW] > 0.0 or p[P_PE_NG] > 0.0)


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


def has_play(p: np.ndarray) -> bool:
    """The mesh has a clearance (``mesh.backlash`` > 0)."""
    return bool(p[P_GAP_HALF] > 0.0)


def load_torque_of(p: np.ndarray) -> float:
    """The constant load torque on the antenna of a packed vector [N m]."""
    return float(p[P_TLOAD])


def with_load_torque(p: np.ndarray, torque: float) -> np.ndarray:
    """A copy of the packed vector with another constant load torque [N m]."""
    q = p.copy()
    q[P_TLOAD] = torque
    return q


def without_play(p: np.ndarray) -> np.ndarray:
    """A copy of the packed vector without the clearance."""
    q = p.copy()
    q[P_GAP_HALF] = 0.0
    return q


def rest_flank(p: np.ndarray) -> float:
    """The flank a drive at rest leans on: +1 drive (q > h), -1 coast (q < -h), 0 the
    centre of the play.  A load torque T_load > 0 turns the antenna back, so the worm holds
    it on the drive flank; T_load < 0 on the coast flank; without a load the flank of
    ``mesh.initial_flank``."""
    load = float(p[P_TLOAD])
    return 1.0 if load > 0.0 else -1.0 if load < 0.0 else float(p[P_INIT_FLANK])


def play_rest_shift(p: np.ndarray) -> tuple[np.ndarray, bool]:
    """Where a drive with play rests: (shift of (theta2, theta3, theta4) to subtract from
    the rest without play, loaded), on the flank of :func:`rest_flank` (no tooth force at
    the centre)."""
    load = float(p[P_TLOAD])
    d = rest_flank(p) * p[P_GAP_HALF] / p[P_RG]
    return np.array([0.0, d, d]), load != 0.0


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
