# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The real-time segment of :meth:`~worm_gear_sim.dynamics.stepping.Stepper.advance_to`,
compiled: the command on one interpolation segment sampled on the step grid, then a kernel
over it (:func:`advance_segment`: the fixed step of
:func:`~worm_gear_sim.dynamics.integrator.advance`; :func:`advance_segment_adaptive`: the
variable step of :func:`~worm_gear_sim.dynamics.adaptive.advance_adaptive`, whose steps end on
the segment's end)."""

from __future__ import annotations

import numpy as np
from numba import njit

from .adaptive import advance_adaptive
from .integrator import advance
from .layout import N_AUX


@njit(cache=True, error_model='numpy')
def segment_command(theta1_now, theta1_dot_now, t0, k0, dt, n, cmd_t, cmd_value, slope, t_end,
                    theta1_end):
    """The command and its rate at the n + 1 grid points t0 + (k0 + j) dt (j = 0..n) on the
    segment theta1(t) = cmd_value + slope (t - cmd_t) up to the new sample (t_end,
    theta1_end) (slope 0: held).  Same arithmetic as SampledProfile's linear interpolation
    (np.interp), so stepping and batch agree bit for bit: a grid point at or after the
    sample time takes the sample's value."""
    th = np.empty(n + 1)
    td = np.empty(n + 1)
    th[0] = theta1_now
    td[0] = theta1_dot_now
    for j in range(1, n + 1):
        grid = t0 + float(k0 + j) * dt
        if slope == 0.0 or grid >= t_end:
            th[j] = theta1_end if slope != 0.0 else cmd_value
        else:
            th[j] = cmd_value + slope * (grid - cmd_t)
        td[j] = slope
    return th, td


@njit(cache=True, error_model='numpy', nogil=True)   # a check's trial on a fit's threads
def advance_segment(p, C, u, v, a, theta1_now, theta1_dot_now, t0, k0, dt, n, cmd_t,
                    cmd_value, slope, t_end, theta1_end, stats, ctl, load):
    """Real-time stepping: n steps on the grid t0 + (k0 + j) dt with the command of
    :func:`segment_command`; ``load``: the load torque at the n + 1 grid points (empty: the
    model's constant load)."""
    th, td = segment_command(theta1_now, theta1_dot_now, t0, k0, dt, n, cmd_t, cmd_value,
                             slope, t_end, theta1_end)
    empty3 = np.empty((0, 3))
    # np.int64(0), not 0: a literal argument would make numba compile a second copy of
    # the whole kernel (the Python callers pass an int64 stride)
    return advance(p, C, u, v, a, th, td, dt, np.int64(0), empty3, empty3, empty3,
                   np.empty((0, N_AUX)), stats, ctl, load)


@njit(cache=True, error_model='numpy', nogil=True)
def advance_segment_adaptive(p, ap, C, u, v, a, theta1_now, theta1_dot_now, t0, k0, dt, n,
                             cmd_t, cmd_value, slope, t_end, theta1_end, stats, ctl, load, log):
    """:func:`advance_segment` with the variable step: the n grid steps in steps of any size
    that end on the segment's end (``ap``, ``log``: as
    :func:`~worm_gear_sim.dynamics.adaptive.advance_adaptive` takes them)."""
    th, td = segment_command(theta1_now, theta1_dot_now, t0, k0, dt, n, cmd_t, cmd_value,
                             slope, t_end, theta1_end)
    empty3 = np.empty((0, 3))
    return advance_adaptive(p, ap, C, u, v, a, th, td, dt, t0 + float(k0) * dt, np.int64(0),
                            empty3, empty3, empty3, np.empty((0, N_AUX)), stats, ctl, load, log)
