# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Velocities and accelerations of a dense trajectory made consistent with its positions
(pure core), so that the controller's interpolation between the dense points (cubic with
positions and velocities, quintic with accelerations too) stays with them.

A spline read at the dense instants gives its own slope and curvature there; when the
waypoints are closer together than one dense period those belong to a feature between two
dense points (waypoints 1e-12 s apart: a slope of 1e11 rad/s on a 0.1 rad step, read back
as 1.5e7 rad).  The rule, per dense point i with the secants
m = (p[i+1] - p[i]) / dt on either side (0 before the first point and after the last:
the trajectory starts and ends at rest):

* velocity: between the two secants (the slope of a path at a point lies between its
  neighbouring chords).  A smooth path's own derivative is there already (v ~ the mean of
  the two); unchanged on the paper's move.
* acceleration: between the second derivatives the cubic pieces on either side have at
  the point.  A smooth path's own acceleration moves by O(dt^2 p'''') at most.

A cubic piece then strays from the straight line between its two points by at most
4/27 dt (|m[i-1] - m[i]| + |m[i+1] - m[i]|), i.e. less than 0.6 of the largest of the
three dense steps around it: no interpolation makes the output jump beyond what its dense
points do (measured in test/test_hostile_trajectories.py, quintic too).
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
