# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The feed-forward across the mesh play, measured on reversal moves (``worm-gear-sim sweep
reversal``).

Reversal moves on the base drive with play and 3 % modal damping, under ``REVERSAL_LOADS``;
series uncompensated, ``blind``, compensated, with the play mis-sized by 30 %, and without
play; the RMS antenna error over :func:`reversal_window`.  docs/compensation.md ("Across
the mesh play").
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..compensation.streaming import centring_preview
from ..config.usable import Config
from ..parallel.threads import map_like_serial
from .compensation_eval import CompensationRun, Scenario, radar_slew_scenario, run_scenario

__all__ = ['ARCMIN', 'REVERSAL_PLAY_ARCMIN', 'REVERSAL_DAMPING', 'REVERSAL_LOADS',
           'REVERSAL_MOVES', 'PLAY_ERRORS', 'REVERSAL_COLUMNS',
           'reversal_window', 'reversal_rms', 'reversal_case', 'reversal_rows']

ARCMIN = math.pi / 180.0 / 60.0
REVERSAL_PLAY_ARCMIN = 2.0
REVERSAL_DAMPING = {'damping.modal_damping_ratios': [0.03, 0.03, 0.03]}
REVERSAL_LOADS: dict[str, dict[str, Any]] = {
    'drag': {'load.output_torque': 0.0, 'load.output_viscous_coefficient': 2.0},
    'load': {'load.output_torque': 2.0, 'load.output_viscous_coefficient': 2.0},
}
#: antenna rate [rad/s] and acceleration [rad/s^2] of the reversal moves
REVERSAL_MOVES: dict[str, dict[str, float]] = {
    'slew': {'antenna_rate': 0.2, 'antenna_acceleration': 60.0},
    'slow': {'antenna_rate': 0.02, 'antenna_acceleration': 6.0},
}
PLAY_ERRORS = (-0.3, 0.3)
WINDOW_BEFORE, WINDOW_AFTER = 0.05, 0.1      # s around the reversal
REVERSAL_COLUMNS = ['study', 'move', 'load', 'preview_ms', 'series', 'play_used_arcmin',
                    'reversal_rms_err4', 'improvement', 'max_err4']


def reversal_window(scenario: Scenario) -> tuple[float, float]:
    """(start, end) [s] of the reversal window: from WINDOW_BEFORE before the first tracking
    phase ends to WINDOW_AFTER after the second one starts."""
    (_, a), (b, _) = scenario.constant_rate[:2]
    return a - WINDOW_BEFORE, b + WINDOW_AFTER


def reversal_rms(run: CompensationRun) -> float:
    """RMS antenna error [rad] of a run over its reversal window."""
    a, b = reversal_window(run.scenario)
    t = run.trajectory.t
    e = run.error[(t >= a) & (t <= b)]
    return float(np.sqrt(np.mean(e ** 2)))


def reversal_case(base: Config, move: str = 'slew', load: str = 'drag',
                  preview: bool = False,
                  play_arcmin: float = REVERSAL_PLAY_ARCMIN,
                  play_errors: Sequence[float] = PLAY_ERRORS) -> list[dict]:
    """Rows of one case (module docstring): every series on one reversal move."""
    plant = base.replace({**REVERSAL_DAMPING, **REVERSAL_LOADS[load],
                          'mesh.backlash': play_arcmin * ARCMIN,
                          'compensation.backlash_inverse': True})
    p_time = centring_preview(plant) if preview else 0.0
    plant = plant.replace({'compensation.preview_time': p_time})
    scenario = radar_slew_scenario(plant, **REVERSAL_MOVES[move])
    no_play = plant.replace({'mesh.backlash': 0.0})
    series: list[tuple[str, Config, Config | None, float]] = [
        ('uncompensated', plant, None, 0.0),
        ('blind', plant, plant.replace({'compensation.backlash_inverse': False}), 0.0),
        ('compensated', plant, plant, play_arcmin)]
    for f in play_errors:
        used = play_arcmin * (1.0 + f)
        series.append((f'play {f:+.0%}', plant,
                       plant.replace({'mesh.backlash': used * ARCMIN}), used))
    series.append(('no play', no_play, no_play, 0.0))
    rows = []
    off = math.nan
    for name, drive, comp, used in series:
        run = run_scenario(drive, scenario, comp)
        rms = reversal_rms(run)
        if name == 'uncompensated':
            off = rms
        rows.append({'study': 'reversal', 'move': move, 'load': load,
                     'preview_ms': p_time * 1e3, 'series': name, 'play_used_arcmin': used,
                     'reversal_rms_err4': rms, 'improvement': off / rms,
                     'max_err4': float(np.max(np.abs(run.error)))})
    return rows


def reversal_rows(base: Config, moves: Sequence[str] = tuple(REVERSAL_MOVES),
                  loads: Sequence[str] = tuple(REVERSAL_LOADS),
                  previews: Sequence[bool] = (False, True),
                  workers: int | None = None) -> list[dict]:
    """Rows of the whole study: every move x load x preview case, the cases on ``workers``
    threads (:func:`~worm_gear_sim.parallel.threads.map_like_serial`; 1: in order in this
    thread), the same rows either way."""
    cases = [(m, ld, pv) for m in moves for ld in loads for pv in previews]
    per_case = map_like_serial(lambda c: reversal_case(base, *c), cases, workers=workers)
    return [r for rows in per_case for r in rows]

