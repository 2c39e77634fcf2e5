# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A drive node process and a probe that talks to it over DDS: trajectories in, the
compensated trajectories, the compensated commands and /diagnostics out, and a 1 kHz
stamped reference stream.  Shared by test/ros/test_hostile_node.py (the checks) and
benchmarks/bench_trajectory_node.py (the overrun figures)."""

from __future__ import annotations

import collections
import contextlib
import math
import os
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from processes import start_logged, stop_and_read

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / 'config' / 'worm_gear_sim.yaml'
JOINT = 'worm_input_joint'
#: node.max_catch_up: a stamp gap longer than this is an overrun of the node
MAX_CATCH_UP_NS = 50_000_000


def trajectory(times: Sequence[float], positions: Sequence[float], stamp_ns: int = 0) -> Any:
    """A one-joint JointTrajectory message (positions only)."""
    from builtin_interfaces.msg import Duration, Time
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
    msg = JointTrajectory()
    msg.header.stamp = Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
    msg.joint_names = [JOINT]
    for t, x in zip(times, positions):
        p = JointTrajectoryPoint()
        p.positions = [float(x)]
        sec = math.floor(t)
        p.time_from_start = Duration(sec=sec, nanosec=int(round((t - sec) * 1e9)))
        msg.points.append(p)
    return msg


def big_trajectory(stamp_ns: int, n: int = 100_000, period: float = 1e-3,
                   phase: float = 0.0) -> bytes:
    """``n`` waypoints ``period`` apart (100 s at the defaults) of 0.3 + 0.2 sin((t +
    phase) / 10 s) rad (``phase``: the seconds since an earlier one's stamp, which it then
    continues), serialized here: a message object of 100 000 points would hold the probe's
    interpreter (and its 1 kHz stream) for a second while it is published."""
    from std_msgs.msg import Header

    from worm_gear_sim.joint_trajectory.compensate import JointTrajectoryData
    from worm_gear_sim.ros.trajectory_cdr import serialize_trajectory
    header = Header()
    header.stamp.sec, header.stamp.nanosec = stamp_ns // 10**9, stamp_ns % 10**9
    t = np.arange(1, n + 1) * period
    return serialize_trajectory(JointTrajectoryData(
        (JOINT,), t, (0.3 + 0.2 * np.sin((t + phase) / 10)).reshape(-1, 1)), header)


#: The probe's queue of the node's answers (~/compensated_command): more than a stream sends.
ANSWER_DEPTH = 20_000


class Probe:
    """The probe node, spun by hand (:meth:`spin_until`, :meth:`stream`)."""

    def __init__(self, ctx: Any, proc: Any) -> None:
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import JointState
        from trajectory_msgs.msg import JointTrajectory
        self.proc = proc
        self.node = rclpy.create_node('hostile_probe', context=ctx)
        self.ex = SingleThreadedExecutor(context=ctx)
        self.ex.add_node(self.node)
        rel = QoSProfile(depth=4000, reliability=ReliabilityPolicy.RELIABLE)
        self.pub = self.node.create_publisher(JointTrajectory, 'reference_trajectory', rel)
        self.ref = self.node.create_publisher(JointState, 'worm_angle_reference', 1000)
        self.out: list[tuple[float, bytes]] = []   # (arrival monotonic time, serialized)
        self.node.create_subscription(
            JointTrajectory, '/worm_gear_sim/compensated_trajectory',
            lambda m: self.out.append((time.monotonic(), m)), 100, raw=True)
        self.answers = 0
        self.sent = 0                                # stamped samples, every stream
        self.sent_stamps: list[int] = []             # their stamps [ns], in order
        self.answered: collections.Counter[int] = collections.Counter()   # answers per stamp
        # a deep queue: this probe takes one message per spin while it also publishes at
        # 1 kHz, and a loaded machine (CI's two workers, the node's worker process) starved it
        # long enough that a queue of 1000 overflowed and ~500 answers were lost on the way
        # back, although the node had answered every sample
        self.node.create_subscription(JointState, '/worm_gear_sim/compensated_command',
                                      self._answer, ANSWER_DEPTH)
        self.diag: dict[str, dict[str, str]] = {}
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._diag, 10)

    def _answer(self, msg: Any) -> None:
        self.answers += 1
        self.answered[msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec] += 1

    def unanswered(self, since: int) -> tuple[int, int]:
        """Of the samples sent since the ``since``-th: how many have no answer, how many
        more than one (answers are matched by stamp: a backlog of earlier samples answered
        meanwhile counts for neither)."""
        stamps = self.sent_stamps[since:]
        return (sum(self.answered[s] == 0 for s in stamps),
                sum(self.answered[s] > 1 for s in stamps))

    def wait_answered(self, since: int, timeout: float) -> tuple[int, int]:
        """Spin until every sample sent since the ``since``-th is answered (or ``timeout``
        s); :meth:`unanswered` then."""
        left = set(self.sent_stamps[since:])
        t0 = time.monotonic()
        while left and time.monotonic() - t0 < timeout and self.proc.poll() is None:
            self.ex.spin_once(timeout_sec=0.01)
            left = {s for s in left if self.answered[s] == 0}
        return self.unanswered(since)

    def _diag(self, msg: Any) -> None:
        for s in msg.status:
            self.diag[s.name] = {kv.key: kv.value for kv in s.values}

    def spin_until(self, pred: Callable[[], Any], timeout: float) -> bool:
        t0 = time.monotonic()
        while not pred():
            if time.monotonic() - t0 > timeout or self.proc.poll() is not None:
                return False
            self.ex.spin_once(timeout_sec=0.01)
        return True

    def last(self) -> Any:
        """The last compensated trajectory received (JointTrajectoryData)."""
        from worm_gear_sim.ros.trajectory_cdr import parse_trajectory
        return parse_trajectory(self.out[-1][1])[0]

    def fresh_status(self, task: str, pred: Callable[[dict[str, str]], bool] = lambda v: True,
                     timeout: float = 10.0) -> dict[str, str]:
        """The values of the next 'worm_gear_sim: <task>' status satisfying ``pred`` (the
        last one seen if none does in ``timeout``)."""
        name = f'worm_gear_sim: {task}'
        self.diag.pop(name, None)
        self.spin_until(lambda: name in self.diag and pred(self.diag[name]), timeout)
        return self.diag.get(name, {})

    def counters(self, names: Sequence[str]) -> dict[str, int]:
        """The counters ``names`` of the node's next 'inputs' and 'simulation' statuses,
        read while the 1 kHz stream goes on (a pause would make the stream stale)."""
        want = ('worm_gear_sim: inputs', 'worm_gear_sim: simulation')
        for name in want:
            self.diag.pop(name, None)
        self.stream(lambda: all(n in self.diag for n in want), 5.0)
        assert all(n in self.diag for n in want), 'no statuses'
        vals = {**self.diag[want[0]], **self.diag[want[1]]}
        return {k: int(vals[k]) for k in names}

    def stream(self, until: Callable[[], bool], timeout: float,
               extra: Any = None, extra_at: int = 100) -> dict[str, int]:
        """Stamped 1 kHz reference samples (position 0) until ``until()`` (checked every
        sample) or ``timeout`` s; ``extra`` published on the trajectory topic after
        ``extra_at`` samples.  Returns the samples sent, this probe's own stamp gaps over
        node.max_catch_up (a loaded machine pausing the probe, not the node) and the
        widest one [ms]."""
        from builtin_interfaces.msg import Time
        from sensor_msgs.msg import JointState
        msg = JointState(name=[JOINT], position=[0.0])
        clock = self.node.get_clock()
        t0 = time.monotonic()
        k = gaps = widest = 0
        last = None
        while time.monotonic() - t0 < timeout and not (k > extra_at and until()):
            if time.monotonic() >= t0 + k * 1e-3:
                if k == extra_at and extra is not None:
                    self.pub.publish(extra)
                ns = clock.now().nanoseconds
                if last is not None:
                    gaps += ns - last > MAX_CATCH_UP_NS
                    widest = max(widest, ns - last)
                last = ns
                msg.header.stamp = Time(sec=ns // 10**9, nanosec=ns % 10**9)
                self.ref.publish(msg)
                k += 1
                self.sent += 1
                self.sent_stamps.append(ns)
            self.ex.spin_once(timeout_sec=0.0)
        return {'sent': k, 'probe_gaps': gaps, 'widest_gap_ms': widest / 1e6}


@contextlib.contextmanager
def node_and_probe(log_path: Path, domain: int, ros_args: Sequence[str] = ()
                   ) -> Iterator[Probe]:
    """A drive node process (the package's params file, then ``ros_args``) on ``domain``
    (discovery LOCALHOST) and a probe in its own context; asserts the node's log holds no
    traceback when it is stopped."""
    import rclpy
    env = dict(os.environ)
    env.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               PYTHONUNBUFFERED='1')
    env.pop('ROS_STATIC_PEERS', None)
    old = os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE')
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    proc, log = start_logged([sys.executable, '-m', 'worm_gear_sim.ros', '--ros-args',
                              '--params-file', str(CONFIG), *ros_args], env, log_path)
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=domain)
    probe = Probe(ctx, proc)
    try:
        assert probe.spin_until(
            lambda: probe.pub.get_subscription_count() > 0 and probe.node.count_publishers(
                '/worm_gear_sim/compensated_trajectory') > 0, 90.0), 'node did not come up'
        yield probe
    finally:
        probe.ex.shutdown()
        probe.node.destroy_node()
        rclpy.try_shutdown(context=ctx)
        if old is None:
            os.environ.pop('ROS_AUTOMATIC_DISCOVERY_RANGE', None)
        else:
            os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = old
        rc, text = stop_and_read(proc, log)
        assert 'Traceback' not in text, text
