# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The layout of the packed parameter vector and of the mesh output of the compiled kernels.

This module contains the indices ``P_*`` of the vector :func:`~.model.pack_parameters`
fills from a Config (compile-time constants for numba), the layout of the flat output of
:func:`~.equations.mesh_eval` (``O_*``, ``AUX_*``) and the friction law's codes.  Only the
model, its equations, its inverse and the integrator read the vector by index.
"""

from __future__ import annotations

from ..schema.sections import MAX_ERROR_ORDERS

# ---- packed parameter vector layout (compile-time constants for numba) -------------------
P_JW, P_JG, P_J4 = 0, 1, 2
P_KW, P_KG, P_KWS, P_KGS = 3, 4, 5, 6
P_LW, P_RW, P_RG, P_SINL, P_COSL, P_COSPHI = 7, 8, 9, 10, 11, 12
P_MESH_LINEAR, P_CWKW_LIN, P_CGKG_LIN = 13, 14, 15
P_WORM_SCALE, P_WORM_B, P_WORM_X0 = 16, 17, 18      # M e^{a_w} * multiplier, b_w, x0_w
P_GEAR_SCALE, P_GEAR_B, P_GEAR_X0 = 19, 20, 21
P_ZG, P_PHASE0 = 22, 23
P_FRIC_MODEL, P_FRIC_PAPER, P_MU_CONST, P_MU_K, P_MU_DROP, P_VS, P_VEPS = (
    24, 25, 26, 27, 28, 29, 30)
P_FRIC_IN_COMPLIANCE = 31
P_COUT, P_TLOAD = 32, 33
P_BETA, P_GAMMA, P_RTOL, P_ATOL, P_MAXIT, P_MAXSUB = 34, 35, 36, 37, 38, 39
P_OUTPUT_PER_INPUT = 40          # l_w / r_g: theta3, theta4 per theta1 in rigid motion
P_INV_KGS, P_INV_KWS, P_INV_VEPS, P_LIN_COMPLIANCE = 41, 42, 43, 44   # precomputed
P_INV_SQRT_VS = 45
P_MESH_COSINE = 46                                   # contact mapping: 1 cosine, 0 sawtooth
P_FRIC_SET_VALUED, P_MU_STATIC = 47, 48              # set-valued law; mu(0), the cone's edge
P_VCUSP = 49                                         # Stribeck cusp rounding speed
P_JW_STEP = 50                                       # worm inertia in the Newmark step
P_GAP_HALF, P_INIT_FLANK = 51, 52     # half the play along q, r_g b / 2 [m]; +1/-1/0 flank
# periodic transmission error e(theta2, theta3) [rad at the gear]: orders of the worm and of
# the gear harmonics in use, then [s1, c1, s2, c2, ...] of each (MAX_ERROR_ORDERS pairs)
P_PE_NW, P_PE_NG = 53, 54
P_PE_WORM = 55
P_PE_GEAR = P_PE_WORM + 2 * MAX_ERROR_ORDERS
# 1: the cosine mapping's tooth compliance tabulated at the vector's end (periodic.with_table:
# 1024 intervals, kept within 1e-12 of Eq. 7, its slope (Jacobian only) within 1e-9)
P_TEETH_TABLE = P_PE_GEAR + 2 * MAX_ERROR_ORDERS
N_PARAMS = P_TEETH_TABLE + 1

# layout of the flat output of mesh_eval: Q (3), dQ/du (3x3 row-major), dQ/dv (3x3), aux
O_Q, O_DQDU, O_DQDV, O_AUX = 0, 3, 12, 21
N_OUT = 21 + 8

FRICTION_OFF, FRICTION_CONSTANT, FRICTION_STRIBECK = 0, 1, 2

# aux outputs of generalized_forces
AUX_WN, AUX_MU, AUX_CWKW, AUX_CGKG, AUX_VS, AUX_FX, AUX_FY, AUX_Q = range(8)
N_AUX = 8
