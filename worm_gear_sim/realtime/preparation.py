# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A configuration made ready for the pipeline, in steps (:mod:`worm_gear_sim._support.stepwise`).

:func:`prepare_steps` is :meth:`~.predictor.RealtimePredictor.prepare` (the model built
once, the simulator's parameters tried on a copy, the compensator designed), cut between its
pieces so that the node can run it a slice at a time between samples; :func:`design_steps`
the compensator's part (the predictor's own design at its start and on a reconfigure goes
through it too).  Each step is ~0.05-0.4 ms on an idle core.
"""

from __future__ import annotations

from typing import Any

from .._support.stepwise import Steps
from ..compensation.streaming import Compensator
from ..config.usable import Config
from ..dynamics.model import DriveModel
from ..dynamics.simulation import Simulator
from .outputs import Prepared

__all__ = ['prepare_steps', 'design_steps']


def design_steps(model: DriveModel, compensate: bool) -> Steps[Prepared]:
    """``model`` with its compensator designed (none when not ``compensate``; a design
    that fails: none, and why, the pipeline then runs uncompensated)."""
    if not compensate:
        return Prepared(model, None)
    try:
        return Prepared(model, (yield from Compensator.design_steps(model)))
    except Exception as exc:  # noqa: BLE001 - run uncompensated, say why
        return Prepared(model, None, f'{type(exc).__name__}: {exc}')


def prepare_steps(predictor: Any, config: DriveModel | Config, trial: Simulator | None = None
                  ) -> Steps[Prepared]:
    """:meth:`~.predictor.RealtimePredictor.prepare` of ``predictor`` in steps (it only
    reads the pipeline: its simulator, copied for the trial unless ``trial`` is given, and
    whether it compensates)."""
    model = DriveModel.of(config)         # (its config is the one given: not a cached one)
    yield
    sim = predictor.sim
    if sim is not None:
        (sim.trial_copy() if trial is None else trial).reconfigure(model)
        yield
    return (yield from design_steps(model, predictor.compensate))
