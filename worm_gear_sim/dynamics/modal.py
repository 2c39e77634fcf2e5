# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Static equilibrium, linearised modes and the structural damping matrix."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from .._support.stepwise import Steps, run_steps
from ..schema.parameters import Parameters
from ..schema.sections import ANGLE_LIMIT
from .equations import (
    forces,
    linear_stiffness,
    mass_matrix,
    rigid_motion_vector,
    transmission_error,
)
from .model import DriveModel, has_periodic_error, has_play, play_rest_shift, without_play

__all__ = ['static_equilibrium', 'ModalResult', 'modes', 'modes_steps', 'natural_modes',
           'damping_matrix',
           'open_mesh_damping_matrix', 'stepping_damping',
           'amplitude_time_step', 'step_resolution', 'step_resolution_warning',
           'StepResolutionWarning', 'STEPS_PER_PERIOD']


def static_equilibrium(model: DriveModel | np.ndarray, theta1: float,
                       u_guess: np.ndarray | None = None, tol: float = 1e-15,
                       max_iter: int = 50) -> np.ndarray:
    """Solve Q(u, 0, theta1) = 0 (at rest, so no sliding friction) by Newton's method;
    ``model``: a :class:`DriveModel` (or its packed vector)."""
    p = model.p if isinstance(model, DriveModel) else model
    if has_play(p) and (u_guess is None or not play_rest_shift(p)[1]):
        return _rest_with_play(p, theta1, tol, max_iter)    # unloaded: not a Newton problem
    u = rigid_motion_vector(p) * theta1 if u_guess is None else np.array(u_guess, float)
    v = np.zeros(3)
    for _ in range(max_iter):
        Q, dQdu, _, _ = forces(p, u, v, theta1)
        du = np.linalg.solve(dQdu, -Q)
        u = u + du
        if np.all(np.abs(du) <= tol * (1.0 + np.abs(u))):
            break
    return u


def _rest_with_play(p: np.ndarray, theta1: float, tol: float, max_iter: int) -> np.ndarray:
    """Rest with a mesh clearance: under a load torque on the loaded flank, without one on
    ``mesh.initial_flank`` (:func:`~worm_gear_sim.dynamics.model.play_rest_shift`)."""
    shift, loaded = play_rest_shift(p)
    if not loaded:
        u = rigid_motion_vector(p) * theta1 - shift
        if has_periodic_error(p):
            # the approach keeps its flank value: that of the rigid rest without the error
            _keep_approach(p, u, 0.0)
        return u
    # the drive without play at rest, shifted onto the loaded flank: the same region
    rest = static_equilibrium(without_play(p), theta1, None, tol, max_iter)
    u = rest - shift
    if has_periodic_error(p):
        # the gear error moves with the shifted gear: its change (~1e-10 m) can put a lightly
        # loaded drive back inside the clearance, where the stiffness is singular; the
        # approach is kept at the rest's plus the clearance (the error as at the rest)
        _keep_approach(p, u, transmission_error(p, rest[0], rest[1])[0])
    return static_equilibrium(p, theta1, u, tol, max_iter)


def _keep_approach(p: np.ndarray, u: np.ndarray, e_ref: float) -> None:
    """Shift the gear (and the antenna with it) in ``u`` by d such that the approach
    q = l_w theta2 - r_g theta3 + r_g e keeps the value it has with the error ``e_ref``:
    r_g e(theta2, theta3 + d) - r_g d = r_g e_ref, a contraction (|de/dtheta3| <= 0.1,
    schema), converged to round-off in a few iterations."""
    d = 0.0
    for _ in range(60):
        d_new = transmission_error(p, u[0], u[1] + d)[0] - e_ref
        if abs(d_new - d) <= 1e-16 * (1.0 + abs(u[1])):
            d = d_new
            break
        d = d_new
    u[1] += d
    u[2] += d


#: Damping ratios below this are the round-off of the state-space eigenvalues (an undamped
#: model gives +-1e-16, which printed as -1.4e-16): they are returned as 0.
ZETA_RESOLUTION = 1e-12


@dataclass(frozen=True)
class ModalResult:
    """Linearised modes at an operating point, lowest first."""

    frequencies_hz: np.ndarray      # damped natural frequencies (undamped if no damping)
    undamped_hz: np.ndarray         # sqrt of eig(K, M) / 2 pi
    damping_ratios: np.ndarray      # from the state-space eigenvalues (friction linearised)
    shapes: np.ndarray              # columns: (theta2, theta3, theta4), max |entry| = 1
    M: np.ndarray
    K: np.ndarray
    C: np.ndarray
    operating_point: np.ndarray     # u at which the model was linearised

    def table(self) -> str:
        lines = ['mode  f [Hz]      f_undamped [Hz]  zeta        shape (theta2, theta3, theta4)']
        for i in range(len(self.undamped_hz)):
            s = ', '.join(f'{x:+.4f}' for x in self.shapes[:, i])
            lines.append(f'{i + 1:<5d} {self.frequencies_hz[i]:<11.4f} '
                         f'{self.undamped_hz[i]:<16.4f} {self.damping_ratios[i]:<11.3e} ({s})')
        return '\n'.join(lines)


def modes(model: DriveModel | Parameters, theta1: float = 0.0, sliding_rate: float = 0.0,
          include_damping: bool = True) -> ModalResult:
    """Linearise Eq. 15 of ``model`` (a :class:`DriveModel` or a Config) about the static
    equilibrium at ``theta1`` (motor end held).

    ``sliding_rate`` is a worm speed [rad/s] of the operating point (steady slewing); the
    friction terms are linearised there (at rest, tanh makes friction act like viscous
    damping of slope mu/v_eps).
    """
    for name, x, limit in (('theta1', theta1, ANGLE_LIMIT), ('sliding_rate', sliding_rate,
                                                            1e6)):
        if not (math.isfinite(float(x)) and abs(float(x)) <= limit):
            raise ValueError(f'modes: {name} = {x!r} must be finite and within +-{limit:g}')
    return run_steps(modes_steps(model, theta1, sliding_rate, include_damping))


def modes_steps(model: DriveModel | Parameters, theta1: float = 0.0, sliding_rate: float = 0.0,
                include_damping: bool = True) -> Steps[ModalResult]:
    """:func:`modes` in steps (:mod:`worm_gear_sim._support.stepwise`), its arguments unchecked."""
    model = DriveModel.of(model)
    u, K, dQdv, M = _linearised(model.p, theta1, sliding_rate)
    C = damping_matrix(model) - dQdv if include_damping else np.zeros((3, 3))
    yield
    undamped, shapes = _undamped_modes(K, M)
    yield
    # state-space eigenvalues for damped frequencies and damping ratios
    damped, zeta = _damped_modes(M, K, C, len(undamped))
    return ModalResult(frequencies_hz=damped, undamped_hz=undamped, damping_ratios=zeta,
                       shapes=shapes, M=M, K=K, C=C, operating_point=u)


def _linearised(p: np.ndarray, theta1: float, sliding_rate: float
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(u, K, dQ/dv, M) of Eq. 15 linearised about the static equilibrium at theta1."""
    u = static_equilibrium(p, theta1)
    v = rigid_motion_vector(p) * sliding_rate
    _, dQdu, dQdv, _ = forces(p, u, v, theta1)
    return u, -dQdu, dQdv, mass_matrix(p)


def natural_modes(model: DriveModel | Parameters) -> tuple[np.ndarray, np.ndarray]:
    """(natural frequencies [Hz], shapes) of :func:`modes` at theta1 = 0, the same numbers,
    without its damped frequencies and damping ratios (the usability check's)."""
    model = DriveModel.of(model)
    _, K, _, M = _linearised(model.p, 0.0, 0.0)
    return _undamped_modes(K, M)


def _undamped_modes(K: np.ndarray, M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Natural frequencies [Hz] and shapes (columns, max |entry| = 1) of K phi = w^2 M phi,
    lowest first.  A massless degree of freedom (J_4 = 0 without flywheel) is a constraint,
    not a mode: its infinite eigenvalue is dropped, its entry of each shape follows the
    others through K."""
    w2, vecs = sla.eig(K, M)
    keep = np.isfinite(w2) & (np.abs(w2) < 1e300)
    w2, vecs = w2[keep].real, vecs[:, keep].real
    order = np.argsort(w2)
    w2, shapes = w2[order], vecs[:, order]
    undamped = np.sqrt(np.clip(w2, 0.0, None)) / (2 * np.pi)
    n = shapes.shape[1]
    shapes = shapes / np.max(np.abs(shapes), axis=0) * np.sign(shapes[np.argmax(
        np.abs(shapes), axis=0), np.arange(n)])
    return undamped, shapes


def _damped_modes(M: np.ndarray, K: np.ndarray, C: np.ndarray,
                  n_modes: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Damped frequency [Hz] and damping ratio of each mode, lowest natural frequency first.

    The finite eigenvalues of the first-order pencil ([0 I; -K -C], [I 0; 0 M]) are grouped
    into modes: a complex-conjugate pair is an under-damped mode (omega_n = |lambda|, zeta =
    -Re/|lambda|); the real eigenvalues, sorted, are paired into over-damped modes (omega_n =
    sqrt(l1 l2), zeta = -(l1 + l2) / (2 omega_n) >= 1, damped frequency 0).  A massless
    degree of freedom gives infinite eigenvalues, which are dropped."""
    n = M.shape[0]
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-K, -C]])
    B = np.block([[np.eye(n), np.zeros((n, n))], [np.zeros((n, n)), M]])
    lam = sla.eigvals(A, B)
    lam = lam[np.isfinite(lam) & (np.abs(lam) < 1e300)]
    scale = np.abs(lam).max() + 1.0
    is_real = np.abs(lam.imag) <= 1e-9 * scale
    modes_ = []
    for z in lam[(~is_real) & (lam.imag > 0)]:
        wn = abs(z)
        modes_.append((wn, abs(z.imag) / (2 * np.pi), -z.real / wn))
    reals = np.sort(lam[is_real].real)
    for i in range(0, len(reals) - 1, 2):
        l1, l2 = reals[i], reals[i + 1]
        wn = np.sqrt(abs(l1 * l2))
        modes_.append((wn, 0.0, -(l1 + l2) / (2 * wn) if wn > 0 else 1.0))
    modes_.sort(key=lambda m: m[0])
    modes_ = (modes_ + [(0.0, 0.0, 1.0)] * n_modes)[:n_modes]
    zeta = np.array([m[2] for m in modes_])
    zeta[np.abs(zeta) < ZETA_RESOLUTION] = 0.0
    return np.array([m[1] for m in modes_]), zeta


def damping_matrix(model: DriveModel | Parameters) -> np.ndarray:
    """Structural damping C of ``model`` (a :class:`DriveModel` or a Config; acts on
    velocities relative to the rigid kinematic motion): Rayleigh alpha M + beta K0 plus modal
    damping M Phi diag(2 zeta w) Phi^T M, with K0 the frictionless stiffness at the mean mesh
    stiffness."""
    model = DriveModel.of(model)
    if model.damping_C is not None:         # computed for this model already (its check's
        return model.damping_C.copy()       # modes, then the integrator's damping)
    p, d = model.p, model.config.damping
    M = mass_matrix(p)
    K0 = linear_stiffness(p)
    C = d.rayleigh_alpha * M + d.rayleigh_beta * K0
    zetas = np.asarray(d.modal_damping_ratios, float)
    if np.any(zetas > 0):
        f_hz, phi = _undamped_modes(K0, M)   # without flywheel: 2 modes, zetas[:2] used
        phi = phi / np.sqrt(np.einsum('ik,ij,jk->k', phi, M, phi))   # phi^T M phi = I
        w = 2 * np.pi * f_hz
        z = zetas[:len(w)]
        C = C + M @ phi @ np.diag(2.0 * z * w) @ phi.T @ M
    model.damping_C = np.ascontiguousarray(C)
    return model.damping_C.copy()


def open_mesh_damping_matrix(model: DriveModel | Parameters) -> np.ndarray:
    """The structural damping that still acts while the mesh play is open (no tooth
    contact): none of it through the mesh.  Rayleigh alpha on the worm only (against its
    motor end: the gear and antenna are then not tied to the kinematic motion of theta1),
    beta times the stiffness of the two shafts alone, and modal damping on the modes of
    the open drive (the worm on its shaft, the gear against the antenna; the free rigid
    motion of gear and antenna gets none), each with the ratio of the engaged mode it
    resembles most (largest mass-weighted overlap of the shapes)."""
    model = DriveModel.of(model)
    p, d = model.p, model.config.damping
    M = mass_matrix(p)
    K0 = linear_stiffness(p)
    Kw, Kg = model.derived.K_w, model.derived.K_g        # the shafts, without the mesh
    Ko = np.array([[Kw, 0.0, 0.0], [0.0, Kg, -Kg], [0.0, -Kg, Kg]])
    C = np.zeros((3, 3))
    C[0, 0] = d.rayleigh_alpha * M[0, 0]
    C = C + d.rayleigh_beta * Ko
    zetas = np.asarray(d.modal_damping_ratios, float)
    if np.any(zetas > 0):
        _, phi_e = _undamped_modes(K0, M)
        f_o, phi_o = _undamped_modes(Ko, M)
        for k in range(f_o.size):
            w = 2.0 * np.pi * f_o[k]
            norm = float(phi_o[:, k] @ M @ phi_o[:, k])
            if not (w > 0.0 and norm > 0.0):
                continue                      # the free rigid motion of gear and antenna
            overlap = np.abs(phi_o[:, k] @ M @ phi_e) / np.sqrt(
                norm * np.einsum('ik,ij,jk->k', phi_e, M, phi_e))
            j = int(np.argmax(overlap))
            z = float(zetas[j]) if j < zetas.size else 0.0
            mphi = M @ phi_o[:, k] / np.sqrt(norm)
            C = C + 2.0 * z * w * np.outer(mphi, mphi)
    return np.ascontiguousarray(C)


def stepping_damping(model: DriveModel | Parameters) -> np.ndarray:
    """The damping the integrator takes: :func:`damping_matrix` (3 x 3), stacked over
    :func:`open_mesh_damping_matrix` (6 x 3: rows 3..5 for the steps that start inside the
    play) when the drive has play and some structural damping.  Computed once per model
    (``DriveModel.stepping_C``): treat it as read-only, like the model's ``p``."""
    model = DriveModel.of(model)
    if model.stepping_C is not None:        # computed for this model already
        return model.stepping_C
    C = damping_matrix(model)
    if has_play(model.p) and np.any(C != 0.0):
        C = np.vstack((C, open_mesh_damping_matrix(model)))
    model.stepping_C = np.ascontiguousarray(C)
    return model.stepping_C


#: Steps per period of the highest linearised mode (the worm on its shaft) that a step must
#: give for pointwise theta2 and amplitude metrics: omega_max dt <= 2 pi / 20 = 0.314.  Measured
#: (benchmarks/bench_step.py, frequency-matched worm): within it theta2 stayed within 3.6 % and
#: theta4 within 0.03 % of their oscillation amplitudes pointwise on the 18-step move and its
#: variants (stiffer and softer worm shaft, modules M1/M3, 16-32 ms moves, ramp, sawtooth
#: mapping, tanh friction); a worm shaft twice as stiff at 5 us (16.5 steps per period) was
#: 5.6 % off.  Not covered by the rule: theta4 without the flywheel (= theta3, 0.9 % at 4 us)
#: and long sliding on the falling branch of Eq. 18 (a load torque, the paper's lead
#: convention: 5-26 % even at 1 us), where the pointwise error does not come from the step's
#: resolution of a mode.
STEPS_PER_PERIOD = 20.0


class StepResolutionWarning(UserWarning):
    """The time step gives the highest mode fewer than STEPS_PER_PERIOD steps per period."""


def step_resolution(model: DriveModel | Parameters) -> float:
    """omega_max dt: the configured step against the highest linearised mode (the worm on
    its shaft); 2 pi / (omega_max dt) steps per period of that mode."""
    model = DriveModel.of(model)
    return model.worm_frequency() * model.config.integrator.time_step


def step_resolution_warning(model: DriveModel | Parameters) -> str:
    """'' if ``integrator.time_step`` resolves the highest mode with at least
    STEPS_PER_PERIOD steps per period, else a one-line warning (the rule of
    :func:`amplitude_time_step`; a coarser step is allowed: the average-acceleration rule
    is stable at any step, only theta2's pointwise accuracy degrades)."""
    model = DriveModel.of(model)
    x = step_resolution(model)
    if not x > 2.0 * math.pi / STEPS_PER_PERIOD:
        return ''
    dt = model.config.integrator.time_step
    return (f'integrator.time_step = {dt:g} s gives the highest mode ({x / (2 * math.pi * dt):.4g}'
            f' Hz) {2 * math.pi / x:.1f} steps per period (< {STEPS_PER_PERIOD:g}, omega dt = '
            f'{x:.3g}): theta2 can be more than 5 % of its oscillation off pointwise; use '
            f'<= {amplitude_time_step(model):.3g} s for theta2 and amplitudes')


def amplitude_time_step(model: DriveModel | Parameters,
                        steps_per_period: float = STEPS_PER_PERIOD) -> float:
    """Time step for amplitude and pointwise metrics (studies, figures): the configured step
    divided by the smallest integer n that gives the highest linearised mode (the worm on its
    shaft, 8.6 kHz for Table 1) at least ``steps_per_period`` steps per period, so no metric
    depends on an unresolved mode.  An integer divisor keeps the grids of both steps aligned.
    The default step (4 us, 29 steps per period for Table 1) needs no division."""
    model = DriveModel.of(model)
    f_top = model.worm_frequency() / (2.0 * math.pi)
    dt = model.config.integrator.time_step
    n = max(1, math.ceil(dt * steps_per_period * f_top - 1e-9))
    return dt / n
