# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Where the per-sample cost of a drive node goes, in-process (no second process, no DDS
timing): the figures behind docs/pedestal.md, "Cost per axis".

1. The compiled kernel alone: ``Simulator.advance_to`` for 1 ms of the 2 rad/s slew of
   bench_node.py (250 Newmark steps of 4 us), thread time per sample.
2. The node's reference callback (``WormGearSimNode._on_reference``) fed 1 kHz stamped
   samples in real time: thread time per callback and the share of it in
   ``RealtimePredictor.push``; wall time p50 / p99 / max.
3. The same wall times while the trajectory worker compensates and publishes a trajectory
   of ``--points`` waypoints over ``--duration`` s (default 100 000 points, 100 s: issue
   28's case; the interpreter lock shared with the per-sample path), with the samples
   answered, rejected too_old and the overruns; ``--message-object`` builds the output as
   a message object point by point (the path before numpy serialization) for the
   side-by-side figure.

    python benchmarks/bench_sample_path.py [--samples 5000] [--points 100000]
        [--duration 100] [--message-object]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from node_probe import slew  # noqa: E402


def kernel(samples: int) -> float:
    from worm_gear_sim import Simulator, load_config
    sim = Simulator(load_config())
    for k in range(1000):
        sim.advance_to((k + 1) * 1e-3, slew(k * 1e-3, 2.0))
    t0 = time.thread_time()
    for k in range(1000, 1000 + samples):
        sim.advance_to((k + 1) * 1e-3, slew(k * 1e-3, 2.0))
    return (time.thread_time() - t0) / samples * 1e6


def callbacks(samples: int, points: int = 100_000, duration: float = 100.0,
              message_object: bool = False) -> dict:
    import rclpy
    from builtin_interfaces.msg import Duration
    from sensor_msgs.msg import JointState
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from worm_gear_sim.ros import trajectory_bridge
    from worm_gear_sim.ros.node import WormGearSimNode
    from worm_gear_sim.ros.run import make_executor
    if message_object:
        trajectory_bridge.serialize_trajectory = trajectory_bridge.to_message
    rclpy.init()
    node = WormGearSimNode()
    probe = rclpy.create_node('sample_path_probe')
    probe.create_subscription(JointState, '/worm_gear_sim/compensated_command',
                              lambda m: None, 1000)
    probe.create_subscription(JointTrajectory, '/worm_gear_sim/compensated_trajectory',
                              lambda m: None, 10)
    ex = make_executor('single_threaded')
    ex.add_node(node)
    ex.add_node(probe)
    for _ in range(50):
        ex.spin_once(timeout_sec=0.01)
    msg = JointState(name=[node.config.node.joint_names[0]], position=[0.0])
    base = [node.get_clock().now().nanoseconds + 10_000_000]
    push_ns = [0]
    push = node.rt.push

    def timed_push(*a, **k):
        t = time.thread_time_ns()
        r = push(*a, **k)
        push_ns[0] += time.thread_time_ns() - t
        return r
    node.rt.push = timed_push

    lag = [0]

    def run(n: int, k0: int) -> tuple[np.ndarray, float]:
        wall, cpu = [], 0
        lag[0] = 0
        for k in range(k0, k0 + n):
            st = base[0] + k * 1_000_000
            while time.time_ns() < st:     # real time: the sample's own instant
                pass
            lag[0] = max(lag[0], time.time_ns() - st)
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(st, 10**9)
            msg.position[0] = slew(k * 1e-3, 2.0)
            t, c = time.perf_counter_ns(), time.thread_time_ns()
            node._on_reference(msg)
            cpu += time.thread_time_ns() - c
            wall.append(time.perf_counter_ns() - t)
        return np.array(wall) / 1e3, cpu / n / 1e3

    # the trajectory, serialized as the (raw) subscription hands it over: built first
    traj = JointTrajectory()
    traj.joint_names = [node.config.node.joint_names[0]]
    st = node.get_clock().now().nanoseconds + 30 * 10**9      # starts after the runs
    traj.header.stamp.sec, traj.header.stamp.nanosec = divmod(st, 10**9)
    for s in range(1, points + 1):
        p = JointTrajectoryPoint()
        t = s * duration / points
        p.positions = [float(0.5 * np.sin(t / 30))]
        sec = int(t)
        p.time_from_start = Duration(sec=sec, nanosec=int(round((t - sec) * 1e9)))
        traj.points.append(p)
    from rclpy.serialization import serialize_message
    raw = serialize_message(traj)
    base[0] = node.get_clock().now().nanoseconds + 10_000_000
    run(1000, 0)
    push_ns[0] = 0
    quiet, cpu = run(samples, 1000)
    out = {'cpu_us': cpu, 'push_us': push_ns[0] / samples / 1e3, 'quiet': quiet}
    c = {**node.rt.counters, **node.counters}
    before = {k: c[k] for k in ('rejected_too_old', 'overruns', 'corrections',
                                'trajectories_compensated')}
    t_sent = time.perf_counter()
    node.trajectories.on_trajectory(raw)
    out['busy'], _ = run(samples, 1000 + samples)
    out['lag_s'] = lag[0] / 1e9
    out['published_within_run'] = node.counters['trajectories_compensated'] > \
        before['trajectories_compensated']
    done = node.trajectories.wait(120.0)
    c = {**node.rt.counters, **node.counters}
    out['after'] = {k: c[k] - before[k] for k in before}
    out['published_s'] = time.perf_counter() - t_sent if done else float('nan')
    ex.shutdown()
    node.destroy_node()
    probe.destroy_node()
    rclpy.try_shutdown()
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--samples', type=int, default=5000)
    ap.add_argument('--points', type=int, default=100_000)
    ap.add_argument('--duration', type=float, default=100.0)
    ap.add_argument('--message-object', action='store_true')
    args = ap.parse_args()
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    load0 = os.getloadavg()[0]
    k = kernel(args.samples)
    c = callbacks(args.samples, args.points, args.duration, args.message_object)
    print(f'load average {load0:.2f} before, {os.getloadavg()[0]:.2f} after; '
          f'{args.samples} samples of the 2 rad/s slew at 1 kHz')
    print(f'  compiled kernel, Simulator.advance_to 1 ms: {k:.0f} us thread time '
          f'({k / 1000:.3f} core at 1 kHz)')
    print(f'  reference callback: {c["cpu_us"]:.0f} us thread time, of which '
          f'RealtimePredictor.push {c["push_us"]:.0f} us')
    how = 'message object' if args.message_object else 'numpy serialization'
    for name, d in (('no trajectory', c['quiet']),
                    (f'{args.points} points / {args.duration:g} s trajectory ({how})',
                     c['busy'])):
        print(f'  callback wall, {name}: p50 {np.percentile(d, 50):.0f} us, '
              f'p99 {np.percentile(d, 99):.0f} us, max {d.max():.0f} us, '
              f'> 10 ms: {int(np.sum(d > 1e4))}')
    a = c['after']
    print(f'  while it was compensated: {a["corrections"]}/{args.samples} samples answered, '
          f'{a["rejected_too_old"]} too_old, {a["overruns"]} overruns (the feed '
          f'fell {c["lag_s"]:.3f} s behind real time at most); published '
          f'{c["published_s"]:.2f} s after reception '
          f'({"within" if c["published_within_run"] else "after"} the sampled window)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
