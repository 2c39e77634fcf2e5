# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``calibrate`` command: excite, record, fit, validate and write the fitted parameters in one
command (:mod:`worm_gear_sim.identification.calibrate`).

    worm-gear-sim calibrate --fit KEY[,KEY...] -o FITTED.yaml --plant PLANT.yaml

Writes FITTED.yaml only when accepted (exit status 2 otherwise), always FITTED.json and
FITTED.png (``worm-gear-sim calibrate --help``; docs/identification.md).
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

from .._support.guarded_io import GuardedFileError, check_write_target
from ..config.files import load_config
from ..identification import FitOptions
from ..identification.calibration_options import add_limit_options, angle_list, limits_of
from ..schema.validation import ConfigError
from .common import CliError, add_config_options, config_from_args, fit_in_process, say
from .limits import MAX_CALIBRATION_SAMPLES, check_work

__all__ = ['register', 'cmd_calibrate']


def register(subparsers: Any) -> None:
    """Add the ``calibrate`` command."""
    p = subparsers.add_parser(
        'calibrate', help='excite, record, fit, validate, write: one-command calibration',
        description='Design an excitation within the limits (steps out and back, a small '
        'step, a held-out S-curve; or, when the play, load torque or drag is fitted, slow '
        'and fast sweeps out and back at constant rates and a held-out sweep), run it on the '
        'drive (--plant: a simulated drive), fit the chosen parameters, validate on the '
        'held-out move, and write the fitted params file when accepted; print the verdict, '
        'the compensator settings it recommends and the improvement they predict on a '
        'sector scan. A real drive behind a running node: worm_gear_sim_calibrate (the same '
        'calibration streamed to the servo over ROS; it asks before it moves the axis). See '
        'docs/identification.md, "Calibrate in one command".')
    add_config_options(p, end_time=False)
    p.add_argument('--fit', action='append', required=True, metavar='KEY[,KEY...]',
                   help='parameters to fit (as for identify; repeatable)')
    p.add_argument('--output', '-o', required=True, metavar='FITTED.yaml',
                   help='fitted parameter file (written when accepted); report beside it')
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument('--plant', metavar='PLANT.yaml', help='a simulated drive standing in '
                     'for the real one (a params file)')
    src.add_argument('--export-excitation', metavar='CSV', help='only write the designed '
                     'excitation as one command series (t, theta1) for a servo outside ROS')
    add_limit_options(p)
    r = p.add_argument_group('recording (--plant)')
    r.add_argument('--sample-rate', type=float, default=1e4, metavar='HZ',
                   help='encoder sample rate (default: %(default)g Hz)')
    r.add_argument('--measure', default='theta4', metavar='LIST',
                   help='measured angles, e.g. theta4 or theta2,theta4 (default: theta4)')
    r.add_argument('--noise', type=float, default=1e-6, metavar='RAD',
                   help='encoder noise RMS (default: %(default)g rad)')
    r.add_argument('--encoder-bits', type=int, default=20, metavar='N',
                   help='encoder resolution 2 pi / 2^N (default: %(default)s; 0: none)')
    r.add_argument('--seed', type=int, default=0, help='noise seed')
    p.add_argument('--outputs', metavar='LIST', help='outputs to fit (as for identify)')
    p.add_argument('--accept', type=float, default=0.05, metavar='SHARE',
                   help='accept when the held-out theta4 RMS error is within this share of '
                   'its amplitude (default: %(default)s)')
    p.add_argument('--serial', action='store_true', help='fit in this process (the default '
                   'without --workers: the evaluations on one forked worker process per core)')
    p.add_argument('--workers', type=int, metavar='N', help='fit the starts on a Dask '
                   'LocalCluster of N worker processes')
    p.add_argument('--no-plot', action='store_true', help='skip the figure')
    p.add_argument('--no-progress', action='store_true', help='no progress bar')
    p.set_defaults(func=cmd_calibrate)


def _check_outputs(out: Path, plot: bool) -> None:
    """FITTED.yaml, its report and its figure can be written (before the run)."""
    if out.suffix.lower() not in ('.yaml', '.yml'):
        raise CliError(f'-o {out}: the fitted parameter file must end in .yaml')
    for path in [out, out.with_suffix('.json')] + ([out.with_suffix('.png')] if plot else []):
        try:
            check_write_target(path)
        except GuardedFileError as exc:
            raise CliError(f'-o {out}: {exc}; nothing was run') from None


def _check_record_size(moves: list, args: argparse.Namespace, columns: int) -> None:
    """The records (or the exported series) of the designed moves at --sample-rate within
    MAX_CALIBRATION_SAMPLES (.limits)."""
    n = sum(int(math.floor(m.t_end * args.sample_rate + 1e-9)) + 1 for m in moves)
    seconds = sum(m.t_end for m in moves)
    check_work(f'--sample-rate {args.sample_rate:g} Hz', n, MAX_CALIBRATION_SAMPLES,
               'samples', f'{len(moves)} moves of {seconds:.3g} s in all: {n:.3g} samples, '
               f'~{n * columns * 8 / 1e9:.3g} GB of records',
               'lower --sample-rate (the fit uses at most 200000 samples of a move) or '
               '--duration')


def cmd_calibrate(args: argparse.Namespace) -> int:
    from ..adaptation.plant import encoder_resolution
    from ..identification.calibrate import calibrate, excitation_series, plant_runner
    from ..identification.calibration_report import StageBar, report_calibration
    from ..identification.excitation import design_excitation
    from ..studies.recommendation import calibration_recommendation
    cfg = config_from_args(args)
    keys = [k.strip() for item in args.fit for k in item.split(',') if k.strip()]
    out = Path(args.output)
    if not (math.isfinite(args.sample_rate) and args.sample_rate > 0):
        raise CliError(f'--sample-rate {args.sample_rate!r}: must be a positive number')
    if not (math.isfinite(args.accept) and 0 < args.accept < 1):
        raise CliError(f'--accept {args.accept!r}: a share between 0 and 1')
    # a bad angle: IdentificationError (a ValueError: exit 2, one line)
    measure = angle_list(args.measure, '--measure') or ('theta4',)
    outputs = angle_list(args.outputs, '--outputs')
    if not (math.isfinite(args.noise) and args.noise >= 0):
        raise CliError(f'--noise {args.noise!r}: an encoder noise RMS >= 0 rad')
    if args.seed < 0:
        raise CliError(f'--seed {args.seed}: must be >= 0')
    try:
        res_bits = encoder_resolution(args.encoder_bits)
    except ValueError as exc:
        raise CliError(f'--encoder-bits: {exc}') from None
    if args.export_excitation:
        try:
            check_write_target(args.export_excitation)
        except GuardedFileError as exc:
            raise CliError(f'--export-excitation: {exc}') from None
    else:
        _check_outputs(out, not args.no_plot)
    limits = limits_of(args)
    moves = design_excitation(limits, keys, cfg)   # IdentificationError: exit 2, one line
    _check_record_size(moves, args, 2 + (0 if args.export_excitation else len(measure)))
    for m in moves:
        say(args, f'move {m.name} ({m.role}): {m.profile.describe()}, {m.t_end:.3f} s')
    if args.export_excitation:
        import numpy as np

        from ..records import write_csv_columns
        t, x = excitation_series(moves, args.sample_rate)
        path = write_csv_columns(args.export_excitation, ['t[s]', 'theta1[rad]'],
                                 np.column_stack([t, x]), comment=(
                                     'worm_gear_sim calibration excitation: '
                                     + ', '.join(f'{m.name} ({m.role})' for m in moves)))
        say(args, f'wrote {path}: stream it to the servo, record theta1 and the encoders, '
            'then: worm-gear-sim identify RECORD --fit ... (hold out validate_scurve)')
        return 0
    try:
        plant = load_config(args.plant)
    except (ConfigError, OSError) as exc:
        raise CliError(f'--plant {args.plant}: {exc}') from None
    run = plant_runner(plant, args.sample_rate, measure, args.noise, res_bits, args.seed)
    opt = FitOptions(strategy='robust', serial=fit_in_process(args),
                     workers=args.workers)
    t0 = time.perf_counter()
    stages = StageBar(len(moves), not (args.no_progress or args.quiet))
    try:
        res = calibrate(cfg, keys, limits, run, options=opt,
                        outputs=list(outputs) if outputs else None, accept_rel=args.accept,
                        progress=stages)
        advice = calibration_recommendation(res, stages)
    finally:
        stages.close()
    wall = time.perf_counter() - t0
    json_path, figures = report_calibration(
        res, cfg, keys, limits, out, f'plant {args.plant}',
        ' '.join(getattr(args, '_argv', [])), wall, not args.no_plot,
        lambda line: say(args, line), advice, plant=args.plant)
    if not res.accepted:
        raise CliError(f'calibration not accepted: {res.reasons[0]}; no YAML written '
                       f'(report: {json_path}); the previous parameters stay in use')
    return 0
