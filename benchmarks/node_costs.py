# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The per-tick costs of the node, for ``bench_node.py --breakdown``: the pieces of a tick
in-process (no DDS transport), and the platform's floor in separate processes (an empty
1 kHz timer per executor, one JointState published to another process)."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from node_probe import ROOT, slew  # noqa: E402

__all__ = ['breakdown', 'empty_timer_cost', 'publish_cost']


def breakdown(n_ticks: int = 2000) -> dict[str, float]:
    """Per-tick costs [us] of the pieces of a tick, in-process (no DDS transport)."""
    import rclpy
    from std_msgs.msg import Float64

    from worm_gear_sim.ros.node import WormGearSimNode
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'OFF'
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '44')))
    node = WormGearSimNode(context=ctx)
    out: dict[str, float] = {}
    try:
        msg = Float64()
        sim, comp = node.sim, node.compensator
        # whole tick callback at the slew, wall time, without the executor
        t0 = time.monotonic()
        for i in range(n_ticks + 200):
            if i == 200:
                busy0, k0 = node.load.window['busy_ns'], node.counters['ticks']
            msg.data = slew(time.monotonic() - t0)
            node._on_command(msg)
            node._on_tick()
            while time.monotonic() - t0 < (i + 1) * 1e-3:
                pass
        out['tick callback (all below)'] = \
            (node.load.window['busy_ns'] - busy0) / (node.counters['ticks'] - k0) / 1e3
        # physics alone: 1 ms of the same slew per call
        from worm_gear_sim.dynamics.simulation import Simulator
        s = Simulator(node.config, theta1=slew(0.0))
        t, a = 0.0, time.perf_counter()
        for _ in range(n_ticks):
            t += 1e-3
            s.advance_to(t, slew(t))
        steps = round(1e-3 / s.dt)
        out[f'  Simulator.advance_to ({steps} Newmark steps)'] = \
            (time.perf_counter() - a) / n_ticks * 1e6
        if comp is not None:
            from worm_gear_sim.compensation.streaming import Compensator
            c = Compensator(node.config)
            c.reset(slew(0.0), 0.0)
            t, a = 0.0, time.perf_counter()
            for _ in range(n_ticks):
                t += 1e-3
                c.update(t, slew(t))
            out['  Compensator.update'] = (time.perf_counter() - a) / n_ticks * 1e6

        def per(f) -> float:
            a = time.perf_counter()
            for _ in range(n_ticks):
                f()
            return (time.perf_counter() - a) / n_ticks * 1e6
        out['  state + joint_torques'] = per(lambda: (sim.state, sim.joint_torques()))
        pubs = node.publishing
        out['  4 publishes (joint_states + 3 one-joint answers)'] = per(lambda: (
            pubs._pub_js.publish(pubs._js), pubs._err.pub.publish(pubs._err.msg),
            pubs._worm.pub.publish(pubs._worm.msg), pubs._ff.pub.publish(pubs._ff.msg)))
        out['  clock.now()'] = per(lambda: node.get_clock().now())
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    return out


def empty_timer_cost(kind: str, seconds: float = 10.0) -> tuple[float, float, float]:
    """An empty 1 kHz timer alone in a process with the given executor: (CPU [core],
    missed ticks [%], remote JointState publish [us of CPU per message]).  The platform's
    floor for the node's figures."""
    code = f'''
import time, rclpy
from rclpy.node import Node
from worm_gear_sim.ros.run import make_executor
rclpy.init(domain_id={int(os.environ.get('ROS_DOMAIN_ID', '44')) + 1})
n = Node('empty_timer'); ts = []
n.create_timer(1e-3, lambda: ts.append(time.monotonic_ns()))
ex = make_executor('{kind}'); ex.add_node(n)
fut = rclpy.task.Future()
ex.spin_until_future_complete(fut, timeout_sec=1.0)
ts.clear()
c0, w0 = time.process_time(), time.monotonic()
while time.monotonic() - w0 < {seconds}:
    ex.spin_until_future_complete(fut, timeout_sec=1.0)
cpu = (time.process_time() - c0) / (time.monotonic() - w0)
lost = 0
for a, b in zip(ts, ts[1:]):
    g = (b - a) / 1e6
    if g > 1.5:
        lost += round(g) - 1
print(cpu, 100.0 * lost / (len(ts) + lost))
'''
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         timeout=seconds + 60, cwd=ROOT)
    cpu, missed = (float(x) for x in out.stdout.split()[-2:])
    return cpu, missed


def publish_cost(n: int = 2000) -> float:
    """CPU [us] per JointState published to a subscriber in another process (the
    DDS/rclpy floor of one output topic at 1 kHz on this machine)."""
    dom = int(os.environ.get('ROS_DOMAIN_ID', '44')) + 2
    sub = subprocess.Popen([sys.executable, '-c', f'''
import time, rclpy
from sensor_msgs.msg import JointState
rclpy.init(domain_id={dom})
n = rclpy.create_node('pub_cost_sub')
n.create_subscription(JointState, 'pub_cost', lambda m: None, 10)
t0 = time.monotonic()
try:
    while time.monotonic() - t0 < 60:
        rclpy.spin_once(n, timeout_sec=0.1)
except Exception:
    pass
'''], cwd=ROOT)
    code = f'''
import time, rclpy
from sensor_msgs.msg import JointState
rclpy.init(domain_id={dom})
n = rclpy.create_node('pub_cost_pub')
p = n.create_publisher(JointState, 'pub_cost', 10)
js = JointState(name=['a', 'b', 'c', 'd'], position=[0.1] * 4, velocity=[0.2] * 4,
                effort=[0.3] * 4)
t0 = time.monotonic()
while p.get_subscription_count() == 0 and time.monotonic() - t0 < 30:
    time.sleep(0.05)
time.sleep(0.5)
c0 = time.process_time()
for _ in range({n}):
    p.publish(js)
    time.sleep(0.001)
c1 = time.process_time()
for _ in range({n}):
    time.sleep(0.001)
print(((c1 - c0) - (time.process_time() - c1)) / {n} * 1e6)
'''
    try:
        out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                             timeout=120, cwd=ROOT)
    finally:
        sub.terminate()
        sub.wait()
    return float(out.stdout.split()[-1])
