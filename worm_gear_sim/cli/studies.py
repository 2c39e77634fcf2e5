# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``experiment`` (the paper's Sec. 3) and ``sweep`` (Sec. 4 parametric studies, any
parameter, on threads or Dask)."""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ..config.files import check_key, params_document, params_json_dump, typed_value
from ..config.usable import Config
from ..records import write_csv_columns
from ..studies import PAPER_STUDIES
from ..studies.engine import DEFAULT_ENGINE, ENGINE_TEXT, ENGINES
from ..studies.metrics import fmt_table
from .common import PROG, CliError, add_config_options, config_from_args, say
from .limits import CALIBRATION_S_PER_DRIVE, MAX_MISMATCH_DRIVES, check_work, duration_text


def register(sub: Any) -> None:
    """Add the ``experiment`` and ``sweep`` commands to the subparsers ``sub``."""
    _register_experiment(sub)
    _register_sweep(sub)


def _register_experiment(sub: Any) -> None:
    p = sub.add_parser('experiment', help="the paper's Sec. 3 experiment (Figs. 9-11)",
                       description='18-step move: nonlinear model vs the linear model '
                       '(constant tooth stiffness 3.5e8/2.5e8 N/m, mu 0.145) in the '
                       'kinematic and the paper lead convention; table of equilibrium levels, '
                       'frequencies and amplitudes, plot of the oscillating parts.')
    add_config_options(p)
    p.add_argument('--out-dir', '-o', default='experiment', metavar='DIR',
                   help='output directory (default: %(default)s)')
    p.add_argument('--traces', action='store_true',
                   help='also write the oscillating parts as CSV (experiment_traces.csv)')
    p.add_argument('--trace-every', type=int, default=3, metavar='N',
                   help='trace CSV keeps every N-th step (default: %(default)s = 30 us, '
                   'the paper sampled at 25 us)')
    p.set_defaults(func=cmd_experiment)


def _register_sweep(sub: Any) -> None:
    p = sub.add_parser('sweep', help="the paper's Sec. 4 parametric studies, in parallel",
                       description='Parametric studies (paper Figs. 12-18) or a sweep of any '
                       'parameter. Output per study: <study>.csv (max oscillation amplitudes '
                       'of theta2 and theta4 after the move, and more) and <study>.png. Runs '
                       f'on {ENGINE_TEXT[DEFAULT_ENGINE]}, one per core, by default '
                       '(--engine). A case the model refuses (checked at the step it runs '
                       'at) or that fails fails its own row (column error, and a line on '
                       'stderr); the others run; exit status 1 then.')
    add_config_options(p)
    p.add_argument('study', nargs='*', metavar='STUDY',
                   help=f'{", ".join(PAPER_STUDIES)} or all; or play / gust: the antenna '
                   'error on the radar slew against the mesh play / the gust intensity, '
                   'with and without the feed-forward; or reversal: the feed-forward '
                   'across the play on reversal moves; crossing: the soft crossing of the '
                   'play on a sector scan; mismatch: the feed-forward on a drive that differs '
                   'from its model, and calibrate-then-compensate (docs/compensation.md)')
    p.add_argument('--param', metavar='PATH[,PATH]', help='sweep this dotted parameter '
                   '(several comma-separated paths get the same value)')
    p.add_argument('--values', metavar='V1,V2,...', help='values for --param')
    p.add_argument('--range', metavar='START:STOP:NUM', help='evenly spaced values for '
                   '--param (with --log: geometric)')
    p.add_argument('--log', action='store_true', help='geometric --range')
    p.add_argument('--name', metavar='NAME', help='file name of a --param sweep '
                   '(default: custom)')
    p.add_argument('--compare', metavar='KEY=V1,V2', help='repeat every case for each value '
                   'of KEY (one line per value), e.g. input.move_time=0.02,0.04; also writes '
                   '<study>_envelope.csv/png, the worst case over those values')
    p.add_argument('--out-dir', '-o', default='sweep', metavar='DIR',
                   help='output directory (default: %(default)s)')
    p.add_argument('--workers', '-j', type=int, metavar='N',
                   help='threads (--engine threads) or LocalCluster worker processes '
                   '(--engine dask); default: all cores')
    p.add_argument('--engine', choices=ENGINES, default=DEFAULT_ENGINE,
                   help='; '.join(f'{k}: {v}' for k, v in ENGINE_TEXT.items())
                   + ' (default: %(default)s)')
    p.add_argument('--scheduler', metavar='ADDRESS', help='run on an existing Dask cluster, '
                   'e.g. tcp://10.0.0.5:8786 (workers need worm_gear_sim installed)')
    p.add_argument('--serial', action='store_true', help='run in this process, one case '
                   'after the other')
    p.add_argument('--no-progress', action='store_true', help='no progress bar')
    p.add_argument('--traces', action='store_true', help='also plot the time traces of '
                   'studies with at most 8 cases (e.g. flywheel, Figs. 12-13)')
    _add_crossing_mismatch_options(p)
    p.set_defaults(func=cmd_sweep)


def _add_crossing_mismatch_options(p: Any) -> None:
    g = p.add_argument_group('crossing and mismatch (docs/compensation.md)')
    g.add_argument('--plays', metavar='A1,A2,...', help='crossing: plays [arcmin] '
                   '(default: 0.5,1,2,5)')
    g.add_argument('--loads', metavar='T1,T2,...', help='crossing: load torques [N m] '
                   '(default: 0,0.5,1,2,5)')
    g.add_argument('--drags', metavar='C1,C2,...', help='crossing: drags [N m s/rad] '
                   '(default: 0,10,50)')
    g.add_argument('--damping', type=float, default=0.0, metavar='ZETA',
                   help='crossing: modal damping ratio of the drives (default: 0)')
    g.add_argument('--scan-rest', type=float, default=0.0, metavar='S',
                   help='crossing: rest before the scan (default: 0 s)')
    g.add_argument('--axes', metavar='A1,A2,...', help='mismatch: model errors to sweep, of '
                   'play, load, teeth, bearings (default: all)')
    g.add_argument('--errors', metavar='E1,E2,...', help='mismatch: errors as shares '
                   '(default: -0.3,-0.2,-0.1,0,0.1,0.2,0.3)')
    g.add_argument('--drives', type=int, default=20, metavar='N',
                   help='mismatch: random drives to calibrate then compensate (default: '
                   '%(default)s; 0: none)')
    g.add_argument('--seed', type=int, default=0, help='mismatch: seed of the random drives')
    g.add_argument('--moves', default='sector,slew', metavar='M1,M2',
                   help='mismatch: moves, of sector, slew (default: %(default)s)')
    g.add_argument('--calibrate-fit', metavar='KEY[,KEY...]', help='mismatch: the keys '
                   'calibrated (default: mesh.backlash, load.output_torque, '
                   'load.output_viscous_coefficient, mesh.gear_tooth_stiffness_multiplier)')
    g.add_argument('--fit-strategy', default='robust', metavar='NAME',
                   help="mismatch: the calibration fit's strategy (default: %(default)s)")


def cmd_experiment(args: argparse.Namespace) -> int:
    from ..studies import EXPERIMENT_COLUMNS, experiment_table, move_end_time, rows_to_csv
    from .plotting import plot_experiment
    cfg = config_from_args(args)
    if cfg.geometry.lead_convention != 'kinematic' or cfg.mesh.stiffness_model != 'nonlinear':
        say(args, 'note: the experiment sets lead_convention and the linear/nonlinear '
             'model itself; the base values of those keys are ignored')
    outdir = Path(args.out_dir)
    outdir.mkdir(parents=True, exist_ok=True)
    rows, trajs = experiment_table(cfg)
    rows_to_csv(rows, EXPERIMENT_COLUMNS, outdir / 'experiment.csv')
    from ..dynamics.profiles import make_profile
    t_move = move_end_time(cfg, make_profile(cfg.input))
    plot_experiment(trajs, rows, outdir / 'experiment.png', t_move=t_move)
    if args.traces:
        _write_traces(trajs, outdir / 'experiment_traces.csv', args.trace_every)
    say(args, f'18-step move ({next(iter(trajs.values())).profile}), '
         f'{cfg.input.end_time:g} s; levels in rad, amplitudes after the move:')
    say(args, fmt_table(rows, [
        ('model', 'model', ''), ('lead_convention', 'lead', ''),
        ('eq2', 'theta2_eq', '.7f'), ('eq4', 'theta4_eq', '.7f'),
        ('mean4', 'theta4_mean', '.7f'), ('freq4_hz', 'f4_fft[Hz]', '.2f'),
        ('freq4_zc_hz', 'f4_zc[Hz]', '.2f'), ('modal4_hz', 'f1_modal[Hz]', '.2f'),
        ('freq2_hz', 'f2_fft[Hz]', '.1f'), ('amp2', 'amp2', '.3e'), ('amp4', 'amp4', '.3e'),
        ('max_err4', 'max|err4|', '.3e'), ('decay4', 'decay4', '.3f')]))
    say(args, f'paper (Sec. 3.2): theta2 -> 0.1130973 rad, theta4 -> 0.0127076 rad; '
         f'wrote {outdir / "experiment.csv"}, {outdir / "experiment.png"}')
    return 0


def _write_traces(trajs: Mapping[str, Any], path: Path, every: int) -> None:
    import numpy as np
    first = next(iter(trajs.values()))
    cols = {'t': first.t[::every]}
    for key, tr in trajs.items():
        cols[f'{key}:theta2-theta1'] = tr.worm_error[::every]
        cols[f'{key}:theta4-theta1*lw/rg'] = tr.output_error[::every]
    write_csv_columns(path, list(cols), np.column_stack(list(cols.values())))


# ---- sweep -----------------------------------------------------------------------------
SWEEP_COLUMNS: tuple[str, ...] = (
    'study', 'series', 'label', 'x', 'amp2', 'amp3', 'amp4', 'half_pp2', 'half_pp4', 'eq2',
    'eq4', 'mean2', 'mean4', 'freq2_hz', 'freq4_hz', 'max_err2', 'max_err4', 'decay4', 'J_4',
    'ratio', 't_move', 't_end', 'steps', 'subdivision_events', 'overrides', 'error',
)


def _sweep_studies(args: argparse.Namespace, cfg: Config) -> list:
    from ..studies import PAPER_STUDIES, paper_study, param_study, parse_values
    names = list(args.study or [])
    studies = []
    if args.param:
        paths = [s.strip() for s in args.param.split(',') if s.strip()]
        defaults = {pth: check_key(pth) for pth in paths}
        try:
            raw = parse_values(args.values, args.range, args.log)
        except ValueError as exc:
            raise CliError(str(exc)) from None
        values = [typed_value(paths[0], r, defaults[paths[0]]) for r in raw]
        for pth in paths[1:]:
            for r in raw:
                typed_value(pth, r, defaults[pth])
        studies.append(param_study(paths, values, labels=raw, name=args.name or 'custom'))
    elif args.values or args.range:
        raise CliError('--values/--range need --param PATH')
    if 'all' in names:
        names = [n for n in names if n != 'all'] + [n for n in PAPER_STUDIES if n not in names]
    for n in dict.fromkeys(names):
        if n not in PAPER_STUDIES:
            raise CliError(f'unknown study {n!r}; choose from {", ".join(PAPER_STUDIES)}, all '
                           '(or --param PATH --values ...)')
        studies.append(paper_study(n, cfg))
    if not studies:
        raise CliError(f'nothing to sweep: name a study ({", ".join(PAPER_STUDIES)}, all) or '
                       'give --param PATH --values V1,V2,...')
    if args.compare:
        studies = [_with_compare(s, args.compare, cfg) for s in studies]
    return studies


def _refused(cfg: Config, studies: list) -> dict[int, str]:
    """Each case checked as it will run (``studies.case_config``: at the smaller step a stiff
    case needs), before any runs: the index among all cases -> why it is refused."""
    from ..studies import case_config
    from ..studies.engine import CASE_ERRORS, case_error
    out = {}
    cases = [c for st in studies for c in st.cases]
    for i, c in enumerate(cases):
        try:
            case_config(cfg, dict(c.overrides))
        except CASE_ERRORS as exc:
            out[i] = case_error(exc)
    if len(out) == len(cases):
        raise CliError(f'every case refused ({len(cases)}); the first: {out[0]}')
    return out


def _with_compare(study, spec: str, cfg: Config):
    from ..studies import COMPARE_SEP, Case
    key, sep, vals = spec.partition('=')
    key = key.strip()
    if not sep or not vals.strip():
        raise CliError(f'--compare {spec!r}: expected KEY=V1,V2,...')
    default = check_key(key)
    raws = [v.strip() for v in vals.split(',') if v.strip()]
    cases = []
    for raw in raws:
        v = typed_value(key, raw, default)
        for c in study.cases:
            if key in c.overrides:
                raise CliError(f'--compare {key}: the {study.name} study sets it itself')
            cases.append(Case(c.study, f'{c.series}{COMPARE_SEP}{key.split(".")[-1]}={raw}', c.x,
                              c.label, {key: v, **c.overrides}))
    return dataclasses.replace(study, cases=tuple(cases),
                               title=f'{study.title}; compare {key}')


#: studies of the antenna error on the radar slew (worm_gear_sim.studies.play_gust)
ERROR_STUDIES = {
    'play': ('antenna error against the mesh play (radar slew, 2 N m load)',
             'mesh.backlash [arcmin]'),
    'gust': ('antenna error against the gust intensity (radar slew, 5 N m mean wind, '
             '0.2 s gusts, 3 seeds)', 'turbulence intensity sigma_u / U'),
    'reversal': ('the feed-forward across 2 arcmin of play on reversal moves (3 % damping)',
                 ''),
    'crossing': ('the soft crossing of the play: ±5° sector scan (4 s), perfect knowledge',
                 ''),
    'mismatch': ('the feed-forward on a drive that differs from its model', '')}


def _floats(text: str | None, default: tuple, what: str) -> list[float]:
    if text is None:
        return list(default)
    try:
        return [float(v) for v in text.split(',') if v.strip()]
    except ValueError:
        raise CliError(f'{what} {text!r}: expected comma-separated numbers') from None


def _crossing_study(args: argparse.Namespace, cfg: Config, outdir: Path) -> None:
    from ..studies import rows_to_csv
    from ..studies.mismatch import (
        CROSSING_COLUMNS,
        CROSSING_DRAGS,
        CROSSING_LOADS,
        CROSSING_PLAYS,
        crossing_rows,
        summary,
    )
    from .mismatch_plot import plot_crossing_study
    plays = _floats(args.plays, CROSSING_PLAYS, '--plays')
    loads = _floats(args.loads, CROSSING_LOADS, '--loads')
    drags = _floats(args.drags, CROSSING_DRAGS, '--drags')
    if not (plays and loads and drags) or min(plays) <= 0 or min(loads + drags) < 0:
        raise CliError('--plays must be > 0, --loads and --drags >= 0')
    if not 0.0 <= args.damping < 1.0:
        raise CliError(f'--damping {args.damping!r}: must be in [0, 1)')
    if not 0.0 <= args.scan_rest <= 10.0:
        raise CliError(f'--scan-rest {args.scan_rest!r}: must be in [0, 10] s')
    rows = crossing_rows(cfg, plays, loads, drags, args.damping, args.scan_rest,
                         workers=1 if args.serial else args.workers)
    rows_to_csv(rows, CROSSING_COLUMNS, outdir / 'crossing.csv')
    title = ERROR_STUDIES['crossing'][0]
    plot_crossing_study(rows, outdir / 'crossing.png', title)
    say(args, fmt_table(rows, [
        ('play_arcmin', 'play [arcmin]', '.3g'), ('load_torque', 'load [N m]', '.3g'),
        ('drag', 'drag [N m s/rad]', '.3g'), ('raw_rms', 'raw RMS [rad]', '.3e'),
        ('causal_x', 'causal', '.3g'), ('step_x', 'step', '.3g'),
        ('stream_x', 'stream', '.3g'), ('soft_x', 'soft', '.3g'),
        ('crossing_ms', 'crossings [ms]', '')]))
    for col in ('causal_x', 'step_x', 'stream_x', 'soft_x'):
        sm = summary(rows, col)
        say(args, f'{col[:-2]}: {sm["min"]:.3g}x .. {sm["max"]:.3g}x (median '
             f'{sm["median"]:.3g}x)')
    say(args, f'wrote {outdir / "crossing.csv"}, {outdir / "crossing.png"}')


def _mismatch_study(args: argparse.Namespace, cfg: Config, outdir: Path) -> None:
    from ..identification import FitOptions
    from ..identification.fit import STRATEGIES
    from ..studies import rows_to_csv
    from ..studies.mismatch import (
        CALIBRATION_COLUMNS,
        CALIBRATION_KEYS,
        MISMATCH_AXES,
        MISMATCH_COLUMNS,
        MISMATCH_DRIVE,
        MISMATCH_ERRORS,
        MOVES,
        calibration_rows,
        mismatch_rows,
        summary,
    )
    from .mismatch_plot import plot_mismatch_study
    axes = [a.strip() for a in args.axes.split(',') if a.strip()] if args.axes \
        else list(MISMATCH_AXES)
    bad = [a for a in axes if a not in MISMATCH_AXES]
    if bad or not axes:
        raise CliError(f'--axes {args.axes!r}: choose from {", ".join(MISMATCH_AXES)}')
    errors = _floats(args.errors, MISMATCH_ERRORS, '--errors')
    if not errors or min(errors) <= -1.0:
        raise CliError('--errors must be shares > -1 (e.g. -0.3,0,0.3)')
    if args.drives < 0:
        raise CliError(f'--drives {args.drives}: must be >= 0')
    check_work(f'--drives {args.drives}', args.drives, MAX_MISMATCH_DRIVES, 'drives',
               f'{args.drives} random drives, each a calibration of ~'
               f'{CALIBRATION_S_PER_DRIVE:g} s (~'
               f'{duration_text(args.drives * CALIBRATION_S_PER_DRIVE)} on one machine)',
               'give fewer (runs with other --seed values add up)')
    moves = [m.strip() for m in args.moves.split(',') if m.strip()]
    if not moves or any(m not in MOVES for m in moves):
        raise CliError(f'--moves {args.moves!r}: choose from {", ".join(MOVES)}')
    keys = [k.strip() for k in args.calibrate_fit.split(',') if k.strip()] \
        if args.calibrate_fit else list(CALIBRATION_KEYS)
    for k in keys:
        check_key(k)
    if args.fit_strategy not in STRATEGIES:
        raise CliError(f'--fit-strategy {args.fit_strategy!r}: one of '
                       f'{", ".join(STRATEGIES)}')
    drive = cfg.replace(MISMATCH_DRIVE)
    rows = mismatch_rows(drive, axes, errors, moves, workers=1 if args.serial else args.workers)
    rows_to_csv(rows, MISMATCH_COLUMNS, outdir / 'mismatch.csv')
    say(args, fmt_table(rows, [('move', 'move', ''), ('axis', 'axis', ''),
                               ('error', 'error', '+.0%'),
                               ('raw_rms', 'raw RMS [rad]', '.3e'),
                               ('compensated_rms', 'compensated [rad]', '.3e'),
                               ('improvement', 'improvement', '.3g')]))
    drives: list[dict] = []
    if args.drives:
        opts = FitOptions(strategy=args.fit_strategy, serial=True) if args.serial else \
            FitOptions(strategy=args.fit_strategy, workers=args.workers,
                       scheduler=args.scheduler)

        def told(r: dict) -> None:
            say(args, f'drive {r["drive"]}: play {r["play_arcmin"]:.2f} arcmin, load '
                 f'{r["load_torque"]:.2f} N m, drag {r["drag"]:.1f} N m s/rad, teeth '
                 f'x{r["teeth"]:.2f}, bearings x{r["bearings"]:.2f}: '
                 f'{"accepted" if r["accepted"] else "refused"} in '
                 f'{r["calibration_s"]:.0f} s; '
                 + ', '.join(f'{m} {r[m + "_x"]:.3g}x (nominal model '
                             f'{r[m + "_nominal_x"]:.3g}x)' for m in moves))
        drives = calibration_rows(cfg, args.drives, args.seed, keys=keys, options=opts,
                                  moves=moves, progress=told)
        rows_to_csv(drives, CALIBRATION_COLUMNS, outdir / 'mismatch_drives.csv')
        for col in (m + '_x' for m in moves):
            sm = summary(drives, col)
            say(args, f'calibrate-then-compensate, {col[:-2]}: min {sm["min"]:.3g}x, median '
                 f'{sm["median"]:.3g}x, max {sm["max"]:.3g}x '
                 f'({sum(bool(r["accepted"]) for r in drives)} of {len(drives)} accepted)')
    plot_mismatch_study(rows, drives, outdir / 'mismatch.png', ERROR_STUDIES['mismatch'][0])
    say(args, f'wrote {outdir / "mismatch.csv"}'
         + (f', {outdir / "mismatch_drives.csv"}' if drives else '')
         + f', {outdir / "mismatch.png"}')


def _error_studies(args: argparse.Namespace, cfg: Config, names: list[str]) -> None:
    """``sweep play`` / ``gust`` / ``reversal``: CSV, PNG and a table per study."""
    from ..studies import rows_to_csv
    from ..studies.backlash_reversal import REVERSAL_COLUMNS, reversal_rows
    from ..studies.play_gust import PLAY_GUST_COLUMNS, gust_rows, play_rows
    from .plotting import plot_error_study, plot_reversal_study
    outdir = Path(args.out_dir)
    outdir.mkdir(parents=True, exist_ok=True)
    for n in names:
        t0 = time.perf_counter()
        title, x_label = ERROR_STUDIES[n]
        csv_path, png_path = outdir / f'{n}.csv', outdir / f'{n}.png'
        if n in ('crossing', 'mismatch'):
            say(args, f'{title}')
            (_crossing_study if n == 'crossing' else _mismatch_study)(args, cfg, outdir)
            say(args, f'({time.perf_counter() - t0:.1f} s)')
            continue
        if n == 'reversal':
            rows = reversal_rows(cfg, workers=1 if args.serial else args.workers)
            rows_to_csv(rows, REVERSAL_COLUMNS, csv_path)
            plot_reversal_study(rows, png_path, title)
            table = [('move', 'move', ''), ('load', 'load', ''),
                     ('preview_ms', 'preview [ms]', '.3g'), ('series', 'series', ''),
                     ('reversal_rms_err4', 'reversal RMS [rad]', '.3e'),
                     ('improvement', 'improvement', '.3g')]
        else:
            workers = 1 if args.serial else args.workers      # runs on threads
            rows = play_rows(cfg, workers=workers) if n == 'play' else \
                gust_rows(cfg, workers=workers)
            rows_to_csv(rows, PLAY_GUST_COLUMNS, csv_path)
            plot_error_study(rows, png_path, title, x_label)
            table = [('series', 'series', ''), ('label', 'case', ''),
                     ('rms_err4', 'RMS err4 [rad]', '.3e'),
                     ('reversal_rms_err4', 'reversal RMS [rad]', '.3e'),
                     ('static_err4', 'static [rad]', '.3e')]
        say(args, f'\n{title} ({time.perf_counter() - t0:.1f} s)')
        say(args, fmt_table(rows, table))
        say(args, f'wrote {csv_path}, {png_path}')


def cmd_sweep(args: argparse.Namespace) -> int:
    cfg = config_from_args(args)
    if args.workers is not None and args.workers < 1:
        raise CliError('--workers must be >= 1 (use --serial to run in this process)')
    if args.serial and args.scheduler:
        raise CliError('--serial and --scheduler exclude each other')
    special = [n for n in (args.study or []) if n in ERROR_STUDIES]
    if special:
        if len(special) != len(args.study) or args.param or args.compare:
            raise CliError(f'{", ".join(ERROR_STUDIES)} run alone (no other study, --param '
                           'or --compare)')
        _error_studies(args, cfg, list(dict.fromkeys(special)))
        return 0
    studies = _sweep_studies(args, cfg)
    outdir = Path(args.out_dir)
    rows, wall = _run_sweep(args, cfg, studies, outdir)
    params_json_dump(params_document(cfg), outdir / 'sweep_params.json')
    k = 0
    for st in studies:
        _write_study(args, cfg, st, rows[k:k + len(st.cases)], outdir)
        k += len(st.cases)
    return _sweep_summary(args, rows, wall)


def _run_sweep(args: argparse.Namespace, cfg: Config, studies: list, outdir: Path
               ) -> tuple[list[dict[str, Any]], float]:
    """Every case of ``studies`` run (a refused one gets its failed row): the rows in
    order and the wall time [s]."""
    from ..parallel.threads import default_workers
    from ..studies import run_cases
    all_cases = [c for st in studies for c in st.cases]
    refused = _refused(cfg, studies)
    outdir.mkdir(parents=True, exist_ok=True)
    n_workers = args.workers or default_workers()
    engine = ('this process' if args.serial else f'Dask scheduler {args.scheduler}'
              if args.scheduler else f'{n_workers} threads' if args.engine == 'threads' else
              f'Dask LocalCluster, {n_workers} worker processes')
    say(args, f'{len(all_cases)} cases in {len(studies)} '
         f'stud{"y" if len(studies) == 1 else "ies"} on {engine}'
         + (f' ({len(refused)} refused before the run: rows with an error)' if refused
            else ''))
    t0 = time.perf_counter()
    ran = iter(run_cases(cfg, [c for i, c in enumerate(all_cases) if i not in refused],
                         workers=args.workers, scheduler=args.scheduler, serial=args.serial,
                         progress=not args.no_progress, engine=args.engine,
                         failed_rows=True))
    rows = [_failed_row(c, refused[i]) if i in refused else next(ran)
            for i, c in enumerate(all_cases)]
    for r in rows:
        if r.get('error'):
            r.update({k: math.nan for k in _METRICS if k not in r})
    return rows, time.perf_counter() - t0


def _write_study(args: argparse.Namespace, cfg: Config, st: Any, part: list[dict[str, Any]],
                 outdir: Path) -> None:
    """One study's CSV, plot and table (with --compare its envelope, with --traces its
    time traces)."""
    from ..studies import rows_to_csv
    from .plotting import plot_sweep
    csv_path = outdir / f'{st.name}.csv'
    png_path = outdir / f'{st.name}.png'
    rows_to_csv(part, SWEEP_COLUMNS, csv_path)
    plot_sweep(part, png_path, st.title, st.x_label, st.x_log, st.categorical)
    say(args, f'\n{st.title}')
    cols = [('series', 'series', ''), ('label', 'case', ''),
            ('amp2', 'amp theta2 [rad]', '.4e'), ('amp4', 'amp theta4 [rad]', '.4e'),
            ('freq4_hz', 'f4 [Hz]', '.2f'), ('max_err4', 'max|err4| [rad]', '.4e')]
    if any(r.get('error') for r in part):
        cols.append(('failed', 'error', ''))
    say(args, fmt_table([{**r, 'failed': _short(r.get('error', ''))} for r in part],
                        cols))
    say(args, f'wrote {csv_path}, {png_path}')
    if args.compare:
        _write_envelope(args, st, part, outdir)
    ok = [c for c, r in zip(st.cases, part) if not r.get('error')]
    if args.traces and ok and len(st.cases) <= 8:
        _sweep_traces(cfg, dataclasses.replace(st, cases=tuple(ok)),
                      outdir / f'{st.name}_traces.png')
        say(args, f'wrote {outdir / (st.name + "_traces.png")}')


def _write_envelope(args: argparse.Namespace, st: Any, part: list[dict[str, Any]],
                    outdir: Path) -> None:
    """The worst case over the --compare values: CSV, plot and table."""
    from ..studies import ENVELOPE_COLUMNS, envelope_rows, rows_to_csv
    from .plotting import plot_sweep
    env = envelope_rows(part)
    env_csv, env_png = outdir / f'{st.name}_envelope.csv', \
        outdir / f'{st.name}_envelope.png'
    rows_to_csv(env, ENVELOPE_COLUMNS, env_csv)
    key, _, vals = args.compare.partition('=')
    plot_sweep(env, env_png, f'{st.title}: worst case over '
               f'{len(vals.split(","))} values of {key}', st.x_label, st.x_log,
               st.categorical)
    say(args, f'worst case over {args.compare}:')
    say(args, fmt_table(env, [('series', 'series', ''), ('label', 'case', ''),
                                ('amp2', 'amp theta2 [rad]', '.4e'),
                                ('amp2_at', 'at', ''),
                                ('amp4', 'amp theta4 [rad]', '.4e'),
                                ('amp4_at', 'at', '')]))
    say(args, f'wrote {env_csv}, {env_png}')


def _sweep_summary(args: argparse.Namespace, rows: list[dict[str, Any]], wall: float) -> int:
    """The run's totals and each failed case on stderr; the exit status."""
    kernel = sum(r.get('kernel_s', 0.0) for r in rows)
    say(args, f'\n{len(rows)} cases in {wall:.2f} s wall ({len(rows) / wall:.2f} cases/s; '
         f'integration time summed over the cases {kernel:.2f} s)')
    failed = [r for r in rows if r.get('error')]
    for r in failed:
        print(f'{PROG}: case {r["study"]} / {r["series"]} / {r["label"]} failed: '
              f'{r["error"]}', file=sys.stderr)
    if failed:
        print(f'{PROG}: {len(failed)} of {len(rows)} cases failed (their rows hold the '
              'reason in the column error); the others ran', file=sys.stderr)
        return 1
    return 0


#: The metric columns of a sweep row (nan in a failed case's row).
_METRICS = SWEEP_COLUMNS[SWEEP_COLUMNS.index('amp2'):SWEEP_COLUMNS.index('overrides')]


def _failed_row(case: Any, error: str) -> dict[str, Any]:
    return {'study': case.study, 'series': case.series, 'x': case.x, 'label': case.label,
            'overrides': dict(case.overrides), 'error': error}


def _short(text: str, width: int = 60) -> str:
    return text if len(text) <= width else text[:width - 3] + '...'


def _sweep_traces(cfg: Config, study, path: Path) -> None:
    from ..studies import move_end_time, run_case
    from .plotting import plot_traces
    trajs = {}
    for c in study.cases:
        res = run_case(cfg, c.overrides, keep_trajectory=True)
        trajs[f'{c.series}: {c.label}' if len({x.series for x in study.cases}) > 1
              else c.label] = res['trajectory']
    from ..dynamics.profiles import make_profile
    plot_traces(trajs, path, study.title, move_end_time(cfg, make_profile(cfg.input)))
