# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A fresh installation's start: the node with an empty kernel cache, adaptation on, then a
stamped 1 kHz stream with encoder samples from its first sample on.

    python benchmarks/bench_fresh_start.py [--seconds 30] [--domain-id 150] [--warm-too]

The node (``python -m worm_gear_sim.ros``, a process, ``adaptation.enabled`` and
``node.compensation_applied`` true) starts with ``NUMBA_CACHE_DIR`` an empty temporary
folder: every kernel compiles before it says "ready" (:mod:`worm_gear_sim.adaptation.warmup`).
Then this process (rclpy) waits until it is connected, streams stamped references at 1 kHz on
``worm_angle_reference`` (a slow sine, stamps of its own clock) for ``--seconds`` and sends
an encoder sample (``measured_joint_states``, the answer's stamp) back for each answer on
``~/compensated_command``.  Printed: the start to "ready" [s]; the first sample's answer
time (sent to answered) [ms] (target <= 5 ms); the answer time's p50 / p99 / worst over the
first second and the whole stream; the samples never answered (target 0 over 30 s); the
node's log lines of a stale stream, an overrun or a restart; the adaptation's counters from
its last ``~/adapted_parameters``; the machine's load.  ``--warm-too``: a second start with
the cache the first one filled, for comparison.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
EVENTS = ('stream stale', 'no reference sample for', 'behind', 'clock went backwards',
          'reference moved', 'Traceback')


def start(env: dict[str, str], log: Path) -> tuple[subprocess.Popen, float]:
    """The node; (process, seconds to its "ready" line)."""
    fh = open(log, 'w')
    t0 = time.monotonic()
    proc = subprocess.Popen([sys.executable, '-m', 'worm_gear_sim.ros', '--ros-args',
                             '-p', 'adaptation.enabled:=true',
                             '-p', 'node.compensation_applied:=true'],
                            env=env, stdout=fh, stderr=subprocess.STDOUT, cwd=ROOT)
    while 'ready: dt' not in log.read_text():
        if proc.poll() is not None or time.monotonic() - t0 > 900:
            raise SystemExit(f'the node did not start:\n{log.read_text()}')
        time.sleep(0.05)
    return proc, time.monotonic() - t0


def stream(ctx: object, seconds: float) -> dict:
    import rclpy
    from builtin_interfaces.msg import Time
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String
    node = rclpy.create_node('fresh_start_bench', context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    ref = node.create_publisher(JointState, 'worm_angle_reference', qos)
    enc = node.create_publisher(JointState, 'measured_joint_states', qos)
    sent: dict[int, float] = {}
    answered: dict[int, float] = {}
    adapted: list[dict] = []

    def on_answer(msg: JointState) -> None:
        ns = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        answered.setdefault(ns, time.monotonic())
        e = JointState()
        e.header = msg.header
        e.name, e.position = ['antenna_joint'], [0.0]       # the config's encoder joint
        enc.publish(e)

    node.create_subscription(JointState, '/worm_gear_sim/compensated_command', on_answer, qos)
    node.create_subscription(String, '/worm_gear_sim/adapted_parameters',
                             lambda m: adapted.append(json.loads(m.data)), 10)
    t_wait = time.monotonic()
    while ref.get_subscription_count() < 1 or \
            node.count_publishers('/worm_gear_sim/compensated_command') < 1:
        ex.spin_once(timeout_sec=0.01)
        if time.monotonic() - t_wait > 60:
            raise SystemExit('no connection to the node')
    connect = time.monotonic() - t_wait
    msg = JointState()
    msg.name, msg.position = ['worm_input_joint'], [0.0]
    clock = node.get_clock()
    t0 = next_send = time.monotonic()
    while time.monotonic() - t0 < seconds:
        now = time.monotonic()
        if now >= next_send:
            ns = clock.now().nanoseconds
            msg.header.stamp = Time(sec=ns // 10**9, nanosec=ns % 10**9)
            msg.position[0] = 0.05 * math.sin(math.pi * (now - t0))
            sent[ns] = time.monotonic()
            ref.publish(msg)
            next_send += 1e-3
        ex.spin_once(timeout_sec=0.0)
    t1 = time.monotonic()
    while time.monotonic() - t1 < 3.0:
        ex.spin_once(timeout_sec=0.01)
    ex.shutdown()
    node.destroy_node()
    return {'sent': sent, 'answered': answered, 'adapted': adapted, 'connect': connect}


def report(label: str, ready: float, got: dict, log: str) -> None:
    sent, answered = got['sent'], got['answered']
    stamps = sorted(sent)
    first = stamps[0]
    lat = np.array([answered[s] - sent[s] for s in stamps if s in answered]) * 1e3
    first_s = np.array([answered[s] - sent[s] for s in stamps
                        if s in answered and sent[s] - sent[first] < 1.0]) * 1e3
    lost = len(stamps) - lat.size
    events = {w: log.count(w) for w in EVENTS if w in log}
    counters = got['adapted'][-1]['counters'] if got['adapted'] else {}
    first_ms = (answered[first] - sent[first]) * 1e3 if first in answered else math.nan
    print(f'{label}: start to "ready" {ready:.1f} s, connected {got["connect"]:.2f} s later; '
          f'first sample answered in {first_ms:.2f} ms (target <= 5); answer time first '
          f'second p50 {np.median(first_s):.2f} p99 {np.quantile(first_s, 0.99):.2f} worst '
          f'{first_s.max():.2f} ms, whole stream p50 {np.median(lat):.2f} p99 '
          f'{np.quantile(lat, 0.99):.2f} worst {lat.max():.2f} ms; {len(stamps)} sent, '
          f'{lost} never answered (target 0); log events {events or "none"}; adaptation '
          + ', '.join(f'{k} {counters.get(k)}' for k in ('samples', 'used', 'switches',
                                                           'late_steps', 'late_samples')),
          flush=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seconds', type=float, default=30.0, help='the stream [30 s]')
    ap.add_argument('--domain-id', type=int, default=150)
    ap.add_argument('--cache-dir', default='',
                    help='NUMBA_CACHE_DIR of the node (default: a new empty folder)')
    ap.add_argument('--warm-too', action='store_true',
                    help='a second start with the cache the first one filled')
    args = ap.parse_args()
    import rclpy
    print(f'load average at start: {os.getloadavg()}', flush=True)
    cache = args.cache_dir or tempfile.mkdtemp(prefix='bench_fresh_start_')
    env = dict(os.environ, NUMBA_CACHE_DIR=cache, ROS_DOMAIN_ID=str(args.domain_id),
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', PYTHONUNBUFFERED='1')
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=args.domain_id)
    try:
        for label in ('empty cache', 'warm cache')[:2 if args.warm_too else 1]:
            log = Path(cache) / f'node_{label.split()[0]}.log'
            proc, ready = start(env, log)
            try:
                got = stream(ctx, args.seconds)
            finally:
                proc.send_signal(signal.SIGINT)
                proc.wait(timeout=30)
            report(label, ready, got, log.read_text())
    finally:
        rclpy.try_shutdown(context=ctx)
    print(f'load average at end: {os.getloadavg()}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
