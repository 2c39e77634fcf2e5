# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``adapt`` command: the offline twin of the node's live adaptation
(:mod:`worm_gear_sim.studies.adaptation_twin`).

    worm-gear-sim adapt --plant PLANT.yaml --scenario sector|slew|pass --duration S -o OUT.csv

Writes OUT.csv and OUT.png and prints the RMS per window and the estimates
(``worm-gear-sim adapt --help``; docs/adaptation.md).
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..config.files import load_config
from ..schema.validation import ConfigError
from .common import CliError, add_config_options, config_from_args, header, say

__all__ = ['register', 'cmd_adapt', 'window_rms']

#: Longest scenario the command runs [s] (about 2x real time per simulated second).
MAX_DURATION = 3600.0


def register(subparsers: Any) -> None:
    """Add the ``adapt`` command."""
    from ..studies.adaptation_twin import SCENARIOS
    p = subparsers.add_parser(
        'adapt', help='offline twin of live adaptation: scenario -> adapting feed-forward '
        '-> plant -> encoder -> adapter',
        description='Stream a scenario through the node\'s real-time pipeline with live '
        'adaptation on: the compensated command drives a simulated plant, its encoder '
        'theta4 comes back to the adapter. Writes the antenna error without and with the '
        'adapting feed-forward (CSV) and a figure. See docs/adaptation.md.')
    add_config_options(p, end_time=False)
    p.add_argument('--plant', required=True, metavar='PLANT.yaml',
                   help='the simulated drive standing in for the real one (a params file)')
    p.add_argument('--scenario', required=True, choices=SCENARIOS)
    p.add_argument('--duration', type=float, required=True, metavar='S',
                   help=f'scenario length (at most {MAX_DURATION:g} s)')
    p.add_argument('--output', '-o', required=True, metavar='OUT.csv')
    p.add_argument('--noise', type=float, default=1e-6, metavar='RAD',
                   help='encoder noise RMS (default: %(default)g rad)')
    p.add_argument('--encoder-bits', type=int, default=20, metavar='N',
                   help='encoder resolution 2 pi / 2^N (default: %(default)s; 0: none)')
    p.add_argument('--seed', type=int, default=0, help='noise seed')
    p.add_argument('--preview', type=float, metavar='S', help='stream the reference this '
                   'far ahead (default: compensation.preview_time, or the centring preview '
                   'when it is 0)')
    p.add_argument('--no-adapt', action='store_true',
                   help='keep the start model (the feed-forward of --config, not adapted)')
    p.add_argument('--no-plot', action='store_true', help='skip the figure')
    p.set_defaults(func=cmd_adapt)


def window_rms(t: np.ndarray, e: np.ndarray, start: float, end: float) -> float:
    """RMS of ``e`` over start <= t < end (nan when empty)."""
    m = (t >= start) & (t < end)
    return float(np.sqrt(np.mean(e[m] ** 2))) if np.any(m) else math.nan


def cmd_adapt(args: argparse.Namespace) -> int:
    from ..studies.adaptation_twin import run_twin
    out = Path(args.output)
    if out.suffix.lower() != '.csv':
        raise CliError(f'-o {out}: the output must end in .csv')
    if not (math.isfinite(args.duration) and 0 < args.duration <= MAX_DURATION):
        raise CliError(f'--duration {args.duration!r}: between 0 and {MAX_DURATION:g} s')
    if not (math.isfinite(args.noise) and args.noise >= 0):
        raise CliError(f'--noise {args.noise!r}: a finite value >= 0 rad')
    if not 0 <= args.encoder_bits <= 40:
        raise CliError(f'--encoder-bits {args.encoder_bits}: between 0 and 40')
    if args.preview is not None and not (math.isfinite(args.preview)
                                         and 0 <= args.preview <= 1):
        raise CliError(f'--preview {args.preview!r}: between 0 and 1 s')
    start = config_from_args(args)
    try:
        plant = load_config(args.plant)
    except (ConfigError, OSError) as exc:
        raise CliError(f'--plant {args.plant}: {exc}') from None
    t0 = time.perf_counter()
    run = run_twin(plant, start, args.scenario, args.duration, noise=args.noise,
                   encoder_bits=args.encoder_bits, seed=args.seed,
                   adapt=not args.no_adapt, preview=args.preview)
    wall = time.perf_counter() - t0
    from ..records.csv_io import write_csv_columns
    data = np.column_stack([run.t, run.theta1_ref, run.error_uncompensated,
                            run.error_compensated])
    write_csv_columns(out, ['t', 'theta1_ref', 'error_uncompensated', 'error_compensated'],
                      data, comment=header(args) + f'\nplant: {args.plant}; scenario '
                      f'{args.scenario}, {args.duration:g} s; units s, rad')
    say(args, f'wrote {out} ({run.t.size} samples, {wall:.1f} s)')
    for msg in run.messages:
        say(args, f'  {msg}')
    t = run.t
    edges = [0.0, 2.0] + [float(x) for x in np.arange(10.0, args.duration + 1e-9, 10.0)]
    if edges[-1] < args.duration:
        edges.append(args.duration + 1e-9)
    say(args, '   window [s]   uncompensated [rad]   adapting [rad]   ratio')
    for a, b in zip(edges[:-1], edges[1:]):
        u, c = window_rms(t, run.error_uncompensated, a, b), \
            window_rms(t, run.error_compensated, a, b)
        say(args, f'{a:6.1f}-{min(b, args.duration):<6.1f} {u:18.3e} {c:16.3e} {u / c:9.1f}')
    say(args, f'steps applied: {len(run.steps)}; counters: '
        + ', '.join(f'{k} {v}' for k, v in run.counters.items() if v and 'predictor' not in k))
    for k, v in run.in_use.items():
        say(args, f'  in use {k} = {v}')
    if not args.no_plot:
        from .plotting import plot_adaptation
        png = plot_adaptation(run, out.with_suffix('.png'),
                              f'adapt: {args.scenario}, plant {Path(args.plant).name}')
        say(args, f'wrote {png}')
    return 0
