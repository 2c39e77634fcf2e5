# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Independent check: the Newmark result agrees with scipy's Radau (tight tolerances) on the
same parameters to <= 0.1 % of the peak oscillation amplitude of theta2 and theta4, in
linear and nonlinear mode, for the paper's 18-step move.

Only the equations are shared (mesh_forces); the integration scheme, step control and
Newton iteration are scipy's.  The 8.6 kHz worm mode needs a small Newmark step for a
pointwise match (docs/model-notes.md): dt = 50 ns over the move and 5 ms of ringing."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from worm_gear_sim import Config, make_profile, simulate
from worm_gear_sim.model import P_J4, P_JG, P_JW, P_KG, mesh_forces, pack_parameters

T_END = 0.025
BREAKS = (0.0, 0.004, 0.016, 0.020, T_END)      # kinks of the trapezoidal command


def radau_reference(cfg: Config, times: np.ndarray) -> np.ndarray:
    p = pack_parameters(cfg)
    M = np.array([p[P_JW], p[P_JG], p[P_J4]])
    prof = make_profile(cfg.input)

    def theta1(t):
        return float(prof.theta1(np.array([t]))[0])

    if M[2] == 0.0:
        return _radau_free_shaft_end(p, M, theta1, times)

    def rhs(t, y):
        f = mesh_forces(p, y[0], y[1], y[2], y[3], y[4], y[5], theta1(t))
        return np.array([y[3], y[4], y[5], f[0] / M[0], f[1] / M[1], f[2] / M[2]])

    def jac(t, y):
        f = mesh_forces(p, y[0], y[1], y[2], y[3], y[4], y[5], theta1(t))
        kg = p[P_KG]
        J = np.zeros((6, 6))
        J[0, 3] = J[1, 4] = J[2, 5] = 1.0
        dQdu = np.array([[f[3], f[4], 0.0], [f[5], f[6], kg], [0.0, kg, -kg]])
        dQdv = np.array([[f[7], f[8], 0.0], [f[9], f[10], 0.0], [0.0, 0.0, 0.0]])
        J[3:, :3] = dQdu / M[:, None]
        J[3:, 3:] = dQdv / M[:, None]
        return J

    y = np.zeros(6)
    out = np.empty((len(times), 3))
    for a, b in zip(BREAKS[:-1], BREAKS[1:]):
        sel = (times >= a) & (times <= b)
        sol = solve_ivp(rhs, (a, b), y, method='Radau', jac=jac, rtol=1e-11,
                        atol=np.r_[np.full(3, 1e-15), np.full(3, 1e-12)], dense_output=True)
        assert sol.success, sol.message
        out[sel] = sol.sol(times[sel])[:3].T
        y = sol.y[:, -1]
    return out


def _radau_free_shaft_end(p, M, theta1, times):
    """No flywheel, no load (assumption 8): the massless gear shaft ends free, so it carries
    no torque and theta4 = theta3.  Two degrees of freedom (theta2, theta3) for Radau."""
    def rhs(t, y):
        f = mesh_forces(p, y[0], y[1], y[1], y[2], y[3], y[3], theta1(t))
        return np.array([y[2], y[3], f[0] / M[0], f[1] / M[1]])

    def jac(t, y):
        f = mesh_forces(p, y[0], y[1], y[1], y[2], y[3], y[3], theta1(t))
        kg = p[P_KG]
        J = np.zeros((4, 4))
        J[0, 2] = J[1, 3] = 1.0
        J[2:, :2] = np.array([[f[3], f[4]], [f[5], f[6] + kg]]) / M[:2, None]
        J[2:, 2:] = np.array([[f[7], f[8]], [f[9], f[10]]]) / M[:2, None]
        return J

    y = np.zeros(4)
    out = np.empty((len(times), 3))
    for a, b in zip(BREAKS[:-1], BREAKS[1:]):
        sel = (times >= a) & (times <= b)
        sol = solve_ivp(rhs, (a, b), y, method='Radau', jac=jac, rtol=1e-11,
                        atol=np.r_[np.full(2, 1e-15), np.full(2, 1e-12)], dense_output=True)
        assert sol.success, sol.message
        out[sel, :2] = sol.sol(times[sel])[:2].T
        out[sel, 2] = out[sel, 1]
        y = sol.y[:, -1]
    return out


@pytest.mark.parametrize('over, min_osc2, min_osc4', [
    ({'mesh.stiffness_model': 'linear', 'friction.model': 'constant'}, 5e-6, 1e-4),  # Figs 10-11
    ({}, 5e-6, 1e-4),                                                   # nonlinear default
    ({'geometry.flywheel_enabled': False}, 5e-7, 5e-7),                 # free shaft end
], ids=['linear', 'nonlinear', 'no_flywheel'])
def test_newmark_agrees_with_radau(over, min_osc2, min_osc4):
    cfg = Config().replace(dict(over, **{'integrator.time_step': 5e-8}))
    assert cfg.friction.model != 'off'
    tr = simulate(cfg, t_end=T_END, record_every=200)         # every 10 us
    ref = radau_reference(cfg, tr.t)
    osc2 = np.abs(tr.worm_error).max()                        # theta2 - theta1
    osc4 = np.abs(tr.output_error).max()                      # theta4 - theta1 l_w/r_g
    assert osc2 > min_osc2 and osc4 > min_osc4                # a real oscillation to match
    err2 = np.abs(tr.theta2 - ref[:, 0]).max()
    err4 = np.abs(tr.theta4 - ref[:, 2]).max()
    assert err2 <= 1e-3 * osc2, (err2 / osc2)
    assert err4 <= 1e-3 * osc4, (err4 / osc4)
