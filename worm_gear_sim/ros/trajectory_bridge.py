# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``reference_trajectory`` in, ``~/compensated_trajectory`` out: the I/O of the core's
:class:`~worm_gear_sim.trajectory_compensation.TrajectoryCompensator` for the drives of a node (one
drive: :class:`~.node.WormGearSimNode`; several: :mod:`.pedestal`).

A ``trajectory_msgs/JointTrajectory`` is turned into the core's
:class:`~worm_gear_sim.trajectory_compensation.Trajectory` in the callback (one line per rule
broken, counted as ``rejected_trajectory_<reason>``, nothing forwarded); the compensation (seconds
for a long trajectory) runs on one worker thread, in arrival order, so the node's
per-sample paths are not held up by it; the worker publishes the dense compensated
trajectory with the input's joint names, header and timing.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from builtin_interfaces.msg import Duration
from rclpy.qos import QoSProfile, ReliabilityPolicy
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from ..topics import COMPENSATED_TRAJECTORY_TOPIC, TRAJECTORY_TOPIC
from ..trajectory_compensation import (
    TRAJECTORY_REJECT_REASONS,
    JointTrajectoryData,
    TrajectoryCompensator,
    TrajectoryRejected,
    TrajectoryResult,
)

__all__ = ['TrajectoryBridge', 'TRAJECTORY_COUNTERS', 'to_message', 'from_message']

_NS = 1_000_000_000
#: The counters a bridge keeps in its node's counter dict.
TRAJECTORY_COUNTERS = ('trajectories_received', 'trajectories_compensated', 'trajectory_errors',
                       *(f'rejected_trajectory_{r}' for r in TRAJECTORY_REJECT_REASONS))
QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)   # as the controller's
#: Compensated points waiting for the worker at most (~16 s of its work); a trajectory that
#: would exceed it is rejected as ``busy`` (a flood of long trajectories must not queue
#: without bound); one is always taken when none waits.  A burst of short trajectories
#: (hundreds of 1 s ones) is all taken.
MAX_PENDING_POINTS = 2_000_000


def from_message(msg: JointTrajectory) -> JointTrajectoryData:
    """The core's JointTrajectoryData of a message (TrajectoryRejected for ragged points)."""
    pts = msg.points
    st = msg.header.stamp
    return JointTrajectoryData.from_points(
        list(msg.joint_names),
        [p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 for p in pts],
        [p.positions for p in pts], [p.velocities for p in pts],
        [p.accelerations for p in pts], st.sec * _NS + st.nanosec)


def to_message(traj: JointTrajectoryData, header: Any) -> JointTrajectory:
    """The dense compensated trajectory as a message with the input's ``header``."""
    msg = JointTrajectory()
    msg.header = header
    msg.joint_names = list(traj.joint_names)
    ns = (traj.time_from_start * 1e9).round().astype('int64').tolist()
    pos = traj.positions.tolist()
    vel = None if traj.velocities is None else traj.velocities.tolist()
    acc = None if traj.accelerations is None else traj.accelerations.tolist()
    points = []
    for i, t_ns in enumerate(ns):
        p = JointTrajectoryPoint()
        p.positions = pos[i]
        if vel is not None:
            p.velocities = vel[i]
        if acc is not None:
            p.accelerations = acc[i]
        sec, nsec = divmod(t_ns, _NS)
        p.time_from_start = Duration(sec=sec, nanosec=nsec)
        points.append(p)
    msg.points = points
    return msg


class TrajectoryBridge:
    """The trajectory topics of ``node`` for the drives ``models()`` returns (joint name ->
    DriveModel; asked again for each trajectory, so parameter sets apply).  ``counters``
    (the node's dict) gets :data:`TRAJECTORY_COUNTERS`; ``warn(cause, text)`` logs
    throttled; ``publish(pub, msg)`` publishes without ever raising; ``guard`` wraps the
    subscription callback (quiet at shutdown)."""

    def __init__(self, node: Any, models: Callable[[], Mapping[str, Any]],
                 counters: dict[str, Any], warn: Callable[[str, str], None],
                 publish: Callable[[Any, Any], None],
                 guard: Callable[[Any], Any] = lambda f: f) -> None:
        self._node = node
        self._models = models
        self._counters = counters
        counters.update({k: 0 for k in TRAJECTORY_COUNTERS})
        self._warn = warn
        self._publish = publish
        self.compensator = TrajectoryCompensator(models())
        self.last_result: TrajectoryResult | None = None
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix='trajectory')
        self._pending = 0          # dense points submitted, not finished (+= here, -= worker)
        self._lock = threading.Lock()
        self._pub = node.create_publisher(JointTrajectory, COMPENSATED_TRAJECTORY_TOPIC, QOS)
        self._sub = node.create_subscription(JointTrajectory, TRAJECTORY_TOPIC,
                                             guard(self.on_trajectory), QOS)

    @property
    def joints(self) -> tuple[str, ...]:
        return self.compensator.joints

    def on_trajectory(self, msg: JointTrajectory) -> None:
        """Validate in the callback, compensate and publish on the worker."""
        self._counters['trajectories_received'] += 1
        now_ns = self._node.get_clock().now().nanoseconds
        try:
            traj = from_message(msg)
            self.compensator.check(traj, now_ns)
            points = self.compensator.dense_points(traj)
            with self._lock:
                if self._pending and self._pending + points > MAX_PENDING_POINTS:
                    raise TrajectoryRejected('busy', f'{self._pending} compensated points '
                                             f'still to compute, {points} more would '
                                             f'exceed {MAX_PENDING_POINTS}')
                self._pending += points
        except TrajectoryRejected as exc:
            self._reject(exc)
            return
        self._pool.submit(self._work, traj, msg.header, now_ns, points)

    def _reject(self, exc: TrajectoryRejected) -> None:
        key = f'rejected_trajectory_{exc.reason}'
        self._counters[key] += 1
        self._warn(key, f'rejected {TRAJECTORY_TOPIC}: {exc.reason} ({exc}); '
                        f'{self._counters[key]} so far; nothing forwarded')

    def _work(self, traj: JointTrajectoryData, header: Any, now_ns: int, points: int) -> None:
        try:
            self._compensate_and_publish(traj, header, now_ns)
        finally:
            with self._lock:
                self._pending -= points

    def _compensate_and_publish(self, traj: JointTrajectoryData, header: Any, now_ns: int) -> None:
        try:
            models = self._models()
            comp = self.compensator
            if any(comp.drives.get(j) is not m for j, m in models.items()):
                comp = self.compensator = comp.with_drives(models)
            result = comp.compensate(traj, now_ns)
        except TrajectoryRejected as exc:
            self._reject(exc)
            return
        except Exception as exc:  # noqa: BLE001 - a worker error must not pass silently
            self._counters['trajectory_errors'] += 1
            self._warn('trajectory_error', f'{TRAJECTORY_TOPIC}: compensation failed '
                       f'({type(exc).__name__}: {exc}); nothing forwarded')
            return
        self.last_result = result
        self._publish(self._pub, to_message(result.trajectory, header))
        self._counters['trajectories_compensated'] += 1

    def wait(self, timeout: float = 30.0) -> None:
        """Block until the trajectories received so far are published (tests, shutdown)."""
        self._pool.submit(lambda: None).result(timeout)

    def shutdown(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)
