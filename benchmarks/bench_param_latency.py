# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Latency of the node's parameter service while bursts of stamped samples arrive, for both
executors side by side in one run.

For each executor (``events``, the default, and ``single_threaded``) the node runs as a
process; this process sends bursts of ``--burst`` stamped references every ``--period`` s
(1000 every 0.25 s: 4 kHz on average, each burst a full reliable queue) and, between them,
calls ``get_parameters`` every ~20 ms and ``set_parameters`` (a valid
``load.output_torque``) every 10th call, timing each answer.

    python benchmarks/bench_param_latency.py [--duration 6] [--burst 1000] [--period 0.25]

The EventsExecutor serves events in arrival order, so a request that arrives behind a burst
waits for the burst's samples; the SingleThreadedExecutor takes one ready item per entity
per wait, so it answers between samples.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from node_probe import start_node, stop_node


def run(executor: str, duration: float, burst: int, period: float) -> dict:
    import rclpy
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import GetParameters, SetParameters
    from sensor_msgs.msg import JointState
    logs = tempfile.TemporaryDirectory()
    proc, log = start_node(Path(logs.name) / 'node.log', executor=executor, log_level='error')
    rclpy.init()
    node = rclpy.create_node('param_latency_probe')
    try:
        pub = node.create_publisher(JointState, 'worm_angle_reference', 1000)
        get = node.create_client(GetParameters, '/worm_gear_sim/get_parameters')
        put = node.create_client(SetParameters, '/worm_gear_sim/set_parameters')
        if not get.wait_for_service(timeout_sec=90.0):
            raise RuntimeError('the node did not come up')
        while pub.get_subscription_count() == 0:
            rclpy.spin_once(node, timeout_sec=0.05)
        time.sleep(1.0)
        lat_get, lat_set = [], []
        sent = 0
        last_burst = 0.0
        t_end = time.monotonic() + duration
        i = 0
        while time.monotonic() < t_end:
            if time.monotonic() - last_burst > period:
                base = node.get_clock().now().nanoseconds
                for j in range(burst):
                    m = JointState()
                    m.name = ['worm_input_joint']
                    m.position = [0.001 * ((sent // 500) % 2)]
                    m.header.stamp.sec, m.header.stamp.nanosec = divmod(
                        base - (burst - j) * int(period * 1e9 / burst), 10 ** 9)
                    pub.publish(m)
                    sent += 1
                last_burst = time.monotonic()
            req = GetParameters.Request()
            req.names = ['load.output_torque']
            t0 = time.monotonic()
            fut = get.call_async(req)
            rclpy.spin_until_future_complete(node, fut, timeout_sec=5.0)
            lat_get.append(time.monotonic() - t0 if fut.done() else float('inf'))
            i += 1
            if i % 10 == 0:
                sreq = SetParameters.Request()
                sreq.parameters = [Parameter(name='load.output_torque', value=ParameterValue(
                    type=ParameterType.PARAMETER_DOUBLE, double_value=0.5 + 0.1 * (i % 7)))]
                t0 = time.monotonic()
                fut = put.call_async(sreq)
                rclpy.spin_until_future_complete(node, fut, timeout_sec=5.0)
                lat_set.append(time.monotonic() - t0 if fut.done() else float('inf'))
            time.sleep(0.02)
        alive = proc.poll() is None
    finally:
        node.destroy_node()
        rclpy.shutdown()
        rc, _ = stop_node(proc, log, signal.SIGINT)
        logs.cleanup()
    g, s = np.array(lat_get), np.array(lat_set)
    return {'executor': executor, 'samples': sent, 'get_n': g.size,
            'get_p50_ms': 1e3 * float(np.median(g)),
            'get_p99_ms': 1e3 * float(np.quantile(g, 0.99)),
            'get_max_ms': 1e3 * float(g.max()), 'set_n': s.size,
            'set_max_ms': 1e3 * float(s.max()) if s.size else float('nan'),
            'alive': alive, 'rc': rc}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--duration', type=float, default=6.0)
    ap.add_argument('--burst', type=int, default=1000)
    ap.add_argument('--period', type=float, default=0.25)
    ap.add_argument('--domain-id', type=int, default=87)
    args = ap.parse_args()
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    os.environ['ROS_DOMAIN_ID'] = str(args.domain_id)
    print(f'parameter-service latency under bursts of {args.burst} stamped samples every '
          f'{args.period:g} s, {args.duration:g} s per executor; load average '
          f'{os.getloadavg()[0]:.2f}')
    for ex in ('events', 'single_threaded'):
        r = run(ex, args.duration, args.burst, args.period)
        print(f'  {r["executor"]:16s} samples {r["samples"]}; get_parameters n={r["get_n"]} '
              f'p50 {r["get_p50_ms"]:.1f} ms, p99 {r["get_p99_ms"]:.1f} ms, max '
              f'{r["get_max_ms"]:.1f} ms; set_parameters n={r["set_n"]} max '
              f'{r["set_max_ms"]:.1f} ms; node alive {r["alive"]}, exit {r["rc"]}',
              flush=True)
    return 0


if __name__ == '__main__':
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    raise SystemExit(main())
