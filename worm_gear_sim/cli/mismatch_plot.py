# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Figures of ``sweep crossing`` and ``sweep mismatch`` (:mod:`worm_gear_sim.studies.
mismatch`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

__all__ = ['plot_crossing_study', 'plot_mismatch_study']


def _figure(ncols: int, width: float = 6.0, height: float = 4.2) -> tuple[Any, Any]:
    import matplotlib
    matplotlib.use('Agg', force=False)
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, ncols, figsize=(width * ncols, height), squeeze=False)
    return fig, axes[0]


def plot_crossing_study(rows: Sequence[Mapping[str, Any]], path: str | Path,
                        title: str) -> None:
    """Improvement against the play, one panel per drag, a line per load: the step
    crossing (dashed), the streaming soft crossing (dotted) and the planned soft crossing
    (solid); the 100x target dotted in black."""
    drags = sorted({float(r['drag']) for r in rows})
    loads = sorted({float(r['load_torque']) for r in rows})
    fig, axes = _figure(len(drags), 4.6)
    import matplotlib.pyplot as plt
    colors = plt.rcParams['axes.prop_cycle'].by_key()['color']
    for ax, drag in zip(axes, drags):
        for k, load in enumerate(loads):
            sel = sorted((r for r in rows if float(r['drag']) == drag
                          and float(r['load_torque']) == load),
                         key=lambda r: float(r['play_arcmin']))
            x = [float(r['play_arcmin']) for r in sel]
            c = colors[k % len(colors)]
            ax.plot(x, [float(r['step_x']) for r in sel], '--', color=c, alpha=0.6)
            if sel and 'stream_x' in sel[0]:
                ax.plot(x, [float(r['stream_x']) for r in sel], ':', color=c, alpha=0.8)
            ax.plot(x, [float(r['soft_x']) for r in sel], 'o-', color=c,
                    label=f'{load:g} N m')
        ax.axhline(100.0, color='k', ls=':', lw=1)
        ax.set_xscale('log')
        ax.set_yscale('log')
        plays = sorted({float(r['play_arcmin']) for r in rows})
        ax.set_xticks(plays, [f'{p:g}' for p in plays])
        ax.set_xticks([], minor=True)
        ax.set_xlabel('play [arcmin]')
        ax.set_title(f'drag {drag:g} N m s/rad')
        ax.grid(True, which='both', alpha=0.3)
    axes[0].set_ylabel('antenna error RMS: raw / compensated')
    axes[0].legend(title='load (solid: soft, dashed: step)', fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_mismatch_study(axis_rows: Sequence[Mapping[str, Any]],
                        drive_rows: Sequence[Mapping[str, Any]], path: str | Path,
                        title: str) -> None:
    """Left: improvement against the model's error, a line per axis and move.  Right (with
    ``drive_rows``): calibrate-then-compensate and the nominal model on each random drive,
    both moves, with the 30x / 50x targets."""
    fig, axes = _figure(2 if drive_rows else 1, 6.0)
    import matplotlib.pyplot as plt
    ax = axes[0]
    styles = {'sector': '-', 'slew': '--'}
    colors = plt.rcParams['axes.prop_cycle'].by_key()['color']
    names = list(dict.fromkeys(r['axis'] for r in axis_rows))
    for k, axis in enumerate(names):
        for mv in dict.fromkeys(r['move'] for r in axis_rows):
            sel = sorted((r for r in axis_rows if r['axis'] == axis and r['move'] == mv),
                         key=lambda r: float(r['error']))
            ax.plot([100 * float(r['error']) for r in sel],
                    [float(r['improvement']) for r in sel], styles.get(mv, ':'),
                    marker='o', ms=3, color=colors[k % len(colors)], label=f'{axis}, {mv}')
    ax.set_yscale('log')
    ax.set_xlabel("model's error [%]")
    ax.set_ylabel('antenna error RMS: raw / compensated')
    ax.grid(True, which='both', alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    ax.set_title('one model error at a time')
    if drive_rows:
        ax = axes[1]
        n = len(drive_rows)
        xs = list(range(n))
        bars = [(f'{m}{suffix}', f'{m}, {what}') for m in ('sector', 'slew')
                for suffix, what in (('_nominal_x', 'nominal model'), ('_x', 'calibrated'))
                if f'{m}_x' in drive_rows[0]]
        w = 0.8 / max(len(bars), 1)
        for j, (col, lab) in enumerate(bars):
            ax.bar([x + (j - 0.5 * (len(bars) - 1)) * w for x in xs],
                   [float(r[col]) for r in drive_rows], w, label=lab,
                   color=colors[j % len(colors)])
        for x, r in zip(xs, drive_rows):
            if r['accepted'] not in (True, 'True', 'true'):
                ax.text(x, 1.4, 'refused', rotation=90, ha='center', va='bottom', fontsize=6)
        ax.axhline(30.0, color='k', ls=':', lw=1)
        ax.axhline(50.0, color='k', ls='--', lw=1)
        ax.set_yscale('log')
        ax.set_xticks(xs)
        ax.set_xlabel('random drive')
        ax.set_title('calibrate, then compensate')
        ax.legend(fontsize=7)
        ax.grid(True, axis='y', which='both', alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
