# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``compensate``: a move with and without the feed-forward correction.

Writes a CSV of the two runs (SI units, rad) and a PNG plot, and prints the evaluation
metrics (:mod:`worm_gear_sim.studies.compensation_eval`) with and without compensation.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..compensation.streaming import Compensator
from ..config.files import resolve_config
from ..dynamics.model import DriveModel
from ..dynamics.profiles import make_profile, motion_span
from ..records import write_csv_columns
from ..studies.compensation_eval import (
    DETUNINGS,
    METRICS,
    RADAR_LOAD,
    Scenario,
    detuned,
    improvement,
    paper_step_scenario,
    radar_slew_scenario,
    run_scenario,
)
from .common import CliError, add_config_options

SCENARIOS = ('step', 'slew', 'config')


def register(sub: Any) -> None:
    """Add the ``compensate`` command to the subparsers ``sub``."""
    p = sub.add_parser(
        'compensate', help='a move with and without feed-forward compensation: CSV + PNG',
        description='Run a reference move on the nonlinear model (plant, optionally detuned) '
        'with and without the feed-forward correction of worm_gear_sim.compensation.streaming '
        '(designed on the nominal config), stream the reference at node.publish_rate_hz, '
        'and write both runs as CSV plus a PNG plot. Prints residual oscillation, '
        'settling time (10 urad), static error and constant-rate RMS tracking error.')
    add_config_options(p, end_time=False)
    p.add_argument('--scenario', choices=SCENARIOS, default='step',
                   help="step: the paper's 18-step move (input.* move size and timing); "
                   'slew: radar slew with a sharp reversal under RADAR_LOAD (unless the '
                   "config sets a load); config: the config's input profile "
                   '(default: %(default)s)')
    p.add_argument('--detune', action='append', default=[], metavar='GROUP=FACTOR',
                   help='scale a parameter group of the simulated plant only: '
                   'tooth_stiffness, friction or flywheel_inertia, e.g. flywheel_inertia=0.8 '
                   '(repeatable)')
    p.add_argument('--end-time', type=float, metavar='S',
                   help='simulated duration for step/config (default: input.end_time)')
    p.add_argument('--output', '-o', default='compensation.csv', metavar='CSV',
                   help='output CSV (default: %(default)s)')
    p.add_argument('--plot', metavar='PNG', help='plot file (default: the CSV name with .png)')
    p.add_argument('--no-plot', action='store_true', help='skip the PNG')
    p.add_argument('--record-every', type=int, default=10, metavar='N',
                   help='keep every N-th integration step (default: %(default)s)')
    p.set_defaults(func=cmd_compensate)


def parse_detune(items: Sequence[str]) -> dict[str, float]:
    """``['flywheel_inertia=0.8']`` -> {'flywheel_inertia': 0.8} (validated)."""
    out: dict[str, float] = {}
    for item in items or ():
        key, sep, raw = item.partition('=')
        key = key.strip()
        if not sep or key not in DETUNINGS:
            raise CliError(f'--detune {item!r}: expected GROUP=FACTOR with GROUP one of '
                           f'{", ".join(DETUNINGS)}')
        try:
            f = float(raw)
        except ValueError:
            raise CliError(f'--detune {item!r}: FACTOR must be a number') from None
        if not (math.isfinite(f) and f > 0.0):
            raise CliError(f'--detune {item!r}: FACTOR must be > 0')
        out[key] = f
    return out


def _scenario(args: argparse.Namespace, cfg):
    period = 1.0 / cfg.node.publish_rate_hz
    t_end = cfg.input.end_time if args.end_time is None else args.end_time
    if not (math.isfinite(t_end) and t_end > 0.0):
        raise CliError(f'--end-time must be > 0, got {args.end_time!r}')
    if args.scenario == 'slew':
        if cfg.load.output_torque == 0.0 and cfg.load.output_viscous_coefficient == 0.0:
            cfg = cfg.replace(RADAR_LOAD)
        if args.end_time is not None:
            raise CliError('--end-time applies to --scenario step or config (the slew has '
                           'its own length)')
        return cfg, radar_slew_scenario(cfg, period=period)
    if args.scenario == 'step':
        start = max(0.01, cfg.input.start_time)
        scen = paper_step_scenario(cfg, start=start, t_end=t_end, period=period)
    else:
        prof = make_profile(cfg.input)
        times = np.arange(0.0, t_end + 0.5 * period, period)
        x = prof.theta1(times)
        span = motion_span(times, x)
        end = 0.0 if span is None else span[1]
        rate = np.diff(x) / np.diff(times)
        const = np.zeros(times.size, bool)
        const[1:-1] = (np.abs(np.diff(rate)) <= 1e-9 * (1.0 + np.abs(rate[1:]))) & \
            (np.abs(rate[1:]) > 0.0)
        spans = _runs(times, const)
        scen = Scenario('config', times, x, end, tuple(spans), prof.describe())
    if scen.move_end >= t_end:
        raise CliError(f'--end-time {t_end:g} s must be later than the end of the move '
                       f'({scen.move_end:g} s)')
    return cfg, scen


def _runs(times: np.ndarray, mask: np.ndarray) -> list[tuple[float, float]]:
    out, start = [], None
    for i, m in enumerate(mask):
        if m and start is None:
            start = times[i]
        elif not m and start is not None:
            out.append((float(start), float(times[i - 1])))
            start = None
    if start is not None:
        out.append((float(start), float(times[-1])))
    return out


def cmd_compensate(args: argparse.Namespace) -> int:
    """Run the scenario with and without compensation; write CSV (+ PNG); print metrics."""
    if args.record_every < 1:
        raise CliError(f'--record-every must be >= 1, got {args.record_every}')
    factors = parse_detune(args.detune)
    cfg = resolve_config(args.config, args.set)
    cfg, scen = _scenario(args, cfg)
    plant = detuned(cfg, factors) if factors else cfg
    nominal = DriveModel(cfg.replace({'compensation.enabled': True}))
    plant_model = DriveModel(plant)
    off = run_scenario(plant_model, scen, None, record_every=args.record_every)
    on = run_scenario(plant_model, scen, nominal, record_every=args.record_every)
    out = Path(args.output)
    described = Compensator(nominal).describe()
    write_csv(out, off, on, header=f'scenario: {scen.description}\ncompensator: '
              f'{described}\nplant detuning: {factors or "none"}')
    quiet = getattr(args, 'quiet', False)
    if not quiet:
        print(f'{scen.name}: {scen.description}')
        print(f'compensator: {described}')
        if factors:
            print(f'plant detuned: {factors}')
        print(f'{"metric":16s} {"without":>12s} {"with":>12s} {"ratio":>9s}')
        for m in METRICS:
            print(metric_row(m, off.metrics[m], on.metrics[m]))
        print(f'wrote {out}')
    if not args.no_plot:
        png = Path(args.plot) if args.plot else out.with_suffix('.png')
        plot_runs(off, on, png, title=f'{scen.description}'
                  + (f'; plant {factors}' if factors else ''))
        if not quiet:
            print(f'wrote {png}')
    return 0


def write_csv(path: str | Path, off: Any, on: Any, header: str = '') -> Path:
    """Both runs on the same time grid: reference, correction, command, theta4, errors."""
    t = on.trajectory.t
    sc = on.scenario
    ref = np.interp(t, sc.times, sc.theta1_ref)
    delta = np.interp(t, sc.times, on.delta)
    cols = {
        't[s]': t, 'theta1_ref[rad]': ref, 'delta[rad]': delta,
        'theta1_cmd[rad]': ref + delta,
        'theta4_ref[rad]': ref * on.trajectory.output_per_input,
        'theta4_uncompensated[rad]': off.trajectory.theta[:, 2],
        'theta4_compensated[rad]': on.trajectory.theta[:, 2],
        'error_uncompensated[rad]': off.error, 'error_compensated[rad]': on.error,
    }
    return write_csv_columns(path, list(cols), np.column_stack(list(cols.values())),
                             comment='worm_gear_sim compensate\n' + header)


def plot_runs(off: Any, on: Any, path: str | Path, title: str = '') -> Path:
    """Antenna error with and without compensation (full run and zoom) and the correction."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    fig = Figure(figsize=(9.0, 8.5), layout='constrained')
    FigureCanvasAgg(fig)
    ax = fig.subplots(3, 1)
    t = on.trajectory.t
    sc = on.scenario
    for a in ax[:2]:
        a.plot(t, off.error * 1e6, lw=0.8, label='without compensation')
        a.plot(t, on.error * 1e6, lw=0.8, label='with compensation')
        a.axhspan(-10, 10, color='0.85', zorder=0, label='+-10 urad')
        a.axvline(sc.move_end, color='k', lw=0.6, ls=':')
        a.set_ylabel('theta4 error [urad]')
        a.grid(alpha=0.3)
    ax[0].set_title(title, fontsize=9)
    ax[0].legend(fontsize=8, loc='upper right')
    span = motion_span(sc.times, sc.theta1_ref)
    t0 = 0.0 if span is None else span[0]
    zoom = (max(0.0, t0 - 0.005), min(t[-1], sc.move_end + 0.06))
    ax[1].set_xlim(*zoom)
    ax[1].set_title('zoom on the move (dotted: end of the reference move)', fontsize=9)
    ax[2].plot(sc.times, on.delta * 1e3, lw=0.9)
    ax[2].set_xlim(*zoom)
    ax[2].set_ylabel('correction delta [mrad of worm]')
    ax[2].set_xlabel('t [s]')
    ax[2].grid(alpha=0.3)
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(p, dpi=100, format='png')
    return p


def metric_row(metric: str, off: float, on: float) -> str:
    """One row of the table: a settling time that never comes prints ``never``; the ratio
    (:func:`improvement`) is ``-`` when neither run settles, ``settles`` / ``never`` when
    only one does, ``n/a`` when both errors are below the resolution floor."""
    unit = 's' if metric == 'settling_time' else 'rad'

    def value(x: float) -> str:
        return 'never' if metric == 'settling_time' and math.isinf(x) else f'{x:.4g}'
    if metric == 'settling_time' and (math.isinf(off) or math.isinf(on)):
        rs = '-' if math.isinf(off) and math.isinf(on) else \
            ('settles' if math.isinf(off) else 'never')
    else:
        r = improvement(metric, off, on)
        rs = 'n/a' if math.isnan(r) else ('inf' if math.isinf(r) else f'{r:.3g}x')
    return f'{metric:16s} {value(off):>12s} {value(on):>12s} {rs:>9s}  [{unit}]'
