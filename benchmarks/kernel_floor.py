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

from worm_gear_sim.dynamics.model import (
    P_BETA,
    P_COSL,
    P_COSPHI,
    P_COUT,
    P_GAMMA,
    P_GEAR_B,
    P_GEAR_SCALE,
    P_GEAR_X0,
    P_INV_KGS,
    P_INV_KWS,
    P_INV_SQRT_VS,
    P_J4,
    P_JG,
    P_JW_STEP,
    P_KG,
    P_KW,
    P_LW,
    P_MU_DROP,
    P_MU_K,
    P_PHASE0,
    P_RG,
    P_RW,
    P_SINL,
    P_TLOAD,
    P_VCUSP,
    P_WORM_B,
    P_WORM_SCALE,
    P_WORM_X0,
    P_ZG,
)


@njit(cache=True, error_model='numpy')
def floor_steps(p, u, v, a, theta1, dt, n_evals):
    """len(theta1) - 1 steps from (u, v, a) (updated in place), ``n_evals`` Newton
    iterations each."""
    m0, m1, m2 = p[P_JW_STEP], p[P_JG], p[P_J4]
    Kw, Kg, lw, rw, rg = p[P_KW], p[P_KG], p[P_LW], p[P_RW], p[P_RG]
    sl, cl, cphi = p[P_SINL], p[P_COSL], p[P_COSPHI]
    k2, k3 = rw * cl, rg * sl
    zg, ph0 = p[P_ZG], p[P_PHASE0]
    ws, wb, wx = p[P_WORM_SCALE], p[P_WORM_B], p[P_WORM_X0]
    gs, gb, gx = p[P_GEAR_SCALE], p[P_GEAR_B], p[P_GEAR_X0]
    muk, mud, isv, vc = p[P_MU_K], p[P_MU_DROP], p[P_INV_SQRT_VS], p[P_VCUSP]
    k_shafts = cphi * sl * sl * p[P_INV_KGS] + cphi * cl * cl * p[P_INV_KWS]
    cout, tl = p[P_COUT], p[P_TLOAD]
    beta, gamma = p[P_BETA], p[P_GAMMA]
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
            c, s = math.cos(ph), math.sin(ph)
            cw = ws * math.exp(wb * (wx + 180.0 * (1.0 - c)))
            cg = gs * math.exp(gb * (gx + 180.0 * (1.0 - c)))
            icw, icg = 1.0 / cw, 1.0 / cg
            kgws = icw + icg + k_shafts                   # Eqs. 7, 10
            dk = -(cw * wb * 180.0 * s) * icw * icw - (cg * gb * 180.0 * s) * icg * icg
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


def floor_ns_per_step(p: np.ndarray, u: np.ndarray, v: np.ndarray, a: np.ndarray,
                      theta1: np.ndarray, dt: float, n_evals: int = 1,
                      repeats: int = 7) -> float:
    """Minimum over ``repeats`` of the floor's ns per step from the state (u, v, a)."""
    import time
    floor_steps(p, u.copy(), v.copy(), a.copy(), theta1[:3], dt, n_evals)    # compile
    best = np.inf
    for _ in range(repeats):
        uu, vv, aa = u.copy(), v.copy(), a.copy()
        t0 = time.perf_counter()
        floor_steps(p, uu, vv, aa, theta1, dt, n_evals)
        best = min(best, time.perf_counter() - t0)
    return best / (theta1.shape[0] - 1) * 1e9
