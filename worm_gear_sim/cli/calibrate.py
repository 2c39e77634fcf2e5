# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``calibrate`` command: excite, record, fit, validate and write the fitted parameters in one
command (:mod:`worm_gear_sim.identification.calibrate`).

    worm-gear-sim calibrate --fit KEY[,KEY...] -o FITTED.yaml --plant PLANT.yaml
                            [--max-angle RAD] [--max-rate RAD/S] [--max-accel RAD/S2]
                            [--duration S] [--sample-rate HZ] [--noise RAD] [--encoder-bits N]
    worm-gear-sim calibrate ... --export-excitation EXCITATION.csv

``--plant``: a simulated drive (a params file such as ``-o`` writes, or any config) stands in
for the real one, so the whole loop runs on a fresh machine.  ``--export-excitation``: write
the designed moves as one CSV command series for a servo outside ROS; record the drive's
response and fit it with ``identify``.  Writes FITTED.yaml only when the calibration is
accepted (trustworthy fit and held-out theta4 within ``--accept`` of its amplitude), and
always the report FITTED.json and the before/after figure FITTED.png; exit status 2 when not
accepted (nothing written that a node would load).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

from ..config_io import load_config
from ..guarded_io import GuardedFileError, check_write_target
from ..identification import FitOptions
from ..validation import ConfigError
from .common import CliError, add_config_options, config_from_args, fit_in_process, say
from .identify import _jsonable, write_params_yaml
from .limits import MAX_CALIBRATION_SAMPLES, check_work

__all__ = ['register', 'cmd_calibrate', 'report_calibration', 'add_limit_options',
           'limits_of', 'angle_list', 'StageBar', 'recommendation', 'verdict_line']


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


def add_limit_options(p: argparse.ArgumentParser) -> None:
    """The excitation's limits (this command and ``worm_gear_sim_calibrate``)."""
    g = p.add_argument_group('limits of the excitation (worm angle theta1)')
    g.add_argument('--max-angle', type=float, default=0.12, metavar='RAD',
                   help='travel each way from the start (default: %(default)s rad)')
    g.add_argument('--max-rate', type=float, default=6.0, metavar='RAD/S',
                   help='(default: %(default)s rad/s)')
    g.add_argument('--max-accel', type=float, default=1500.0, metavar='RAD/S2',
                   help='(default: %(default)s rad/s^2)')
    g.add_argument('--duration', type=float, default=2.0, metavar='S',
                   help='longest total time of the moves (default: %(default)s s)')
    g.add_argument('--start', type=float, default=0.0, metavar='RAD',
                   help='the current worm angle (default: %(default)s)')


def limits_of(args: argparse.Namespace) -> Any:
    from ..identification.excitation import Limits
    return Limits(args.max_angle, args.max_rate, args.max_accel, args.duration, args.start)


def angle_list(text: str | None, option: str) -> tuple[str, ...] | None:
    """``theta2,theta4`` -> ('theta2', 'theta4'), each one of the model's measurable angles
    (``identification.OUTPUTS``); CliError naming ``option`` otherwise (None: not given).
    Shared with ``worm_gear_sim_calibrate``."""
    from ..identification import OUTPUTS
    if text is None:
        return None
    names = tuple(dict.fromkeys(o.strip() for o in text.split(',') if o.strip()))
    bad = [o for o in names if o not in OUTPUTS]
    if bad or not names:
        raise CliError(f'{option} {text}: ' + (f'{", ".join(bad)} is not' if bad else 'give')
                       + f' one of {", ".join(OUTPUTS)} (comma-separated)')
    return names


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
    from ..identification.excitation import design_excitation
    cfg = config_from_args(args)
    keys = [k.strip() for item in args.fit for k in item.split(',') if k.strip()]
    out = Path(args.output)
    if not (math.isfinite(args.sample_rate) and args.sample_rate > 0):
        raise CliError(f'--sample-rate {args.sample_rate!r}: must be a positive number')
    if not (math.isfinite(args.accept) and 0 < args.accept < 1):
        raise CliError(f'--accept {args.accept!r}: a share between 0 and 1')
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
        advice = recommendation(res, stages)
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


class StageBar:
    """The progress of a calibration (:func:`~worm_gear_sim.identification.calibrate.
    calibrate`'s ``progress`` callback): one step per stage (each move's record, the fit,
    the validation, ..., the recommendation), the running stage's name as the bar's
    description; no bar when not ``enabled``.  Shared with ``worm_gear_sim_calibrate``."""

    def __init__(self, moves: int, enabled: bool) -> None:
        from ..progress import progress_bar
        self.bar = progress_bar(moves + 4, 'calibrate', 'stage') if enabled else None
        self.started = False

    def __call__(self, stage: str) -> None:
        if self.bar is None:
            return
        if self.started:
            self.bar.update(1)
        self.started = True
        if self.bar.n >= self.bar.total:      # a refit: one stage more than planned
            self.bar.total = self.bar.n + 1
        self.bar.set_description_str(stage)

    def close(self) -> None:
        if self.bar is not None:
            if self.started:
                self.bar.total = self.bar.n + 1
                self.bar.update(1)
            self.bar.close()


def recommendation(res: Any, stage: Any = None) -> Any:
    """The compensator settings recommended for an accepted calibration and the improvement
    they predict on a sector scan (:func:`~worm_gear_sim.studies.recommendation.
    recommend_compensator`); None when not accepted."""
    if not res.accepted:
        return None
    from ..studies.recommendation import recommend_compensator
    if stage is not None:
        stage('predict a sector scan')
    return recommend_compensator(res.config)


def verdict_line(res: Any) -> str:
    """``verdict: accepted`` or ``verdict: refused — <reasons>``."""
    return 'verdict: accepted' if res.accepted else \
        'verdict: refused — ' + '; '.join(res.reasons)


def report_calibration(res: Any, base: Any, keys: list[str], limits: Any, out: Path,
                       source: str, command: str, wall: float, plot: bool,
                       say_line: Any, advice: Any = None,
                       **extra: Any) -> tuple[Path, list[str]]:
    """Print the fit, the held-out errors and bounds, the verdict and (``advice``:
    :func:`recommendation`) the recommended compensator and its predicted improvement;
    write FITTED.json (the report), the figure FITTED.png (the verdict on it) and, only
    when accepted, FITTED.yaml.  Shared by this command and the node's calibration
    (``worm_gear_sim_calibrate``).  Returns the report's path and the figures."""
    say_line(res.fit.table())
    direct = res.fit.frequency_info.get('direct', {})
    if direct.get('values'):
        say_line('direct estimates (constant-rate lags): ' + ', '.join(
            f'{k} = {v:.4g}' for k, v in direct['values'].items())
            + ('' if direct.get('play_seen', True) else ' (play not seen)'))
    say_line('the excitation shows: ' + (', '.join(res.seen) or 'none of the fitted keys'))
    for line in res.not_seen.values():
        say_line(f'NOT SEEN: {line}')
    for row_b, row_a in zip(res.validation_before, res.validation_after):
        for o in row_a:
            if o != 'name':
                say_line(f'held-out {row_a["name"]}: {o} RMS {100 * row_b[o]["rel"]:.2f} % '
                         f'-> {100 * row_a[o]["rel"]:.2f} % of its amplitude '
                         f'{row_a[o]["amplitude_rad"]:.3g} rad')
    for b, row in zip(res.bounds, res.validation_after):
        say_line(f'95 % bound on the theta4 RMS prediction error over a {b.duration:.3g} s '
                 f'move: {b.bound_rad:.3g} rad (misfit {b.misfit_rad:.3g}, parameters '
                 f'{b.spread_rad:.3g}); held-out {row["name"]}: '
                 f'{row["theta4"]["rms_rad"]:.3g} rad '
                 f'({"within" if b.covers(row["theta4"]["rms_rad"]) else "OUTSIDE"})')
    say_line(verdict_line(res))
    if advice is not None:
        for line in advice.lines():
            say_line(line)
    stem = out.with_suffix('')
    out.parent.mkdir(parents=True, exist_ok=True)
    report = res.fit.to_dict()
    report.update(command=command, **extra,
                  limits={k: getattr(limits, k) for k in ('max_angle', 'max_rate',
                                                          'max_accel', 'duration', 'start')},
                  moves=[{'name': m.name, 'role': m.role, 'profile': m.profile.describe(),
                          'duration_s': m.t_end} for m in res.moves],
                  validation={'before': res.validation_before, 'after': res.validation_after},
                  prediction_bound=[{'output': b.output, 'level': b.level,
                                     'duration_s': b.duration, 'bound_rad': b.bound_rad,
                                     'misfit_rad': b.misfit_rad, 'spread_rad': b.spread_rad}
                                    for b in res.bounds],
                  accepted=res.accepted, reasons=res.reasons, verdict=verdict_line(res),
                  recommendation=advice.to_dict() if advice is not None else None,
                  seconds=wall,
                  seen=res.seen, not_seen=res.not_seen,
                  output_yaml=None)
    figures = []
    if plot:
        from ..identification.plot import plot_fit
        worst = res.worst_held_out()
        figures.append(str(plot_fit(
            res.held_out + res.train, base, res.config, stem.with_suffix('.png'),
            'calibrate: held-out move and training moves',
            _figure_verdict(res) + (f' (held-out theta4 RMS {100 * worst:.2f} % of its '
                                    'amplitude)' if math.isfinite(worst) else ''))))
    report['figures'] = figures
    if res.accepted:
        header = [f'worm_gear_sim parameters calibrated ({source}); created '
                  f'{time.strftime("%Y-%m-%d %H:%M:%S")}',
                  f'held-out theta4 RMS {100 * res.worst_held_out():.2f} % of its amplitude']
        for k, v, (lo, hi) in zip(res.fit.keys, res.fit.values, res.fit.ci95):
            header.append(f'{k} = {v:.9g}  (95 % interval {lo:.6g} .. {hi:.6g})')
        write_params_yaml(res.config, out, header)
        report['output_yaml'] = str(out)
    json_path = stem.with_suffix('.json')
    json_path.write_text(json.dumps(_jsonable(report), indent=2, allow_nan=True) + '\n')
    say_line(f'calibrated {len(keys)} parameter(s) in {wall:.1f} s; wrote {json_path}'
             + (f', {out}' if res.accepted else '') + (f', {", ".join(figures)}' if figures
                                                       else ''))
    return json_path, figures


def _figure_verdict(res: Any) -> str:
    """The verdict for the figure's title: the first reason only (a title is one line)."""
    if res.accepted:
        return 'verdict: accepted'
    more = f' (+{len(res.reasons) - 1} more)' if len(res.reasons) > 1 else ''
    return f'verdict: refused — {res.reasons[0] if res.reasons else "?"}{more}'
