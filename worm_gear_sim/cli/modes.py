# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``modes`` (linearised natural frequencies and mode shapes) and ``params`` (the fully
resolved parameters)."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

from ..config.files import params_document, params_json_dump, params_yaml_text
from .common import CliError, add_config_options, config_from_args


def register(sub: Any) -> None:
    """Add the ``modes`` and ``params`` commands to the subparsers ``sub``."""
    p = sub.add_parser('modes', help='linearised natural frequencies and mode shapes',
                       description='Linearise Eq. 15 about the static equilibrium at theta1 '
                       '(motor end held), optionally at a steady worm speed (friction '
                       'linearised there).')
    add_config_options(p, end_time=False)
    p.add_argument('--theta1', type=float, default=0.0, metavar='RAD',
                   help='operating point: commanded worm angle (default: %(default)s)')
    p.add_argument('--sliding-rate', type=float, default=0.0, metavar='RAD_S',
                   help='steady worm speed of the operating point (default: %(default)s)')
    p.add_argument('--output', '-o', metavar='CSV', help='write the modes as CSV')
    p.add_argument('--json', metavar='FILE', help='write modes and M, K, C as JSON')
    p.add_argument('--plot', metavar='PNG', help='plot the mode shapes')
    p.set_defaults(func=cmd_modes)

    p = sub.add_parser('params', help='fully resolved parameters as JSON (reproducible)',
                       description='Print every parameter after defaults and overrides, plus '
                       'a "derived" block. Feeding the JSON back with --config reproduces the '
                       'same run bit for bit (the derived block is checked, not read).')
    add_config_options(p)
    p.add_argument('--output', '-o', metavar='FILE', help='write to FILE (default: stdout)')
    p.add_argument('--format', choices=('json', 'yaml'), default='json',
                   help='json (default) or a ROS params YAML (derived block as a comment)')
    p.set_defaults(func=cmd_params)


# ---- modes -----------------------------------------------------------------------------
def cmd_modes(args: argparse.Namespace) -> int:
    from ..dynamics.modal import modes
    cfg = config_from_args(args)
    for name in ('theta1', 'sliding_rate'):
        if not math.isfinite(getattr(args, name)):
            raise CliError(f'--{name.replace("_", "-")} must be finite')
    res = modes(cfg, theta1=args.theta1, sliding_rate=args.sliding_rate)
    dt = cfg.integrator.time_step
    rows = []
    for i in range(len(res.undamped_hz)):
        w_dt = 2 * math.pi * res.undamped_hz[i] * dt
        elong = w_dt / (2 * math.atan(w_dt / 2)) - 1 if w_dt > 0 else 0.0
        rows.append({'mode': i + 1, 'frequency_hz': float(res.frequencies_hz[i]),
                     'undamped_hz': float(res.undamped_hz[i]),
                     'damping_ratio': float(res.damping_ratios[i]),
                     'shape_theta2': float(res.shapes[0, i]),
                     'shape_theta3': float(res.shapes[1, i]),
                     'shape_theta4': float(res.shapes[2, i]),
                     'steps_per_period': (1.0 / (res.undamped_hz[i] * dt)
                                          if res.undamped_hz[i] > 0 else math.inf),
                     'period_elongation': elong})
    print(f'operating point: theta1 = {args.theta1:g} rad, worm speed '
          f'{args.sliding_rate:g} rad/s; equilibrium theta2..4 = '
          + ', '.join(f'{x:.9g}' for x in res.operating_point))
    print(res.table())
    print(f'dt = {dt:g} s: ' + '; '.join(
        f'mode {r["mode"]} {r["steps_per_period"]:.1f} steps/period, Newmark period '
        f'elongation {100 * r["period_elongation"]:.2f} %' for r in rows))
    from ..identification.observability import ADVISED_SAMPLES_PER_PERIOD, sampling_advice
    advice = sampling_advice(cfg)
    print(f'sample rates to measure each angle for identify ({ADVISED_SAMPLES_PER_PERIOD:g} '
          'samples per period of the highest mode that moves it): '
          + ', '.join(f'{o} >= {f:.0f} Hz' for o, f in advice.items()))
    if args.output:
        from ..studies import rows_to_csv
        out = Path(args.output)
        out.parent.mkdir(parents=True, exist_ok=True)
        rows_to_csv(rows, list(rows[0]), out)
        print(f'wrote {out}')
    if args.json:
        doc = {'theta1': args.theta1, 'sliding_rate': args.sliding_rate,
               'operating_point': [float(x) for x in res.operating_point], 'modes': rows,
               'M': res.M.tolist(), 'K': res.K.tolist(), 'C': res.C.tolist(),
               'advised_sample_rate_hz': {o: float(f) for o, f in advice.items()}}
        params_json_dump(doc, args.json)
        print(f'wrote {args.json}')
    if args.plot:
        from .plotting import plot_modes
        plot_modes(res, args.plot)
        print(f'wrote {args.plot}')
    return 0


def cmd_params(args: argparse.Namespace) -> int:
    cfg = config_from_args(args)
    doc = params_document(cfg)
    if args.format == 'yaml':
        text = params_yaml_text(doc)
    else:
        text = params_json_dump(doc, None)
    if args.output and args.output != '-':
        p = Path(args.output)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)
        print(f'wrote {p}', file=sys.stderr)
    else:
        sys.stdout.write(text)
    return 0
