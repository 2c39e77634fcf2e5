# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The tracking pass with live adaptation through the pedestal's processes: the live
counterpart of ``worm-gear-sim pass --adapt`` (``scripts/run_pass.sh --adapt``).

    python -m worm_gear_sim.ros.live_pedestal [--pedestal PEDESTAL.yaml] [--twin] -o DIR

:func:`run_live_pedestal` starts ``worm_gear_sim_pedestal`` and a plant node per drive and
commands both drives on one ``/clock`` (the commander of :mod:`.live_adaptation`); each
drive's result (a ``LiveRun``) equals its twin with no late samples nor steps.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from rclpy.executors import SingleThreadedExecutor
from std_srvs.srv import Trigger

from ..config.pedestal import Drive, load_pedestal
from ..config.usable import Config
from ..records.topics import MEASURED_TOPIC, private_topic
from ..schema.sections import NODE_NAME
from ..studies.adaptation_twin import prepare_start
from ..studies.adaptive_pass import AxisPass, pass_reference
from .adaptation import WRITE_SERVICE
from .live_adaptation import (
    LiveRun,
    ScenarioCommander,
    live_result,
    plant_command,
    start_process,
    stop_process,
    stream_through,
    write_params,
)
from .teardown import teardown_deadline

__all__ = ['LivePedestal', 'run_live_pedestal', 'pedestal_command', 'main', 'Report',
           'run_report', 'parse_args']


@dataclass
class LivePedestal:
    """The live pass: per drive (pedestal order) its name and :class:`LiveRun`; the
    handshake's hold messages, t = 0's stamp, whether the stream stalled, the answers of
    the write services (drive name -> (success, message)) and the pedestal's log."""

    drives: list[tuple[str, LiveRun]]
    held: int = 0
    t0_ns: int = 0
    stalled: bool = False
    written: dict[str, tuple[bool, str]] = field(default_factory=dict)
    pedestal_log: str = ''

    def axes(self, joints: dict[str, str]) -> list[AxisPass]:
        """As the twin's :class:`AxisPass` (no nominal run: its errors nan); ``joints``:
        drive name -> worm input joint."""
        return [AxisPass(n, joints[n], r.t, r.theta1_ref, r.error_uncompensated,
                         np.full(r.t.size, np.nan), r.error_compensated, r)
                for n, r in self.drives]


def pedestal_command(pedestal: Path, ros_params: Path) -> list[str]:
    """The pedestal's process for the pedestal file ``pedestal`` and the ROS params file
    ``ros_params``."""
    return [sys.executable, '-c', 'import sys; from worm_gear_sim.ros.startup import '
            'pedestal_main; sys.exit(pedestal_main())', '--pedestal', str(pedestal),
            '--ros-args', '--params-file', str(ros_params)]


def _ros_params(names: list[str]) -> str:
    """use_sim_time for every node, each drive node's encoder subscription reliable, keep
    last 1000 (a ``qos_overrides`` key names a topic of one node: a ``-p`` would reach all
    of them, and a drive node refuses another's topic)."""
    doc: dict[str, Any] = {'/**': {'ros__parameters': {'use_sim_time': True}}}
    for n in names:
        topic = f'/{n}/{MEASURED_TOPIC}'
        doc[f'/{n}/{NODE_NAME}'] = {'ros__parameters': {'qos_overrides': {topic: {
            'subscription': {'reliability': 'reliable', 'depth': 1000}}}}}
    return yaml.safe_dump(doc, sort_keys=False)


def run_live_pedestal(drives: list[Drive], plants: dict[str, Config], duration: float, *,
                      context: Any, env: dict[str, str], workdir: Path,
                      max_elevation: float = math.radians(85.0), altitude: float = 500e3,
                      noise: float = 1e-6, encoder_bits: int = 20, seed: int = 0,
                      lead: float = 0.02, speed: float = 1.0, write: bool = False,
                      startup_timeout: float = 120.0, drain_timeout: float = 30.0,
                      stall_timeout: float = 20.0) -> LivePedestal:
    """The pass of ``duration`` s over the first two ``drives`` through the processes
    (module docstring); ``plants``: drive name -> the stand-in (missing: the drive's own
    set); ``context``, ``env``, ``noise``, ``encoder_bits``, ``lead``, ``speed`` and the
    timeouts as :func:`~.live_adaptation.run_live` (the clock's ``max_lag``: half of the
    smallest ``adaptation.sample_delay`` less ``lead``); ``write``: call each drive's
    ``~/write_adapted_parameters`` after the stream.  RuntimeError if the processes do not
    connect within ``startup_timeout`` s (the logs are in ``workdir``)."""
    workdir.mkdir(parents=True, exist_ok=True)
    axes = drives[:2]
    if len(axes) < 2:
        raise ValueError(f'a pass needs two drives (azimuth, elevation); {len(axes)} given')
    cfgs, ahead, max_lag = _start_sets(axes, lead)
    refs = {}
    for k, d in enumerate(axes):
        c = cfgs[d.name]
        refs[d.name] = pass_reference(k, duration, max_elevation, altitude)(
            c, duration + ahead + 5.0 / c.node.publish_rate_hz)
    t = refs[axes[0].name][0]
    keep = t <= duration + 1e-12
    _write_pedestal_files(workdir, axes, cfgs)
    records = {d.name: workdir / f'{d.name}_plant_record.npz' for d in axes}
    procs: list[tuple[Any, Any]] = []
    logs: dict[str, list[str]] = {}
    commander = ex = None
    out = LivePedestal([])
    try:
        procs.append(start_process(pedestal_command(workdir / 'pedestal.yaml',
                                                    workdir / 'ros_params.yaml'),
                                   env, workdir / 'pedestal.log', cwd=workdir))
        for k, d in enumerate(axes):
            records[d.name].unlink(missing_ok=True)
            plant = write_params(plants.get(d.name, d.config), workdir / f'{d.name}_plant.yaml')
            procs.append(start_process(
                plant_command(plant, records[d.name], noise=noise, encoder_bits=encoder_bits,
                              seed=seed + k, namespace=d.name), env,
                workdir / f'{d.name}_plant.log'))
        commander = ScenarioCommander(
            t, [(d.name, d.joint, refs[d.name][1]) for d in axes], ahead + lead,
            speed=speed, max_lag=max_lag, context=context)
        ex = SingleThreadedExecutor(context=context)
        ex.add_node(commander)
        out.stalled, wall = stream_through(
            commander, ex, [p for p, _ in procs], int(np.count_nonzero(keep)) - 1,
            startup_timeout=startup_timeout, drain_timeout=drain_timeout,
            stall_timeout=stall_timeout)
        if write:
            out.written = _write(commander, ex, [d.name for d in axes], startup_timeout)
    finally:
        texts = [stop_process(p, fh) for p, fh in procs]
        out.pedestal_log = texts[0] if texts else ''
        for d, text in zip(axes, texts[1:]):
            logs[d.name] = [out.pedestal_log, text]
        if ex is not None:
            ex.shutdown()
        if commander is not None:
            commander.destroy_node()
    assert commander is not None
    out.held, out.t0_ns = commander.held, commander.t0_ns or 0
    for d, s in zip(axes, commander.streams):
        x = refs[d.name][1]
        out.drives.append((d.name, live_result(
            plants.get(d.name, d.config), cfgs[d.name], t[keep], x[keep], out.t0_ns,
            s.adapted, records[d.name], logs.get(d.name, ['', '']), wall)))
    return out


def _start_sets(axes: list[Drive], lead: float) -> tuple[dict[str, Config], float, float]:
    """Each axis's start set as the twin runs it, the largest preview [s] and the clock's
    ``max_lag`` [s]; ValueError when the axes stream at different rates or ``lead`` is too
    long for the adaptation's sample delay."""
    cfgs = {d.name: prepare_start(d.config) for d in axes}
    rates = {c.node.publish_rate_hz for c in cfgs.values()}
    if len(rates) != 1:
        raise ValueError(f'the drives stream at {sorted(rates)} Hz: one rate for a pass')
    ahead = max(c.compensation.preview_time for c in cfgs.values())
    max_lag = 0.5 * (min(c.adaptation.sample_delay for c in cfgs.values()) - lead)
    if not max_lag > 0.0:
        raise ValueError(f'adaptation.sample_delay must exceed lead {lead!r} s')
    return cfgs, ahead, max_lag


def _write_pedestal_files(workdir: Path, axes: list[Drive], cfgs: dict[str, Config]) -> None:
    """The pedestal file naming each axis's start set, the sets, the ROS parameter file."""
    lines = ['pedestal:', '  drives:']
    for d in axes:
        write_params(cfgs[d.name], workdir / f'{d.name}_start.yaml')
        lines += [f'    {d.name}:', f'      params_file: {d.name}_start.yaml']
    (workdir / 'pedestal.yaml').write_text('\n'.join(lines) + '\n')
    (workdir / 'ros_params.yaml').write_text(_ros_params([d.name for d in axes]))


def _write(node: Any, ex: SingleThreadedExecutor, names: list[str], timeout: float
           ) -> dict[str, tuple[bool, str]]:
    """Each drive's ``~/write_adapted_parameters`` called once: name -> (success,
    message); (False, 'no answer') when none came within ``timeout`` s."""
    out = {}
    for n in names:
        cli = node.create_client(Trigger, f'/{n}/{private_topic(WRITE_SERVICE, NODE_NAME)}')
        end = time.monotonic() + timeout
        while not cli.wait_for_service(timeout_sec=0.1) and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.01)
        fut = cli.call_async(Trigger.Request())
        while not fut.done() and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
        res = fut.result() if fut.done() else None
        out[n] = (False, 'no answer') if res is None else (bool(res.success), res.message)
        node.destroy_client(cli)
    return out


def parse_args(argv: list[str]) -> argparse.Namespace:
    """The options of :func:`main`."""
    ap = argparse.ArgumentParser(prog='live_pedestal', description=__doc__.split('\n\n')[0])
    ap.add_argument('--pedestal', default=None, help='the drives (default: the package\'s)')
    ap.add_argument('--plant', default=None, metavar='PLANT_PEDESTAL.yaml',
                    help='the drives\' stand-ins: a pedestal file with a drive of each name')
    ap.add_argument('--plant-set', action='append', default=[], metavar='DRIVE.KEY=VALUE',
                    help='override one parameter of a drive\'s plant (repeatable)')
    ap.add_argument('--duration', type=float, default=60.0, help='seconds of the pass [60]')
    ap.add_argument('--max-elevation', type=float, default=85.0, help='deg at culmination')
    ap.add_argument('--seed', type=int, default=0, help='the first drive\'s encoder seed')
    ap.add_argument('--twin', action='store_true', help='also run the twin from the live '
                    'run\'s start (and the nominal feed-forward) and compare')
    ap.add_argument('--no-nominal', action='store_true',
                    help='with --twin: no run of the nominal feed-forward')
    ap.add_argument('-o', '--output', default='pass', help='directory for CSV, PNG, logs')
    ap.add_argument('--timeout', type=float, default=120.0,
                    help='seconds to wait for the processes to connect')
    return ap.parse_args(argv)


@dataclass
class Report:
    """What :func:`run_report` ran: the exit status, the live run, its axes (with the
    twin's nominal errors when the twin ran) and the twin's axes (or None)."""

    status: int
    live: LivePedestal
    axes: list[AxisPass]
    twins: list[AxisPass] | None


def run_report(opts: argparse.Namespace, drives: list[Drive], plants: dict[str, Config],
               context: Any, env: dict[str, str]) -> Report:
    """The live pass of ``opts`` (:func:`main`'s options) over ``drives`` against
    ``plants``, printed (and with ``--twin`` the twin beside), CSV and PNG written."""
    from ..studies.adaptive_pass import TAIL_S, run_adaptive_pass
    from ..studies.pass_report import adaptive_table, in_use_lines, write_adaptive_pass
    out = Path(opts.output)
    elevation = math.radians(opts.max_elevation)
    t0 = time.perf_counter()
    live = run_live_pedestal(drives, plants, opts.duration, context=context, env=env,
                             workdir=out / 'processes', max_elevation=elevation,
                             seed=opts.seed, write=True, startup_timeout=opts.timeout)
    wall = time.perf_counter() - t0
    axes = live.axes({d.name: d.joint for d in drives})
    tail = min(TAIL_S, opts.duration)
    title = (f'live pass through the pedestal with adaptation: {opts.duration:g} s around a '
             f'{opts.max_elevation:g} deg culmination, the last {tail:g} s')
    ok = not live.stalled and all(r.missing == 0 for _, r in live.drives)
    print(title)
    print(f'stream {live.drives[0][1].stream_wall_s:.1f} s of wall time ({wall:.1f} s in all); '
          + '; '.join(f'{n}: {r.missing} stamps unanswered' for n, r in live.drives)
          + ('; STALLED' if live.stalled else ''))
    twins = None
    if opts.twin:
        twins = run_adaptive_pass(drives, plants, opts.duration, max_elevation=elevation,
                                  seed=opts.seed, base_ns=live.t0_ns,
                                  nominal=not opts.no_nominal)
        for a, tw in zip(axes, twins):
            a.nominal = tw.nominal
            c = a.run.counters
            exact = c.get('late_samples', 1) == 0 and c.get('late_steps', 1) == 0
            same = bool(np.array_equal(a.adapted, tw.adapted))
            diff = float(np.nanmax(np.abs(a.adapted - tw.adapted)))
            print(f'{a.name}: live - twin max |error difference| {diff:.3e} rad '
                  f'({"equal bit for bit" if same else "not equal"}; late samples '
                  f'{c.get("late_samples")}, late steps {c.get("late_steps")}); the twin '
                  f'over the last {tail:g} s: {tw.tail(tail)["adapted_ratio"]:.4g}x')
            ok = ok and (same or not exact)
    print(adaptive_table(axes, tail))
    for line in in_use_lines(axes):
        print(line)
    for n, (success, msg) in live.written.items():
        print(f'{n}: ~/write_adapted_parameters: {"ok" if success else "FAILED"}: {msg}')
        ok = ok and success
    csv, png = write_adaptive_pass(axes, out, title)
    print(f'wrote {csv} and {png}')
    return Report(0 if ok else 1, live, axes, twins)


def main(argv: list[str] | None = None) -> int:
    """Exit status 0 when every drive's encoder answered every sample and each drive wrote
    its file, 1 if not (or, with ``--twin``, if a drive with no late sample or step differs
    from its twin), 2 for bad arguments."""
    import os

    import rclpy

    from ..schema.validation import ConfigError
    from ..studies.adaptive_pass import pedestal_plants
    opts = parse_args(sys.argv[1:] if argv is None else argv)
    if not (0 < opts.duration <= 1200 and 0 < opts.max_elevation < 90):
        print('live_pedestal: --duration in (0, 1200] s, --max-elevation in (0, 90) deg',
              file=sys.stderr)
        return 2
    try:
        drives = load_pedestal(opts.pedestal)
        plants = pedestal_plants(drives, opts.plant, opts.plant_set)
    except (ConfigError, OSError) as exc:
        print(f'live_pedestal: {exc}', file=sys.stderr)
        return 2
    rclpy.init(args=[])
    try:
        return run_report(opts, drives, plants, rclpy.get_default_context(),
                          dict(os.environ)).status
    finally:
        with teardown_deadline():       # Fast DDS can hang in it (.teardown)
            rclpy.try_shutdown()


if __name__ == '__main__':   # pragma: no cover
    sys.exit(main())
