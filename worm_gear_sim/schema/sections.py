# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Sections of the worm-gear drive's parameters: the schema, typed and immutable.

This module contains one frozen dataclass per YAML section (every field with its default and
the metadata the node declares descriptors and the CLI prints help from: description, unit,
range, choices, read-only), :data:`SECTIONS`, and the constants every floor shares
(:data:`ANGLE_LIMIT`, :data:`NODE_NAME`, ...).  SI units and radians (REP 103).  The whole
set is :class:`~worm_gear_sim.schema.parameters.Parameters` (checked across fields there, per
value in :mod:`~worm_gear_sim.schema.validation`); users build its subclass
:class:`~worm_gear_sim.config.usable.Config`.  ``config/worm_gear_sim.yaml`` (ROS layout)
holds the same defaults (a test checks that they agree); nested YAML groups are the sections
here, dotted parameter names (``mesh.stiffness_model``) in the node.  This module imports
nothing of the package.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

__all__ = [
    'NODE_NAME', 'ANGLE_LIMIT', 'LOAD_LIMIT', 'SECTIONS',
    'DEG', 'PHASE_AT_MEAN_STIFFNESS', 'MAX_ERROR_ORDERS', 'ERROR_HARMONIC_LIMIT',
    'ERROR_SLOPE_LIMIT', 'Geometry', 'Materials', 'Shafts', 'Mesh', 'Friction',
    'Damping', 'Load', 'Integrator', 'InputProfile', 'NodeSettings', 'CompensationSettings',
    'AdaptationSettings', 'ADAPTABLE_KEYS',
]

NODE_NAME = 'worm_gear_sim'
DEG = math.pi / 180.0
#: Largest |angle| [rad] the model accepts (commands, initial states, equilibria): at 1e9 rad
#: the mesh phase and the approach q = l_w theta2 - r_g theta3 keep ~1e-7 of their resolution
#: in double precision (a year of continuous slewing of the worm at 30 rad/s).
ANGLE_LIMIT = 1e9
#: Largest |load torque| [N m] a signal may take (the range of ``load.output_torque``).
LOAD_LIMIT = 1e5
# Mesh phase at which the mesh stiffness k_Y of the cosine contact mapping equals its mean
# over the cycle (default parameters; test_model checks it)
PHASE_AT_MEAN_STIFFNESS = 1.8373
#: Most harmonic orders of each periodic transmission error (``mesh.worm_error_harmonics``,
#: ``mesh.gear_error_harmonics``): the compiled kernel holds a fixed number.
MAX_ERROR_ORDERS = 8
#: Largest |coefficient| [rad at the gear] of a periodic-error harmonic: 1e-3 rad (3.4 arcmin,
#: 20x the worst telescope drive's 100 arcsec peak to peak).  A cross-field check also
#: bounds the slope: r_g |de/dtheta2| <= ERROR_SLOPE_LIMIT l_w (the approach keeps rising
#: with the worm, the mesh force its virtual-work direction).
ERROR_HARMONIC_LIMIT = 1e-3
#: Largest r_g max|de/dtheta2| / l_w (and max|de/dtheta3|) the harmonics may give.
ERROR_SLOPE_LIMIT = 0.1


def _f(default: Any, description: str, unit: str = '', lo: float | None = None,
       hi: float | None = None, lo_open: bool = False, choices: tuple[str, ...] = (),
       read_only: bool = False, length: int | None = None) -> Any:
    """Declare a parameter field with its metadata (single source for docs, ROS, checks)."""
    meta = dict(description=description, unit=unit, lo=lo, hi=hi, lo_open=lo_open,
                choices=choices, read_only=read_only, length=length)
    if isinstance(default, list):
        return field(default_factory=lambda: tuple(default), metadata=meta)
    return field(default=default, metadata=meta)


@dataclass(frozen=True)
class Geometry:
    """Worm-gear set geometry (Table 1, module M2). R in Table 1 is a radius."""

    module: float = _f(2.0, 'Gear module M in mm: tooth stiffness scales with M (the M of '
                       'Eqs. 16-17; the linear values are given at M = 2). Geometry is set '
                       'separately', 'mm', 0.0, 50.0, lo_open=True)
    worm_pitch_radius: float = _f(0.0158, 'Worm pitch radius r_w = R2', 'm', 0.0, 1.0,
                                  lo_open=True)
    worm_length: float = _f(0.015, 'Worm body length L2 (inertia J_w)', 'm', 0.0, 2.0,
                            lo_open=True)
    gear_pitch_radius: float = _f(0.056, 'Worm-gear pitch radius r_g = R3', 'm', 0.0, 5.0,
                                  lo_open=True)
    gear_width: float = _f(0.02, 'Worm-gear body width L3 (inertia J_g)', 'm', 0.0, 2.0,
                           lo_open=True)
    lead: float = _f(0.006283185, 'Worm lead per revolution (Table 1)', 'm/rev', 0.0, 1.0,
                     lo_open=True)
    lead_convention: str = _f('kinematic', 'kinematic: l_w = lead/2pi (ratio 1:56); paper: '
                              'lead used as if per radian (reproduces the printed 0.0127 rad)',
                              choices=('kinematic', 'paper'))
    lead_angle: float = _f(0.0, 'Lead angle lambda; 0 derives tan(lambda) = l_w/r_w '
                           '(conservative mesh). Table 1 prints 3deg41min = 0.064286 rad',
                           'rad', 0.0, 0.8)
    pressure_angle: float = _f(0.30543261909900765, 'Normal pressure angle phi_n (17deg30min)',
                               'rad', 0.0, 0.8, lo_open=True)
    flywheel_enabled: bool = _f(True, 'Flywheel J_4 on the gear shaft; false: the massless '
                                'gear shaft ends free (assumption 8), theta4 = theta3 - '
                                'T_load/K_g, plus shaft_end_inertia if set')
    shaft_end_inertia: float = _f(0.0, 'Inertia on the free end of the gear shaft when '
                                  'flywheel_enabled is false (a coupling, an encoder); 0 keeps '
                                  'the paper\'s massless shaft: no extra degree of freedom',
                                  'kg*m^2', 0.0, 1e3)
    flywheel_radius: float = _f(0.12, 'Flywheel radius R5', 'm', 0.0, 5.0, lo_open=True)
    flywheel_length: float = _f(0.03, 'Flywheel length L5', 'm', 0.0, 5.0, lo_open=True)


@dataclass(frozen=True)
class Materials:
    """Densities and elastic moduli."""

    worm_density: float = _f(7850.0, 'Worm (Cr-Mo steel) density', 'kg/m^3', 0.0, 3e4,
                             lo_open=True)
    gear_density: float = _f(8800.0, 'Worm-gear (phosphor bronze) density', 'kg/m^3', 0.0,
                             3e4, lo_open=True)
    flywheel_density: float = _f(7850.0, 'Flywheel (steel) density', 'kg/m^3', 0.0, 3e4,
                                 lo_open=True)
    shaft_density: float = _f(7850.0, 'Shaft (steel) density, used by the shaft inertia '
                              'fractions', 'kg/m^3', 0.0, 3e4, lo_open=True)
    worm_shaft_shear_modulus: float = _f(77e9, 'Shear modulus G of the worm shaft', 'Pa',
                                         0.0, 1e16, lo_open=True)
    gear_shaft_shear_modulus: float = _f(77e9, 'Shear modulus G of the worm-gear shaft', 'Pa',
                                         0.0, 1e16, lo_open=True)
    youngs_modulus: float = _f(206e9, "Young's modulus E of both shafts (axial stiffness)",
                               'Pa', 0.0, 1e16, lo_open=True)


@dataclass(frozen=True)
class Shafts:
    """Shafts (massless torsional springs, assumption 8) and bearings."""

    worm_shaft_radius: float = _f(0.01534, 'Worm shaft radius R1', 'm', 0.0, 1.0, lo_open=True)
    worm_shaft_length: float = _f(0.20, 'Worm shaft length L1', 'm', 0.0, 10.0, lo_open=True)
    gear_shaft_radius: float = _f(0.0175, 'Worm-gear shaft radius R4', 'm', 0.0, 1.0,
                                  lo_open=True)
    gear_shaft_length: float = _f(0.37, 'Worm-gear shaft length L4', 'm', 0.0, 10.0,
                                  lo_open=True)
    worm_shaft_inertia_fraction: float = _f(0.0, 'Share of the worm shaft polar inertia lumped '
                                            'on the worm (paper: 0, usual lumped value 1/3)',
                                            '', 0.0, 1.0)
    gear_shaft_inertia_fraction: float = _f(0.0, 'Share of the gear shaft polar inertia lumped '
                                            'on the gear and on the flywheel end each', '',
                                            0.0, 1.0)
    worm_bearing_axial_stiffness: float = _f(2e8, 'Axial stiffness K_bTws of the worm bearing',
                                             'N/m', 0.0, 1e14, lo_open=True)
    gear_bearing_axial_stiffness: float = _f(2e8, 'Axial stiffness K_bTgs of the gear bearing',
                                             'N/m', 0.0, 1e14, lo_open=True)


@dataclass(frozen=True)
class Mesh:
    """Tooth mesh stiffness, Eqs. (16)-(17)."""

    stiffness_model: str = _f('nonlinear', 'nonlinear: Eqs. 16-17 over the mesh cycle; linear: '
                              'constant tooth stiffnesses (paper Figs. 10-11)',
                              choices=('nonlinear', 'linear'))
    worm_tooth_stiffness_linear: float = _f(3.5e8, 'c_w k_w in linear mode', 'N/m', 0.0, 1e14,
                                            lo_open=True)
    gear_tooth_stiffness_linear: float = _f(2.5e8, 'c_g k_g in linear mode', 'N/m', 0.0, 1e14,
                                            lo_open=True)
    worm_fit_a: float = _f(19.38843319, 'a_w of Eq. 16', '', -100.0, 100.0)
    worm_fit_b: float = _f(0.000656069, 'b_w of Eq. 16', '1/deg', -1.0, 1.0)
    gear_fit_a: float = _f(19.64527077, 'a_g of Eq. 17', '', -100.0, 100.0)
    gear_fit_b: float = _f(-0.00055956, 'b_g of Eq. 17', '1/deg', -1.0, 1.0)
    calibrate_to_linear_mean: bool = _f(True, 'Shift the contact-position origin so that the '
                                        'mean of Eqs. 16-17 over a mesh cycle equals the '
                                        'linear values')
    contact_mapping: str = _f('cosine', 'Contact positions x of Eqs. 16-17 over a mesh cycle '
                              '(one worm revolution): cosine: x = x0 + 180(1 - cos s) deg, out '
                              'along the fitted range and back, no jump at the tooth hand-over; '
                              'sawtooth: x = x0 + s, jumps 27 % (worm) / 18 % (gear) at every '
                              'hand-over', choices=('cosine', 'sawtooth'))
    phase_offset: float = _f(PHASE_AT_MEAN_STIFFNESS, 'Mesh-cycle phase (worm rotation) at '
                             'theta2 = theta3 = 0; the default starts the cosine mapping at '
                             'the mean mesh stiffness', 'rad', 0.0, 2.0 * math.pi)
    worm_tooth_stiffness_multiplier: float = _f(1.0, 'Multiplier on c_w k_w (Fig. 17 study)',
                                                '', 0.0, 1e6, lo_open=True)
    gear_tooth_stiffness_multiplier: float = _f(1.0, 'Multiplier on c_g k_g (Fig. 17 study)',
                                                '', 0.0, 1e6, lo_open=True)
    backlash: float = _f(0.0, 'Total angular play b of the worm gear with the worm held: no '
                         'tooth force and no friction while |q| < r_g b / 2 (q = l_w theta2 - '
                         'r_g theta3); beyond it the flank in contact carries the mesh law of '
                         'the penetration q -/+ r_g b / 2. Less than half a tooth pitch, '
                         '0.5 lead / r_g', 'rad', 0.0, 0.1)
    initial_flank: str = _f('drive', 'Where a drive with play starts at rest without a load '
                            'torque: drive: on the flank the worm drives forward (q = +r_g b/2),'
                            ' coast: on the other one (q = -r_g b/2), center: in the middle of '
                            'the play. Under a load it rests on the loaded flank',
                            choices=('drive', 'coast', 'center'))
    worm_error_harmonics: tuple = _f([], 'Periodic transmission error of the worm, '
                                     '[s1, c1, s2, c2, ...]: e += sum_k s_k sin(k theta2) + '
                                     'c_k cos(k theta2), in rad at the gear (the approach '
                                     'q = l_w theta2 - r_g theta3 + r_g e). Empty: none. At '
                                     f'most {MAX_ERROR_ORDERS} orders, each entry within '
                                     f'+-{ERROR_HARMONIC_LIMIT:g} rad', 'rad',
                                     -ERROR_HARMONIC_LIMIT, ERROR_HARMONIC_LIMIT)
    gear_error_harmonics: tuple = _f([], 'Periodic transmission error of the gear (runout), '
                                     '[S1, C1, S2, C2, ...]: e += sum_m S_m sin(m theta3) + '
                                     'C_m cos(m theta3), in rad at the gear. Empty: none. At '
                                     f'most {MAX_ERROR_ORDERS} orders, each entry within '
                                     f'+-{ERROR_HARMONIC_LIMIT:g} rad', 'rad',
                                     -ERROR_HARMONIC_LIMIT, ERROR_HARMONIC_LIMIT)


@dataclass(frozen=True)
class Friction:
    """Tooth friction, Eq. (18), in SI with the sliding velocity along the thread."""

    model: str = _f('stribeck', 'stribeck: Eq. 18; constant: constant_coefficient; off',
                    choices=('stribeck', 'constant', 'off'))
    direction: str = _f('set_valued', 'set_valued: W_f in mu |W_n| Sgn(v_s), exact stick '
                        '(|W_f| <= mu(0) |W_n|) and slip opposing sliding, solved in each '
                        'Newton step; regularized: sgn(v_s) ~ tanh(v_s/v_eps), sticks by '
                        'viscous creep; paper: fixed sign as printed in Eqs. 1-2 (cannot '
                        'dissipate)', choices=('set_valued', 'regularized', 'paper'))
    mu_kinetic: float = _f(0.0470713, 'mu at high sliding speed (Eq. 18 constant term)', '',
                           0.0, 2.0)
    mu_stribeck_drop: float = _f(0.1056549, 'mu(0) - mu_kinetic (Eq. 18 exponential term)', '',
                                 0.0, 2.0)
    stribeck_velocity: float = _f(0.07454, 'v_S in mu = mu_k + drop*exp(-sqrt(v/v_S)); '
                                  '1/(0.223607*60) m/s reads Eq. 18 in m/min', 'm/s',
                                  0.0, 1e3, lo_open=True)
    constant_coefficient: float = _f(0.145, 'mu of the constant model (paper linear case)', '',
                                     0.0, 2.0)
    regularization_velocity: float = _f(1e-4, 'v_eps of tanh(v_s/v_eps) (direction: '
                                        'regularized only)', 'm/s', 0.0, 1.0, lo_open=True)
    cusp_velocity: float = _f(1e-7, 'v_c rounding the cusp of Eq. 18 at zero sliding speed '
                              'in the set-valued law: sqrt(v) -> v/sqrt(v + v_c) (mu(0) and '
                              'mu at v >> v_c unchanged)', 'm/s', 0.0, 1e-2, lo_open=True)
    in_compliance: bool = _f(False, 'Keep the friction terms of KGWS (Eq. 10, as printed): '
                             'friction loads the shaft bearings axially. Off by default: with '
                             'them the mesh stores energy at each sliding reversal (up to '
                             '1.6e-9 of E per step) instead of only dissipating')


@dataclass(frozen=True)
class Damping:
    """Optional structural damping (assumption 10 of the paper: none)."""

    rayleigh_alpha: float = _f(0.0, 'Mass-proportional damping alpha (relative to the rigid '
                               'kinematic motion)', '1/s', 0.0, 1e6)
    rayleigh_beta: float = _f(0.0, 'Stiffness-proportional damping beta', 's', 0.0, 1.0)
    modal_damping_ratios: tuple = _f([0.0, 0.0, 0.0], 'Damping ratio of each linearised mode, '
                                     'lowest first', '', 0.0, 1.0, length=3)


@dataclass(frozen=True)
class Load:
    """External load on the output (antenna). The paper has none (defaults zero)."""

    output_torque: float = _f(0.0, 'Constant external torque on theta4 (wind, unbalance)',
                              'N*m', -LOAD_LIMIT, LOAD_LIMIT)
    output_viscous_coefficient: float = _f(0.0, 'Viscous bearing drag on theta4', 'N*m*s/rad',
                                           0.0, 1e5)
    max_elastic_windup: float = _f(0.02, 'Static wind-up of the antenna against the held '
                                   'worm beyond which a load is warned about (not carried '
                                   'elastically by a real drive; the model integrates it)',
                                   'rad', 0.0, 10.0, lo_open=True)


@dataclass(frozen=True)
class Integrator:
    """Newmark-beta with Newton-Raphson on the end-of-step state."""

    time_step: float = _f(4e-6, 'Fixed Newmark step dt (4 us: 250 steps per 1 ms tick; '
                          'theta2 pointwise within 5 % of its oscillation, theta4 within 0.1 %; '
                          'warns below 20 steps per period of the highest mode)', 's', 0.0,
                          1e-2, lo_open=True, read_only=True)
    newmark_beta: float = _f(0.25, 'Newmark beta (1/4: average acceleration)', '', 0.0, 0.5,
                             lo_open=True)
    newmark_gamma: float = _f(0.5, 'Newmark gamma (1/2: no numerical damping)', '', 0.5, 1.0)
    worm_frequency_matching: bool = _f(True, 'Scale the worm inertia in the Newmark step by '
                                       '(x/tan x)^2, x = omega_w dt/2, so that the average-'
                                       'acceleration rule gives the 8.6 kHz worm mode its exact '
                                       'frequency (otherwise its period stretches 2.4 %/cycle '
                                       'at 10 us); the physical inertia is used everywhere else',
                                       read_only=True)
    newton_rtol: float = _f(1e-9, 'Newton tolerance on the residual as acceleration error, '
                            'relative to |acceleration|', '', 0.0, 1e-2, lo_open=True)
    newton_atol: float = _f(1e-7, 'Newton tolerance on the residual as acceleration error, '
                            'absolute', 'rad/s^2', 0.0, 1e3, lo_open=True)
    newton_max_iterations: int = _f(12, 'Newton iterations before a step is subdivided', '',
                                    1, 200)
    max_subdivision_level: int = _f(10, 'A failing step is split in 2, 4, ... 2^level parts',
                                    '', 0, 20)
    method: str = _f('fixed', 'fixed: steps of time_step; adaptive: a step of any size set by '
                     'a local error estimate, the friction events located inside it, landing '
                     'on every tick and record point of the time_step grid',
                     choices=('fixed', 'adaptive'), read_only=True)
    adaptive_tolerance_worm: float = _f(5e-10, 'adaptive: theta2 error allowed per step '
                                        '(Zienkiewicz-Xie estimate)', 'rad', 0.0, 1e-3,
                                        lo_open=True)
    adaptive_tolerance_gear: float = _f(3e-8, 'adaptive: theta3 and theta4 error allowed per '
                                        'step', 'rad', 0.0, 1e-3, lo_open=True)
    adaptive_max_step: float = _f(1e-3, 'adaptive: largest step', 's', 0.0, 1e-2, lo_open=True)


@dataclass(frozen=True)
class InputProfile:
    """Commanded worm angle theta1(t) for offline runs (the node takes it from a topic)."""

    profile: str = _f('trapezoidal', 'step | ramp | trapezoidal | s_curve | csv',
                      choices=('step', 'ramp', 'trapezoidal', 's_curve', 'csv'))
    target_angle: float = _f(0.11309733552923255, 'Move size: 18 steps of 0.36 deg', 'rad',
                             -1e4, 1e4)
    start_time: float = _f(0.0, 'Time at which the move starts', 's', 0.0, 1e6)
    move_time: float = _f(0.020, 'Duration of the move (ramp, trapezoidal, s_curve)', 's',
                          0.0, 1e4, lo_open=True)
    accel_time: float = _f(0.004, 'Acceleration (= deceleration) time of trapezoidal and '
                           's_curve moves', 's', 0.0, 1e4, lo_open=True)
    csv_path: str = _f('', 'CSV file with columns t, theta1 (profile: csv)')
    end_time: float = _f(0.5, 'Simulated duration of offline runs', 's', 0.0, 1e6,
                         lo_open=True)


@dataclass(frozen=True)
class NodeSettings:
    """ROS node settings (read by worm_gear_sim.ros.node; pure data, no rclpy here)."""

    publish_rate_hz: float = _f(1000.0, 'Tick (publish) rate', 'Hz', 1.0, 20000.0,
                                read_only=True)
    joint_names: tuple = _f(['worm_input_joint', 'worm_joint', 'worm_gear_joint',
                             'antenna_joint'], 'JointState names for theta1..theta4',
                            read_only=True, length=4)
    executor: str = _f('events', 'events | single_threaded', choices=('events',
                       'single_threaded'), read_only=True)
    max_command_jump: float = _f(1.0, 'Largest accepted change of theta1 between two '
                                 'commands', 'rad', 0.0, 1e4, lo_open=True)
    max_command_abs: float = _f(1e4, 'Largest accepted |theta1|', 'rad', 0.0, ANGLE_LIMIT,
                                lo_open=True)
    max_catch_up: float = _f(0.05, 'Largest simulated time integrated in one tick; the rest '
                             'is dropped and counted as an overrun', 's', 0.0, 10.0,
                             lo_open=True)
    command_interpolation: str = _f('linear', 'How theta1 moves between command samples: '
                                    'linear, or hold (steps at the sample time)',
                                    choices=('linear', 'hold'))
    command_timing: str = _f('tick', 'Time of a command sample on the wall clock: tick (the '
                             'tick that reads it; the newest command since the previous tick), '
                             'reception (its reception time) or stream (reception times '
                             'smoothed onto the steady rate of the stream); with use_sim_time '
                             'always the /clock reading at reception',
                             choices=('tick', 'reception', 'stream'))
    compensation_applied: bool = _f(False, 'Predict the drive as if ~/feedforward were added '
                                    'to the command')
    diagnostic_period: float = _f(1.0, 'Period of /diagnostics', 's', 0.01, 60.0,
                                  read_only=True)
    float64_outputs: bool = _f(False, 'Publish ~/positioning_error, ~/worm_error, '
                               '~/feedforward and ~/backdrive_margin as std_msgs/Float64 '
                               '(no stamp) instead of stamped one-joint JointStates',
                               read_only=True)
    monitor_rate_hz: float = _f(0.0, 'Largest rate of the monitoring topics (joint_states, '
                                '~/positioning_error, ~/worm_error), by the stamps of the '
                                'predictions; 0.0: one message per prediction.  The '
                                'per-sample outputs (~/compensated_command, ~/feedforward) '
                                'are not limited', 'Hz', 0.0, 1e6)
    residual_window: float = _f(1.0, 'Live model check: window of the RMS of measured - '
                                'predicted (measured_joint_states)', 's', 0.0, 3600.0,
                                lo_open=True, read_only=True)
    residual_warn_rms: tuple = _f([1e-3, 1e-4, 1e-4], 'Live model check: /diagnostics turns '
                                  'WARN when the windowed residual RMS of theta2, theta3 or '
                                  'theta4 exceeds its entry', 'rad', 0.0, 1e3, lo_open=True,
                                  length=3)
    residual_plausible_max: float = _f(0.25, 'Live model check and adaptation: an encoder '
                                       'sample (measured_joint_states) farther than this from '
                                       'the prediction of its stamp on a joint they use is '
                                       'rejected as implausible and counted: an encoder of '
                                       'another drive, a wrapped or corrupted reading. About '
                                       'twice the worst model error of the default drive '
                                       '(docs/node.md)', 'rad', 0.0, 1e3, lo_open=True,
                                       read_only=True)
    backdrive_margin_warn: float = _f(1.2, '/diagnostics turns WARN when the back-drive '
                                      'margin (~/backdrive_margin: the friction the mesh can '
                                      'hold over what the load would need to turn the worm '
                                      'if the motor let go) falls below this', '', 0.0, 1e3)


@dataclass(frozen=True)
class CompensationSettings:
    """Feed-forward compensation (worm_gear_sim.compensation.streaming)."""

    enabled: bool = _f(True, 'Compute the feed-forward correction')
    quasi_static: bool = _f(True, 'Compensate compliance and friction wind-up')
    shaper: str = _f('none', 'Input shaper in the reference filter: none | zv | zvd | ei '
                     '(measured: none is best for tracking; zv/zvd/ei with lag_order 0 for '
                     'robust point-to-point moves)', choices=('none', 'zv', 'zvd', 'ei'))
    preview_time: float = _f(0.0, 'Preview horizon of future command samples', 's', 0.0, 1.0)
    model_inverse: bool = _f(False, 'Also the 3rd/4th-derivative terms of the model inverse '
                             '(gear and worm body inertia); needs a longer smoothing kernel')
    smoothing_time: float = _f(0.0, 'Width of the B-spline that smooths the reference (gives '
                               'its derivatives causally); 0: (degree+1) command periods '
                               '1/node.publish_rate_hz', 's', 0.0, 0.1)
    lag_order: int = _f(2, 'Lead of the reference filter: it tracks polynomials of this '
                        'degree without lag (0: plain delay, 1: ramps, 2: parabolas)', '', 0, 2)
    backlash_inverse: bool = _f(True, 'With mesh.backlash > 0: move the worm across the play '
                                'to the flank the motion needs, in one command period when '
                                'the mesh torque demand changes sign (docs/compensation.md)')
    soft_crossing: bool = _f(True, 'With the backlash inverse: where the demand, extrapolated, '
                             'will change sign within half an antenna-mode period, cross the '
                             'play along a smooth step centred on that zero instead of in one '
                             'command period (docs/compensation.md)')


#: The keys live adaptation may estimate (``adaptation.keys``), in the order of its state.
ADAPTABLE_KEYS: tuple[str, ...] = ('load.output_torque', 'load.output_viscous_coefficient',
                                   'mesh.backlash', 'mesh.worm_error_harmonics',
                                   'mesh.gear_error_harmonics')


@dataclass(frozen=True)
class AdaptationSettings:
    """Live adaptation of the model from measured_joint_states (worm_gear_sim.adaptation;
    docs/adaptation.md)."""

    enabled: bool = _f(False, 'Estimate adaptation.keys online from the encoders and update '
                       'the model used for prediction and correction')
    keys: tuple = _f(list(ADAPTABLE_KEYS), 'Which parameters may be adapted: any of '
                     + ', '.join(ADAPTABLE_KEYS))
    worm_error_orders: int = _f(3, 'Orders of the per-worm-turn error estimated (at least '
                                'those of mesh.worm_error_harmonics)', '', 1, MAX_ERROR_ORDERS)
    gear_error_orders: int = _f(1, 'Orders of the per-gear-turn error estimated', '', 1,
                                MAX_ERROR_ORDERS)
    memory: float = _f(20.0, 'Time constant over which the estimator forgets (each variance '
                       'grows by dt / memory, capped at its prior)', 's', 0.1, 1e6)
    window: float = _f(2.0, 'Window of the residual RMS that decides a switch (and the data '
                       'needed before the first)', 's', 0.1, 3600.0)
    min_improvement: float = _f(0.1, 'Share by which the adapted set must lower the windowed '
                                'mean-square residual of the model in use', '', 0.0, 0.99,
                                lo_open=True)
    max_step: float = _f(5e-3, 'Largest change of the static correction of the command per '
                         'applied step', 'rad', 0.0, 1.0, lo_open=True)
    step_interval: float = _f(0.25, 'Time between applied steps (and switch decisions)', 's',
                              0.01, 60.0)
    sample_delay: float = _f(0.05, 'An encoder sample stamped s enters the estimate at the '
                             'first prediction stamped >= s + sample_delay (what each '
                             'decision sees depends on the stamps only, not on when the '
                             'sample came; one that comes later enters at once and is '
                             'counted, late_samples); at most 0.1 s, below the 0.15 s '
                             'hold-off after an applied step', 's', 0.0, 0.1, lo_open=True)
    params_file: str = _f('worm_gear_sim_adapted.yaml', 'Where the node\'s '
                          '~/write_adapted_parameters service writes the params file of the '
                          'model in use (relative: to the working directory)')
    measurement_noise: float = _f(4e-6, 'RMS of what the theta4 residual keeps besides the '
                                  'adapted keys: encoder noise and steps, model error '
                                  '(measurement noise of the estimator)', 'rad', 0.0, 1.0,
                                  lo_open=True)


SECTIONS: dict[str, type] = {
    'geometry': Geometry,
    'materials': Materials,
    'shafts': Shafts,
    'mesh': Mesh,
    'friction': Friction,
    'damping': Damping,
    'load': Load,
    'integrator': Integrator,
    'input': InputProfile,
    'node': NodeSettings,
    'compensation': CompensationSettings,
    'adaptation': AdaptationSettings,
}
