# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A change of parameters without a jolt, for the stepping integration.

This module contains :func:`reseated`: the deflections under new parameters that keep the
generalized forces of the old ones, which
:meth:`~worm_gear_sim.dynamics.stepping.Stepper.reconfigure` moves the drive to with
``reseat`` (a load released does not set a drive without drag ringing for ever).
"""

from __future__ import annotations

import numpy as np

from .equations import forces

__all__ = ['reseated']


def reseated(p_old: np.ndarray, p_new: np.ndarray, u: np.ndarray, v: np.ndarray,
             theta1: float, tol: float = 1e-13, max_iter: int = 30) -> np.ndarray:
    """The deflections under the parameters ``p_new`` that give the generalized forces
    ``p_old`` gives at (``u``, ``v``, ``theta1``) (Newton's method): the drive's
    accelerations go on through a change of parameters, its twist follows the new load,
    drag and play without a jolt.  Not converged: ``u`` (the state as it was)."""
    target = forces(p_old, u, v, theta1)[0]
    x = np.array(u, float)
    for _ in range(max_iter):
        Q, dQdu, _, _ = forces(p_new, x, v, theta1)
        try:
            dx = np.linalg.solve(dQdu, target - Q)
        except np.linalg.LinAlgError:
            return np.array(u, float)
        x = x + dx
        if not np.all(np.isfinite(x)):
            return np.array(u, float)
        if np.all(np.abs(dx) <= tol * (1.0 + np.abs(x))):
            return x
    return np.array(u, float)
