# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Antenna error against the mesh play and against the gust intensity, with and without the
feed-forward (``worm-gear-sim sweep play gust``): the radar slew on a plant with play
(``PLAYS_ARCMIN``) or wind (``GUST_INTENSITIES``).  docs/compensation.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..compensation.streaming import centring_preview
from ..config.usable import Config
from ..dynamics.load import WindLoad
from ..parallel.threads import map_like_serial
from .backlash_reversal import ARCMIN, REVERSAL_DAMPING
from .compensation_eval import radar_slew_scenario, run_scenario

__all__ = ['PLAYS_ARCMIN', 'GUST_INTENSITIES', 'play_rows', 'gust_rows',
           'PLAY_GUST_COLUMNS']

PLAYS_ARCMIN = (0.0, 0.5, 1.0, 2.0, 3.0, 5.0)
PLAY_LOAD = {'load.output_torque': 2.0, 'load.output_viscous_coefficient': 2.0}
GUST_INTENSITIES = (0.0, 0.05, 0.1, 0.2, 0.3)
GUST_MEAN = 5.0             # N m: the radar scenarios' steady wind torque
GUST_TIME_SCALE = 0.2       # s: gusts that vary within the 0.64 s slew
GUST_SEEDS = (1, 2, 3)
PLAY_GUST_COLUMNS = ['study', 'series', 'label', 'x', 'rms_err4', 'reversal_rms_err4',
                     'static_err4', 'max_err4', 'runs']


def _metrics(run: Any) -> dict[str, float]:
    sc = run.scenario
    t, e = run.trajectory.t, run.error
    rev = (t > sc.constant_rate[0][1]) & (t < sc.constant_rate[1][0] + 0.1)
    last = t > t[-1] - 0.05
    return {'rms_err4': float(np.sqrt(np.mean(e ** 2))),
            'reversal_rms_err4': float(np.sqrt(np.mean(e[rev] ** 2))),
            'static_err4': float(np.mean(e[last])), 'max_err4': float(np.max(np.abs(e)))}


def _run_all(jobs: Sequence[tuple], workers: int | None) -> list[dict[str, float]]:
    """The metrics of ``run_scenario(*job)`` for every job, on ``workers`` threads
    (:func:`~worm_gear_sim.parallel.threads.map_like_serial`; 1: in order in this thread): the
    same numbers either way; a failed run raises its own error."""
    return map_like_serial(lambda job: _metrics(run_scenario(*job)), jobs, workers=workers)


def play_rows(base: Config, plays_arcmin: Sequence[float] = PLAYS_ARCMIN,
              workers: int | None = None) -> list[dict]:
    """Rows of the play study (module docstring); the runs on ``workers`` threads."""
    rows, jobs = [], []
    for b in plays_arcmin:
        plant = base.replace({**PLAY_LOAD, **REVERSAL_DAMPING, 'mesh.backlash': float(b) * ARCMIN,
                              'compensation.backlash_inverse': True})
        sc = radar_slew_scenario(plant)
        blind = plant.replace({'compensation.backlash_inverse': False})
        ahead = plant.replace({'compensation.preview_time': centring_preview(plant)})
        for series, comp in (('uncompensated', None), ('blind', blind), ('compensated', plant),
                             ('compensated, preview', ahead)):
            jobs.append((plant, sc, comp))
            rows.append({'study': 'play', 'series': series, 'label': f'{b:g} arcmin',
                         'x': float(b), 'runs': 1})
    return [{**r, **m} for r, m in zip(rows, _run_all(jobs, workers))]


def gust_rows(base: Config, intensities: Sequence[float] = GUST_INTENSITIES,
              seeds: Sequence[int] = GUST_SEEDS, workers: int | None = None) -> list[dict]:
    """Rows of the gust study (module docstring): metrics averaged over the seeds (the
    static error as the mean of its magnitude); the runs on ``workers`` threads."""
    plant = base.replace({'load.output_torque': GUST_MEAN,
                          'load.output_viscous_coefficient': 2.0})
    sc = radar_slew_scenario(plant)
    rows: list[dict] = []
    jobs: list[tuple] = []
    for inten in intensities:
        for series, comp in (('uncompensated', None), ('compensated', plant)):
            jobs.extend((plant, sc, comp, 10, WindLoad(GUST_MEAN, float(inten),
                                                       GUST_TIME_SCALE, int(seed)))
                        for seed in seeds)
            rows.append({'study': 'gust', 'series': series, 'label': f'I = {inten:g}',
                         'x': float(inten), 'runs': len(seeds)})
    ms_all = _run_all(jobs, workers)
    out = []
    for i, r in enumerate(rows):
        ms = ms_all[i * len(seeds):(i + 1) * len(seeds)]
        m = {k: float(np.mean([abs(x[k]) if k == 'static_err4' else x[k] for x in ms]))
             for k in ms[0]}
        out.append({**r, **m})
    return out
