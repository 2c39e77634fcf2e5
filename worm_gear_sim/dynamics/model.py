# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The drive's model built once from a parameter set.

This module contains :class:`DriveModel` (the Config, its derived quantities and the
packed parameter vector of the compiled kernels), :func:`pack_parameters` (a Config to
that vector, laid out as :mod:`.layout` says) and the readers of the vector by name (the
play, the rest flank, the load, the back-drive margin).  The equations that read it are in
:mod:`.equations`.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit
from numpy.typing import ArrayLike

from ..schema.parameters import Parameters
from .derived import Derived, derive
from .equations import linear_stiffness, mass_matrix, rigid_motion_vector, tooth_stiffness
from .layout import (
    FRICTION_CONSTANT,
    FRICTION_OFF,
    FRICTION_STRIBECK,
    N_PARAMS,
    P_ATOL,
    P_BETA,
    P_CGKG_LIN,
    P_COSL,
    P_COSPHI,
    P_COUT,
    P_CWKW_LIN,
    P_FRIC_IN_COMPLIANCE,
    P_FRIC_MODEL,
    P_FRIC_PAPER,
    P_FRIC_SET_VALUED,
    P_GAMMA,
    P_GAP_HALF,
    P_GEAR_B,
    P_GEAR_SCALE,
    P_GEAR_X0,
    P_INIT_FLANK,
    P_INV_KGS,
    P_INV_KWS,
    P_INV_SQRT_VS,
    P_INV_VEPS,
    P_J4,
    P_JG,
    P_JW,
    P_JW_STEP,
    P_KG,
    P_KGS,
    P_KW,
    P_KWS,
    P_LIN_COMPLIANCE,
    P_LW,
    P_MAXIT,
    P_MAXSUB,
    P_MESH_COSINE,
    P_MESH_LINEAR,
    P_MU_CONST,
    P_MU_DROP,
    P_MU_K,
    P_MU_STATIC,
    P_OUTPUT_PER_INPUT,
    P_PE_GEAR,
    P_PE_NG,
    P_PE_NW,
    P_PE_WORM,
    P_PHASE0,
    P_RG,
    P_RTOL,
    P_RW,
    P_SINL,
    P_TEETH_TABLE,
    P_TLOAD,
    P_VCUSP,
    P_VEPS,
    P_VS,
    P_WORM_B,
    P_WORM_SCALE,
    P_WORM_X0,
    P_ZG,
)
from .periodic import with_table

MODULE_OF_FIT = 2.0     # Eqs. 16-17 and the linear tooth stiffnesses are the paper's M2



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
    """The drive's model built once from a validated :class:`Config`: the Config, its derived
    quantities (:class:`Derived`: inertias, stiffnesses, l_w, ratio) and the packed parameter
    vector ``p`` of the compiled kernels, whose layout (``P_*``, :mod:`.layout`) is private to
    the model's modules and the integrator.  Build it once and pass it to :class:`Simulator`,
    :class:`Compensator`, :func:`modes`, the studies and the real-time pipeline (each also
    accepts a Config and builds the model itself).  Treat it as immutable: ``p`` is shared by
    everyone holding the model (it stays a writeable array because the compiled kernels are
    specialised on that array type)."""

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
    def half_play(self) -> float:
        """Half the mesh play b / 2 [rad at the gear] (``mesh.backlash`` / 2): what the
        gear turns, the worm held, from the centre of the play to a flank; 0 without play."""
        return 0.5 * self.config.mesh.backlash

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



def has_periodic_error(p: np.ndarray) -> bool:
    """The model has a periodic transmission error (``mesh.*_error_harmonics``)."""
    return bool(p[P_PE_NW] > 0.0 or p[P_PE_NG] > 0.0)



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
