# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``identify`` command: fit parameters of the model to measured records.

    worm-gear-sim identify DATA [DATA ...] --fit KEY[,KEY...] -o FITTED.yaml
                           [--config FILE] [--set KEY=VALUE] [--validate DATA [DATA ...]]
                           [--bounds KEY=LO:HI] [--strategy NAME] [--starts N]
                           [--scheduler ADDRESS | --workers N | --serial]

Writes FITTED.yaml (the node's params-file layout: loadable by ``--ros-args --params-file``,
``load_config()`` and every command), the JSON report FITTED.json and the PNG figures
FITTED.png (and FITTED_validation.png).  A fit that is not trustworthy writes the report and
the figures, no YAML (unless ``--force``), and exits with status 2.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..config.files import write_params_yaml
from ..config.usable import Config
from ..identification import (
    MAX_FIT_SAMPLES,
    MIN_SAMPLES,
    STRATEGIES,
    FitOptions,
    IdentificationError,
    check_record,
    decimation,
    identify,
    prediction_errors,
)
from ..identification.report import jsonable
from ..records import Record, read_record
from .common import CliError, add_config_options, config_from_args, fit_in_process, say

__all__ = ['register', 'cmd_identify', 'parse_bounds']


def register(subparsers: Any) -> None:
    """Add the ``identify`` command to the subparsers."""
    p = subparsers.add_parser(
        'identify', help='fit model parameters to measured records (CSV / rosbag2)',
        description='Fit numeric parameters of the model to one or several measured records '
        'jointly (scipy least_squares; positive quantities in log scale, bounds from the '
        'parameter metadata; frequency start, growing windows and multi-start on Dask). '
        'Writes the fitted parameters as a ROS params file, a JSON report (estimates, 95 % '
        'intervals, correlations, residual RMS) and PNG figures. See docs/identification.md.')
    p.add_argument('data', nargs='+', metavar='DATA', help='records: CSV (columns t, theta1 '
                   'and theta2/theta3/theta4 by header) or rosbag2 (directory, .db3, .mcap)')
    p.add_argument('--fit-harmonics', metavar='worm:N,gear:M', help='also fit the first N '
                   'worm and M gear orders of the periodic error (mesh.*_error_harmonics) as '
                   'linear parameters, alternating with the --fit keys')
    p.add_argument('--fit', action='append', default=[], metavar='KEY[,KEY...]',
                   help='parameters to fit, e.g. materials.gear_shaft_shear_modulus,'
                   'damping.modal_damping_ratios[0] (repeatable)')
    p.add_argument('--output', '-o', required=True, metavar='FITTED.yaml',
                   help='fitted parameter file; the report goes beside it (.json, .png)')
    add_config_options(p, end_time=False)
    p.add_argument('--validate', nargs='+', default=[], metavar='DATA',
                   help='held-out records: prediction error of the fitted model')
    p.add_argument('--bounds', action='append', default=[], metavar='KEY=LO:HI',
                   help='narrower bounds (and multi-start box) for a fitted key')
    p.add_argument('--outputs', metavar='LIST', help='the measured outputs to fit, e.g. '
                   'theta4 or theta2,theta4 (default: every measured output observable at '
                   'its sampling; one whose motion lies above its Nyquist frequency is named '
                   'and left out, docs/identification.md)')
    g = p.add_argument_group('search')
    g.add_argument('--strategy', choices=list(STRATEGIES), default='robust',
                   help='robust (default): frequency start + growing windows + multi-start; '
                   'see docs/identification.md for the comparison')
    g.add_argument('--starts', type=int, metavar='N', help='number of starts (multi-start)')
    g.add_argument('--seed', type=int, default=0, help='seed of the multi-start points')
    g.add_argument('--max-nfev', type=int, default=100, metavar='N',
                   help='residual evaluations per local fit stage (default: %(default)s)')
    e = p.add_argument_group('engine (multi-start)')
    e.add_argument('--scheduler', metavar='ADDRESS', help='run the starts on an existing Dask '
                   'scheduler, e.g. tcp://host:8786')
    e.add_argument('--workers', type=int, metavar='N', help='run the starts on a Dask '
                   'LocalCluster of N worker processes')
    e.add_argument('--serial', action='store_true', help='run every start in this process '
                   '(the default without --workers or --scheduler: the evaluations on one '
                   'forked worker process per core)')
    b = p.add_argument_group('rosbag2 records')
    b.add_argument('--command-topic', metavar='TOPIC', help='theta1: std_msgs/Float64 or the '
                   'stamped JointState reference (default: worm_angle_reference, else '
                   'worm_angle_command)')
    b.add_argument('--joint-states-topic', metavar='TOPIC', help='measured '
                   'sensor_msgs/JointState (default: measured_joint_states, else joint_states)')
    c = p.add_argument_group('CSV records')
    c.add_argument('--column', action='append', default=[], metavar='ROLE=NAME',
                   help='map a header name to a role (t, theta1..theta4), e.g. '
                   'theta4=antenna_encoder (repeatable)')
    p.add_argument('--force', action='store_true',
                   help='write the YAML even if the fit is not trustworthy')
    p.add_argument('--no-plot', action='store_true', help='skip the PNG figures')
    p.add_argument('--no-progress', action='store_true', help='no progress bar')
    p.add_argument('--quiet', '-q', action='store_true', help='print errors only')
    p.set_defaults(func=cmd_identify)


def parse_bounds(items: Sequence[str]) -> dict[str, tuple[float, float]]:
    """``['KEY=LO:HI', ...]`` -> {key: (lo, hi)}."""
    out = {}
    for item in items:
        key, sep, rng = item.partition('=')
        lo, sep2, hi = rng.partition(':')
        try:
            if not (sep and sep2):
                raise ValueError
            vals = (float(lo), float(hi))
        except ValueError:
            raise IdentificationError(f'--bounds {item!r}: expected KEY=LO:HI, e.g. '
                                      'materials.flywheel_density=5000:12000') from None
        if not all(math.isfinite(v) for v in vals):
            raise IdentificationError(f'--bounds {item!r}: bounds must be finite')
        out[key.strip()] = vals
    return out


def _read(paths: Sequence[str], args: argparse.Namespace, cfg: Config,
          what: str) -> list[Record]:
    recs = []
    for i, path in enumerate(paths):
        rec = read_record(path, columns=_columns(args.column), command_topic=args.command_topic,
                          joint_states_topic=args.joint_states_topic,
                          joint_names=tuple(cfg.node.joint_names), require_measured=True,
                          min_samples=MIN_SAMPLES)
        try:
            check_record(rec, i)
        except IdentificationError as exc:
            raise IdentificationError(f'{what} {path}: {exc}') from None
        recs.append(rec)
    return recs


def _columns(items: Sequence[str]) -> dict[str, str] | None:
    out = {}
    for item in items:
        role, sep, name = item.partition('=')
        if not sep or not role.strip() or not name.strip():
            raise IdentificationError(f'--column {item!r}: expected ROLE=NAME, e.g. '
                                      'theta4=antenna_encoder')
        out[role.strip()] = name.strip()
    return out or None


def _fmt_errors(rows: list[dict[str, Any]]) -> list[str]:
    out = []
    for row in rows:
        for o, e in row.items():
            if o == 'name':
                continue
            out.append(f'  {row["name"]}: {o} RMS {e["rms_rad"]:.4g} rad = '
                       f'{100 * e["rel"]:.2f} % of its oscillation amplitude '
                       f'{e["amplitude_rad"]:.4g} rad')
    return out


def cmd_identify(args: argparse.Namespace) -> int:
    cfg = config_from_args(args)
    keys = [k.strip() for item in args.fit for k in item.split(',') if k.strip()]
    out = _checked_output(args)
    bounds = parse_bounds(args.bounds)
    records = _read(args.data, args, cfg, 'DATA')
    held = _read(args.validate, args, cfg, '--validate')
    _say_records(args, records + held)
    opt = FitOptions(strategy=args.strategy, n_starts=args.starts, seed=args.seed,
                     max_nfev=args.max_nfev, workers=args.workers, scheduler=args.scheduler,
                     serial=fit_in_process(args), progress=not (args.no_progress or args.quiet))
    t0 = time.perf_counter()
    outputs = [o.strip() for o in args.outputs.split(',') if o.strip()] \
        if args.outputs else None
    if args.fit_harmonics:
        return _identify_harmonics(args, cfg, records, keys, bounds, opt, out)
    if not keys:
        raise CliError('nothing to fit: give --fit KEY[,KEY...] or --fit-harmonics')
    res = identify(cfg, records, keys, bounds=bounds, options=opt, outputs=outputs)
    wall = time.perf_counter() - t0
    say(args, f'fitted {len(keys)} parameter(s) to {len(records)} record(s) in {wall:.1f} s '
        f'({res.strategy["n_starts"]} start(s), strategy {args.strategy})')
    say(args, res.table())
    report = res.to_dict()
    report.update(command=' '.join(args._argv),
                  data=[str(p) for p in args.data], validate=[str(p) for p in args.validate],
                  output_yaml=None, base_config=args.config or 'package default')
    if held:
        report['validation'] = _validation(args, cfg, res.config, held)
    out.parent.mkdir(parents=True, exist_ok=True)
    stem = out.with_suffix('')
    figures = [] if args.no_plot else _plot_fits(records, held, cfg, res.config, stem)
    report['figures'] = figures
    json_path = stem.with_suffix('.json')
    if res.trustworthy or args.force:
        _write_fitted_yaml(res, report, out)
    json_path.write_text(json.dumps(jsonable(report), indent=2, allow_nan=True) + '\n')
    say(args, f'wrote {json_path}' + (f', {out}' if report['output_yaml'] else '')
        + (f', {", ".join(figures)}' if figures else ''))
    if not res.trustworthy and not args.force:
        raise CliError(f'fit not trustworthy: {res.problems[0]}; no YAML written (report: '
                        f'{json_path}; --force writes it anyway)')
    return 0


def _checked_output(args: argparse.Namespace) -> Path:
    """The fitted parameter file, the run's options checked."""
    out = Path(args.output)
    if out.suffix.lower() not in ('.yaml', '.yml'):
        raise CliError(f'-o {out}: the fitted parameter file must end in .yaml')
    if args.serial and args.scheduler:
        raise CliError('--serial and --scheduler exclude each other')
    if args.workers is not None and args.workers < 1:
        raise CliError('--workers must be >= 1 (use --serial to run in this process)')
    if args.starts is not None and args.starts < 1:
        raise CliError('--starts must be >= 1')
    if args.max_nfev < 2:
        raise CliError('--max-nfev must be >= 2')
    return out


def _say_records(args: argparse.Namespace, records: list[Any]) -> None:
    """Each record read, and how the fit thins a long one."""
    for r in records:
        say(args, f'read {r.describe()}')
        every = decimation(len(r.t))
        if every > 1:
            say(args, f'  {len(r.t)} samples: the fit uses every {every}th '
                f'(at most {MAX_FIT_SAMPLES} per record)')


def _validation(args: argparse.Namespace, cfg: Any, fitted: Any, held: list[Any]
                ) -> dict[str, Any]:
    """The prediction errors on the held-out records before and after the fit."""
    v_before = prediction_errors(cfg, held)
    v_after = prediction_errors(fitted, held)
    say(args, 'held-out records, before the fit:')
    say(args, '\n'.join(_fmt_errors(v_before)))
    say(args, 'held-out records, fitted model:')
    say(args, '\n'.join(_fmt_errors(v_after)))
    return {'before': v_before, 'after': v_after}


def _plot_fits(records: list[Any], held: list[Any], cfg: Any, fitted: Any, stem: Path
               ) -> list[str]:
    """Figures of the fit on the training and the held-out records."""
    from ..identification.plot import plot_fit
    figures = [str(plot_fit(records, cfg, fitted, stem.with_suffix('.png'),
                            'identify: training records'))]
    if held:
        figures.append(str(plot_fit(held, cfg, fitted, Path(f'{stem}_validation.png'),
                                    'identify: held-out records')))
    return figures


def _write_fitted_yaml(res: Any, report: dict[str, Any], out: Path) -> None:
    """The fitted set as YAML, its header saying how it was made and how good it is."""
    header = [f'worm_gear_sim parameters fitted by: worm-gear-sim {report["command"]}',
              f'data: {", ".join(report["data"])}',
              f'base: {report["base_config"]}; created {time.strftime("%Y-%m-%d %H:%M:%S")}']
    for k, v, (lo, hi) in zip(res.keys, res.values, res.ci95):
        header.append(f'{k} = {v:.9g}  (95 % interval {lo:.6g} .. {hi:.6g})')
    for out_name, verdict in res.output_verdicts.items():
        header.append(verdict if verdict.startswith(out_name) else
                      f'{out_name}: {verdict}')
    if not res.trustworthy:
        header.append('NOT TRUSTWORTHY (written with --force): ' + '; '.join(res.problems))
    write_params_yaml(res.config, out, header)
    report['output_yaml'] = str(out)


def _identify_harmonics(args: argparse.Namespace, cfg: Config, records: list, keys: list,
                        bounds: dict, opt: FitOptions, out: Path) -> int:
    """``--fit-harmonics``: the periodic-error harmonics (and the --fit keys, alternating),
    identification/harmonics.py; writes the fitted YAML and the JSON report."""
    from ..identification.data import IdentificationError
    from ..identification.harmonics import identify_with_harmonics, parse_orders
    try:
        nw, ng = parse_orders(args.fit_harmonics)
    except IdentificationError as exc:
        raise CliError(str(exc)) from exc
    t0 = time.perf_counter()
    fit = identify_with_harmonics(cfg, records, keys, nw, ng, options=opt, bounds=bounds)
    say(args, f'fitted {nw} worm and {ng} gear order(s) of the periodic error'
        + (f' with {len(keys)} key(s)' if keys else '')
        + f' to {len(records)} record(s) in {time.perf_counter() - t0:.1f} s')
    say(args, fit.table())
    if fit.nonlinear is not None:
        say(args, fit.nonlinear.table())
    report = fit.to_dict()
    report.update(command=' '.join(args._argv), data=[str(p) for p in args.data],
                  base_config=args.config or 'package default')
    out.parent.mkdir(parents=True, exist_ok=True)
    header = [f'worm_gear_sim parameters fitted by: worm-gear-sim {report["command"]}',
              f'data: {", ".join(report["data"])}']
    header += [f'{n} = {v:.9g}  ({fit.verdicts[n]})' for n, v in zip(fit.names, fit.values)]
    write_params_yaml(fit.config, out, header)
    json_path = out.with_suffix('.json')
    json_path.write_text(json.dumps(jsonable(report), indent=2, allow_nan=True) + '\n')
    say(args, f'wrote {json_path}, {out}')
    return 0
