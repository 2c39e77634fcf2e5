# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``worm-gear-sim``: the offline command line (no ROS needed).

Commands: ``simulate``, ``experiment``, ``sweep``, ``modes``, ``params`` (and ``compensate``
when :mod:`worm_gear_sim.compensation_cli` is installed).  Every command takes ``--config``
(YAML in the ROS layout or plain sections, or a JSON written by ``params``) and repeatable
``--set key=value`` dotted overrides.  Errors are reported as one line on stderr with a
non-zero exit status (2: bad usage or input, 1: the run failed); ``--debug`` shows the
traceback instead.  See docs/studies.md.
"""

from __future__ import annotations

import argparse
import dataclasses
import difflib
import json
import math
import os
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml

from .params import Config, ConfigError, config_from_mapping, derive, load_config

__all__ = ['main', 'build_parser', 'resolve_config', 'parse_set', 'params_document',
           'load_params_json', 'CliError', 'PARAMS_FORMAT']

PROG = 'worm-gear-sim'
PARAMS_FORMAT = 'worm_gear_sim.params/1'
_RESERVED_JSON_KEYS = ('format', 'derived')


class CliError(Exception):
    """A usage or input error: reported as one line, exit status 2."""

    def __init__(self, message: str, prog: str = PROG):
        super().__init__(message)
        self.prog = prog


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors become :class:`CliError` (one line, no usage dump)."""

    def error(self, message: str):  # type: ignore[override]
        raise CliError(message, self.prog)

    def exit(self, status: int = 0, message: str | None = None):  # type: ignore[override]
        if status:
            raise CliError((message or '').strip() or f'exit status {status}', self.prog)
        if message:
            sys.stdout.write(message)
        raise SystemExit(0)


# ---- configuration: --config, --set, params JSON ----------------------------------------
def _suggest(key: str, known: Sequence[str]) -> str:
    close = difflib.get_close_matches(key, list(known), n=1, cutoff=0.6)
    return f' (did you mean {close[0]}?)' if close else ''


_TRUE = ('true', 'yes', 'on', '1')
_FALSE = ('false', 'no', 'off', '0')


def typed_value(key: str, raw: str, default: Any) -> Any:
    """Parse a command-line string for the parameter ``key`` using its default's type."""
    text = raw.strip()
    if isinstance(default, bool):
        if text.lower() in _TRUE:
            return True
        if text.lower() in _FALSE:
            return False
        raise ConfigError(key, f'must be true or false, got {raw!r}')
    if isinstance(default, int):
        try:
            return int(text)
        except ValueError:
            try:
                f = float(text)
            except ValueError:
                raise ConfigError(key, f'must be an integer, got {raw!r}') from None
            if not f.is_integer():
                raise ConfigError(key, f'must be an integer, got {raw!r}') from None
            return int(f)
    if isinstance(default, float):
        try:
            return float(text)
        except ValueError:
            raise ConfigError(key, f'must be a number, got {raw!r}') from None
    if isinstance(default, tuple):
        inner = text[1:-1] if text.startswith('[') and text.endswith(']') else text
        items = [s.strip().strip('\'"') for s in inner.split(',')] if inner.strip() else []
        if default and isinstance(default[0], str):
            return items
        out = []
        for i, s in enumerate(items):
            try:
                out.append(float(s))
            except ValueError:
                raise ConfigError(f'{key}[{i}]', f'must be a number, got {s!r}') from None
        return out
    return raw


def parse_set(items: Sequence[str] | None) -> dict[str, Any]:
    """``['mesh.stiffness_model=linear', ...]`` -> typed dotted overrides (unknown keys and
    malformed items raise ConfigError/CliError)."""
    defaults = Config().to_flat_dict()
    out: dict[str, Any] = {}
    for item in items or ():
        key, sep, raw = item.partition('=')
        key = key.strip()
        if not sep or not key:
            raise CliError(f'--set {item!r}: expected KEY=VALUE, e.g. '
                           'mesh.stiffness_model=linear')
        if key not in defaults:
            raise ConfigError(key, 'unknown parameter' + _suggest(key, list(defaults)))
        out[key] = typed_value(key, raw, defaults[key])
    return out


def params_document(cfg: Config) -> dict[str, Any]:
    """The fully resolved parameters: every config section plus a ``derived`` block
    (inertias, stiffnesses, lead per radian, ratio, mesh calibration, linear modes)."""
    from .modal import modes
    from .model import P_GEAR_X0, P_WORM_X0, pack_parameters
    doc: dict[str, Any] = {'format': PARAMS_FORMAT}
    doc.update(cfg.to_nested_dict())
    d = dataclasses.asdict(derive(cfg))
    d['output_per_input'] = derive(cfg).output_per_input
    p = pack_parameters(cfg)
    d['worm_contact_origin_deg'] = float(p[P_WORM_X0])
    d['gear_contact_origin_deg'] = float(p[P_GEAR_X0])
    try:
        d['natural_frequencies_hz'] = [float(f) for f in modes(cfg).undamped_hz]
    except Exception:  # noqa: BLE001 - informative only
        d['natural_frequencies_hz'] = None
    doc['derived'] = d
    return doc


def _close(a: Any, b: Any) -> bool:
    if isinstance(a, bool) or isinstance(b, bool) or a is None or b is None:
        return a == b
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return math.isclose(float(a), float(b), rel_tol=1e-9, abs_tol=1e-300)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_close(x, y) for x, y in zip(a, b))
    return a == b


def load_params_json(path: str | Path, doc: Mapping[str, Any] | None = None) -> Config:
    """Config from a ``params`` JSON: sections are the parameters; the ``derived`` block is
    checked against the values derived again (a mismatch is an error: derived quantities are
    outputs, edit the sections instead)."""
    p = Path(path)
    if doc is None:
        try:
            doc = json.loads(p.read_text())
        except json.JSONDecodeError as exc:
            raise ConfigError('', f'{p}: broken JSON at line {exc.lineno}, column '
                              f'{exc.colno}: {exc.msg}') from None
    if not isinstance(doc, Mapping):
        raise ConfigError('', f'{p}: expected a JSON object of parameter sections')
    fmt = doc.get('format', PARAMS_FORMAT)
    if fmt != PARAMS_FORMAT:
        raise ConfigError('format', f'{p}: unsupported format {fmt!r} (expected '
                          f'{PARAMS_FORMAT!r})')
    sections = {k: v for k, v in doc.items() if k not in _RESERVED_JSON_KEYS}
    cfg = config_from_mapping(sections, source=str(p))
    derived = doc.get('derived')
    if derived is not None:
        if not isinstance(derived, Mapping):
            raise ConfigError('derived', f'{p}: must be an object')
        fresh = params_document(cfg)['derived']
        for key, value in derived.items():
            if key not in fresh:
                raise ConfigError(f'derived.{key}', 'unknown derived quantity'
                                  + _suggest(key, list(fresh)))
            if not _close(value, fresh[key]):
                raise ConfigError(f'derived.{key}', f'{value!r} does not match the value '
                                  f'derived from the parameters ({fresh[key]!r}); derived '
                                  'quantities are outputs: edit the sections and delete the '
                                  'derived block')
    return cfg


def load_any_config(path: str | Path | None) -> Config:
    """YAML (ROS layout or plain sections) or a ``params`` JSON; None = package default."""
    if path is None:
        return load_config()
    p = Path(path)
    if not p.exists():
        raise ConfigError('', f'config file not found: {p}')
    if p.is_dir():
        raise ConfigError('', f'config path is a directory: {p}')
    if p.suffix.lower() == '.json':
        return load_params_json(p)
    text = p.read_text()
    if text.lstrip().startswith('{'):
        try:
            doc = json.loads(text)
        except json.JSONDecodeError:
            doc = None
        if isinstance(doc, Mapping) and ('derived' in doc or 'format' in doc):
            return load_params_json(p, doc)
    return load_config(p)


def resolve_config(config_path: str | Path | None, sets: Sequence[str] | None = None,
                   extra: Mapping[str, Any] | None = None) -> Config:
    """The run's config: file (or default) + ``--set`` items + command-specific overrides."""
    cfg = load_any_config(config_path)
    overrides = parse_set(sets)
    if extra:
        overrides.update(extra)
    return cfg.replace(overrides) if overrides else cfg


def _config_from_args(args: argparse.Namespace, extra: Mapping[str, Any] | None = None
                      ) -> Config:
    ex = dict(extra or {})
    if getattr(args, 'end_time', None) is not None:
        ex['input.end_time'] = args.end_time
    csv_in = getattr(args, 'input_csv', None)
    if csv_in:
        p = Path(csv_in)
        if not p.is_file():
            raise CliError(f'input CSV not found: {p}')
        ex['input.profile'] = 'csv'
        ex['input.csv_path'] = str(p.resolve())
    return resolve_config(args.config, args.set, ex)


def _add_config_options(p: argparse.ArgumentParser, end_time: bool = True) -> None:
    g = p.add_argument_group('configuration')
    g.add_argument('--config', '-c', metavar='FILE', help='parameter file: YAML (ROS '
                   'layout or plain sections) or a JSON written by "params" '
                   '(default: the package config/worm_gear_sim.yaml)')
    g.add_argument('--set', '-s', action='append', default=[], metavar='KEY=VALUE',
                   help='override one dotted parameter, e.g. mesh.stiffness_model=linear '
                   '(repeatable)')
    if end_time:
        g.add_argument('--end-time', type=float, metavar='S',
                       help='simulated duration (= --set input.end_time=S)')


def _header(cfg: Config, args: argparse.Namespace) -> str:
    argv = ' '.join(getattr(args, '_argv', []) or [])
    return (f'command: {PROG} {argv}\nconfig: {args.config or "package default"}; '
            f'overrides: {json.dumps(parse_set(args.set))}')


def _say(args: argparse.Namespace, msg: str) -> None:
    if not getattr(args, 'quiet', False):
        print(msg)


# ---- simulate --------------------------------------------------------------------------
def cmd_simulate(args: argparse.Namespace) -> int:
    from .plotting import plot_trajectory
    from .simulation import simulate
    from .studies import equilibrium, move_end_time, oscillation_metrics
    cfg = _config_from_args(args)
    out = Path(args.output)
    if out.suffix.lower() != '.csv':
        raise CliError(f'--output must end in .csv, got {out}')
    if args.record_every < 1:
        raise CliError('--record-every must be >= 1')
    t0 = time.perf_counter()
    traj = simulate(cfg, record_every=args.record_every)
    wall = time.perf_counter() - t0
    out.parent.mkdir(parents=True, exist_ok=True)
    traj.to_csv(out, header_comment=_header(cfg, args))
    files = [out]
    if args.npz:
        import numpy as np
        np.savez(args.npz, **traj.columns())
        files.append(Path(args.npz))
    if not args.no_plot:
        png = Path(args.plot) if args.plot else out.with_suffix('.png')
        plot_trajectory(traj, png)
        files.append(png)
    _say(args, f'profile: {traj.profile}')
    _say(args, f'simulated {traj.t[-1]:.6g} s in {wall:.3f} s wall '
         f'({traj.stats.get("steps", 0)} steps, '
         f'{traj.stats.get("subdivision_events", 0)} subdivision events)')
    try:
        from .profiles import make_profile
        t_move = move_end_time(cfg, make_profile(cfg.input))
        if traj.t[-1] > t_move:
            eq = equilibrium(cfg, float(traj.theta1[-1]))
            m = oscillation_metrics(traj, t_move, eq)
            _say(args, f'after the move (t >= {t_move:g} s): max |theta2 - eq| = '
                 f'{m["amp2"]:.4e} rad, max |theta4 - eq| = {m["amp4"]:.4e} rad, theta4 '
                 f'rings at {m["freq4_hz"]:.2f} Hz')
    except ValueError:
        pass
    _say(args, f'final errors: theta2 - theta1 = {traj.worm_error[-1]:.4e} rad, '
         f'theta4 - theta1 l_w/r_g = {traj.output_error[-1]:.4e} rad')
    _say(args, 'wrote ' + ', '.join(str(f) for f in files))
    return 0


# ---- experiment ------------------------------------------------------------------------
def _fmt_table(rows: Sequence[Mapping[str, Any]], cols: Sequence[tuple[str, str, str]]) -> str:
    head = [h for _, h, _ in cols]
    body = []
    for r in rows:
        line = []
        for key, _, fmt in cols:
            v = r.get(key, '')
            line.append(format(v, fmt) if isinstance(v, float) else str(v))
        body.append(line)
    widths = [max(len(h), *(len(b[i]) for b in body)) for i, h in enumerate(head)]
    fmt_line = lambda cells: '  '.join(c.rjust(w) for c, w in zip(cells, widths))  # noqa: E731
    return '\n'.join([fmt_line(head)] + [fmt_line(b) for b in body])


def cmd_experiment(args: argparse.Namespace) -> int:
    from .plotting import plot_experiment
    from .studies import EXPERIMENT_COLUMNS, experiment_table, move_end_time, rows_to_csv
    cfg = _config_from_args(args)
    if cfg.geometry.lead_convention != 'kinematic' or cfg.mesh.stiffness_model != 'nonlinear':
        _say(args, 'note: the experiment sets lead_convention and the linear/nonlinear '
             'model itself; the base values of those keys are ignored')
    outdir = Path(args.out_dir)
    outdir.mkdir(parents=True, exist_ok=True)
    rows, trajs = experiment_table(cfg)
    rows_to_csv(rows, EXPERIMENT_COLUMNS, outdir / 'experiment.csv')
    from .profiles import make_profile
    t_move = move_end_time(cfg, make_profile(cfg.input))
    plot_experiment(trajs, rows, outdir / 'experiment.png', t_move=t_move)
    if args.traces:
        _write_traces(trajs, outdir / 'experiment_traces.csv', args.trace_every)
    _say(args, f'18-step move ({next(iter(trajs.values())).profile}), '
         f'{cfg.input.end_time:g} s; levels in rad, amplitudes after the move:')
    _say(args, _fmt_table(rows, [
        ('model', 'model', ''), ('lead_convention', 'lead', ''),
        ('eq2', 'theta2_eq', '.7f'), ('eq4', 'theta4_eq', '.7f'),
        ('mean4', 'theta4_mean', '.7f'), ('freq4_hz', 'f4_fft[Hz]', '.2f'),
        ('freq4_zc_hz', 'f4_zc[Hz]', '.2f'), ('modal4_hz', 'f1_modal[Hz]', '.2f'),
        ('freq2_hz', 'f2_fft[Hz]', '.1f'), ('amp2', 'amp2', '.3e'), ('amp4', 'amp4', '.3e'),
        ('max_err4', 'max|err4|', '.3e'), ('decay4', 'decay4', '.3f')]))
    _say(args, f'paper (Sec. 3.2): theta2 -> 0.1130973 rad, theta4 -> 0.0127076 rad; '
         f'wrote {outdir / "experiment.csv"}, {outdir / "experiment.png"}')
    return 0


def _write_traces(trajs: Mapping[str, Any], path: Path, every: int) -> None:
    import numpy as np
    first = next(iter(trajs.values()))
    cols = {'t': first.t[::every]}
    for key, tr in trajs.items():
        cols[f'{key}:theta2-theta1'] = tr.worm_error[::every]
        cols[f'{key}:theta4-theta1*lw/rg'] = tr.output_error[::every]
    with open(path, 'w') as fh:
        fh.write(','.join(cols) + '\n')
        np.savetxt(fh, np.column_stack(list(cols.values())), delimiter=',', fmt='%.12g')


# ---- sweep -----------------------------------------------------------------------------
SWEEP_COLUMNS: tuple[str, ...] = (
    'study', 'series', 'label', 'x', 'amp2', 'amp3', 'amp4', 'half_pp2', 'half_pp4', 'eq2',
    'eq4', 'mean2', 'mean4', 'freq2_hz', 'freq4_hz', 'max_err2', 'max_err4', 'decay4', 'J_4',
    'ratio', 't_move', 't_end', 'steps', 'subdivision_events', 'overrides',
)


def _sweep_studies(args: argparse.Namespace, cfg: Config) -> list:
    from .studies import PAPER_STUDIES, paper_study, param_study, parse_values
    names = list(args.study or [])
    studies = []
    if args.param:
        paths = [s.strip() for s in args.param.split(',') if s.strip()]
        defaults = cfg.to_flat_dict()
        for pth in paths:
            if pth not in defaults:
                raise ConfigError(pth, 'unknown parameter' + _suggest(pth, list(defaults)))
        try:
            raw = parse_values(args.values, args.range, args.log)
        except ValueError as exc:
            raise CliError(str(exc)) from None
        values = [typed_value(paths[0], r, Config().to_flat_dict()[paths[0]]) for r in raw]
        for pth in paths[1:]:
            for r in raw:
                typed_value(pth, r, Config().to_flat_dict()[pth])
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
    # validate every case before starting workers (a bad value fails fast, in one line)
    for st in studies:
        for c in st.cases:
            cfg.replace(dict(c.overrides))
    return studies


def _with_compare(study, spec: str, cfg: Config):
    from .studies import COMPARE_SEP, Case
    key, sep, vals = spec.partition('=')
    key = key.strip()
    defaults = Config().to_flat_dict()
    if not sep or not vals.strip():
        raise CliError(f'--compare {spec!r}: expected KEY=V1,V2,...')
    if key not in defaults:
        raise ConfigError(key, 'unknown parameter' + _suggest(key, list(defaults)))
    raws = [v.strip() for v in vals.split(',') if v.strip()]
    cases = []
    for raw in raws:
        v = typed_value(key, raw, defaults[key])
        for c in study.cases:
            if key in c.overrides:
                raise CliError(f'--compare {key}: the {study.name} study sets it itself')
            cases.append(Case(c.study, f'{c.series}{COMPARE_SEP}{key.split(".")[-1]}={raw}', c.x,
                              c.label, {key: v, **c.overrides}))
    return dataclasses.replace(study, cases=tuple(cases),
                               title=f'{study.title}; compare {key}')


def cmd_sweep(args: argparse.Namespace) -> int:
    from .plotting import plot_sweep
    from .studies import ENVELOPE_COLUMNS, envelope_rows, rows_to_csv, run_cases
    cfg = _config_from_args(args)
    if args.workers is not None and args.workers < 1:
        raise CliError('--workers must be >= 1 (use --serial to run in this process)')
    if args.serial and args.scheduler:
        raise CliError('--serial and --scheduler exclude each other')
    studies = _sweep_studies(args, cfg)
    outdir = Path(args.out_dir)
    outdir.mkdir(parents=True, exist_ok=True)
    all_cases = [c for st in studies for c in st.cases]
    engine = ('this process' if args.serial else f'Dask scheduler {args.scheduler}'
              if args.scheduler else
              f'Dask LocalCluster, {args.workers or os.cpu_count()} worker processes')
    _say(args, f'{len(all_cases)} cases in {len(studies)} '
         f'stud{"y" if len(studies) == 1 else "ies"} on {engine}')
    t0 = time.perf_counter()
    rows = run_cases(cfg, all_cases, workers=args.workers, scheduler=args.scheduler,
                     serial=args.serial, progress=not args.no_progress)
    wall = time.perf_counter() - t0
    params_json_dump(params_document(cfg), outdir / 'sweep_params.json')
    k = 0
    for st in studies:
        part = rows[k:k + len(st.cases)]
        k += len(st.cases)
        csv_path = outdir / f'{st.name}.csv'
        png_path = outdir / f'{st.name}.png'
        rows_to_csv(part, SWEEP_COLUMNS, csv_path)
        plot_sweep(part, png_path, st.title, st.x_label, st.x_log, st.categorical)
        _say(args, f'\n{st.title}')
        _say(args, _fmt_table(part, [('series', 'series', ''), ('label', 'case', ''),
                                     ('amp2', 'amp theta2 [rad]', '.4e'),
                                     ('amp4', 'amp theta4 [rad]', '.4e'),
                                     ('freq4_hz', 'f4 [Hz]', '.2f'),
                                     ('max_err4', 'max|err4| [rad]', '.4e')]))
        _say(args, f'wrote {csv_path}, {png_path}')
        if args.compare:
            env = envelope_rows(part)
            env_csv, env_png = outdir / f'{st.name}_envelope.csv', \
                outdir / f'{st.name}_envelope.png'
            rows_to_csv(env, ENVELOPE_COLUMNS, env_csv)
            key, _, vals = args.compare.partition('=')
            plot_sweep(env, env_png, f'{st.title}: worst case over '
                       f'{len(vals.split(","))} values of {key}', st.x_label, st.x_log,
                       st.categorical)
            _say(args, f'worst case over {args.compare}:')
            _say(args, _fmt_table(env, [('series', 'series', ''), ('label', 'case', ''),
                                        ('amp2', 'amp theta2 [rad]', '.4e'),
                                        ('amp2_at', 'at', ''),
                                        ('amp4', 'amp theta4 [rad]', '.4e'),
                                        ('amp4_at', 'at', '')]))
            _say(args, f'wrote {env_csv}, {env_png}')
        if args.traces and len(st.cases) <= 8:
            _sweep_traces(cfg, st, outdir / f'{st.name}_traces.png')
            _say(args, f'wrote {outdir / (st.name + "_traces.png")}')
    kernel = sum(r.get('kernel_s', 0.0) for r in rows)
    _say(args, f'\n{len(rows)} cases in {wall:.2f} s wall ({len(rows) / wall:.2f} cases/s; '
         f'integration time summed over the cases {kernel:.2f} s)')
    return 0


def _sweep_traces(cfg: Config, study, path: Path) -> None:
    from .plotting import plot_traces
    from .studies import move_end_time, run_case
    trajs = {}
    for c in study.cases:
        res = run_case(cfg, c.overrides, keep_trajectory=True)
        trajs[f'{c.series}: {c.label}' if len({x.series for x in study.cases}) > 1
              else c.label] = res['trajectory']
    from .profiles import make_profile
    plot_traces(trajs, path, study.title, move_end_time(cfg, make_profile(cfg.input)))


# ---- modes -----------------------------------------------------------------------------
def cmd_modes(args: argparse.Namespace) -> int:
    from .modal import modes
    cfg = _config_from_args(args)
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
    if args.output:
        from .studies import rows_to_csv
        out = Path(args.output)
        out.parent.mkdir(parents=True, exist_ok=True)
        rows_to_csv(rows, list(rows[0]), out)
        print(f'wrote {out}')
    if args.json:
        doc = {'theta1': args.theta1, 'sliding_rate': args.sliding_rate,
               'operating_point': [float(x) for x in res.operating_point], 'modes': rows,
               'M': res.M.tolist(), 'K': res.K.tolist(), 'C': res.C.tolist()}
        params_json_dump(doc, args.json)
        print(f'wrote {args.json}')
    if args.plot:
        from .plotting import plot_modes
        plot_modes(res, args.plot)
        print(f'wrote {args.plot}')
    return 0


# ---- params ----------------------------------------------------------------------------
def params_json_dump(doc: Mapping[str, Any], path: str | Path | None) -> str:
    """JSON text with exact float round trip (repr); written to ``path`` unless None."""
    text = json.dumps(doc, indent=2, allow_nan=False) + '\n'
    if path is not None:
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)
    return text


def cmd_params(args: argparse.Namespace) -> int:
    cfg = _config_from_args(args)
    doc = params_document(cfg)
    if args.format == 'yaml':
        body = {k: v for k, v in doc.items() if k not in _RESERVED_JSON_KEYS}
        derived = json.dumps(doc['derived'])
        text = ('# worm_gear_sim resolved parameters (ROS params file)\n'
                f'# derived: {derived}\n'
                + yaml.safe_dump({'worm_gear_sim': {'ros__parameters': body}},
                                 sort_keys=False, default_flow_style=None))
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


# ---- parser and entry point ------------------------------------------------------------
def _register_compensate(sub: Any) -> None:
    try:
        from . import compensation_cli  # noqa: F401  (issue 5, optional)
    except ImportError:
        return
    compensation_cli.add_parser(sub)


def build_parser() -> argparse.ArgumentParser:
    """The argparse tree of ``worm-gear-sim`` (subcommands set ``func``)."""
    from . import __version__
    parser = _Parser(prog=PROG, description='Offline studies of the Chung & Shaw (2007) '
                     'worm-gear model: simulate, reproduce the experiment and parametric '
                     'studies, modes and resolved parameters.')
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    parser.add_argument('--debug', action='store_true',
                        help='show the full traceback on errors')
    parser.add_argument('--quiet', '-q', action='store_true', help='print less')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND', parser_class=_Parser)

    p = sub.add_parser('simulate', help='one run: CSV time series and PNG plot',
                       description='Integrate the model for the config\'s input profile (or '
                       'a CSV of t, theta1) and write the time series (theta1..4, rates, '
                       'accelerations, W_n, mu, errors) as CSV plus a PNG plot.')
    _add_config_options(p)
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

    p = sub.add_parser('experiment', help="the paper's Sec. 3 experiment (Figs. 9-11)",
                       description='18-step move: nonlinear model vs the linear model '
                       '(constant tooth stiffness 3.5e8/2.5e8 N/m, mu 0.145) in the '
                       'kinematic and the paper lead convention; table of equilibrium levels, '
                       'frequencies and amplitudes, plot of the oscillating parts.')
    _add_config_options(p)
    p.add_argument('--out-dir', '-o', default='experiment', metavar='DIR',
                   help='output directory (default: %(default)s)')
    p.add_argument('--traces', action='store_true',
                   help='also write the oscillating parts as CSV (experiment_traces.csv)')
    p.add_argument('--trace-every', type=int, default=3, metavar='N',
                   help='trace CSV keeps every N-th step (default: %(default)s = 30 us, '
                   'the paper sampled at 25 us)')
    p.set_defaults(func=cmd_experiment)

    from .studies import PAPER_STUDIES
    p = sub.add_parser('sweep', help="the paper's Sec. 4 parametric studies, in parallel",
                       description='Parametric studies (paper Figs. 12-18) or a sweep of any '
                       'parameter. Output per study: <study>.csv (max oscillation amplitudes '
                       'of theta2 and theta4 after the move, and more) and <study>.png. Runs '
                       'on a Dask LocalCluster with one worker process per core by default.')
    _add_config_options(p)
    p.add_argument('study', nargs='*', metavar='STUDY',
                   help=f'{", ".join(PAPER_STUDIES)} or all')
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
                   help='LocalCluster worker processes (default: all cores)')
    p.add_argument('--scheduler', metavar='ADDRESS', help='run on an existing Dask cluster, '
                   'e.g. tcp://10.0.0.5:8786 (workers need worm_gear_sim installed)')
    p.add_argument('--serial', action='store_true', help='run in this process (no Dask)')
    p.add_argument('--no-progress', action='store_true', help='no progress bar')
    p.add_argument('--traces', action='store_true', help='also plot the time traces of '
                   'studies with at most 8 cases (e.g. flywheel, Figs. 12-13)')
    p.set_defaults(func=cmd_sweep)

    p = sub.add_parser('modes', help='linearised natural frequencies and mode shapes',
                       description='Linearise Eq. 15 about the static equilibrium at theta1 '
                       '(motor end held), optionally at a steady worm speed (friction '
                       'linearised there).')
    _add_config_options(p, end_time=False)
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
    _add_config_options(p)
    p.add_argument('--output', '-o', metavar='FILE', help='write to FILE (default: stdout)')
    p.add_argument('--format', choices=('json', 'yaml'), default='json',
                   help='json (default) or a ROS params YAML (derived block as a comment)')
    p.set_defaults(func=cmd_params)

    _register_compensate(sub)
    return parser


def _one_line(msg: str) -> str:
    return ' '.join(str(msg).split())


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``worm-gear-sim`` and ``python -m worm_gear_sim``; returns the exit
    status (0 ok, 1 the run failed, 2 bad usage or input, 130 interrupted)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = '--debug' in argv
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        if not getattr(args, 'func', None):
            raise CliError('a command is required (simulate, experiment, sweep, modes, '
                           f'params); see {PROG} --help')
        args._argv = argv
        status = args.func(args)
        return int(status or 0)
    except SystemExit as exc:            # --help / --version
        code = exc.code
        return code if isinstance(code, int) else (0 if code is None else 2)
    except KeyboardInterrupt:
        print(f'{PROG}: interrupted', file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - every error becomes one line
        if debug:
            raise
        status, text = _describe(exc)
        prog = exc.prog if isinstance(exc, CliError) else PROG
        print(f'{prog}: error: {_one_line(text)}', file=sys.stderr)
        return status


def _describe(exc: BaseException) -> tuple[int, str]:
    from .simulation import SimulationError
    if isinstance(exc, CliError):
        return 2, str(exc)
    if isinstance(exc, ConfigError):
        return 2, str(exc)
    if isinstance(exc, (FileNotFoundError, IsADirectoryError, PermissionError)):
        name = getattr(exc, 'filename', None)
        return 2, f'{exc.strerror or exc}: {name}' if name else str(exc)
    if isinstance(exc, SimulationError):
        return 1, f'simulation failed: {exc}'
    if isinstance(exc, (ConnectionError, TimeoutError)):
        return 1, str(exc) or type(exc).__name__
    if isinstance(exc, OSError):
        return 1, str(exc)
    if isinstance(exc, ValueError):
        return 2, str(exc)
    return 1, (f'internal error: {type(exc).__name__}: {exc} (run with --debug for the '
               'traceback)')


if __name__ == '__main__':  # pragma: no cover
    sys.exit(main())
