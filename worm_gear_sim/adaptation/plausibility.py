# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Whether an estimate of the live adaptation is plausible, said with the estimate wherever it
is published (``~/adapted_parameters``, the ``adaptation`` status) and required of every
target the adapter takes (:meth:`~.estimator.Adapter.poll`: an implausible estimate is never
applied).

An estimate is plausible when, taken as the switching rule takes it
(:meth:`~.estimator.Adapter.bounded`: a play or drag below zero within its uncertainty
taken as zero, one further below refused):

* its values make a valid parameter set with the model in use's other values: each within
  its range, the play within half a tooth pitch, the periodic error within its slope bound
  (:func:`~worm_gear_sim.schema.replaced`, the checks every parameter set passes);
* its load winds the antenna up by no more than ``load.max_elastic_windup``
  (:func:`~worm_gear_sim.dynamics.load.elastic_load_limit`: beyond it the drive does not carry
  the load elastically, and an estimate there explains something else, e.g. an encoder
  offset, as load);
* and, for the estimate as published, its windowed residual is not worse than the model in
  use's by the margin that decides a switch: the model in use would not be taken over it
  (its mean square lower by ``adaptation.min_improvement``).  An estimate as good as the
  model in use, within noise, is plausible; the adapter takes only one that is better by
  that margin.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from ..dynamics.load import elastic_load_limit
from ..dynamics.model import DriveModel
from ..schema import replaced

if TYPE_CHECKING:
    from .estimator import Adapter

__all__ = ['values_problem', 'estimate_problem']

#: The last model and its elastic load limit (one tuple, replaced whole: thread safe).
_LIMIT: tuple[Any, float] = (None, 0.0)


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


def estimate_problem(adapter: Adapter) -> str:
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
