# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Quantities derived from the parameters, computed in exactly one place (:func:`derive`):
inertias of the bodies (solid cylinders), torsional and axial shaft stiffnesses, the worm
travel per radian l_w, the lead angle, the reduction ``ratio`` = r_g / l_w and its inverse
``output_per_input`` = l_w / r_g (docs/model-notes.md, glossary).

:class:`worm_gear_sim.dynamics.model.DriveModel` holds them next to the kernel's packed parameters.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..schema.parameters import Parameters

__all__ = ['Derived', 'derive']


@dataclass(frozen=True)
class Derived:
    """Quantities computed from the parameters (one place; used by model, node, studies)."""

    J_w: float          # worm inertia [kg m^2]
    J_g: float          # worm-gear inertia [kg m^2]
    J_4: float          # flywheel (antenna) inertia [kg m^2]
    K_w: float          # worm shaft torsional stiffness [N m/rad]
    K_g: float          # worm-gear shaft torsional stiffness [N m/rad]
    K_Lws: float        # worm shaft axial stiffness [N/m]
    K_Lgs: float        # gear shaft axial stiffness [N/m]
    k_ws: float         # worm shaft + bearing axial stiffness, in series [N/m]
    k_gs: float         # gear shaft + bearing axial stiffness, in series [N/m]
    l_w: float          # worm travel per radian used in Eq. 8 [m/rad]
    lead_angle: float   # lambda [rad]
    ratio: float        # r_g / l_w (56 with the kinematic lead)
    gear_teeth: float   # z_g = 2 pi r_g / lead (mesh cycles per gear revolution)
    lead_angle_consistent: bool  # tan(lambda) == l_w/r_w (virtual work holds)
    output_per_input: float      # l_w / r_g: rigid theta4 (and theta3) per theta1 [rad/rad]


def derive(cfg: Parameters) -> Derived:
    """Inertias (solid cylinders), shaft stiffnesses, lead per radian, ratio."""
    g, m, s = cfg.geometry, cfg.materials, cfg.shafts
    cyl = lambda rho, L, R: 0.5 * rho * math.pi * L * R ** 4  # noqa: E731
    J_ws = cyl(m.shaft_density, s.worm_shaft_length, s.worm_shaft_radius)
    J_gs = cyl(m.shaft_density, s.gear_shaft_length, s.gear_shaft_radius)
    J_w = cyl(m.worm_density, g.worm_length, g.worm_pitch_radius) \
        + s.worm_shaft_inertia_fraction * J_ws
    J_g = cyl(m.gear_density, g.gear_width, g.gear_pitch_radius) \
        + s.gear_shaft_inertia_fraction * J_gs
    J_4 = s.gear_shaft_inertia_fraction * J_gs
    if g.flywheel_enabled:
        J_4 += cyl(m.flywheel_density, g.flywheel_length, g.flywheel_radius)
    else:
        # Without a flywheel the massless gear shaft (assumption 8) ends free: J_4 = 0 makes
        # theta4 an algebraic variable (K_g (theta4 - theta3) = -T_load - c_out theta4'), not a
        # mode.  An explicit end inertia can be set.
        J_4 += g.shaft_end_inertia
    K_w = m.worm_shaft_shear_modulus * math.pi * s.worm_shaft_radius ** 4 \
        / (2.0 * s.worm_shaft_length)
    K_g = m.gear_shaft_shear_modulus * math.pi * s.gear_shaft_radius ** 4 \
        / (2.0 * s.gear_shaft_length)
    K_Lws = m.youngs_modulus * math.pi * s.worm_shaft_radius ** 2 / s.worm_shaft_length
    K_Lgs = m.youngs_modulus * math.pi * s.gear_shaft_radius ** 2 / s.gear_shaft_length
    k_ws = K_Lws * s.worm_bearing_axial_stiffness / (K_Lws + s.worm_bearing_axial_stiffness)
    k_gs = K_Lgs * s.gear_bearing_axial_stiffness / (K_Lgs + s.gear_bearing_axial_stiffness)
    lead_per_rad = g.lead / (2.0 * math.pi)
    l_w = lead_per_rad if g.lead_convention == 'kinematic' else g.lead
    if g.lead_angle > 0.0:
        lam = g.lead_angle
    else:
        lam = math.atan(lead_per_rad / g.worm_pitch_radius)
    consistent = abs(g.worm_pitch_radius * math.tan(lam) - l_w) <= 1e-9 * l_w
    return Derived(J_w=J_w, J_g=J_g, J_4=J_4, K_w=K_w, K_g=K_g, K_Lws=K_Lws, K_Lgs=K_Lgs,
                   k_ws=k_ws, k_gs=k_gs, l_w=l_w, lead_angle=lam,
                   ratio=g.gear_pitch_radius / l_w,
                   gear_teeth=2.0 * math.pi * g.gear_pitch_radius / g.lead,
                   lead_angle_consistent=consistent,
                   output_per_input=l_w / g.gear_pitch_radius)
