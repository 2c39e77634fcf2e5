# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Where the per-sample cost of a drive node goes, in-process (no second process, no DDS
timing): the figures behind docs/pedestal.md, "Cost per axis".

1. The compiled kernel alone: ``Simulator.advance_to`` for 1 ms of the 2 rad/s slew of
   bench_node.py (250 Newmark steps of 4 us), thread time per sample.
2. The node's reference callback (``WormGearSimNode._on_reference``) fed 1 kHz stamped
   samples in real time: thread time per callback and the share of it in
   ``RealtimePredictor.push``; wall time p50 / p99 / max.
3. The same wall times while the trajectory worker compensates a 300 s trajectory (the
   interpreter lock shared with the per-sample path).

    python benchmarks/bench_sample_path.py [--samples 5000]
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


def callbacks(samples: int) -> dict:
    import rclpy
    from builtin_interfaces.msg import Duration
    from sensor_msgs.msg import JointState
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from worm_gear_sim.ros.node import WormGearSimNode
    from worm_gear_sim.ros.run import make_executor
    rclpy.init()
    node = WormGearSimNode()
    probe = rclpy.create_node('sample_path_probe')
    probe.create_subscription(JointState, '/worm_gear_sim/compensated_command',
                              lambda m: None, 1000)
    ex = make_executor('single_threaded')
    ex.add_node(node)
    ex.add_node(probe)
    for _ in range(50):
        ex.spin_once(timeout_sec=0.01)
    msg = JointState(name=[node.config.node.joint_names[0]], position=[0.0])
    base = node.get_clock().now().nanoseconds + 10_000_000
    push_ns = [0]
    push = node.rt.push

    def timed_push(*a, **k):
        t = time.thread_time_ns()
        r = push(*a, **k)
        push_ns[0] += time.thread_time_ns() - t
        return r
    node.rt.push = timed_push

    def run(n: int, k0: int) -> tuple[np.ndarray, float]:
        wall, cpu = [], 0
        for k in range(k0, k0 + n):
            st = base + k * 1_000_000
            while time.time_ns() < st:     # real time: the sample's own instant
                pass
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(st, 10**9)
            msg.position[0] = slew(k * 1e-3, 2.0)
            t, c = time.perf_counter_ns(), time.thread_time_ns()
            node._on_reference(msg)
            cpu += time.thread_time_ns() - c
            wall.append(time.perf_counter_ns() - t)
        return np.array(wall) / 1e3, cpu / n / 1e3

    run(1000, 0)
    push_ns[0] = 0
    quiet, cpu = run(samples, 1000)
    out = {'cpu_us': cpu, 'push_us': push_ns[0] / samples / 1e3, 'quiet': quiet}
    traj = JointTrajectory()
    traj.joint_names = [node.config.node.joint_names[0]]
    st = node.get_clock().now().nanoseconds + 10**9
    traj.header.stamp.sec, traj.header.stamp.nanosec = divmod(st, 10**9)
    for s in range(1, 301):
        p = JointTrajectoryPoint()
        p.positions = [float(np.sin(s / 30))]
        p.time_from_start = Duration(sec=s)
        traj.points.append(p)
    node.trajectories.on_trajectory(traj)
    out['busy'], _ = run(samples, 1000 + samples)
    ex.shutdown()
    node.destroy_node()
    probe.destroy_node()
    rclpy.try_shutdown()
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--samples', type=int, default=5000)
    args = ap.parse_args()
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    load0 = os.getloadavg()[0]
    k = kernel(args.samples)
    c = callbacks(args.samples)
    print(f'load average {load0:.2f} before, {os.getloadavg()[0]:.2f} after; '
          f'{args.samples} samples of the 2 rad/s slew at 1 kHz')
    print(f'  compiled kernel, Simulator.advance_to 1 ms: {k:.0f} us thread time '
          f'({k / 1000:.3f} core at 1 kHz)')
    print(f'  reference callback: {c["cpu_us"]:.0f} us thread time, of which '
          f'RealtimePredictor.push {c["push_us"]:.0f} us')
    for name, d in (('no trajectory', c['quiet']),
                    ('300 s trajectory compensating', c['busy'])):
        print(f'  callback wall, {name}: p50 {np.percentile(d, 50):.0f} us, '
              f'p99 {np.percentile(d, 99):.0f} us, max {d.max():.0f} us')
    return 0


if __name__ == '__main__':
    sys.exit(main())
