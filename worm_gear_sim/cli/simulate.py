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
    p.set_defaults(func=cmd_simulate)


def cmd_simulate(args: argparse.Namespace) -> int:
    from ..plotting import plot_trajectory
    from ..simulation import simulate
    from ..studies import equilibrium, move_end_time, oscillation_metrics
    cfg = config_from_args(args)
    out = Path(args.output)
    if out.suffix.lower() != '.csv':
        raise CliError(f'--output must end in .csv, got {out}')
    if args.record_every < 1:
        raise CliError('--record-every must be >= 1')
    t0 = time.perf_counter()
    traj = simulate(cfg, record_every=args.record_every)
    wall = time.perf_counter() - t0
    out.parent.mkdir(parents=True, exist_ok=True)
    traj.to_csv(out, header_comment=header(args))
    files = [out]
    if args.npz:
        import numpy as np
        np.savez(args.npz, allow_pickle=False, **traj.columns())
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
    say(args, f'final errors: theta2 - theta1 = {traj.worm_error[-1]:.4e} rad, '
         f'theta4 - theta1 l_w/r_g = {traj.output_error[-1]:.4e} rad')
    say(args, 'wrote ' + ', '.join(str(f) for f in files))
    return 0
