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

import importlib
from typing import TYPE_CHECKING, Any

from . import kernel_cache as _kernel_cache

__version__ = '0.1.0'

_kernel_cache.choose_cache_dir()     # where the kernels are cached (kernel_cache), then
_kernel_cache.ensure_fresh_cache()   # before any kernel is compiled or loaded

#: public name -> submodule that defines it
_EXPORTS: dict[str, str] = {
    'ModalResult': 'dynamics.modal', 'damping_matrix': 'dynamics.modal',
    'modes': 'dynamics.modal', 'static_equilibrium': 'dynamics.modal',
    'DriveModel': 'dynamics.model',
    'Config': 'params', 'ConfigError': 'validation', 'Derived': 'derived',
    'default_config': 'params', 'derive': 'derived', 'load_config': 'config_io',
    'check_usable': 'params',
    'Profile': 'dynamics.profiles', 'RampProfile': 'dynamics.profiles',
    'SampledProfile': 'dynamics.profiles', 'SCurveProfile': 'dynamics.profiles',
    'StepProfile': 'dynamics.profiles', 'TrapezoidalProfile': 'dynamics.profiles',
    'make_profile': 'dynamics.profiles',
    'SimState': 'dynamics.trajectory', 'Trajectory': 'dynamics.trajectory',
    'SimulationError': 'dynamics.stepping', 'Simulator': 'dynamics.simulation',
    'simulate': 'dynamics.simulation', 'simulate_to_csv': 'dynamics.simulation',
    'simulate_batch': 'dynamics.batch', 'map_batch': 'dynamics.batch',
    'BatchError': 'dynamics.batch', 'BatchFailure': 'dynamics.batch',
    'Compensator': 'compensation', 'feedforward_series': 'realtime',
    'RealtimePredictor': 'realtime',
    'resolve_config': 'config_io', 'params_document': 'config_io',
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
    from .compensation import Compensator
    from .config_io import load_config, params_document, resolve_config
    from .derived import Derived, derive
    from .dynamics.batch import BatchError, BatchFailure, map_batch, simulate_batch
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
    from .params import Config, check_usable, default_config
    from .realtime import RealtimePredictor, feedforward_series
    from .validation import ConfigError


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    value = getattr(importlib.import_module(f'.{module}', __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
