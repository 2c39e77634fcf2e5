# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``pass``: a satellite's tracking pass over a two-axis pedestal, streamed as overlapping
trajectories, with and without compensation (:mod:`worm_gear_sim.studies.tracking_pass`):
a per-axis pointing-error table, a CSV and a figure.  The same pass through the ROS nodes:
``scripts/run_pass.sh``."""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..pedestal import load_pedestal
from ..records import write_csv_columns
from ..studies.tracking_pass import PassResult, pass_window, stream_pass
from ..studies.tracking_pass import evaluate_pass as _evaluate
from ..trajectory_compensation import MAX_TRAJECTORY_POINTS
from .common import CliError, fmt_table, say
from .limits import MAX_PASS_COMPENSATED_S, MAX_PASS_TRAJECTORIES, check_work
from .plotting import plot_pass

__all__ = ['register', 'PASS_COLUMNS', 'write_pass', 'pass_table']

PASS_COLUMNS = [('joint', 'worm input joint', ''), ('rms_raw_urad', 'RMS raw [urad]', '.4g'),
                ('rms_compensated_urad', 'RMS comp. [urad]', '.4g'),
                ('max_raw_urad', 'max raw [urad]', '.4g'),
                ('max_compensated_urad', 'max comp. [urad]', '.4g'),
                ('rms_ratio', 'RMS ratio', '.4g')]


def register(sub: Any) -> None:
    p = sub.add_parser(
        'pass', help='a satellite pass over the two-axis pedestal, with and without '
        'compensation: table, CSV, PNG',
        description='Stream a low-orbit satellite pass (az/el, circular orbit, spherical '
        'Earth) to the pedestal of --pedestal as overlapping trajectories of the worm input '
        'joints, compensate each like the node does, simulate every drive on the raw and '
        'the compensated commands, and report the antenna pointing error per axis.')
    p.add_argument('--pedestal', metavar='PEDESTAL.yaml', default=None,
                   help='the drives (default: config/pedestal.yaml)')
    p.add_argument('-o', '--output', metavar='DIR', default='pass',
                   help='directory for pass.csv and pass.png (default: %(default)s)')
    p.add_argument('--duration', type=float, default=60.0, metavar='S',
                   help='seconds of the pass around culmination (default: %(default)s)')
    p.add_argument('--max-elevation', type=float, default=85.0, metavar='DEG',
                   help='elevation at culmination (default: %(default)s deg)')
    p.add_argument('--altitude', type=float, default=500e3, metavar='M',
                   help='orbit altitude (default: %(default)g m)')
    p.add_argument('--chunk', type=float, default=20.0, metavar='S',
                   help='length of each trajectory sent (default: %(default)s s)')
    p.add_argument('--every', type=float, default=10.0, metavar='S',
                   help='a new trajectory every S seconds (default: %(default)s s)')
    p.add_argument('--waypoint-period', type=float, default=1.0, metavar='S',
                   help='waypoint spacing (default: %(default)s s)')
    p.set_defaults(func=cmd_pass)


def pass_table(result: PassResult) -> str:
    return fmt_table(result.table(), PASS_COLUMNS)


def write_pass(result: PassResult, out: Path, title: str) -> tuple[Path, Path]:
    """pass.csv (t, then per axis: antenna reference, raw and compensated error) and
    pass.png under ``out``."""
    names, cols = ['t'], [result.t]
    for j in result.raw_error:
        names += [f'{j}_antenna_reference', f'{j}_raw_error', f'{j}_compensated_error']
        cols += [result.reference[j], result.raw_error[j], result.compensated_error[j]]
    csv = write_csv_columns(out / 'pass.csv', names, np.column_stack(cols),
                            comment=f'{title}; SI units, rad')
    return csv, plot_pass(result, out / 'pass.png', title)


def _check(args: argparse.Namespace) -> None:
    for name in ('duration', 'chunk', 'every', 'waypoint_period', 'altitude'):
        v = getattr(args, name)
        if not (math.isfinite(v) and v > 0):
            raise CliError(f'--{name.replace("_", "-")} = {v!r}: must be > 0')
    if not 0 < args.max_elevation < 90:
        raise CliError(f'--max-elevation = {args.max_elevation!r}: must be in (0, 90) deg')
    if args.every > args.chunk:
        raise CliError('--every must not exceed --chunk (trajectories must overlap)')
    if args.duration > 1200:
        raise CliError(f'--duration = {args.duration:g} s: at most 1200 s')
    for name in ('duration', 'chunk'):
        if getattr(args, name) < args.waypoint_period:
            raise CliError(f'--{name} = {getattr(args, name):g} s: shorter than '
                           f'--waypoint-period = {args.waypoint_period:g} s (a trajectory '
                           'needs two waypoints)')
    if args.chunk / args.waypoint_period > MAX_TRAJECTORY_POINTS - 2:
        raise CliError(f'--waypoint-period = {args.waypoint_period:g} s: '
                       f'{args.chunk / args.waypoint_period:.6g} waypoints per --chunk, at '
                       f'most {MAX_TRAJECTORY_POINTS - 2}')
    n = math.ceil(args.duration / args.every) + 1
    work = f'{n} trajectories of {args.chunk:g} s ({n * args.chunk:.6g} s to compensate)'
    way_out = 'raise --every or shorten --chunk'
    check_work(f'--every = {args.every:g} s', n, MAX_PASS_TRAJECTORIES, 'trajectories', work,
               way_out)
    check_work(f'--every = {args.every:g} s', n * args.chunk, MAX_PASS_COMPENSATED_S,
               's to compensate', work, way_out)


def cmd_pass(args: argparse.Namespace) -> int:
    _check(args)
    drives = load_pedestal(args.pedestal)
    if len(drives) != 2:
        raise CliError(f'a pass needs a two-axis pedestal (azimuth, elevation); '
                       f'{len(drives)} drives given')
    models = {d.joint: d.config for d in drives}
    t0 = time.perf_counter()
    t, az, el = pass_window(args.duration, args.altitude, math.radians(args.max_elevation))
    az_joint, el_joint = (d.joint for d in drives)
    sent, comp = stream_pass(models, {az_joint: az - az[0], el_joint: el}, t,
                             args.waypoint_period, args.chunk, args.every)
    result = _evaluate(models, sent, comp)
    title = (f'pass: {args.duration:g} s around a {args.max_elevation:g} deg culmination, '
             f'{len(sent)} trajectories')
    csv, png = write_pass(result, Path(args.output), title)
    say(args, title)
    say(args, pass_table(result))
    say(args, f'wrote {csv} and {png} ({time.perf_counter() - t0:.1f} s)')
    return 0
