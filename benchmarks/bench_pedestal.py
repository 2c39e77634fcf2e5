# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Cost per axis of a two-axis pedestal at 1 kHz stamped, a correction per sample, in one
run with three layouts measured one after the other on the same traffic:

* ``floor``: relay_node.py, one process with an empty node per axis that only relays each
  ``worm_angle_reference`` to ``~/compensated_command`` (rclpy + DDS, no physics);
* ``pedestal``: ``worm_gear_sim_pedestal`` (one process, a drive node per axis, the
  pedestal's trajectory node idle);
* ``processes``: two ``worm_gear_sim_node`` processes (namespaces /azimuth, /elevation).

The probe (this process) publishes both axes' stamped references at 1 kHz (the slew of
bench_node.py, 2 rad/s with reversals; ``--traffic pass``: a satellite pass) and subscribes
only to each axis' ``~/compensated_command`` (what a servo needs per sample; the monitoring
topics have no subscriber, so the nodes do not publish them; ``--monitor`` adds a
joint_states subscriber per axis: the drives publish it at ``node.monitor_rate_hz`` = 50 Hz).
Reported per layout: CPU of the node process(es) per axis (utime + stime over wall
time), answered fraction, publish -> compensated_command latency p50 / p99 / max per
axis.  Targets: <= 0.20 core per axis, p99 <= 1 ms.

    python benchmarks/bench_pedestal.py --duration 15
    python benchmarks/bench_pedestal.py --layouts floor,pedestal,pedestal@adaptive \
        --traffic pass
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from node_probe import (  # noqa: E402
    PARAMS_FILE,
    proc_cpu_seconds,
    slew,
    start_logged,
    stop_and_read,
)

AXES = ('azimuth', 'elevation')
TARGETS = dict(cpu_per_axis=0.20, p99_ms=1.0)
PEDESTAL = ('import sys; from worm_gear_sim.ros.startup import pedestal_main; '
            'sys.exit(pedestal_main())')


def commands(layout: str) -> list[list[str]]:
    """The processes of ``layout``; ``pedestal@adaptive`` / ``processes@adaptive``: the same
    with every drive on the variable step (``-p integrator.method:=adaptive``)."""
    py = sys.executable
    layout, _, method = layout.partition('@')
    extra = ['-p', f'integrator.method:={method}'] if method else []
    if layout == 'floor':
        return [[py, str(Path(__file__).resolve().parent / 'relay_node.py'), *AXES]]
    if layout == 'pedestal':
        return [[py, '-c', PEDESTAL, '--ros-args', '--log-level', 'warn', *extra]]
    return [[py, '-m', 'worm_gear_sim.ros', '--ros-args', '--params-file', str(PARAMS_FILE),
             '-r', f'__ns:=/{ns}', '-p', 'node.monitor_rate_hz:=50.0', '--log-level', 'warn',
             *extra] for ns in AXES]


def traffic(kind: str, n: int) -> dict[str, np.ndarray]:
    """Each axis' worm command every ms: ``slew``, the 2 rad/s slew with reversals of
    bench_node.py (elevation at half the amplitude); ``pass``, a satellite pass around
    culmination after a 2 s lead-in from rest (bench_method.py's stream), then held."""
    if kind == 'slew':
        x = np.array([slew(k * 1e-3, 2.0) for k in range(n)])
        return {'azimuth': x, 'elevation': 0.5 * x}
    from bench_method import lead_in

    from worm_gear_sim import Config
    from worm_gear_sim.dynamics.model import DriveModel
    from worm_gear_sim.studies.tracking_pass import pass_window
    ratio = DriveModel(Config()).output_per_input
    _, az, el = pass_window(40.0)
    return {'azimuth': lead_in((az - az[0]) / ratio), 'elevation': lead_in((el - el[0]) / ratio)}


def measure(layout: str, args: argparse.Namespace, logs: Path) -> dict[str, Any]:
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rclpy.task import Future
    from sensor_msgs.msg import JointState

    from worm_gear_sim.ros.run import make_executor
    procs = [start_logged(c, dict(os.environ), logs / f'{layout}{i}.log')
             for i, c in enumerate(commands(layout))]
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx)
    probe = rclpy.create_node('pedestal_bench_probe', context=ctx)
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    n_max = int((args.duration + args.warmup + 130.0) * 1000)
    pubs, t_pub, t_rx = {}, {}, {}
    base = {'ns': 0}
    for ax in AXES:
        pubs[ax] = probe.create_publisher(JointState, f'/{ax}/worm_angle_reference', qos)
        t_pub[ax], t_rx[ax] = np.full(n_max, np.nan), np.full(n_max, np.nan)

        def on_cc(msg: JointState, ax: str = ax) -> None:
            now = time.monotonic()
            k = (msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec - base['ns']) \
                // 1_000_000
            if 0 <= k < n_max:
                t_rx[ax][k] = now
        probe.create_subscription(JointState, f'/{ax}/worm_gear_sim/compensated_command',
                                  on_cc, qos)
        if args.monitor:       # a monitor on joint_states (rqt_plot, a bag recorder)
            probe.create_subscription(JointState, f'/{ax}/joint_states',
                                      lambda m: None, QoSProfile(depth=10))
    joints = {'azimuth': 'azimuth_worm_input_joint', 'elevation': 'elevation_worm_input_joint'}
    if layout.partition('@')[0] != 'pedestal':
        joints = dict.fromkeys(AXES, 'worm_input_joint')
    msgs = {ax: JointState(name=[joints[ax]], position=[0.0]) for ax in AXES}
    path = traffic(args.traffic, n_max)
    run: dict[str, Any] = {'phase': 'wait', 'error': '', 'k': 0}
    done = Future()
    t_start = time.monotonic()

    def on_timer() -> None:
        now = time.monotonic()
        if any(p.poll() is not None for p, _ in procs):
            run['error'] = f'{layout}: a node process exited'
            done.set_result(True)
            return
        if run['phase'] == 'wait':
            if all(p.get_subscription_count() for p in pubs.values()) and all(
                    probe.count_publishers(f'/{ax}/worm_gear_sim/compensated_command')
                    for ax in AXES):
                run.update(phase='warm', t_warm=now, mono0=now)
                base['ns'] = probe.get_clock().now().nanoseconds
            elif now - t_start > 120.0:
                run['error'] = f'{layout}: the nodes did not come up within 120 s'
                done.set_result(True)
            return
        if run['phase'] == 'warm' and now - run['t_warm'] >= args.warmup:
            run.update(phase='measure', k0=run['k'], wall0=now,
                       cpu0=sum(proc_cpu_seconds(p.pid) for p, _ in procs))
        elif run['phase'] == 'measure' and now - run['wall0'] >= args.duration:
            run.update(wall1=now, k1=run['k'],
                       cpu1=sum(proc_cpu_seconds(p.pid) for p, _ in procs))
            done.set_result(True)
            return
        due = int((now - run['mono0']) * 1000.0)
        k = run['k']
        while k <= due and k < n_max:
            st = base['ns'] + k * 1_000_000
            for ax in AXES:
                m = msgs[ax]
                m.header.stamp.sec, m.header.stamp.nanosec = divmod(st, 10**9)
                m.position[0] = float(path[ax][min(k, path[ax].size - 1)])
                t_pub[ax][k] = time.monotonic()
                pubs[ax].publish(m)
            k += 1
        run['k'] = k

    probe.create_timer(1e-3, on_timer)
    ex = make_executor('events', context=ctx)
    ex.add_node(probe)
    try:
        while not done.done():
            ex.spin_until_future_complete(done, timeout_sec=1.0)
        end = time.monotonic() + 0.5
        while time.monotonic() < end:
            ex.spin_until_future_complete(Future(), timeout_sec=0.1)
    finally:
        logs_text = [stop_and_read(p, log, timeout=30.0)[1] for p, log in procs]
        ex.shutdown()
        probe.destroy_node()
        rclpy.try_shutdown(context=ctx)
    if run['error']:
        return {'error': run['error'] + '\n' + '\n'.join(logs_text)}
    win = slice(run['k0'], run['k1'])
    wall = run['wall1'] - run['wall0']
    out: dict[str, Any] = {'cpu_per_axis': (run['cpu1'] - run['cpu0']) / wall / len(AXES),
                           'wall': wall}
    for ax in AXES:
        lat = (t_rx[ax][win] - t_pub[ax][win]) * 1e3
        got = ~np.isnan(lat)
        out[ax] = dict(answered=float(got.mean()), p50=float(np.percentile(lat[got], 50)),
                       p99=float(np.percentile(lat[got], 99)), max=float(lat[got].max()))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--duration', type=float, default=15.0, help='measured s per layout')
    ap.add_argument('--warmup', type=float, default=3.0)
    ap.add_argument('--layouts', default='floor,pedestal,processes')
    ap.add_argument('--traffic', choices=('slew', 'pass'), default='slew',
                    help='the commands (traffic()): the slew with reversals, or a pass')
    ap.add_argument('--monitor', action='store_true',
                    help='also subscribe to each axis\' joint_states (published at '
                    'node.monitor_rate_hz = 50 Hz by the pedestal\'s drives)')
    ap.add_argument('--domain-id', type=int, default=int(os.environ.get('ROS_DOMAIN_ID', 77)))
    args = ap.parse_args()
    os.environ['ROS_DOMAIN_ID'] = str(args.domain_id)
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    load0 = os.getloadavg()
    results = {}
    with tempfile.TemporaryDirectory(prefix='bench_pedestal_') as d:
        for layout in args.layouts.split(','):
            results[layout] = measure(layout, args, Path(d))
    load1 = os.getloadavg()
    print(f'two axes at 1 kHz stamped ({args.traffic}), a correction per sample, '
          f'{args.duration:g} s per '
          f'layout after {args.warmup:g} s warm-up; load average {load0[0]:.2f} before, '
          f'{load1[0]:.2f} after (2 cores; the probe shares them)')
    print(f'  targets: <= {TARGETS["cpu_per_axis"]:g} core per axis, p99 <= '
          f'{TARGETS["p99_ms"]:g} ms')
    rc = 0
    for layout, r in results.items():
        if 'error' in r:
            print(f'  {layout}: ERROR {r["error"]}')
            rc = 1
            continue
        axes = '; '.join(f'{ax} answered {100 * r[ax]["answered"]:.2f} %, p50 '
                         f'{r[ax]["p50"]:.3f} ms, p99 {r[ax]["p99"]:.3f} ms, max '
                         f'{r[ax]["max"]:.1f} ms' for ax in AXES)
        print(f'  {layout:17s}: {r["cpu_per_axis"]:.3f} core per axis; {axes}')
    if 'floor' in results and 'error' not in results['floor']:
        f = results['floor']['cpu_per_axis']
        for layout, r in results.items():
            if layout != 'floor' and 'error' not in r:
                print(f'  {layout}: {r["cpu_per_axis"] / f:.2f}x the floor per axis '
                      f'(+{r["cpu_per_axis"] - f:.3f} core per axis above it)')
    return rc


if __name__ == '__main__':
    sys.exit(main())
