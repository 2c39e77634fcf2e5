# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``simulate``: one run, CSV time series and PNG plot; ``--csv`` runs a recorded command,
``--bag`` replays a bag through the node's real-time pipeline (docs/data-formats.md)."""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

from .common import CliError, add_config_options, config_from_args, header, say

DEFAULT_OUTPUT_RATE = 10_000.0   # Hz: resolves the 94.5 Hz and 1.56 kHz modes, ~1/10 the size
MAX_CSV_GB = 2.0                 # default --max-csv-size [GB]


def wind_from_arg(text: str) -> Any:
    """``MEAN,INTENSITY[,TIME_SCALE[,SEED]]`` -> a WindLoad; CliError naming the option."""
    from ..dynamics.load import WindLoad
    parts = [x.strip() for x in str(text).split(',')]
    if not 2 <= len(parts) <= 4:
        raise CliError(f'--wind {text!r}: give MEAN,INTENSITY[,TIME_SCALE[,SEED]], e.g. '
                       '--wind 20,0.15,2,7')
    try:
        mean, intensity = float(parts[0]), float(parts[1])
        scale = float(parts[2]) if len(parts) > 2 else 1.0
        seed = int(parts[3]) if len(parts) > 3 else 0
        return WindLoad(mean, intensity, scale, seed)
    except ValueError as exc:
        raise CliError(f'--wind {text!r}: {exc}') from None


def register(sub: Any) -> None:
    """Add the ``simulate`` command to the subparsers ``sub``."""
    p = sub.add_parser('simulate', help='one run: CSV time series and PNG plot',
                       description='Integrate the model for the config\'s input profile, a '
                       'recorded command (--csv) or a bag\'s command stream (--bag, replayed '
                       'through the node\'s pipeline) and write the prediction as CSV (and '
                       'PNG, or a rosbag2 bag for --bag). Formats: docs/data-formats.md.')
    add_config_options(p)
    src = p.add_mutually_exclusive_group()
    src.add_argument('--csv', dest='input_csv', metavar='FILE', help='command from a CSV '
                     'whose header names the columns t and theta1 (units such as [ms], '
                     '[deg] converted); the run covers the record unless --end-time is given')
    src.add_argument('--bag', metavar='BAG', help='replay the command stream of a rosbag2 '
                     'bag (directory, .db3 or .mcap) through the node\'s pipeline; writes the '
                     'prediction as a bag (--bag-out) and CSV, stamped on the recording\'s '
                     'clock')
    p.add_argument('--column', action='append', default=[], metavar='ROLE=NAME',
                   help='--csv: read ROLE (t, theta1..theta4, load_torque) from the column '
                   'NAME, e.g. theta1=/worm_angle_command/data (repeatable)')
    p.add_argument('--wind', metavar='MEAN,INTENSITY[,TIME_SCALE[,SEED]]',
                   help='a gusting wind load on the antenna in place of load.output_torque: '
                   'mean torque [N m], turbulence intensity sigma_u/U (0..1), correlation '
                   'time [s] (default 1), seed (default 0); docs/load.md')
    p.add_argument('--output', '-o', default='simulation.csv', metavar='CSV',
                   help='output CSV (default: %(default)s)')
    p.add_argument('--plot', metavar='PNG', help='plot file (default: the CSV name with .png)')
    p.add_argument('--no-plot', action='store_true', help='skip the PNG')
    p.add_argument('--npz', metavar='FILE', help='also write the columns as float64 NPZ '
                   '(bit-exact; keeps the run in memory)')
    rate = p.add_mutually_exclusive_group()
    rate.add_argument('--output-rate', type=float, default=None, metavar='HZ',
                      help=f'rows per simulated second (default: {DEFAULT_OUTPUT_RATE:g}; 0 = '
                      'every integration step); modes above HZ/2 alias in the CSV')
    rate.add_argument('--record-every', type=int, default=None, metavar='N',
                      help='keep every N-th integration step instead (1 = every step)')
    p.add_argument('--max-csv-size', type=float, default=MAX_CSV_GB, metavar='GB',
                   help='refuse runs whose CSV would exceed this size (default: '
                   '%(default)s GB); the CSV is written in chunks, memory stays bounded '
                   'whatever the duration (except with --npz)')
    g = p.add_argument_group('bags (--bag)')
    g.add_argument('--command-topic', metavar='TOPIC', help='command topic (default: '
                   'worm_angle_reference, else worm_angle_command)')
    g.add_argument('--joint-states-topic', default='joint_states', metavar='TOPIC',
                   help='the node\'s recorded prediction in the input bag, compared with '
                   'the replay when present (default: %(default)s)')
    g.add_argument('--bag-out', metavar='DIR', help='prediction bag (default: the CSV name '
                   'without .csv, plus _bag); an existing bag there is replaced')
    g.add_argument('--bag-storage', choices=('sqlite3', 'mcap'), default='sqlite3',
                   help='storage of the prediction bag (default: %(default)s)')
    g.add_argument('--float64-outputs', action='store_true', help='errors and feed-forward '
                   'as std_msgs/Float64 (node.float64_outputs) instead of stamped one-joint '
                   'JointStates')
    g.add_argument('--bag-namespace', default='', metavar='NS', help='put every output '
                   'topic under /NS (to play it beside a recording of the node)')
    g.add_argument('--no-feedforward', action='store_true', help='do not run the '
                   'compensator (no feedforward / compensated_command topics)')
    p.set_defaults(func=cmd_simulate)


def _columns(items: list[str]) -> dict[str, str]:
    out = {}
    for item in items:
        role, sep, name = item.partition('=')
        if not sep or not role.strip() or not name.strip():
            raise CliError(f'--column {item!r}: expected ROLE=NAME, e.g. theta1=cmd_rad')
        out[role.strip()] = name.strip()
    return out


def _stride(args: argparse.Namespace, dt: float) -> tuple[int, str]:
    """Integration steps per output row, and how it was chosen."""
    if args.record_every is not None:
        if args.record_every < 1:
            raise CliError('--record-every must be >= 1')
        return args.record_every, f'every {args.record_every} step(s)'
    from ..dynamics.simulation import record_stride
    rate = DEFAULT_OUTPUT_RATE if args.output_rate is None else args.output_rate
    if not math.isfinite(rate) or rate < 0:
        raise CliError(f'--output-rate must be >= 0 Hz, got {rate!r}')
    n = record_stride(dt, 1.0 / rate if rate > 0 else 0.0)
    if n == 1:
        return 1, f'every step ({1 / dt:g} Hz)'
    return n, f'{1 / (n * dt):g} Hz (every {n} steps; --output-rate 0 for every step)'


def check_output_size(dt: float, t_end: float, stride: int, out: Path, max_gb: float,
                      in_memory: bool = False) -> int:
    """Up-front check of a run's CSV size against ``max_gb``, of its memory when every row
    is kept (``in_memory``: --npz) and of the free disk space; returns the number of rows.
    Raises CliError naming the estimate and the ways out."""
    import shutil

    from ..dynamics.stepping import RUN_MEMORY_LIMIT
    from ..dynamics.trajectory import ROW_BYTES, csv_bytes_estimate
    if not max_gb > 0:
        raise CliError(f'--max-csv-size must be > 0 GB, got {max_gb:g}')
    steps = int(math.floor(t_end / dt + 1e-9))
    rows = steps // stride + 1
    size = csv_bytes_estimate(rows)
    ways = 'lower --output-rate, shorten --end-time, or raise --max-csv-size'
    if size > max_gb * 1e9:
        raise CliError(f'--end-time {t_end:g} s at dt = {dt:g} s, every {stride} step(s): '
                       f'{rows:.4g} rows, ~{size / 1e9:.3g} GB of CSV (and ~'
                       f'{steps * 3e-7 / 60:.3g} min of computation), above --max-csv-size '
                       f'{max_gb:g} GB: {ways}')
    if in_memory and rows * ROW_BYTES > RUN_MEMORY_LIMIT:
        raise CliError(f'--npz keeps every row in memory: {rows:.4g} rows need '
                       f'{rows * ROW_BYTES / 1e9:.3g} GB, above the in-memory limit '
                       f'(max_bytes) of {RUN_MEMORY_LIMIT / 1e9:g} GB: drop --npz (the CSV '
                       'is streamed), lower --output-rate or shorten --end-time')
    probe = out.parent if str(out.parent) else Path('.')
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    free = shutil.disk_usage(probe).free
    if size > free:
        raise CliError(f'{rows:.4g} rows need ~{size / 1e9:.3g} GB of CSV, only '
                       f'{free / 1e9:.3g} GB free in {probe}: {ways}')
    return rows


def cmd_simulate(args: argparse.Namespace) -> int:
    if args.bag:
        return _simulate_bag(args)
    from ..dynamics.model import DriveModel
    from ..dynamics.profiles import Profile, make_profile
    from ..dynamics.simulation import simulate, simulate_to_csv
    from .plotting import plot_trajectory
    if args.column and not args.input_csv:
        raise CliError('--column needs --csv')
    cfg = config_from_args(args)
    load = wind_from_arg(args.wind) if args.wind else None
    out = Path(args.output)
    if out.suffix.lower() != '.csv':
        raise CliError(f'--output must end in .csv, got {out}')
    stride, rate_text = _stride(args, cfg.integrator.time_step)
    note = ''
    profile: Profile
    if cfg.input.profile == 'csv':
        profile, load, t_end, note = _csv_input(args, cfg, load)
    else:
        profile = make_profile(cfg.input)
        t_end = cfg.input.end_time
    rows = check_output_size(cfg.integrator.time_step, t_end, stride, out, args.max_csv_size,
                             in_memory=bool(args.npz))
    t0 = time.perf_counter()
    out.parent.mkdir(parents=True, exist_ok=True)
    model = DriveModel(cfg)           # built once: the run and its equilibrium
    if load is not None:
        say(args, f'load: {load.describe()} (in place of load.output_torque)')
        note += f'\nload torque on the antenna: {load.describe()}'
    if args.npz:
        import numpy as np
        traj = simulate(model, profile, t_end, record_every=stride, load=load)
        traj.to_csv(out, header_comment=header(args) + note)
        np.savez(args.npz, allow_pickle=False, **traj.columns())
    else:                       # streamed: bounded memory; traj is a thinned copy
        traj = simulate_to_csv(model, out, profile, t_end, record_every=stride,
                               header_comment=header(args) + note, load=load)
    wall = time.perf_counter() - t0
    files = [out] + ([Path(args.npz)] if args.npz else [])
    if not args.no_plot:
        png = Path(args.plot) if args.plot else out.with_suffix('.png')
        plot_trajectory(traj, png)
        files.append(png)
    say(args, f'profile: {traj.profile}')
    say(args, f'simulated {traj.t[-1]:.6g} s in {wall:.3f} s wall '
        f'({traj.stats.get("steps", 0)} steps, '
        f'{traj.stats.get("subdivision_events", 0)} subdivision events); CSV rows at '
        f'{rate_text}')
    if load is None:
        _say_move_metrics(args, cfg, model, profile, traj)
    if len(traj.t) < rows:
        say(args, f'{rows} rows in the CSV; plot and metrics from {len(traj.t)} of them '
            '(every k-th row)')
    say(args, f'final errors: theta2 - theta1 = {traj.worm_error[-1]:.4e} rad, '
        f'theta4 - theta1 l_w/r_g = {traj.output_error[-1]:.4e} rad')
    say(args, 'wrote ' + ', '.join(str(f) for f in files))
    return 0


def _csv_input(args: argparse.Namespace, cfg: Any, load: Any) -> tuple[Any, Any, float, str]:
    """The --csv record as the input: (profile, load (its load_torque column), end time,
    note for the CSV header)."""
    from ..dynamics.load import SampledLoad
    from ..dynamics.profiles import SampledProfile
    from ..records import read_csv
    rec = read_csv(cfg.input.csv_path, columns=_columns(args.column))
    profile = SampledProfile(rec.t, rec.theta1, source=cfg.input.csv_path)
    say(args, f'input: {rec.describe()}')
    if rec.load_torque is not None:
        if load is not None:
            raise CliError(f'--wind and the load_torque column of {cfg.input.csv_path}: '
                           'give one load')
        load = SampledLoad(rec.t, rec.load_torque, source=cfg.input.csv_path)
    cols = ', '.join(f'{r} = {c!r}' for r, c in rec.source['columns'].items())
    say(args, f'columns: {cols}' + (f'; ignored: {", ".join(rec.source["ignored_columns"])}'
                                    if rec.source['ignored_columns'] else ''))
    t_end = rec.duration if args.end_time is None else args.end_time
    if args.end_time is not None and args.end_time > rec.duration:
        say(args, f'--end-time {args.end_time:g} s is past the record '
            f'({rec.duration:.6g} s): theta1 held at its last value after it')
    elif args.end_time is not None and args.end_time < rec.duration:
        say(args, f'--end-time {args.end_time:g} s cuts the record ({rec.duration:.6g} s)')
    return profile, load, t_end, f'\ninput t = 0 at t0_ns = {rec.t0_ns} on the record\'s clock'


def _say_move_metrics(args: argparse.Namespace, cfg: Any, model: Any, profile: Any,
                      traj: Any) -> None:
    """The oscillation after the move (none when the run ends before the move does)."""
    from ..studies import equilibrium, move_end_time, oscillation_metrics
    try:
        t_move = move_end_time(cfg, profile)
        if traj.t[-1] > t_move:                     # the rest is the constant load's
            eq = equilibrium(model, float(traj.theta1[-1]))
            m = oscillation_metrics(traj, t_move, eq)
            say(args, f'after the move (t >= {t_move:g} s): max |theta2 - eq| = '
                f'{m["amp2"]:.4e} rad, max |theta4 - eq| = {m["amp4"]:.4e} rad, theta4 '
                f'rings at {m["freq4_hz"]:.2f} Hz')
    except ValueError:
        pass


def _simulate_bag(args: argparse.Namespace) -> int:
    """Replay a bag's command stream through the node's pipeline
    (worm_gear_sim.realtime.replay)."""
    from ..realtime.replay import compare_with_recorded
    from ..records import read_bag
    if args.column:
        raise CliError('--column applies to --csv, not --bag')
    if args.npz or args.output_rate is not None or args.record_every is not None:
        raise CliError('--npz, --output-rate and --record-every apply to simulations, not '
                       'to --bag (one row per prediction of the pipeline)')
    cfg = config_from_args(args)
    out = Path(args.output)
    if out.suffix.lower() != '.csv':
        raise CliError(f'--output must end in .csv, got {out}')
    bag_out = Path(args.bag_out) if args.bag_out else out.with_name(out.stem + '_bag')
    if bag_out.resolve() == Path(args.bag).resolve():
        raise CliError(f'--bag-out {bag_out} is the input bag')
    names = tuple(cfg.node.joint_names)
    rec = read_bag(args.bag, command_topic=args.command_topic, joint_states_topic='',
                   joint_names=names)
    src = rec.source
    say(args, f'input: {rec.describe()}')
    say(args, f'command: {src["command_topic"]} ({src["command_type"]}, time = '
        f'{src["command_stamp"]}), {rec.command_stream()[1].size} samples')
    recorded, early = _recorded_stamps(args, names)
    float64 = src['command_type'].endswith('Float64')
    if early:
        say(args, f'warning: {early} recorded {args.joint_states_topic} message(s) precede the '
            'first recorded command: the bag misses the start of the stream (start recording '
            'before the servo streams), so the replay, which starts at rest at the first '
            'recorded sample, cannot equal the live node')
    t0 = time.perf_counter()
    rep = _replayed(args, cfg, rec, recorded, float64)
    _say_replay(args, rep, time.perf_counter() - t0)
    _say_comparison(args, compare_with_recorded(rep, args.bag, args.joint_states_topic,
                                                names))
    files = rep.write_csv(out, header_comment=header(args))
    rep.write_bag(bag_out, joint_names=names, storage=args.bag_storage,
                  float64_outputs=args.float64_outputs, namespace=args.bag_namespace,
                  overwrite=True)
    files.append(bag_out)
    if not args.no_plot:
        png = Path(args.plot) if args.plot else out.with_suffix('.png')
        files.append(_plot_replay(rep, png))
    say(args, f'final errors: theta2 - theta1 = {rep.worm_error[-1]:.4e} rad, '
        f'positioning error = {rep.positioning_error[-1]:.4e} rad')
    say(args, 'wrote ' + ', '.join(str(f) for f in files))
    return 0


def _replayed(args: argparse.Namespace, cfg: Any, rec: Any, recorded: Any,
              float64: bool) -> Any:
    """The bag replayed, its ticks (Float64) or holds (stamped) where the live node's were."""
    import numpy as np

    from ..realtime.replay import replay
    rep = replay(cfg, rec, compensate=not args.no_feedforward, end_time=args.end_time,
                 tick_stamps_ns=recorded if float64 else None,
                 hold_stamps_ns=np.zeros(0, np.int64) if recorded is not None and not float64
                 else None)
    if recorded is not None and not float64:
        # the node's held predictions (a paused stream) are the recorded stamps that the
        # samples alone do not produce: replay again with its timer firing there
        held = np.setdiff1d(recorded, rep.stamps_ns)
        if held.size:
            rep = replay(cfg, rec, compensate=not args.no_feedforward,
                         end_time=args.end_time, hold_stamps_ns=held)
    return rep


def _say_replay(args: argparse.Namespace, rep: Any, wall: float) -> None:
    """What the replay produced and rejected, and its first events."""
    c = rep.counters
    rejected = {k[9:]: v for k, v in c.items()
                if k.startswith('rejected_') and k != 'rejected_samples' and v}
    say(args, f'replayed through the node pipeline in {wall:.3f} s: {rep.stamps_ns.size} '
        f'predictions over {rep.t[-1]:.6g} s, {rep.delta.size} corrections'
        + (f'; rejected: {", ".join(f"{k} {v}" for k, v in rejected.items())}'
           if rejected else ''))
    if rep.info['input'] == 'float64':
        say(args, 'note: Float64 commands carry no time; samples at the bag\'s receive time, '
            f'ticks at the {rep.info["ticks"]}: close to, not equal to, the live node')
    if rep.info.get('compensation_error'):
        say(args, f'feed-forward unavailable: {rep.info["compensation_error"]}')
    for e in rep.events[:5]:
        say(args, f'event: {e}')
    if len(rep.events) > 5:
        say(args, f'... {len(rep.events) - 5} more events')


def _say_comparison(args: argparse.Namespace, cmp: Any) -> None:
    """The replay against the live node's recorded predictions, when the bag has them."""
    if cmp and cmp['stamps_compared']:
        say(args, f'max |replay - recorded {cmp["topic"]}| = {cmp["max_abs_diff"]:.3e} rad '
            f'(theta2..theta4) over {cmp["stamps_compared"]} equal stamps '
            f'({cmp["live_stamps"]} recorded, {cmp["replay_stamps"]} replayed)')
        for name, a in cmp['answers'].items():
            say(args, f'max |replay - recorded ~/{name}| = {a["max_abs_diff"]:.3e} rad over '
                f'{a["stamps_compared"]} equal stamps')
        if cmp['replay_only'] or cmp['recorded_only']:
            say(args, f'warning: {cmp["replay_only"]} replayed prediction(s) inside the '
                f'recorded span were not recorded and {cmp["recorded_only"]} recorded '
                'one(s) were not replayed: the node did not take every sample of the bag '
                '(its queue overflowed: a loaded machine), or the recorder lost messages')
    elif cmp:
        say(args, f'the bag\'s {cmp["topic"]} has no stamp in common with the replay: '
            'not compared')


def _recorded_stamps(args: argparse.Namespace, names: tuple) -> Any:
    """Stamps of the live node's joint_states in the bag (its ticks, its held
    predictions) or None, and how many of them precede the first recorded command."""
    import numpy as np

    from ..records import RecordError, read_bag
    try:
        live = read_bag(args.bag, command_topic=args.command_topic,
                        joint_states_topic=args.joint_states_topic, joint_names=names,
                        require_measured=True, min_samples=1)
    except RecordError:
        return None, 0
    return (live.t0_ns + np.round(live.t * 1e9).astype(np.int64),
            int(live.source.get('measurements_before_first_command', 0)))


def _plot_replay(rep: Any, png: Path) -> Path:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(3, 1, figsize=(8.0, 7.5), sharex=True)
    t = rep.t
    ax[0].plot(t, rep.position[:, 0], label='theta1 (applied command)')
    ax[0].plot(t, rep.position[:, 1], label='theta2 (worm)', lw=0.8)
    ax[0].set_ylabel('angle [rad]')
    ax[0].legend(loc='best', fontsize=8)
    ax[1].plot(t, rep.positioning_error * 1e6, lw=0.8)
    ax[1].set_ylabel('antenna error [urad]')
    if rep.delta.size:
        ax[2].plot((rep.correction_stamps_ns - rep.t0_ns) * 1e-9, rep.delta * 1e3, lw=0.8)
    ax[2].set_ylabel('feed-forward [mrad]')
    ax[2].set_xlabel(f't [s] after t0_ns = {rep.t0_ns}')
    ax[0].set_title(f'replay of {rep.record.name} through the node pipeline')
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return png
