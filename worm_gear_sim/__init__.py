# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""worm_gear_sim: nonlinear dynamics of a worm and worm-gear drive (Chung & Shaw 2007).

The computational core (this package minus ``node``) never imports rclpy.

    >>> from worm_gear_sim import load_config, simulate
    >>> traj = simulate(load_config())          # the paper's 18-step move, 0.5 s
    >>> traj.output_error[-1]                   # antenna error theta4 - theta1 l_w/r_g [rad]
"""

from .modal import ModalResult, damping_matrix, modes, static_equilibrium
from .params import Config, ConfigError, Derived, default_config, derive, load_config
from .profiles import (
                       Profile,
                       RampProfile,
                       SampledProfile,
                       SCurveProfile,
                       StepProfile,
                       TrapezoidalProfile,
                       make_profile,
)
from .simulation import SimState, SimulationError, Simulator, Trajectory, simulate

__version__ = '0.1.0'

__all__ = [
    'Config', 'ConfigError', 'Derived', 'default_config', 'derive', 'load_config',
    'Profile', 'StepProfile', 'RampProfile', 'TrapezoidalProfile', 'SCurveProfile',
    'SampledProfile', 'make_profile', 'Simulator', 'Trajectory', 'SimState',
    'SimulationError', 'simulate', 'modes', 'ModalResult', 'static_equilibrium',
    'damping_matrix', '__version__',
]
