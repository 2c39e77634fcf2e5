# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``simulate``: one run, CSV time series and PNG plot."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from .common import CliError, add_config_options, config_from_args, header, say


def register(sub: Any) -> None:
    """Add the ``simulate`` command to the subparsers ``sub``."""
    p = sub.add_parser('simulate', help='one run: CSV time series and PNG plot',
                       description='Integrate the model for the config\'s input profile (or '
                       'a CSV of t, theta1) and write the time series (theta1..4, rates, '
                       'accelerations, W_n, mu, errors) as CSV plus a PNG plot.')
    add_config_options(p)
    p.add_argument('--csv', dest='input_csv', metavar='FILE', help='input profile from a '
                   'CSV with columns t, theta1 (= --set input.profile=csv --set '
                   'input.csv_path=FILE); linear interpolation between samples')
    p.add_argument('--output', '-o', default='simulation.csv', metavar='CSV',
                   help='output CSV (default: %(default)s)')
    p.add_argument('--plot', metavar='PNG', help='plot file (default: the CSV name with .png)')
    p.add_argument('--no-plot', action='store_true', help='skip the PNG')
    p.add_argument('--npz', metavar='FILE', help='also write the columns as float64 NPZ '
                   '(bit-exact)')
    p.add_argument('--record-every', type=int, default=1, metavar='N',
                   help='keep every N-th integration step (default: %(default)s = every '
                   'step; N > 1 aliases modes above 1/(2 N dt))')
    p.add_argument('--max-csv-size', type=float, default=MAX_CSV_GB, metavar='GB',
                   help='refuse runs whose CSV would exceed this size (default: '
                   '%(default)s GB); the CSV is written in chunks, memory stays bounded '
                   'whatever the duration')
    p.set_defaults(func=cmd_simulate)


#: Default limit of the CSV size of one run [GB] (--max-csv-size)
MAX_CSV_GB = 2.0


def check_output_size(cfg: Any, record_every: int, out: Path, max_gb: float,
                      in_memory: bool = False) -> int:
    """Up-front check of a run's CSV size against ``max_gb``, of its memory when every row
    is kept (``in_memory``: --npz) and of the free disk space; returns the number of rows.
    Raises CliError naming the estimate and the ways out."""
    import math
    import shutil

    from ..simulation import csv_bytes_estimate
    dt, t_end = cfg.integrator.time_step, cfg.input.end_time
    steps = int(math.floor(t_end / dt + 1e-9))
    rows = steps // record_every + 1
    size = csv_bytes_estimate(rows)
    ways = ('raise --record-every, shorten --end-time, or raise --max-csv-size')
    if size > max_gb * 1e9:
        raise CliError(f'--end-time {t_end:g} s at dt = {dt:g} s, every {record_every} '
                       f'step(s): {rows:.4g} rows, ~{size / 1e9:.3g} GB of CSV (and ~'
                       f'{steps * 3e-7 / 60:.3g} min of computation), above --max-csv-size '
                       f'{max_gb:g} GB: {ways}')
    if in_memory:
        from ..simulation import ROW_BYTES, RUN_MEMORY_LIMIT
        if rows * ROW_BYTES > RUN_MEMORY_LIMIT:
            raise CliError(f'--npz keeps every row in memory: {rows:.4g} rows need '
                           f'{rows * ROW_BYTES / 1e9:.3g} GB, above the in-memory limit '
                           f'(max_bytes) of {RUN_MEMORY_LIMIT / 1e9:g} GB: drop --npz (the '
                           'CSV is streamed), raise --record-every or shorten --end-time')
    parent = out.parent if str(out.parent) else Path('.')
    probe = parent
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    free = shutil.disk_usage(probe).free
    if size > free:
        raise CliError(f'{rows:.4g} rows need ~{size / 1e9:.3g} GB of CSV, only '
                       f'{free / 1e9:.3g} GB free in {probe}: {ways}')
    return rows


def cmd_simulate(args: argparse.Namespace) -> int:
    from ..plotting import plot_trajectory
    from ..simulation import simulate, simulate_to_csv
    from ..studies import equilibrium, move_end_time, oscillation_metrics
    cfg = config_from_args(args)
    out = Path(args.output)
    if out.suffix.lower() != '.csv':
        raise CliError(f'--output must end in .csv, got {out}')
    if args.record_every < 1:
        raise CliError('--record-every must be >= 1')
    if not args.max_csv_size > 0:
        raise CliError(f'--max-csv-size must be > 0, got {args.max_csv_size:g}')
    rows = check_output_size(cfg, args.record_every, out, args.max_csv_size,
                             in_memory=bool(args.npz))
    out.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    if args.npz:           # NPZ needs every row in memory (simulate checks the size first)
        traj = simulate(cfg, record_every=args.record_every)
        traj.to_csv(out, header_comment=header(args))
    else:                  # streamed in chunks: bounded memory; a thinned copy for the plot
        traj = simulate_to_csv(cfg, out, record_every=args.record_every,
                               header_comment=header(args))
    wall = time.perf_counter() - t0
    files = [out]
    if args.npz:
        import numpy as np
        np.savez(args.npz, **traj.columns())
        files.append(Path(args.npz))
    if not args.no_plot:
        png = Path(args.plot) if args.plot else out.with_suffix('.png')
        plot_trajectory(traj, png)
        files.append(png)
    say(args, f'profile: {traj.profile}')
    say(args, f'simulated {traj.t[-1]:.6g} s in {wall:.3f} s wall '
         f'({traj.stats.get("steps", 0)} steps, '
         f'{traj.stats.get("subdivision_events", 0)} subdivision events)')
    try:
        from ..profiles import make_profile
        t_move = move_end_time(cfg, make_profile(cfg.input))
        if traj.t[-1] > t_move:
            eq = equilibrium(cfg, float(traj.theta1[-1]))
            m = oscillation_metrics(traj, t_move, eq)
            say(args, f'after the move (t >= {t_move:g} s): max |theta2 - eq| = '
                 f'{m["amp2"]:.4e} rad, max |theta4 - eq| = {m["amp4"]:.4e} rad, theta4 '
                 f'rings at {m["freq4_hz"]:.2f} Hz')
    except ValueError:
        pass
    if len(traj.t) < rows:
        say(args, f'{rows} rows in the CSV; plot and metrics from {len(traj.t)} of them '
            '(every k-th row)')
    say(args, f'final errors: theta2 - theta1 = {traj.worm_error[-1]:.4e} rad, '
         f'theta4 - theta1 l_w/r_g = {traj.output_error[-1]:.4e} rad')
    say(args, 'wrote ' + ', '.join(str(f) for f in files))
    return 0
