# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""worm_gear_sim: nonlinear dynamics of a worm and worm-gear drive (Chung & Shaw 2007).

The computational core (this package minus ``ros/``) never imports rclpy; the layout and
its import rules: docs/architecture.md.

    >>> from worm_gear_sim import load_config, simulate
    >>> traj = simulate(load_config())          # the paper's 18-step move, 0.5 s
    >>> traj.output_error[-1]                   # antenna error theta4 - theta1 l_w/r_g [rad]

The names below are imported on first use (PEP 562): importing the package itself loads
no numpy/scipy/numba, so the entry points (``python -m worm_gear_sim.ros``) can install
their signal handlers before the heavy imports start.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ._support import kernel_cache as _kernel_cache
from ._support.lazy import lazy_exports

__version__ = '0.1.0'

_kernel_cache.choose_cache_dir()     # where the kernels are cached (kernel_cache), then
_kernel_cache.ensure_fresh_cache()   # before any kernel is compiled or loaded

#: public name -> submodule that defines it
_EXPORTS: dict[str, str] = {
    'ModalResult': '.dynamics.modal', 'damping_matrix': '.dynamics.modal',
    'modes': '.dynamics.modal', 'static_equilibrium': '.dynamics.modal',
    'DriveModel': '.dynamics.model',
    'Config': '.config.usable', 'ConfigError': '.schema.validation',
    'Derived': '.dynamics.derived', 'default_config': '.config.usable',
    'derive': '.dynamics.derived', 'load_config': '.config.files',
    'check_usable': '.config.usable',
    'Profile': '.dynamics.profiles', 'RampProfile': '.dynamics.profiles',
    'SampledProfile': '.dynamics.profiles', 'SCurveProfile': '.dynamics.profiles',
    'StepProfile': '.dynamics.profiles', 'TrapezoidalProfile': '.dynamics.profiles',
    'make_profile': '.dynamics.profiles',
    'SimState': '.dynamics.trajectory', 'Trajectory': '.dynamics.trajectory',
    'SimulationError': '.dynamics.stepping', 'Simulator': '.dynamics.simulation',
    'simulate': '.dynamics.simulation', 'simulate_to_csv': '.dynamics.simulation',
    'simulate_batch': '.parallel.threads', 'map_batch': '.parallel.threads',
    'BatchError': '.parallel.threads', 'BatchFailure': '.parallel.threads',
    'Compensator': '.compensation.streaming', 'feedforward_series': '.realtime',
    'RealtimePredictor': '.realtime',
    'resolve_config': '.config.files', 'params_document': '.config.files',
}

__all__ = [
    'Config', 'ConfigError', 'Derived', 'default_config', 'derive', 'load_config',
    'check_usable', 'DriveModel', 'simulate_to_csv', 'Profile', 'StepProfile', 'RampProfile',
    'TrapezoidalProfile', 'SCurveProfile', 'SampledProfile', 'make_profile', 'Simulator',
    'Trajectory', 'SimState',
    'SimulationError', 'simulate', 'simulate_batch', 'map_batch', 'BatchError', 'BatchFailure',
    'modes', 'ModalResult', 'static_equilibrium',
    'damping_matrix', 'Compensator', 'feedforward_series', 'RealtimePredictor',
    'resolve_config', 'params_document', '__version__',
]

if TYPE_CHECKING:  # static analysers see the eager imports
    from .compensation.streaming import Compensator
    from .config.files import load_config, params_document, resolve_config
    from .config.usable import Config, check_usable, default_config
    from .dynamics.derived import Derived, derive
    from .dynamics.modal import ModalResult, damping_matrix, modes, static_equilibrium
    from .dynamics.model import DriveModel
    from .dynamics.profiles import (
        Profile,
        RampProfile,
        SampledProfile,
        SCurveProfile,
        StepProfile,
        TrapezoidalProfile,
        make_profile,
    )
    from .dynamics.simulation import Simulator, simulate, simulate_to_csv
    from .dynamics.stepping import SimulationError
    from .dynamics.trajectory import SimState, Trajectory
    from .parallel.threads import BatchError, BatchFailure, map_batch, simulate_batch
    from .realtime import RealtimePredictor, feedforward_series
    from .schema.validation import ConfigError

__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
