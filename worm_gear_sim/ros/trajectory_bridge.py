# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``reference_trajectory`` in, ``~/compensated_trajectory`` out: the I/O of the core's
``TrajectoryCompensator`` for the drives of a node (one drive: the node; several:
:mod:`.pedestal`).

A message is checked in the callback and queued; one worker thread compensates in
arrival order (superseded ones dropped), long trajectories in a worker process, and
publishes through :mod:`.trajectory_cdr`.  :func:`trajectory_status` is its /diagnostics
status.  docs/pedestal.md.
"""

from __future__ import annotations

import multiprocessing
import threading
from collections import deque
from collections.abc import Callable, Mapping
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Any

from builtin_interfaces.msg import Duration
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from ..joint_trajectory.compensate import (
    TRAJECTORY_REJECT_REASONS,
    JointTrajectoryData,
    TrajectoryCompensator,
    TrajectoryRejected,
    TrajectoryResult,
    compensate_trajectory,
)
from ..realtime.switch_interval import short_switch_interval
from ..records.topics import COMPENSATED_TRAJECTORY_TOPIC, TRAJECTORY_TOPIC
from . import diagnostics as diag
from .trajectory_cdr import parse_trajectory, serialize_trajectory

__all__ = ['TrajectoryBridge', 'TRAJECTORY_COUNTERS', 'to_message', 'from_message',
           'trajectory_status', 'QUEUE_DEPTH']

_NS = 1_000_000_000
#: The counters a bridge keeps in its node's counter dict.
TRAJECTORY_COUNTERS = ('trajectories_received', 'trajectories_compensated',
                       'trajectories_superseded', 'trajectory_errors',
                       'trajectory_messages_lost',
                       *(f'rejected_trajectory_{r}' for r in TRAJECTORY_REJECT_REASONS))
#: Keep-last depth of the input: 1 s of replacements at 1 kHz while the executor is held
#: (a depth of 10 dropped 215 of 3000 silently); the output keeps the controller's 10.
QUEUE_DEPTH = 1000
QOS_IN = QoSProfile(depth=QUEUE_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)   # as the controller's
#: Compensated points from which a trajectory is compensated in the worker process (20 s
#: at 1 kHz; shorter ones take the interpreter less than ~0.3 s and stay in the thread).
PROCESS_POINTS = 20_000
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


_POOL: list[ProcessPoolExecutor] = []
_POOL_LOCK = threading.Lock()


def _process_pool() -> ProcessPoolExecutor:
    """The worker process of this process's bridges (one, shared; spawned: no fork of the
    middleware's threads; it ends with the process)."""
    with _POOL_LOCK:
        if not _POOL:
            _POOL.append(ProcessPoolExecutor(1, mp_context=multiprocessing.get_context('spawn')))
        return _POOL[0]


def _drop_pool() -> None:
    with _POOL_LOCK:
        if _POOL:
            _POOL.pop().shutdown(wait=False, cancel_futures=True)


@dataclass
class _Item:
    seq: int
    traj: JointTrajectoryData
    header: Any
    now_ns: int
    points: int

    @property
    def start_ns(self) -> int:
        return self.traj.stamp_ns or self.now_ns


class TrajectoryBridge:
    """The trajectory topics of ``node`` for the drives ``models()`` returns (joint name ->
    DriveModel; asked again for each trajectory, so parameter sets apply), input on
    ``topic``.  ``counters`` (the node's dict) gets :data:`TRAJECTORY_COUNTERS`;
    ``warn(cause, text)`` logs throttled; ``publish(pub, msg)`` publishes without ever
    raising; ``guard`` wraps the subscription callback (quiet at shutdown)."""

    def __init__(self, node: Any, models: Callable[[], Mapping[str, Any]],
                 counters: dict[str, Any], warn: Callable[[str, str], None],
                 publish: Callable[[Any, Any], None],
                 guard: Callable[[Any], Any] = lambda f: f,
                 topic: str = TRAJECTORY_TOPIC) -> None:
        self._node = node
        self._models = models
        self._counters = counters
        counters.update({k: 0 for k in TRAJECTORY_COUNTERS})
        self._warn = warn
        self._publish = publish
        self.topic = topic
        self.compensator = TrajectoryCompensator(models())
        self.last_result: TrajectoryResult | None = None
        self._queue: deque[_Item] = deque()
        self._pending = 0          # dense points queued or in work
        self._busy = False
        self._seq = 0
        self._stop = False
        self._cond = threading.Condition()
        self._pub = node.create_publisher(JointTrajectory, COMPENSATED_TRAJECTORY_TOPIC, QOS)
        self._sub = self._subscribe(guard)
        self._thread = threading.Thread(target=self._run, name='trajectory', daemon=True)
        self._thread.start()

    def _in_process(self, model: Any, *args: Any, **kwargs: Any) -> Any:
        """compensate_trajectory(*args, **kwargs) in the worker process (started on first
        use, spawned: no fork of the middleware's threads); here if it cannot run."""
        try:
            return _process_pool().submit(compensate_trajectory, model.config, *args,
                                          **kwargs).result()
        except (BrokenProcessPool, OSError, RuntimeError) as exc:
            if self._stop:
                raise
            _drop_pool()
            self._warn('trajectory_process', f'{self.topic}: worker process failed '
                       f'({type(exc).__name__}: {exc}); compensating in the node')
            return compensate_trajectory(model, *args, **kwargs)

    def _subscribe(self, guard: Callable[[Any], Any]) -> Any:
        """The input; where the middleware reports messages lost, they are counted."""
        try:
            from rclpy.event_handler import SubscriptionEventCallbacks
            events = SubscriptionEventCallbacks(message_lost=self._on_lost)
            return self._node.create_subscription(JointTrajectory, self.topic,
                                                  guard(self.on_trajectory), QOS_IN,
                                                  event_callbacks=events, raw=True)
        except Exception:  # noqa: BLE001 - an rmw without the event: subscribe without
            return self._node.create_subscription(JointTrajectory, self.topic,
                                                  guard(self.on_trajectory), QOS_IN, raw=True)

    def _on_lost(self, info: Any) -> None:
        self._counters['trajectory_messages_lost'] = int(info.total_count)
        self._warn('trajectory_lost', f'{self.topic}: {info.total_count} message(s) lost '
                   'by the middleware')

    @property
    def joints(self) -> tuple[str, ...]:
        return self.compensator.joints

    @property
    def queued(self) -> int:
        """Trajectories waiting for the worker."""
        return len(self._queue)

    @property
    def pending_points(self) -> int:
        return self._pending

    def on_trajectory(self, msg: JointTrajectory | bytes) -> None:
        """Validate in the callback, queue for the worker.  ``msg``: the serialized
        message (the subscription is raw: a 100 000-point message object took the
        executor ~2 s to convert; :func:`~.trajectory_cdr.parse_trajectory` reads it in
        milliseconds) or a message object."""
        self._counters['trajectories_received'] += 1
        now_ns = self._node.get_clock().now().nanoseconds
        try:
            traj = None
            if isinstance(msg, bytes):
                parsed = parse_trajectory(msg)
                if parsed is None:                  # ragged, efforts...: the usual way
                    msg = deserialize_message(msg, JointTrajectory)
                else:
                    traj, (sec, nanosec, frame) = parsed
                    header = Header(frame_id=frame)
                    header.stamp.sec, header.stamp.nanosec = sec, nanosec
            if traj is None:
                traj = from_message(msg)
                header = msg.header
            self.compensator.check(traj, now_ns)
            points = self.compensator.dense_points(traj)
            with self._cond:
                if self._pending and self._pending + points > MAX_PENDING_POINTS:
                    raise TrajectoryRejected('busy', f'{self._pending} compensated points '
                                             f'still to compute, {points} more would '
                                             f'exceed {MAX_PENDING_POINTS}')
                self._pending += points
                self._seq += 1
                self._queue.append(_Item(self._seq, traj, header, now_ns, points))
                self._cond.notify_all()
        except TrajectoryRejected as exc:
            self._reject(exc)

    def _reject(self, exc: TrajectoryRejected) -> None:
        key = f'rejected_trajectory_{exc.reason}'
        self._counters[key] += 1
        self._warn(key, f'rejected {self.topic}: {exc.reason} ({exc}); '
                        f'{self._counters[key]} so far; nothing forwarded')

    def _superseded(self, item: _Item, now_ns: int) -> bool:
        """Every joint of ``item`` is named again by a later trajectory (queued) that
        starts by ``now_ns``: it would be replaced as soon as it arrived (lock held)."""
        left = set(item.traj.joint_names)
        for later in self._queue:
            if later.start_ns <= now_ns:
                left.difference_update(later.traj.joint_names)
                if not left:
                    return True
        return False

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._queue and not self._stop:
                    self._cond.wait()
                if self._stop:
                    return
                item = self._queue.popleft()
                if self._superseded(item, self._node.get_clock().now().nanoseconds):
                    self._counters['trajectories_superseded'] += 1
                    self._pending -= item.points
                    self._cond.notify_all()
                    continue
                self._busy = True
            try:
                with short_switch_interval():
                    self._compensate_and_publish(item.traj, item.header, item.now_ns)
            finally:
                with self._cond:
                    self._busy = False
                    self._pending -= item.points
                    self._cond.notify_all()

    def _compensate_and_publish(self, traj: JointTrajectoryData, header: Any, now_ns: int) -> None:
        try:
            models = self._models()
            comp = self.compensator
            if any(comp.drives.get(j) is not m for j, m in models.items()):
                comp = self.compensator = comp.with_drives(models)
            big = comp.dense_points(traj) * len(traj.joint_names) >= PROCESS_POINTS
            result = comp.compensate(traj, now_ns, run=self._in_process if big else None)
        except TrajectoryRejected as exc:
            self._reject(exc)
            return
        except Exception as exc:  # noqa: BLE001 - a worker error must not pass silently
            self._counters['trajectory_errors'] += 1
            self._warn('trajectory_error', f'{self.topic}: compensation failed '
                       f'({type(exc).__name__}: {exc}); nothing forwarded')
            return
        self.last_result = result
        self._publish(self._pub, serialize_trajectory(result.trajectory, header))
        self._counters['trajectories_compensated'] += 1

    def wait(self, timeout: float = 30.0) -> bool:
        """Block until the trajectories received so far are published or dropped (tests,
        shutdown); False on timeout."""
        with self._cond:
            return self._cond.wait_for(lambda: not self._queue and not self._busy, timeout)

    def shutdown(self) -> None:
        with self._cond:
            self._stop = True
            self._queue.clear()
            self._cond.notify_all()



def trajectory_status(name: str, counters: Mapping[str, Any], bridge: TrajectoryBridge,
                      hardware_id: str) -> diag.DiagnosticStatus:
    """Status 'trajectories' of node ``name``: every trajectory counter, the queue and the
    input topic; WARN after a rejection or a lost message, ERROR after a compensation
    failure."""
    rejected = sum(counters[f'rejected_trajectory_{r}'] for r in TRAJECTORY_REJECT_REASONS)
    values = {k: counters[k] for k in TRAJECTORY_COUNTERS}
    values.update(rejected_trajectories=rejected, queued=bridge.queued,
                  pending_points=bridge.pending_points, input_topic=bridge.topic,
                  joints=', '.join(bridge.joints))
    if counters['trajectory_errors']:
        level, msg = diag.ERROR, f'{counters["trajectory_errors"]} compensation failure(s)'
    elif rejected or counters['trajectory_messages_lost']:
        level, msg = diag.WARN, (f'{rejected} rejected, '
                                 f'{counters["trajectory_messages_lost"]} lost')
    else:
        level, msg = diag.OK, f'{counters["trajectories_compensated"]} compensated'
    return diag.status(name, 'trajectories', level, msg, values, hardware_id)
