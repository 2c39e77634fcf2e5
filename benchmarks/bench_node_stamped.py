# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``bench_node.py --stamped``: the stamped reference path and the Float64 path side by side,
two node processes, one probe (see :func:`stamped_main`)."""

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
    ROOT,
    proc_cpu_seconds,
    slew,
    spin_until_done,
    start_node,
    stop_node,
)

__all__ = ['stamped_main', 'STAMPED_TARGETS']

STAMPED_TARGETS = dict(deviation=1e-6, answered=0.999, cpu=0.25, cpu_ratio=0.6, p99_ms=1.0)


def stamped_main(args: argparse.Namespace) -> int:
    """Two node processes side by side (namespaces /stamped and /float64), one probe.

    Each probe timer callback publishes every 1 ms slot k that is due (a late callback
    publishes the missed slots at once, as a servo catching up would): to /stamped a
    ``worm_angle_reference`` (stamp = base + k ms on the ROS clock, theta1 = the 2 rad/s slew
    with reversals at k ms) and to /float64 the same value as ``worm_angle_command``.  The
    probe subscribes to /stamped's ``~/compensated_command`` and ``joint_states`` and to
    /float64's ``joint_states`` and ``~/feedforward``.  Reported over the measured window:
    the deviation of every received delta (compensated - theta1_ref) from
    ``feedforward_series`` of all published (stamp, value) pairs, the answered fraction,
    both nodes' CPU (utime + stime over wall time), publish -> compensated_command latency.
    """
    os.environ['ROS_DOMAIN_ID'] = str(args.domain_id)
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64

    from worm_gear_sim.config.files import load_config
    from worm_gear_sim.realtime import feedforward_series
    from worm_gear_sim.ros.run import make_executor

    load0 = os.getloadavg()
    cfg_path = ROOT / 'config' / 'worm_gear_sim.yaml'
    cfg = load_config(cfg_path)
    logs = tempfile.TemporaryDirectory(prefix='bench_node_')
    started = {ns: start_node(Path(logs.name) / f'{ns}.log', executor=args.executor,
                              ros_args=['-r', f'__ns:=/{ns}'])
               for ns in ('stamped', 'float64')}
    procs = {ns: p for ns, (p, _) in started.items()}
    rclpy.init()
    probe = rclpy.create_node('bench_probe')
    reliable = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    pub_ref = probe.create_publisher(JointState, '/stamped/worm_angle_reference', reliable)
    pub_cmd = probe.create_publisher(Float64, '/float64/worm_angle_command', QoSProfile(depth=10))
    n_max = int((args.duration + args.warmup + 130.0) * 1000)
    t_pub = np.full(n_max, np.nan)
    x_pub = np.full(n_max, np.nan)
    t_rx = np.full(n_max, np.nan)
    cc = np.full(n_max, np.nan)
    count = {'js_stamped': 0, 'js_float64': 0, 'ff_float64': 0, 'k': 0}
    base = {'ns': 0}

    def on_cc(msg: JointState) -> None:
        now = time.monotonic()
        k = (msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec - base['ns']) // 1_000_000
        if 0 <= k < n_max:
            t_rx[k], cc[k] = now, msg.position[0]

    def counter(key: str):
        def cb(msg: Any) -> None:
            count[key] += 1
        return cb

    probe.create_subscription(JointState, '/stamped/worm_gear_sim/compensated_command', on_cc,
                              QoSProfile(depth=1000))
    probe.create_subscription(JointState, '/stamped/joint_states', counter('js_stamped'),
                              QoSProfile(depth=100))
    probe.create_subscription(JointState, '/float64/joint_states', counter('js_float64'),
                              QoSProfile(depth=100))
    probe.create_subscription(JointState, '/float64/worm_gear_sim/feedforward',
                              counter('ff_float64'), QoSProfile(depth=100))
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient
    params = AsyncParameterClient(probe, '/stamped/worm_gear_sim')
    set_times: list[float] = []
    set_ok: list[bool] = []
    ex = make_executor('events')
    ex.add_node(probe)
    done = rclpy.task.Future()
    t_start = time.monotonic()
    run: dict[str, Any] = {'phase': 'wait', 'error': ''}

    def set_parameters(i: int) -> None:
        fut = params.set_parameters([Parameter('friction.mu_kinetic',
                                               value=0.0470713 + 1e-4 * (i % 7))])
        set_times.append(time.monotonic())
        fut.add_done_callback(lambda f: set_ok.append(
            f.result() is not None and all(r.successful for r in f.result().results)))
    msg = JointState(name=[cfg.node.joint_names[0]], position=[0.0])
    fmsg = Float64()

    def on_timer() -> None:
        now = time.monotonic()
        for ns, p in procs.items():
            if p.poll() is not None:
                run['error'] = f'node process {ns} exited'
                done.set_result(True)
                return
        ph = run['phase']
        if ph == 'wait':
            if pub_ref.get_subscription_count() and pub_cmd.get_subscription_count() and \
                    count['js_float64'] == 0:
                run['phase'], run['t_warm'] = 'warm', now
                base['ns'] = probe.get_clock().now().nanoseconds
                run['mono0'] = now
            elif now - t_start > 120.0:
                run['error'] = 'the nodes did not subscribe within 120 s'
                done.set_result(True)
            return
        if ph == 'warm' and now - run['t_warm'] >= args.warmup:
            run['phase'], run['k0'], run['wall0'] = 'measure', count['k'], now
            run['cpu0'] = {n: proc_cpu_seconds(p.pid) for n, p in procs.items()}
        elif ph == 'measure' and args.param_sets and len(set_times) < args.param_sets and \
                now - run['wall0'] >= (len(set_times) + 0.5) * args.duration / args.param_sets:
            set_parameters(len(set_times))
        elif ph == 'measure' and now - run['wall0'] >= args.duration:
            run['cpu1'] = {n: proc_cpu_seconds(p.pid) for n, p in procs.items()}
            run['wall1'], run['k1'] = now, count['k']
            done.set_result(True)
            return
        due = int((now - run['mono0']) * 1000.0)      # slots due by now
        k = count['k']
        while k <= due and k < n_max:
            x = slew(k * 1e-3, args.slew_rate)
            st = base['ns'] + k * 1_000_000
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(st, 10**9)
            msg.position[0] = x
            t_pub[k], x_pub[k] = time.monotonic(), x
            pub_ref.publish(msg)
            fmsg.data = x
            pub_cmd.publish(fmsg)
            k += 1
        count['k'] = k

    probe.create_timer(1.0 / args.command_rate, on_timer)
    try:
        spin_until_done(ex, done, linger=0.5)     # then let the last answers arrive
    finally:
        errs = {ns: stop_node(p, log, timeout=30.0)[1] for ns, (p, log) in started.items()}
        logs.cleanup()
        ex.shutdown()
        probe.destroy_node()
        rclpy.try_shutdown()
    if run['error']:
        print(f'error: {run["error"]}\n' + '\n'.join(errs.values()), file=sys.stderr)
        return 1
    load1 = os.getloadavg()
    n_all = count['k']
    t = np.arange(n_all) * 1e-3
    expected = feedforward_series(cfg, t, x_pub[:n_all])
    win = slice(run['k0'], run['k1'])
    sent = np.arange(n_all)[win]
    got = ~np.isnan(cc[:n_all][win])
    dev = np.abs(cc[:n_all][win][got] - x_pub[:n_all][win][got] - expected[win][got])
    lat = (t_rx[:n_all][win] - t_pub[:n_all][win])[got] * 1e3
    wall = run['wall1'] - run['wall0']
    cpu = {n: (run['cpu1'][n] - run['cpu0'][n]) / wall for n in procs}
    answered = got.mean() if sent.size else 0.0
    ok_dev = float(np.mean(dev <= STAMPED_TARGETS['deviation'])) if dev.size else 0.0
    tg = STAMPED_TARGETS
    print(f'stamped vs Float64 node, {wall:.1f} s measured after {args.warmup:g} s warm-up, '
          f'1 kHz slew {args.slew_rate:g} rad/s with reversals, {args.executor} executor; '
          f'load average {load0[0]:.2f} before, {load1[0]:.2f} after (2 cores, shared)')
    print(f'  samples published {sent.size}, compensated_command received {int(got.sum())}'
          f' -> answered {100 * answered:.3f} %  (target >= {100 * tg["answered"]:g} %)')
    print(f'  delta - feedforward_series: max {dev.max() if dev.size else float("nan"):.3g}'
          f' rad, {100 * ok_dev:.3f} % <= {tg["deviation"]:g} rad  (target 100 %)')
    print(f'  node CPU: stamped {cpu["stamped"]:.3f} core, Float64 {cpu["float64"]:.3f} core'
          f' -> ratio {cpu["stamped"] / cpu["float64"]:.2f}  (targets <= {tg["cpu"]:g} core,'
          f' <= {tg["cpu_ratio"]:g}x)')
    if lat.size:
        print(f'  publish -> compensated_command: p50 {np.percentile(lat, 50):.3f} ms, '
              f'p99 {np.percentile(lat, 99):.3f} ms, max {lat.max():.2f} ms  '
              f'(target p99 <= {tg["p99_ms"]:g} ms)')
    if set_times:
        tp = t_pub[:n_all][win][got]
        near = np.zeros(tp.size, bool)
        for ts in set_times:
            near |= (tp >= ts) & (tp < ts + 0.05)
        far = ~near
        print(f'  {len(set_times)} parameter sets, {sum(set_ok)} accepted: latency p99 within '
              f'50 ms after a set {np.percentile(lat[near], 99):.3f} ms ({int(near.sum())} '
              f'samples), elsewhere {np.percentile(lat[far], 99):.3f} ms; max '
              f'{lat[near].max():.2f} / {lat[far].max():.2f} ms')
    print(f'  joint_states received: stamped {count["js_stamped"]}, Float64 '
          f'{count["js_float64"]}; Float64 node\'s ~/feedforward {count["ff_float64"]}')
    return 0
