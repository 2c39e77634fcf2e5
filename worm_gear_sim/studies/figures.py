# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""PNG figures on matplotlib's Agg canvas (pyplot and its global backend state are never
touched; matplotlib loads when the first figure is made): the canvas of every figure of the
package's commands (:func:`new_figure`, :func:`save_figure`), the magnitude of adapting
errors (:func:`error_magnitudes`) and the figures of the tracking passes
(:mod:`.tracking_pass`, :mod:`.adaptive_pass`)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ['new_figure', 'save_figure', 'error_magnitudes', 'plot_pass', 'plot_adaptive_pass']

_DPI = 100


def new_figure(nrows: int, ncols: int, size: tuple[float, float]) -> tuple[Any, Any]:
    """A figure of ``size`` inches on an Agg canvas and its ``nrows`` x ``ncols`` axes (a
    2-D array)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    fig = Figure(figsize=size, layout='constrained')
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=False)
    return fig, axes


def save_figure(fig: Any, path: str | Path) -> Path:
    """``fig`` as a PNG at ``path`` (its folder made)."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(p, dpi=_DPI, format='png')
    return p


def error_magnitudes(a: Any, t: np.ndarray, series: Sequence[tuple[np.ndarray, str, dict]],
                     steps: Sequence[tuple[float, Any]], **step_style: Any) -> None:
    """On the axes ``a``: the magnitude of each error of ``series`` ((error [rad], label,
    line style)) in urad on a log scale (an error with no finite value left out), and a
    vertical line (``step_style``) at each time the adapting model was stepped."""
    for e, label, style in series:
        if np.isfinite(e).any():
            a.semilogy(t, np.abs(e) * 1e6 + 1e-3, lw=0.4, label=label, **style)
    for ts, _ in steps:
        a.axvline(ts, **step_style)
    a.set_ylabel('|error| [urad] (grey: model steps)')
    a.set_xlabel('t [s]')
    a.legend(loc='best', fontsize=8)


def plot_pass(result: Any, path: str | Path, title: str = '') -> Path:
    """A tracking pass (:mod:`worm_gear_sim.studies.tracking_pass`): per axis, the antenna
    angle, the pointing error with and without compensation, and the compensated error on
    its own scale."""
    joints = list(result.raw_error)
    fig, ax = new_figure(3, len(joints), (5.0 * len(joints), 8.5))
    t = result.t
    for k, j in enumerate(joints):
        a = ax[0, k]
        a.plot(t, result.reference[j], lw=1, color='k')
        a.set_ylabel('antenna reference [rad]')
        a.set_title(f'{j}', fontsize=9)
        a = ax[1, k]
        a.plot(t, result.raw_error[j] * 1e6, lw=0.8, label='raw trajectory')
        a.plot(t, result.compensated_error[j] * 1e6, lw=0.8, label='compensated')
        a.set_ylabel('pointing error [urad]')
        a.legend(loc='best', fontsize=8)
        a = ax[2, k]
        a.plot(t, result.compensated_error[j] * 1e6, lw=0.8, color='C1')
        a.set_ylabel('compensated error [urad]')
        a.set_xlabel('t [s]')
    fig.suptitle(title or 'worm_gear_sim: tracking pass', fontsize=10)
    return save_figure(fig, path)


def plot_adaptive_pass(axes: Sequence[Any], path: str | Path, title: str = '') -> Path:
    """A pass with live adaptation (:mod:`worm_gear_sim.studies.adaptive_pass`): per axis,
    the pointing error uncompensated, with the nominal feed-forward and with the adapting
    one, and their magnitudes on a log scale with the times the model was stepped."""
    fig, ax = new_figure(2, len(axes), (5.5 * len(axes), 7.0))
    for k, a_ in enumerate(axes):
        t = a_.t
        a = ax[0, k]
        a.plot(t, a_.uncompensated * 1e6, lw=0.6, label='uncompensated')
        if np.isfinite(a_.nominal).any():
            a.plot(t, a_.nominal * 1e6, lw=0.6, label='nominal feed-forward')
        a.plot(t, a_.adapted * 1e6, lw=0.6, label='adapting feed-forward')
        a.set_ylabel('pointing error [urad]')
        a.set_title(a_.name, fontsize=9)
        a.legend(loc='best', fontsize=8)
        error_magnitudes(ax[1, k], t, [(a_.uncompensated, '|uncompensated|', {}),
                                       (a_.nominal, '|nominal|', {}),
                                       (a_.adapted, '|adapting|', {})],
                         getattr(a_.run, 'steps', []), color='0.8', lw=0.4)
    fig.suptitle(title or 'worm_gear_sim: pass with live adaptation', fontsize=10)
    return save_figure(fig, path)
