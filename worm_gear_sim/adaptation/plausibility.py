# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Whether an estimate of the live adaptation is plausible: said wherever it is published and
required of every target the adapter takes (an implausible estimate is never applied).

Plausible: its values make a valid parameter set with the model in use's others, its load
stays within ``load.max_elastic_windup``, and its windowed residual is not worse than the
model in use's by the switching margin.  docs/adaptation.md.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol

import numpy as np

from ..dynamics.load import elastic_load_limit
from ..dynamics.model import DriveModel
from ..schema.parameters import replaced

__all__ = ['values_problem', 'estimate_problem']

#: The last model and its elastic load limit (one tuple, replaced whole: thread safe).
_LIMIT: tuple[Any, float] = (None, 0.0)


class Estimating(Protocol):
    """What :func:`estimate_problem` reads of an estimator (:class:`~.estimator.Adapter`)."""

    theta: np.ndarray
    model: DriveModel
    layout: Any
    settings: Any

    def bounded(self, x: np.ndarray) -> tuple[np.ndarray, str]: ...

    def window_rms(self) -> dict[str, float]: ...


def values_problem(model: DriveModel, overrides: Mapping[str, Any]) -> str:
    """Why the adapted values ``overrides`` (dotted keys) are implausible with ``model``'s
    other values ('' when they are plausible): the first two rules of the module
    docstring."""
    try:
        cfg = replaced(model.config, overrides)
    except ValueError as exc:                  # ConfigError is a ValueError
        return str(exc)
    load = float(cfg.load.output_torque)
    if load != 0.0:
        global _LIMIT
        cached = _LIMIT                       # (the model in use changes at a step only)
        if cached[0] is not model:
            cached = _LIMIT = (model, elastic_load_limit(model))
        limit = cached[1]
        if abs(load) > limit:
            return (f'load.output_torque {load:.6g} N m is beyond what the drive carries '
                    f'elastically (|load| <= {limit:.6g} N m, load.max_elastic_windup = '
                    f'{model.config.load.max_elastic_windup:g} rad)')
    return ''


def estimate_problem(adapter: Estimating) -> str:
    """Why ``adapter``'s current estimate is implausible ('' when it is plausible): the
    rules of the module docstring."""
    cand, why = adapter.bounded(adapter.theta)
    why = why or values_problem(adapter.model, adapter.layout.overrides(cand))
    if why:
        return why
    rms = adapter.window_rms()
    est, cur = rms['estimate'], rms['applied']
    if cur * cur < (1.0 - adapter.settings.min_improvement) * est * est:
        return (f'its windowed residual RMS {est:.3g} rad is worse than that of the model in '
                f'use, {cur:.3g} rad, by more than adaptation.min_improvement')
    return ''
