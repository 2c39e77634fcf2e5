# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""PNG figures of an identification: measured vs predicted (before / after the fit) and the
residuals, per record and measured output (matplotlib's Agg canvas, no pyplot state)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..dynamics.model import DriveModel
from ..dynamics.stepping import SimulationError
from ..params import Config
from ..records import Record
from .data import OUTPUTS, predict, record_name

__all__ = ['plot_fit']

MAX_RECORDS = 6


def plot_fit(records: Sequence[Record], before: DriveModel | Config,
             after: DriveModel | Config, path: str | Path, title: str = '') -> Path:
    """One column per record (at most MAX_RECORDS), per measured output two panels: the
    oscillating part theta_i - theta1 u_rigid [rad] measured, predicted by ``before`` and by
    ``after``; and the residuals predicted - measured of both."""
    recs = list(records)[:MAX_RECORDS]
    outputs = [o for o in OUTPUTS if any(o in r.measured for r in recs)]
    nrow, ncol = 2 * len(outputs), len(recs)
    fig = Figure(figsize=(max(6.0, 4.2 * ncol), 2.4 * nrow + 0.6), layout='constrained')
    FigureCanvasAgg(fig)
    ax = fig.subplots(nrow, ncol, squeeze=False, sharex='col')
    models = {'before': DriveModel.of(before), 'after': DriveModel.of(after)}
    rigid = models['after'].rigid_motion
    for c, rec in enumerate(recs):
        preds: dict[str, dict[str, np.ndarray] | None] = {}
        for label, model in models.items():
            try:
                preds[label] = predict(model, rec)
            except (SimulationError, ValueError):
                preds[label] = None
        t = np.asarray(rec.t)
        th1 = np.asarray(rec.theta1)
        for k, o in enumerate(outputs):
            a, b = ax[2 * k, c], ax[2 * k + 1, c]
            if o not in rec.measured:
                a.set_visible(False)
                b.set_visible(False)
                continue
            ref = rigid[OUTPUTS.index(o)] * th1
            meas = np.asarray(rec.measured[o])
            a.plot(t, meas - ref, color='k', lw=0.8, label='measured')
            for label, style in (('before', dict(color='C3', lw=0.8, ls='--')),
                                 ('after', dict(color='C0', lw=0.9))):
                pr = preds[label]
                if pr is None:
                    continue
                a.plot(t, pr[o] - ref, label=f'predicted, {label} the fit', **style)
                e = pr[o] - meas
                rms = float(np.sqrt(np.mean(e ** 2)))
                b.plot(t, e, label=f'{label}: RMS {rms:.3g} rad', **style)
            a.set_ylabel(f'{o} - theta1 u [rad]', fontsize=8)
            b.set_ylabel(f'{o} residual [rad]', fontsize=8)
            b.axhline(0.0, color='0.6', lw=0.5)
            a.legend(fontsize=7, loc='upper right')
            b.legend(fontsize=7, loc='upper right')
            if k == 0:
                a.set_title(record_name(rec, c), fontsize=9)
        ax[-1, c].set_xlabel('t [s]')
    if title:
        fig.suptitle(title, fontsize=10)
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100, format='png')
    return out
