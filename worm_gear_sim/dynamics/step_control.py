# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The variable step's settings and log: the layout of its parameter vector (``A_*``, built
from a model by :func:`adaptive_parameters`), its controller's constants, and the rows of
its step log (``LOG_*``, read by :func:`step_log_of`).  The kernel: :mod:`.adaptive`."""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg as sla

from .equations import linear_stiffness, mass_matrix
from .layout import P_J4, P_JW
from .model import DriveModel

__all__ = ['adaptive_parameters', 'step_log_of', 'N_AP', 'N_LOG']

# ---- the adaptive parameter vector (built by adaptive_parameters) -------------------------
A_TOL2, A_TOL3, A_TOL4 = 0, 1, 2      # displacement error tolerance per step [rad]
A_OMEGA_W, A_OMEGA_A = 3, 4           # matched frequencies of the worm, antenna [rad/s]
A_JW, A_J4 = 5, 6                     # physical inertias of worm and antenna
A_HMAX, A_HMIN = 7, 8                 # largest step, smallest step before failing [s]
A_H0 = 9                              # first step of a run [s]
A_SAFETY, A_KI, A_KP = 10, 11, 12   # the controller: safety factor, PI exponents
A_HREF = 13                          # the fixed step (integrator.time_step) [s]
N_AP = 14

LOG_T, LOG_H, LOG_MODE, LOG_ERR, LOG_U = 0, 1, 2, 3, 4      # 4..6: theta2..theta4
# LOG_KIND: 0 a step, 1 a located stop, 2 a located cone exit, 3 a contact event; LOG_ROW:
# the coordinate whose error set the step; LOG_EVALS: force evaluations it took (with rejections)
LOG_KIND, LOG_ROW, LOG_EVALS = 7, 8, 9
N_LOG = 10

SAFETY, K_I, K_P = 0.85, 0.5 / 3.0, 0.2 / 3.0    # the PI controller (Gustafsson)
GROW_MAX = 4.0        # a step grows at most this much over the last
SHRINK_MIN = 0.2      # a rejected step shrinks at least to this fraction
EVENT_ITERATIONS = 6  # secant iterations locating an event
EVENT_SPEED = 1e-2    # a stop is located when |v_s| <= this fraction of the step's start
CONE_LAND = 1e-4      # a cone exit is located within this fraction of mu(0)
KIND_STEP, KIND_STOP, KIND_CONE, KIND_CONTACT = 0, 1, 2, 3


def adaptive_parameters(model: DriveModel) -> np.ndarray:
    """The adaptive kernel's parameter vector (``A_*``) of a model: the tolerances of
    ``integrator.adaptive_tolerance_worm`` / ``_gear``, the frequencies it matches (the
    worm's, 8.6 kHz, and the antenna's, 94.5 Hz, with ``integrator.worm_frequency_matching``;
    none without), the largest step, and the smallest (the fixed kernel's finest
    subdivision of its step)."""
    integ = model.config.integrator
    p = model.p
    ap = np.zeros(N_AP)
    ap[A_TOL2] = integ.adaptive_tolerance_worm
    ap[A_TOL3] = ap[A_TOL4] = integ.adaptive_tolerance_gear
    ap[A_JW], ap[A_J4] = p[P_JW], p[P_J4]
    if integ.worm_frequency_matching:
        ap[A_OMEGA_W] = model.worm_frequency()
        if p[P_J4] > 0.0:
            w2 = sla.eigvals(linear_stiffness(p), mass_matrix(p)).real
            ap[A_OMEGA_A] = math.sqrt(float(w2[w2 > 0.0].min()))
    ap[A_HMAX] = integ.adaptive_max_step
    ap[A_HMIN] = integ.time_step * 0.5 ** integ.max_subdivision_level
    ap[A_H0] = ap[A_HREF] = integ.time_step
    ap[A_SAFETY], ap[A_KI], ap[A_KP] = SAFETY, K_I, K_P
    return ap


def step_log_of(log: np.ndarray, n: int) -> dict[str, np.ndarray]:
    """The first n rows of a step log as arrays: end time 't' [s], size 'h' [s], friction
    'mode' (0 stuck, +-1 sliding), 'theta' (rows of theta2..theta4 [rad]), 'event' (the step
    ends at 0 no event, 1 a stop, 2 the cone's edge, 3 a contact edge), 'limit' (the
    coordinate whose error set it: 0 theta2, 1 theta3, 2 theta4) and 'evaluations' (force
    evaluations, its rejected attempts and event search included)."""
    g = log[:n]
    return {'t': g[:, LOG_T].copy(), 'h': g[:, LOG_H].copy(), 'mode': g[:, LOG_MODE].copy(),
            'theta': g[:, LOG_U:LOG_U + 3].copy(), 'event': g[:, LOG_KIND].copy(),
            'limit': g[:, LOG_ROW].copy(), 'evaluations': g[:, LOG_EVALS].copy()}
