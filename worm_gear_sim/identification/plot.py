# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""PNG figures of an identification: measured vs predicted (before / after the fit), the
residuals and the amplitude spectrum, per record and measured output, in µrad (matplotlib's
Agg canvas, no pyplot state)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..config.usable import Config
from ..dynamics.model import DriveModel
from ..dynamics.stepping import SimulationError
from ..records import Record
from .data import OUTPUTS, predict, record_name

__all__ = ['plot_fit', 'amplitude_spectrum', 'oscillating_part_label']

MAX_RECORDS = 6
URAD = 1e6            # rad -> µrad


def oscillating_part_label(output: str) -> str:
    """The name of ``output`` minus its rigid motion: theta2 - theta1 for the worm,
    theta3/theta4 - theta1 l_w/r_g for the gear and the antenna (the ratio 1:56 at the
    defaults)."""
    return f'{output} - theta1' if output == 'theta2' else f'{output} - theta1 l_w/r_g'


def amplitude_spectrum(t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(frequencies [Hz], amplitude [units of y]) of ``y`` minus its mean, resampled on a
    uniform grid over the record (Hann window; a sinusoid of amplitude A reads about A at its
    frequency)."""
    t, y = np.asarray(t, float), np.asarray(y, float)
    if t.size < 16:
        return np.zeros(0), np.zeros(0)
    tu = np.linspace(t[0], t[-1], t.size)
    yu = np.interp(tu, t, y)
    w = np.hanning(yu.size)
    amp = 2.0 * np.abs(np.fft.rfft((yu - yu.mean()) * w)) / w.sum()
    return np.fft.rfftfreq(yu.size, (tu[-1] - tu[0]) / (tu.size - 1)), amp


def plot_fit(records: Sequence[Record], before: DriveModel | Config,
             after: DriveModel | Config, path: str | Path, title: str = '',
             verdict: str = '') -> Path:
    """One column per record (at most MAX_RECORDS), per measured output two panels: its
    oscillating part (:func:`oscillating_part_label`) [µrad] measured, predicted by
    ``before`` and by ``after``, and the residuals predicted - measured of both; a last row:
    the amplitude spectrum of the last measured output's oscillating part, measured against
    both models, the model's first mode marked.  ``verdict`` (a calibration's) heads the
    figure."""
    recs = list(records)[:MAX_RECORDS]
    outputs = [o for o in OUTPUTS if any(o in r.measured for r in recs)]
    nrow, ncol = 2 * len(outputs) + 1, len(recs)
    fig = Figure(figsize=(max(6.0, 4.2 * ncol), 2.4 * nrow + 0.8), layout='constrained')
    FigureCanvasAgg(fig)
    ax = fig.subplots(nrow, ncol, squeeze=False)
    models = {'before': DriveModel.of(before), 'after': DriveModel.of(after)}
    rigid = models['after'].rigid_motion
    mode_hz = _first_mode_hz(models['after'])
    styles = {'before': dict(color='C3', lw=0.8, ls='--'), 'after': dict(color='C0', lw=0.9)}
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
            b.sharex(a)
            if o not in rec.measured:
                a.set_visible(False)
                b.set_visible(False)
                continue
            ref = rigid[OUTPUTS.index(o)] * th1
            meas = np.asarray(rec.measured[o])
            a.plot(t, (meas - ref) * URAD, color='k', lw=0.8, label='measured')
            for label in ('before', 'after'):
                pr = preds[label]
                if pr is None:
                    continue
                a.plot(t, (pr[o] - ref) * URAD, label=f'predicted, {label} the fit',
                       **styles[label])
                e = pr[o] - meas
                rms = float(np.sqrt(np.mean(e ** 2)))
                b.plot(t, e * URAD, label=f'{label}: RMS {rms * URAD:.3g} µrad',
                       **styles[label])
            a.set_ylabel(f'{oscillating_part_label(o)} [µrad]', fontsize=8)
            b.set_ylabel(f'{o} predicted - measured [µrad]', fontsize=8)
            b.axhline(0.0, color='0.6', lw=0.5)
            for x in (a, b):
                x.ticklabel_format(axis='y', useOffset=False, style='plain')
                x.legend(fontsize=7, loc='upper right')
            b.set_xlabel('t [s]', fontsize=8)
            if k == 0:
                a.set_title(record_name(rec, c), fontsize=9)
        _spectrum(ax[-1, c], rec, preds, outputs, rigid, mode_hz, styles)
    head = ' — '.join(x for x in (title, verdict) if x)
    if head:
        fig.suptitle(head, fontsize=10)
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100, format='png')
    return out


def _first_mode_hz(model: DriveModel) -> float:
    try:
        from ..dynamics.modal import modes
        return float(modes(model).undamped_hz[0])
    except (ValueError, ArithmeticError):
        return float('nan')


def _spectrum(a: Any, rec: Record, preds: dict, outputs: list[str], rigid: Any,
              mode_hz: float, styles: dict) -> None:
    """The frequency panel of one record (:func:`plot_fit`)."""
    o = next((x for x in reversed(outputs) if x in rec.measured), None)
    if o is None:
        a.set_visible(False)
        return
    t, ref = np.asarray(rec.t), rigid[OUTPUTS.index(o)] * np.asarray(rec.theta1)
    f, amp = amplitude_spectrum(t, np.asarray(rec.measured[o]) - ref)
    if not f.size:
        a.set_visible(False)
        return
    top = min(float(f[-1]), 5.0 * mode_hz if mode_hz > 0 else float(f[-1]))
    sel = (f > 0) & (f <= top)
    a.semilogy(f[sel], amp[sel] * URAD, color='k', lw=0.8, label='measured')
    for label in ('before', 'after'):
        pr = preds[label]
        if pr is not None:
            _, ap = amplitude_spectrum(t, pr[o] - ref)
            a.semilogy(f[sel], ap[sel] * URAD, label=f'model {label} the fit',
                       **styles[label])
    if 0 < mode_hz <= top:
        a.axvline(mode_hz, color='0.5', lw=0.8, ls=':', label=f'first mode {mode_hz:.4g} Hz '
                  '(fitted model)')
    a.set_xlabel('frequency [Hz]', fontsize=8)
    a.set_ylabel(f'amplitude of {oscillating_part_label(o)} [µrad]', fontsize=8)
    a.legend(fontsize=7, loc='upper right')
    a.grid(True, alpha=0.3, which='both')
