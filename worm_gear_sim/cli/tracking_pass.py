# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``pass``: a satellite's tracking pass over a two-axis pedestal, streamed as overlapping
trajectories, with and without compensation (:mod:`worm_gear_sim.studies.tracking_pass`):
a per-axis pointing-error table, a CSV and a figure.  The same pass through the ROS nodes:
``scripts/run_pass.sh``.

``pass --adapt``: the pass streamed to each drive as stamped samples with live adaptation
on, against a plant per drive (``--plant``, ``--plant-set``), the twin of the pedestal's
nodes (:mod:`worm_gear_sim.studies.adaptive_pass`): the pointing error over the pass's last
10 s uncompensated, with the nominal and with the adapting feed-forward.  Live:
``scripts/run_pass.sh --adapt``."""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

from ..config.pedestal import load_pedestal
from ..joint_trajectory.compensate import MAX_TRAJECTORY_POINTS
from ..schema.validation import ConfigError
from ..studies.adaptive_pass import TAIL_S, pedestal_plants
from ..studies.pass_report import (
    adaptive_table,
    in_use_lines,
    pass_table,
    write_adaptive_pass,
    write_pass,
)
from ..studies.tracking_pass import evaluate_pass as _evaluate
from ..studies.tracking_pass import pass_window, stream_pass
from .common import CliError, say
from .limits import MAX_PASS_COMPENSATED_S, MAX_PASS_TRAJECTORIES, check_work

__all__ = ['register', 'not_adapted']

#: The trajectory options (the pass with --adapt streams samples, not trajectories).
TRAJECTORY_OPTIONS = {'chunk': 20.0, 'every': 10.0, 'waypoint_period': 1.0}


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
    p.add_argument('--chunk', type=float, metavar='S',
                   help='length of each trajectory sent (default: 20 s)')
    p.add_argument('--every', type=float, metavar='S',
                   help='a new trajectory every S seconds (default: 10 s)')
    p.add_argument('--waypoint-period', type=float, metavar='S',
                   help='waypoint spacing (default: 1 s)')
    g = p.add_argument_group('live adaptation (--adapt)')
    g.add_argument('--adapt', action='store_true',
                   help='stream the pass to each drive as stamped samples with live '
                   'adaptation against a plant per drive; report the last 10 s '
                   'uncompensated, with the nominal and with the adapting feed-forward')
    g.add_argument('--plant', metavar='PLANT_PEDESTAL.yaml',
                   help='the drives\' stand-ins: a pedestal file with a drive of each name '
                   '(default: the drives\' own sets)')
    g.add_argument('--plant-set', action='append', default=[], metavar='DRIVE.KEY=VALUE',
                   help='override one parameter of a drive\'s plant, e.g. '
                   'azimuth.mesh.backlash=5.8e-4 (repeatable)')
    g.add_argument('--noise', type=float, default=1e-6, metavar='RAD',
                   help='encoder noise RMS (default: %(default)g rad)')
    g.add_argument('--encoder-bits', type=int, default=20, metavar='N',
                   help='encoder resolution 2 pi / 2^N (default: %(default)s; 0: none)')
    g.add_argument('--seed', type=int, default=0,
                   help='noise seed of the first drive (the second: seed + 1)')
    g.add_argument('--no-nominal', action='store_true',
                   help='skip the run with the nominal feed-forward (half the time)')
    p.set_defaults(func=cmd_pass)


def _check_adapt(args: argparse.Namespace) -> None:
    """The options of one kind of pass only: an option of the other is an error."""
    if args.adapt:
        given = [n for n in TRAJECTORY_OPTIONS if getattr(args, n) is not None]
        if given:
            raise CliError(f'--{given[0].replace("_", "-")} sets the trajectories of the '
                           'pass without --adapt; with --adapt the pass streams samples')
        if not (math.isfinite(args.noise) and args.noise >= 0):
            raise CliError(f'--noise {args.noise!r}: a finite value >= 0 rad')
        if not 0 <= args.encoder_bits <= 40:
            raise CliError(f'--encoder-bits {args.encoder_bits}: between 0 and 40')
        return
    for name, default in TRAJECTORY_OPTIONS.items():
        if getattr(args, name) is None:
            setattr(args, name, default)
    adapt_only = [o for o, v in (('--plant', args.plant), ('--plant-set', args.plant_set),
                                 ('--no-nominal', args.no_nominal)) if v]
    if adapt_only:
        raise CliError(f'{adapt_only[0]} belongs to a pass with --adapt')


def _check(args: argparse.Namespace) -> None:
    _check_adapt(args)
    positive = ('duration', 'altitude') if args.adapt else \
        ('duration', 'chunk', 'every', 'waypoint_period', 'altitude')
    for name in positive:
        v = getattr(args, name)
        if not (math.isfinite(v) and v > 0):
            raise CliError(f'--{name.replace("_", "-")} = {v!r}: must be > 0')
    if not 0 < args.max_elevation < 90:
        raise CliError(f'--max-elevation = {args.max_elevation!r}: must be in (0, 90) deg')
    if args.duration > 1200:
        raise CliError(f'--duration = {args.duration:g} s: at most 1200 s')
    if args.adapt:
        return
    if args.every > args.chunk:
        raise CliError('--every must not exceed --chunk (trajectories must overlap)')
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


def not_adapted(drives: list) -> list[str]:
    """One line per drive whose ``adaptation.enabled`` the trajectory pass does not honour
    (it compensates with the set as it is; ``--adapt`` adapts)."""
    return [f'{d.name}: adaptation.enabled is true; the trajectory pass compensates with the '
            'drive\'s set as it is (--adapt streams the pass with live adaptation)'
            for d in drives if d.config.adaptation.enabled]


def _adaptive(args: argparse.Namespace, drives: list) -> int:
    from ..studies.adaptive_pass import run_adaptive_pass
    try:
        plants = pedestal_plants(drives, args.plant, args.plant_set)
    except (ConfigError, OSError) as exc:
        raise CliError(f'--plant/--plant-set: {exc}') from None
    t0 = time.perf_counter()
    axes = run_adaptive_pass(
        drives, plants, args.duration, max_elevation=math.radians(args.max_elevation),
        altitude=args.altitude, noise=args.noise, encoder_bits=args.encoder_bits,
        seed=args.seed, nominal=not args.no_nominal,
        on_axis=lambda n: say(args, f'{n}: streaming the pass with live adaptation'))
    tail = min(TAIL_S, args.duration)
    title = (f'pass with live adaptation: {args.duration:g} s around a '
             f'{args.max_elevation:g} deg culmination, the last {tail:g} s')
    csv, png = write_adaptive_pass(axes, Path(args.output), title)
    say(args, title)
    say(args, adaptive_table(axes, tail))
    for line in in_use_lines(axes):
        say(args, line)
    say(args, f'wrote {csv} and {png} ({time.perf_counter() - t0:.1f} s)')
    return 0


def cmd_pass(args: argparse.Namespace) -> int:
    _check(args)
    drives = load_pedestal(args.pedestal)
    if len(drives) != 2:
        raise CliError(f'a pass needs a two-axis pedestal (azimuth, elevation); '
                       f'{len(drives)} drives given')
    if args.adapt:
        return _adaptive(args, drives)
    for line in not_adapted(drives):
        say(args, line)
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
