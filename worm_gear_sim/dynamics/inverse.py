# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The model inverse (feed-forward compensation): the worm-shaft input theta1 that makes the
antenna follow a path theta4 = y(t), from y and its derivatives: Eqs. 6, 13, 9-10, 8 and 11
of :mod:`~worm_gear_sim.dynamics.model` solved backwards, with the play's flank and the
periodic transmission error.  A layout owner with the model (it reads the packed vector)."""

from __future__ import annotations

from numba import njit

from .equations import friction_coefficient, mesh_compliance, transmission_error
from .layout import (
    P_COSL,
    P_COSPHI,
    P_COUT,
    P_GAP_HALF,
    P_J4,
    P_JG,
    P_JW,
    P_KG,
    P_KW,
    P_LW,
    P_PE_NG,
    P_PE_NW,
    P_RG,
    P_RW,
    P_SINL,
    P_TLOAD,
)


@njit(cache=True, error_model='numpy')
def gear_torque_demand(p, y1, y2, y3, y4, dynamic):
    """The mesh torque on the gear [N m] that moves the antenna along theta4 = y(t) (Eq. 6
    and the gear body, as :func:`inverse_theta1` takes it): its sign tells the flank that
    must carry it (> 0 the drive flank, < 0 the coast flank)."""
    Jg, J4, Kg = p[P_JG], p[P_J4], p[P_KG]
    cout, Tload = p[P_COUT], p[P_TLOAD]
    if dynamic:
        Ts = J4 * y2 + cout * y1 + Tload                  # gear-shaft torque, Eq. 6
        return Jg * (y2 + (J4 * y4 + cout * y3) / Kg) + Ts
    return (Jg + J4) * y2 + cout * y1 + Tload


@njit(cache=True, error_model='numpy')
def inverse_theta1(p, y0, y1, y2, y3, y4, dynamic, flank):
    """Flat-output inverse of the nominal chain (packed parameters ``p``): the worm-shaft
    input theta1 that makes theta4 = y(t), from y and its derivatives; ``dynamic`` keeps
    the third and fourth derivative terms.  With play (``mesh.backlash`` > 0) the worm
    must also take up half the play on the flank ``flank`` (+1 drive, -1 coast, 0 the
    centre): the approach is q = q_e + flank h (the inverse of :func:`penetration`)."""
    Jw, J4 = p[P_JW], p[P_J4]
    Kw, Kg = p[P_KW], p[P_KG]
    lw, rw, rg = p[P_LW], p[P_RW], p[P_RG]
    sl, cl, cphi = p[P_SINL], p[P_COSL], p[P_COSPHI]
    cout, Tload = p[P_COUT], p[P_TLOAD]
    ratio = rg / lw                                       # theta1 per theta4
    if not dynamic:
        y3 = 0.0
        y4 = 0.0
    Ts = J4 * y2 + cout * y1 + Tload                      # gear-shaft torque, Eq. 6
    th3 = y0 + Ts / Kg
    th3_1 = y1 + (J4 * y3 + cout * y2) / Kg
    th3_2 = y2 + (J4 * y4 + cout * y3) / Kg
    Tm = gear_torque_demand(p, y1, y2, y3, y4, dynamic)
    pe = p[P_PE_NW] > 0.0 or p[P_PE_NG] > 0.0
    g2 = g3 = 1.0                   # torque factors of the normal force, as mesh_forces_mu
    th2_rigid = th3 * ratio
    th2_1 = th3_1 * ratio
    if pe:
        # periodic error: the rigid worm angle solves l_w th2 + r_g e(th2, th3) = r_g th3
        for _ in range(4):
            e, e2, e3, e22, e33 = transmission_error(p, th2_rigid, th3)
            th2_rigid -= (lw * th2_rigid + rg * (e - th3)) / (lw + rg * e2)
        e, e2, e3, e22, e33 = transmission_error(p, th2_rigid, th3)
        g2, g3 = 1.0 + rg * e2 / lw, 1.0 - e3
        th2_1 = th3_1 * g3 / g2 * ratio                   # q' = 0 along the rigid path
    # friction of the rigid sliding speed, flank from the sign of the mesh torque
    v_s = rw * cl * th2_1 + rg * sl * th3_1
    mu = friction_coefficient(p, v_s, Tm)[0]
    B = cphi * cl * g3 - mu * sl
    Wn = Tm / (rg * B)                                    # Eq. 13 at the flat path
    kgws = mesh_compliance(p, th2_rigid, th3, mu)[0]      # Eq. 10, the model's own
    q = Wn * kgws / cl                                    # Eq. 9
    h = p[P_GAP_HALF]
    if h > 0.0:
        q += flank * h                                    # the play, on the flank in contact
    if pe:
        # Eq. 8 with the error: l_w th2 - r_g th3 + r_g e(th2, th3) = q, Newton from the
        # rigid angle (|r_g de/dth2| <= 0.1 l_w: two iterations reach round-off)
        th2 = th2_rigid + q / (lw + rg * e2)
        for _ in range(3):
            e, e2, e3, e22, e33 = transmission_error(p, th2, th3)
            th2 -= (lw * th2 - rg * th3 + rg * e - q) / (lw + rg * e2)
        g2 = 1.0 + rg * e2 / lw
    else:
        th2 = (q + rg * th3) / lw                         # Eq. 8
    A = cphi * sl * g2 + mu * cl
    Tw = rw * A * Wn                                      # mesh torque on the worm
    if dynamic:
        th2_2 = th3_2 * ratio                             # worm-body inertia (rigid)
        if pe:
            th2_2 = (rg * (th3_2 * g3 - e33 * th3_1 * th3_1) - rg * e22 * th2_1 * th2_1) \
                / (lw + rg * e2)
        Tw += Jw * th2_2
    return th2 + Tw / Kw                                  # Eq. 11
