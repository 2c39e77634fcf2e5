# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Velocities and accelerations of a dense trajectory made consistent with its positions
(pure core), so that the controller's interpolation between the dense points stays with them.

Per dense point the velocity is kept between the secants on either side and the
acceleration between the second derivatives of the cubic pieces on either side; a smooth
path keeps its own derivatives.
"""

from __future__ import annotations

import numpy as np

__all__ = ['consistent_rates']


def consistent_rates(position: np.ndarray, velocity: np.ndarray,
                     acceleration: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(velocity, acceleration) of the dense ``position`` (samples ``dt`` apart) limited
    as the module docstring says; arrays of the same shape, new objects."""
    p = np.asarray(position, float)
    v = np.array(velocity, float)
    a = np.array(acceleration, float)
    n = p.size
    if n < 2:
        return np.zeros_like(v), np.zeros_like(a)
    m = np.diff(p) / dt
    left = np.concatenate(([0.0], m))               # secant before each point (at rest
    right = np.concatenate((m, [0.0]))              # before the first, after the last)
    v = np.clip(v, np.minimum(left, right), np.maximum(left, right))
    # second derivatives of each cubic piece at its start and end
    a_start = (6.0 * m - 4.0 * v[:-1] - 2.0 * v[1:]) / dt
    a_end = (-6.0 * m + 2.0 * v[:-1] + 4.0 * v[1:]) / dt
    lft = np.concatenate(([0.0], a_end))
    rgt = np.concatenate((a_start, [0.0]))
    a = np.clip(a, np.minimum(lft, rgt), np.maximum(lft, rgt))
    return v, a
