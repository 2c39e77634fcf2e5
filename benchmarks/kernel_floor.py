# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The floor of the kernel: the default Newmark-Newton step written plainly, without the
model's branches (for bench_core's ratio).

The same equations as the default model in slip (Eqs. 8-10, 16-17 with the cosine contact
mapping evaluated directly, Eqs. 11, 13, 6, the Stribeck slip law of Eq. 18 with its cusp
rounded, in the direction of the sliding speed), the same predictor, analytic Jacobian and
3 x 3 solve by cofactors; no stick, no play, no convergence test: a fixed number of force
evaluations (Newton iterations) per step.  One evaluation per step is the least any
implicit step of this model costs; the kernel's ns/step over this is what its branches,
its convergence control and its extra evaluations cost.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from worm_gear_sim import DriveModel
from worm_gear_sim.dynamics.model import worm_inertia_factor


def floor_constants(model: DriveModel) -> np.ndarray:
    """The constants of the floor's step, read from the model by name."""
    cfg, d = model.config, model.derived
    g, mesh, fr, integ = cfg.geometry, cfg.mesh, cfg.friction, cfg.integrator
    jw = d.J_w
    if integ.worm_frequency_matching:
        jw *= worm_inertia_factor(model.p, integ.time_step)
    m_scale = g.module * mesh.worm_tooth_stiffness_multiplier
    g_scale = g.module * mesh.gear_tooth_stiffness_multiplier
    x0w, x0g = model.contact_origins_deg
    return np.array([
        jw, d.J_g, d.J_4, d.K_w, d.K_g, d.l_w, g.worm_pitch_radius, g.gear_pitch_radius,
        math.sin(d.lead_angle), math.cos(d.lead_angle), math.cos(g.pressure_angle),
        m_scale * math.exp(mesh.worm_fit_a) * (1.0 + math.exp(360.0 * mesh.worm_fit_b)),
        mesh.worm_fit_b, x0w,
        g_scale * math.exp(mesh.gear_fit_a) * (1.0 + math.exp(360.0 * mesh.gear_fit_b)),
        mesh.gear_fit_b, x0g, d.gear_teeth, mesh.phase_offset, fr.mu_kinetic,
        fr.mu_stribeck_drop, 1.0 / math.sqrt(fr.stribeck_velocity), fr.cusp_velocity,
        1.0 / d.k_gs, 1.0 / d.k_ws, cfg.load.output_viscous_coefficient,
        cfg.load.output_torque, integ.newmark_beta, integ.newmark_gamma])


@njit(cache=True, error_model='numpy')
def floor_steps(c, u, v, a, theta1, dt, n_evals):
    """len(theta1) - 1 steps from (u, v, a) (updated in place), ``n_evals`` Newton
    iterations each; ``c``: :func:`floor_constants`."""
    m0, m1, m2, Kw, Kg, lw, rw, rg, sl, cl, cphi = c[0], c[1], c[2], c[3], c[4], c[5], c[6], \
        c[7], c[8], c[9], c[10]
    ws, wb, wx, gs, gb, gx, zg, ph0 = c[11], c[12], c[13], c[14], c[15], c[16], c[17], c[18]
    muk, mud, isv, vc, inv_kgs, inv_kws = c[19], c[20], c[21], c[22], c[23], c[24]
    cout, tl, beta, gamma = c[25], c[26], c[27], c[28]
    k2, k3 = rw * cl, rg * sl
    k_shafts = cphi * sl * sl * inv_kgs + cphi * cl * cl * inv_kws
    c_a = 1.0 / (beta * dt * dt)
    c_v = gamma / (beta * dt)
    gdt = gamma * dt
    h2 = dt * dt * (0.5 - beta)
    g1 = dt * (1.0 - gamma)
    u0, u1, u2 = u[0], u[1], u[2]
    v0, v1, v2 = v[0], v[1], v[2]
    a0, a1, a2 = a[0], a[1], a[2]
    for k in range(theta1.shape[0] - 1):
        t1 = theta1[k + 1]
        us0, us1, us2 = u0 + dt * v0 + h2 * a0, u1 + dt * v1 + h2 * a1, u2 + dt * v2 + h2 * a2
        vs0, vs1, vs2 = v0 + g1 * a0, v1 + g1 * a1, v2 + g1 * a2
        x0 = u0 + dt * v0 + 0.5 * dt * dt * a0
        x1 = u1 + dt * v1 + 0.5 * dt * dt * a1
        x2 = u2 + dt * v2 + 0.5 * dt * dt * a2
        for _ in range(n_evals):
            b0, b1, b2 = c_a * (x0 - us0), c_a * (x1 - us1), c_a * (x2 - us2)
            w0, w1, w2 = vs0 + gdt * b0, vs1 + gdt * b1, vs2 + gdt * b2
            vsl = k2 * w0 + k3 * w1                       # sliding speed, Eq. 18
            av = abs(vsl)
            r = math.sqrt(av + vc)
            ex = math.exp(-av / r * isv)
            sg = 1.0 if vsl >= 0.0 else -1.0
            mu = sg * (muk + mud * ex)
            dmu = -mud * isv * ex * (av + 2.0 * vc) / (2.0 * r * r * r)
            ph = 0.5 * (x0 + zg * x1) + ph0               # Eqs. 16-17, cosine mapping
            cph, sph = math.cos(ph), math.sin(ph)
            cw = ws * math.exp(wb * (wx + 180.0 * (1.0 - cph)))
            cg = gs * math.exp(gb * (gx + 180.0 * (1.0 - cph)))
            icw, icg = 1.0 / cw, 1.0 / cg
            kgws = icw + icg + k_shafts                   # Eqs. 7, 10
            dk = -(cw * wb * 180.0 * sph) * icw * icw - (cg * gb * 180.0 * sph) * icg * icg
            ik = 1.0 / kgws
            q = lw * x0 - rg * x1                         # Eq. 8
            A, B = cphi * sl + mu * cl, cphi * cl - mu * sl
            Wn = q * cl * ik                              # Eq. 9
            dW2 = cl * ik * lw - Wn * ik * dk * 0.5
            dW3 = -cl * ik * rg - Wn * ik * dk * 0.5 * zg
            Q0 = -rw * A * Wn - Kw * (x0 - t1)            # Eqs. 11, 13, 6
            Q1 = rg * B * Wn - Kg * (x1 - x2)
            Q2 = -Kg * (x2 - x1) - cout * w2 - tl
            R0, R1, R2 = m0 * b0 - Q0, m1 * b1 - Q1, m2 * b2 - Q2
            dA, dB = cl * dmu * sg, -sl * dmu * sg        # d/dv_s of A, B
            j00 = m0 * c_a + rw * A * dW2 + Kw + rw * dA * Wn * k2 * c_v
            j01 = rw * A * dW3 + rw * dA * Wn * k3 * c_v
            j10 = -rg * B * dW2 - rg * dB * Wn * k2 * c_v
            j11 = m1 * c_a - rg * B * dW3 + Kg - rg * dB * Wn * k3 * c_v
            j12 = j21 = -Kg
            j22 = m2 * c_a + cout * c_v + Kg
            c00 = j11 * j22 - j12 * j21                   # cofactors (j02 = j20 = 0)
            c01 = -j10 * j22
            c02 = j10 * j21
            idet = 1.0 / (j00 * c00 + j01 * c01)
            x0 -= (c00 * R0 - j01 * j22 * R1 + j01 * j12 * R2) * idet
            x1 -= (c01 * R0 + j00 * j22 * R1 - j00 * j12 * R2) * idet
            x2 -= (c02 * R0 - j00 * j21 * R1 + (j00 * j11 - j01 * j10) * R2) * idet
        b0, b1, b2 = c_a * (x0 - us0), c_a * (x1 - us1), c_a * (x2 - us2)
        u0, u1, u2 = x0, x1, x2
        v0, v1, v2 = vs0 + gdt * b0, vs1 + gdt * b1, vs2 + gdt * b2
        a0, a1, a2 = b0, b1, b2
    u[0], u[1], u[2] = u0, u1, u2
    v[0], v[1], v[2] = v0, v1, v2
    a[0], a[1], a[2] = a0, a1, a2


def floor_ns_per_step(k: np.ndarray, u: np.ndarray, v: np.ndarray, a: np.ndarray,
                      theta1: np.ndarray, dt: float, n_evals: int = 1,
                      repeats: int = 7) -> float:
    """Minimum over ``repeats`` of the floor's ns per step from the state (u, v, a)."""
    import time
    floor_steps(k, u.copy(), v.copy(), a.copy(), theta1[:3], dt, n_evals)    # compile
    best = np.inf
    for _ in range(repeats):
        uu, vv, aa = u.copy(), v.copy(), a.copy()
        t0 = time.perf_counter()
        floor_steps(k, uu, vv, aa, theta1, dt, n_evals)
        best = min(best, time.perf_counter() - t0)
    return best / (theta1.shape[0] - 1) * 1e9
