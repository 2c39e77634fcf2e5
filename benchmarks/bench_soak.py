# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Soak benchmark: the node as a process at 1 kHz for a long time.

Starts ``python -m worm_gear_sim.ros --ros-args --params-file config/worm_gear_sim.yaml``
as a child process and drives it from this process at ``--rate`` (1 kHz): a radar slew
(constant-rate triangle, +-0.5 rad of worm at 0.5 rad/s) as

* ``float64``: std_msgs/Float64 on ``worm_angle_command`` (tick-sampled path);
* ``stamped``: sensor_msgs/JointState on ``worm_angle_reference``, stamped with the send time
  (event-driven path);
* ``alternate`` (default): both paths in turn, switching every ``--switch-period`` seconds
  (the node changes input path at each switch);

and, every ``--param-period`` seconds, sets a valid parameter (``load.output_torque``
between 0 and 1 N m) over the node's parameter service, so that parameter swaps soak too.
Measured after ``--warmup`` over ``--duration`` seconds (default 600 = 10 minutes):

* RSS of the node (/proc/<pid>/status VmRSS every second); the slope [MB/h] is a least
  squares line through the samples of the measured span, with its standard error;
* CPU of the node (utime + stime) in cores;
* missed ticks: JointState stamps more than 1.5 periods apart, counted as periods lost,
  separately per input path (on the stamped path a prediction follows each sample, so the
  probe's own missed send slots, printed too, show up there); plus the node's own counters
  from ``/diagnostics`` (first and last value of every numeric counter that moved);
* parameter sets accepted / rejected / unanswered.

    python benchmarks/bench_soak.py                       # 10 minutes
    python benchmarks/bench_soak.py --duration 120        # 2 minutes
    python benchmarks/bench_soak.py --input float64 --param-period 0

Absolute figures depend on the machine's load (printed at start and end).
"""

from __future__ import annotations

import argparse
import collections
import math
import os
import signal
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))
from node_probe import (  # noqa: E402
    Phases,
    lost_periods,
    slew,
    spin_until_done,
    start_node,
    stop_node,
)


def rss_mb(pid: int) -> float:
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return int(line.split()[1]) / 1024.0
    return math.nan


def slope_per_hour(t: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Least-squares slope of y(t) [per hour] and its standard error."""
    if len(t) < 3:
        return math.nan, math.nan
    A = np.column_stack([t - t.mean(), np.ones_like(t)])
    coef, res, *_ = np.linalg.lstsq(A, y, rcond=None)
    resid = y - A @ coef
    s2 = float(resid @ resid) / max(1, len(t) - 2)
    se = math.sqrt(s2 / float(((t - t.mean()) ** 2).sum()))
    return coef[0] * 3600.0, se * 3600.0


def _numeric(v: str) -> float | None:
    try:
        x = float(v)
    except ValueError:
        return None
    return x if math.isfinite(x) else None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--duration', type=float, default=600.0, help='measured seconds [600]')
    ap.add_argument('--warmup', type=float, default=10.0, help='seconds before measuring [10]')
    ap.add_argument('--rate', type=float, default=1000.0, help='command rate [Hz] (1000)')
    ap.add_argument('--input', choices=('float64', 'stamped', 'alternate'),
                    default='alternate')
    ap.add_argument('--switch-period', type=float, default=60.0,
                    help='alternate: seconds per input path [60]')
    ap.add_argument('--param-period', type=float, default=10.0,
                    help='seconds between parameter sets (0: none) [10]')
    ap.add_argument('--node-log', metavar='FILE',
                    help='write the node\'s warnings (stderr, --log-level warn) to FILE; '
                    'default: errors only')
    ap.add_argument('--domain-id', type=int,
                    default=int(os.environ.get('ROS_DOMAIN_ID', '44') or 44),
                    help='ROS domain of the node and the probe [$ROS_DOMAIN_ID, else 44]')
    args = ap.parse_args(argv)

    os.environ['ROS_DOMAIN_ID'] = str(args.domain_id)
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64

    from worm_gear_sim.ros.run import make_executor

    load0 = os.getloadavg()
    logs = tempfile.TemporaryDirectory(prefix='bench_soak_')
    proc, log = start_node(Path(args.node_log or Path(logs.name) / 'node.log'),
                           log_level='warn' if args.node_log else 'error')
    rclpy.init()
    probe = rclpy.create_node('soak_probe')
    pub_cmd = probe.create_publisher(Float64, 'worm_angle_command', QoSProfile(depth=10))
    pub_ref = probe.create_publisher(JointState, 'worm_angle_reference',
                                     QoSProfile(depth=100))
    param_cli = probe.create_client(SetParameters, '/worm_gear_sim/set_parameters')
    period_ns = 1e9 / args.rate
    stamps: dict[str, list[int]] = {'float64': [], 'stamped': []}
    diag: dict[str, str] = {}
    state = {'measuring': False, 'n_js': 0, 'path': 'float64'}
    params = collections.Counter()
    sends: list[float] = []            # this probe's send times (its own misses, for scale)

    def on_js(msg: JointState) -> None:
        state['n_js'] += 1
        if state['measuring']:
            stamps[state['path']].append(msg.header.stamp.sec * 10**9
                                         + msg.header.stamp.nanosec)

    def on_diag(msg: DiagnosticArray) -> None:
        for s in msg.status:
            for kv in s.values:
                diag[f'{s.name.split(": ")[-1]}/{kv.key}'] = kv.value

    probe.create_subscription(JointState, 'joint_states', on_js, QoSProfile(depth=100))
    probe.create_subscription(DiagnosticArray, '/diagnostics', on_diag, 10)
    ex = make_executor('events')
    ex.add_node(probe)
    done = rclpy.task.Future()
    t_start = time.monotonic()
    phases = Phases(proc, args.warmup, args.duration, t_start)
    run: dict = {'rss': [], 'diag0': {}, 'next_param': 0.0, 'k_param': 0, 'next_rss': 0.0}

    def path_at(now: float) -> str:
        if args.input != 'alternate':
            return args.input
        return ('float64', 'stamped')[int((now - t_start) // args.switch_period) % 2]

    def on_param_done(fut) -> None:
        try:
            res = fut.result().results[0]
            params['accepted' if res.successful else 'rejected'] += 1
        except Exception:  # noqa: BLE001 - counted
            params['failed'] += 1

    def on_timer() -> None:
        now = time.monotonic()
        event = phases.update(now, state['n_js'] > 0)
        if event == 'start':
            state['measuring'] = True
            run['diag0'] = dict(diag)
            run['next_rss'] = now
        elif event == 'end':
            state['measuring'] = False
            done.set_result(True)
            return
        ph = phases.phase
        if ph == 'measure' and now >= run['next_rss']:
            run['rss'].append((now - phases.wall0, rss_mb(proc.pid)))
            run['next_rss'] += 1.0
        if (args.param_period > 0 and ph in ('warm', 'measure') and now >= run['next_param']
                and param_cli.service_is_ready()):
            run['next_param'] = now + args.param_period
            run['k_param'] += 1
            v = ParameterValue(type=ParameterType.PARAMETER_DOUBLE,
                               double_value=0.1 * (run['k_param'] % 11))
            req = SetParameters.Request(parameters=[Parameter(name='load.output_torque',
                                                              value=v)])
            if ph == 'measure':
                params['sent'] += 1
                param_cli.call_async(req).add_done_callback(on_param_done)
            else:
                param_cli.call_async(req)
        path = path_at(now)
        if path != state['path']:
            state['path'] = path
            if ph == 'measure':
                run.setdefault('switches', 0)
                run['switches'] = run.get('switches', 0) + 1
        if state['measuring']:
            sends.append(now)
        v = slew(now - t_start)
        if path == 'float64':
            pub_cmd.publish(Float64(data=v))
        else:
            msg = JointState(name=['worm_input_joint'], position=[v])
            msg.header.stamp = probe.get_clock().now().to_msg()
            pub_ref.publish(msg)

    probe.create_timer(1.0 / args.rate, on_timer)
    print(f'soak: node pid {proc.pid}, input {args.input}, {args.rate:g} Hz, '
          f'{args.duration:g} s after {args.warmup:g} s warm-up; load average '
          f'{load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}', flush=True)
    try:
        spin_until_done(ex, done)
    finally:
        node_alive = proc.poll() is None
        rc, err = stop_node(proc, log, signal.SIGTERM)
        logs.cleanup()
        ex.shutdown()
        probe.destroy_node()
        rclpy.try_shutdown()
    if phases.error:
        print(f'error: {phases.error}\n{err[-2000:]}')
        return 1
    load1 = os.getloadavg()
    wall = phases.wall
    cpu = phases.cores
    rss = np.array(run['rss'])
    slope, se = slope_per_hour(rss[:, 0], rss[:, 1])
    print(f'measured {wall:.1f} s; node exit on SIGTERM: {rc} '
          f'(alive before: {node_alive}); stderr lines: {len(err.splitlines())}')
    half = rss[len(rss) // 2:]
    slope2, se2 = slope_per_hour(half[:, 0], half[:, 1])
    print(f'RSS: {rss[0, 1]:.1f} -> {rss[-1, 1]:.1f} MB (max {rss[:, 1].max():.1f}); fitted '
          f'slope {slope:+.2f} +- {se:.2f} MB/h over {len(rss)} samples; second half '
          f'{slope2:+.2f} +- {se2:.2f} MB/h')
    print(f'CPU of the node: {cpu:.3f} cores')
    for path, st in stamps.items():
        if len(st) < 2:
            continue
        gaps = np.diff(np.array(st, dtype=np.int64)) / period_ns
        # a path switch leaves one long gap per switch: not a missed tick
        lost = lost_periods(st, period_ns, max_gap=1000)
        print(f'{path:8s}: {len(st)} JointStates, missed ticks {lost} '
              f'({100.0 * lost / (len(st) + lost):.3f} %), gaps > 1 s: '
              f'{int(np.sum(gaps >= 1000))}')
    probe_lost = lost_periods(np.round(np.array(sends) * 1e9), 1e9 / args.rate)
    print(f'probe (this process): {len(sends)} commands sent, {probe_lost} send slots missed '
          f'({100.0 * probe_lost / max(1, len(sends) + probe_lost):.3f} %): the share of the '
          'missed ticks that is the sender\'s')
    if args.input == 'alternate':
        print(f'input path switches: {run.get("switches", 0)}')
    if args.param_period > 0:
        print(f'parameter sets: sent {params["sent"]}, accepted {params["accepted"]}, '
              f'rejected {params["rejected"]}, failed {params["failed"]}')
    d0 = run['diag0']
    changed = []
    for k in sorted(diag):
        a, b = _numeric(d0.get(k, '')), _numeric(diag[k])
        if b is not None and a is not None and a != b:
            changed.append(f'{k} {a:g} -> {b:g}')
    print('diagnostics counters that moved: ' + ('; '.join(changed) or 'none'))
    nonzero = [f'{k}={v}' for k, v in sorted(diag.items())
               if ('reject' in k or 'error' in k or 'overrun' in k or 'missed' in k)
               and v not in ('0', '', '0.0')]
    print('diagnostics rejections/errors/overruns/missed at the end: '
          + ('; '.join(nonzero) or 'none'))
    print(f'load average at the end: {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f} '
          '(absolute figures are load-contaminated)')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
