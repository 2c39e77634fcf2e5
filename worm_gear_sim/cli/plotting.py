# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""PNG figures for the CLI (on the Agg canvas of :mod:`worm_gear_sim.studies.figures`; pyplot
and its global backend state are never touched, so importing this module is safe
anywhere)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from ..studies.figures import error_magnitudes, new_figure, save_figure

__all__ = ['plot_adaptation', 'plot_trajectory', 'trajectory_figure', 'mesh_zoom_window',
           'plot_experiment', 'plot_sweep', 'plot_modes',
           'plot_traces']

_STYLES = ('-o', '-s', '-^', '-D', '-v', '-x', '-*', '-P')


#: Periods of the mesh load's oscillation shown in the zoom of :func:`plot_trajectory`, and
#: in each bin of the normal force's range over the whole run (at most ENVELOPE_BINS bins).
ZOOM_CYCLES = 3
ENVELOPE_BINS = 200


def _mesh_oscillation(traj: Any) -> tuple[float, float]:
    """(the instant the command stops, the normal force's dominant frequency after it [Hz]
    or nan); from the start when the command moves over the last tenth of the run."""
    from ..dynamics.spectrum import dominant_frequency
    t, wn = np.asarray(traj.t, float), np.asarray(traj.normal_force, float)
    moving = np.flatnonzero(np.diff(np.asarray(traj.theta1, float)) != 0.0)
    start = float(t[moving[-1] + 1]) if moving.size else float(t[0])
    if t[-1] - start < 0.1 * (t[-1] - t[0]):
        start = float(t[0])
    sel = t >= start
    return start, dominant_frequency(t[sel], wn[sel], f_min=2.0 / max(t[-1] - start, 1e-9))


def mesh_zoom_window(traj: Any) -> tuple[float, float]:
    """The window [s] of the mesh quantities' zoom: ZOOM_CYCLES periods of the normal
    force's dominant oscillation from the instant the command stops (:func:`_mesh_oscillation`;
    20 ms when no oscillation stands out)."""
    t = np.asarray(traj.t, float)
    if t.size < 2:
        return (float(t[0]), float(t[0])) if t.size else (0.0, 0.0)
    start, f = _mesh_oscillation(traj)
    width = ZOOM_CYCLES / f if math.isfinite(f) and f > 0 else 0.02
    width = max(width, 20 * float(t[1] - t[0]))
    return start, min(float(t[-1]), start + width)


def trajectory_figure(traj: Any, title: str = '') -> Figure:
    """Angles, errors and the mesh quantities of one run (:func:`plot_trajectory`): the
    normal force's range over the run (it changes flank at the antenna's ringing, a
    barcode at full length) and a zoom on ZOOM_CYCLES periods with the friction
    coefficient (:func:`mesh_zoom_window`)."""
    fig, ax = new_figure(4, 1, (8.0, 10.5))
    t = traj.t
    ratio = traj.output_per_input
    a = ax[0, 0]
    a.plot(t, traj.theta1, 'k--', lw=1, label='theta1 (command)')
    a.plot(t, traj.theta2, lw=1, label='theta2 (worm)')
    a.plot(t, traj.theta4 / ratio, lw=1, label='theta4 r_g/l_w (antenna, scaled)')
    a.set_ylabel('angle [rad]')
    a.legend(loc='lower right', fontsize=8)
    a.set_title(title or f'worm_gear_sim: {traj.profile}', fontsize=10)
    a = ax[1, 0]
    a.plot(t, traj.worm_error, lw=0.8, label='theta2 - theta1')
    a.plot(t, traj.output_error, lw=0.8, label='theta4 - theta1 l_w/r_g')
    a.set_ylabel('error [rad]')
    a.legend(loc='upper right', fontsize=8)
    t0, t1 = mesh_zoom_window(traj)
    a = ax[2, 0]
    wn = np.asarray(traj.normal_force, float)
    f = _mesh_oscillation(traj)[1] if len(t) > 1 else math.nan
    cycles = (t[-1] - t[0]) * f / ZOOM_CYCLES if math.isfinite(f) and f > 0 else math.inf
    bins = [e for e in np.array_split(np.arange(len(t)), int(min(ENVELOPE_BINS, len(t),
                                                                  max(1.0, cycles))))
            if e.size]
    edges = [float(t[e[0]]) for e in bins] + [float(t[-1])]
    lo, hi = [float(wn[e].min()) for e in bins], [float(wn[e].max()) for e in bins]
    a.stairs(hi, edges, baseline=lo, fill=True, color='C2', alpha=0.5, label='W_n: range')
    a.axvspan(t0, t1, color='0.75', zorder=0, label='the zoom below')
    a.axhline(0.0, color='0.4', lw=0.6)
    a.set_ylabel('W_n [N]', color='C2')
    a.set_title(f'normal force on the teeth: its range over each {len(bins)}th of the run '
                '(sign: the flank in contact)', fontsize=9)
    a.legend(loc='upper right', fontsize=8)
    a = ax[3, 0]
    sel = (t >= t0) & (t <= t1)
    a.plot(t[sel] * 1e3, wn[sel], lw=1.0, color='C2')
    a.set_ylabel('W_n [N]', color='C2')
    a.set_xlim(t0 * 1e3, t1 * 1e3)
    a.set_xlabel('t [ms]')
    b = a.twinx()
    b.plot(t[sel] * 1e3, np.asarray(traj.friction_coefficient)[sel], lw=0.8, color='C3')
    b.set_ylabel('friction coefficient mu (signed)', color='C3')
    a.set_title(f'zoom: {ZOOM_CYCLES} periods of the mesh load, t = {t0 * 1e3:.4g} to '
                f'{t1 * 1e3:.4g} ms', fontsize=9)
    for row in ax[:3, 0]:
        row.set_xlabel('t [s]')
    for row in ax[:, 0]:
        row.grid(True, alpha=0.3)
    return fig


def plot_trajectory(traj: Any, path: str | Path, title: str = '') -> Path:
    """Angles, errors and mesh quantities of one run (simulate): :func:`trajectory_figure`
    as a PNG."""
    return save_figure(trajectory_figure(traj, title), path)


def plot_experiment(trajs: Mapping[str, Any], rows: Sequence[Mapping[str, Any]],
                    path: str | Path, t_move: float = 0.0, zoom: float = 0.03) -> Path:
    """Oscillating parts (paper Figs. 10-11): theta2 - theta1 and theta4 - theta1 l_w/r_g,
    nonlinear (solid) vs linear (dashed), one column per lead convention; rows 2 and 4 zoom
    on the ``zoom`` seconds after the move."""
    convs = sorted({k.split('/')[1] for k in trajs}, key=lambda c: c != 'kinematic')
    fig, ax = new_figure(4, len(convs), (6.0 * len(convs), 12.0))
    panels = (('worm_error', 1e6, 'theta2 - theta1 [urad]', False),
              ('worm_error', 1e6, 'theta2 - theta1 [urad]', True),
              ('output_error', 1e3, 'theta4 - theta1 l_w/r_g [mrad]', False),
              ('output_error', 1e3, 'theta4 - theta1 l_w/r_g [mrad]', True))
    for j, conv in enumerate(convs):
        for i, (attr, scale, ylabel, zoomed) in enumerate(panels):
            a = ax[i, j]
            for model, style in (('nonlinear', '-'), ('linear', '--')):
                tr = trajs.get(f'{model}/{conv}')
                if tr is None:
                    continue
                t, y = tr.t, getattr(tr, attr)
                if zoomed:
                    sel = (t >= t_move) & (t <= t_move + zoom)
                    t, y = t[sel], y[sel]
                a.plot(t * 1e3, y * scale, style, lw=0.8 if zoomed else 0.6, label=model)
            a.set_ylabel(ylabel)
            a.grid(True, alpha=0.3)
            a.legend(fontsize=8, loc='upper right')
            if t_move > 0 and not zoomed:
                a.axvline(t_move * 1e3, color='0.6', lw=0.8, ls=':')
            if zoomed:
                a.set_title(f'zoom: {zoom * 1e3:g} ms after the move', fontsize=9)
        ax[0, j].set_title(f'lead convention: {conv}', fontsize=10)
        ax[3, j].set_xlabel('t [ms]')
    fig.suptitle('18-step move: oscillating parts (paper Figs. 10-11); dotted: end of move',
                 fontsize=10)
    return save_figure(fig, path)


def _series(rows: Sequence[Mapping[str, Any]]) -> dict[str, list[Mapping[str, Any]]]:
    out: dict[str, list[Mapping[str, Any]]] = {}
    for r in rows:
        out.setdefault(str(r['series']), []).append(r)
    return out


def plot_sweep(rows: Sequence[Mapping[str, Any]], path: str | Path, title: str,
               x_label: str, x_log: bool = False, categorical: bool = False) -> Path:
    """Max oscillation amplitudes of theta2 and theta4 per case (paper Figs. 14-18)."""
    fig, ax = new_figure(1, 2, (11.0, 4.4))
    groups = _series(rows)
    for i, (key, label) in enumerate((('amp2', 'theta2 (worm)'), ('amp4', 'theta4 (antenna)'))):
        a = ax[0, i]
        if categorical:
            labels = list(dict.fromkeys(str(r['label']) for r in rows))
            width = 0.8 / max(1, len(groups))
            for k, (name, rs) in enumerate(groups.items()):
                pos = [labels.index(str(r['label'])) + (k - (len(groups) - 1) / 2) * width
                       for r in rs]
                a.bar(pos, [r[key] for r in rs], width=width, label=name)
            a.set_xticks(range(len(labels)))
            a.set_xticklabels(labels, rotation=30 if len(labels) > 4 else 0, fontsize=8)
        else:
            for k, (name, rs) in enumerate(groups.items()):
                rs = sorted(rs, key=lambda r: r['x'])
                a.plot([r['x'] for r in rs], [r[key] for r in rs], _STYLES[k % len(_STYLES)],
                       ms=4, lw=1, label=name)
            if x_log:
                a.set_xscale('log')
        vals = [r[key] for r in rows if isinstance(r[key], float) and math.isfinite(r[key])]
        if vals and min(vals) > 0 and max(vals) / min(vals) > 30:
            a.set_yscale('log')
        elif vals:
            a.set_ylim(0.0, 1.12 * max(vals) if max(vals) > 0 else 1.0)
        a.set_title(f'max |{label.split()[0]} - equilibrium| after the move', fontsize=9)
        a.set_ylabel(f'amplitude of {label} [rad]')
        a.set_xlabel(x_label)
        a.grid(True, alpha=0.3, which='both')
        a.legend(fontsize=7)
    fig.suptitle(title, fontsize=10)
    return save_figure(fig, path)


def plot_traces(trajs: Mapping[str, Any], path: str | Path, title: str,
                t_move: float = 0.0) -> Path:
    """Oscillating parts of a few runs on common axes (paper Figs. 12-13 style)."""
    fig, ax = new_figure(2, 1, (8.0, 6.5))
    for k, (name, tr) in enumerate(trajs.items()):
        ax[0, 0].plot(tr.t * 1e3, tr.worm_error * 1e6, lw=0.7, label=name, color=f'C{k}')
        ax[1, 0].plot(tr.t * 1e3, tr.output_error * 1e6, lw=0.7, label=name, color=f'C{k}')
    ax[0, 0].set_ylabel('theta2 - theta1 [urad]')
    ax[1, 0].set_ylabel('theta4 - theta1 l_w/r_g [urad]')
    ax[1, 0].set_xlabel('t [ms]')
    for a in ax[:, 0]:
        a.grid(True, alpha=0.3)
        a.legend(fontsize=8, loc='upper right')
        if t_move > 0:
            a.axvline(t_move * 1e3, color='0.6', lw=0.8, ls=':')
    fig.suptitle(title, fontsize=10)
    return save_figure(fig, path)


def plot_modes(result: Any, path: str | Path, title: str = '') -> Path:
    """Mode shapes (theta2, theta3, theta4) as bars, one panel per mode."""
    n = len(result.undamped_hz)
    fig, ax = new_figure(1, n, (3.6 * n, 3.4))
    names = ('theta2', 'theta3', 'theta4')
    for i in range(n):
        a = ax[0, i]
        a.bar(names, np.asarray(result.shapes[:, i]), color=['C0', 'C1', 'C2'])
        a.axhline(0.0, color='k', lw=0.6)
        a.set_ylim(-1.1, 1.1)
        a.set_title(f'mode {i + 1}: {result.frequencies_hz[i]:.1f} Hz, '
                    f'zeta {result.damping_ratios[i]:.2e}', fontsize=9)
        a.grid(True, alpha=0.3)
    fig.suptitle(title or 'Linearised modes (max |entry| = 1)', fontsize=10)
    return save_figure(fig, path)


def plot_error_study(rows: Sequence[Mapping[str, Any]], path: str | Path, title: str,
                     x_label: str) -> Path:
    """Antenna error RMS (whole run, reversal) and static error per case, one line per
    series (uncompensated / compensated): ``sweep play`` and ``sweep gust``."""
    fig, ax = new_figure(1, 3, (13.0, 4.2))
    series = dict.fromkeys(str(r['series']) for r in rows)
    panels = (('rms_err4', 'RMS antenna error, whole slew [rad]'),
              ('reversal_rms_err4', 'RMS antenna error, reversal [rad]'),
              ('static_err4', '|static error| after the stop [rad]'))
    for a, (key, label) in zip(ax[0], panels):
        for s in series:
            rs = [r for r in rows if r['series'] == s]
            a.semilogy([r['x'] for r in rs], [max(abs(r[key]), 1e-12) for r in rs], 'o-',
                       label=s)
        a.set_xlabel(x_label)
        a.set_ylabel(label)
        a.grid(True, which='both', alpha=0.3)
        a.legend()
    fig.suptitle(title)
    return save_figure(fig, path)


def plot_reversal_study(rows: Sequence[Mapping[str, Any]], path: str | Path,
                        title: str) -> Path:
    """``sweep reversal``: the reversal-window RMS antenna error of each series, one panel
    per move, one line per load and preview (:mod:`worm_gear_sim.studies.backlash_reversal`)."""
    moves = list(dict.fromkeys(str(r['move']) for r in rows))
    fig, ax = new_figure(1, len(moves), (6.5 * len(moves), 4.6))
    for a, mv in zip(ax[0], moves):
        rs = [r for r in rows if r['move'] == mv]
        series = list(dict.fromkeys(str(r['series']) for r in rs))
        for ld, pv in dict.fromkeys((r['load'], r['preview_ms']) for r in rs):
            case = {r['series']: r for r in rs if (r['load'], r['preview_ms']) == (ld, pv)}
            a.semilogy(range(len(series)), [case[s]['reversal_rms_err4'] for s in series],
                       'o-', label=f'{ld}, preview {pv:.3g} ms')
        a.set_xticks(range(len(series)))
        a.set_xticklabels(series, rotation=30, ha='right', fontsize=8)
        a.set_ylabel('RMS antenna error around the reversal [rad]')
        a.set_title(f'{mv} reversal', fontsize=9)
        a.grid(True, which='both', alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    return save_figure(fig, path)


def plot_adaptation(run: Any, path: str | Path, title: str = '') -> Path:
    """The offline adaptation twin (:mod:`worm_gear_sim.studies.adaptation_twin`): the reference,
    the antenna error without and with the adapting feed-forward, and the latter on its own
    (log) scale with the times the model was stepped."""
    fig, ax = new_figure(3, 1, (9.0, 8.5))
    t = run.t
    ax[0, 0].plot(t, run.theta1_ref, lw=1, color='k')
    ax[0, 0].set_ylabel('theta1_ref [rad]')
    a = ax[1, 0]
    a.plot(t, run.error_uncompensated * 1e6, lw=0.6, label='uncompensated')
    a.plot(t, run.error_compensated * 1e6, lw=0.6, label='adapting feed-forward')
    a.set_ylabel('antenna error [urad]')
    a.legend(loc='best', fontsize=8)
    error_magnitudes(ax[2, 0], t, [(run.error_uncompensated, '|uncompensated|',
                                    {'alpha': 0.6}),
                                   (run.error_compensated, '|adapting feed-forward|', {})],
                     run.steps, color='0.7', lw=0.5)
    fig.suptitle(title or 'worm_gear_sim: live adaptation (offline twin)', fontsize=10)
    return save_figure(fig, path)
