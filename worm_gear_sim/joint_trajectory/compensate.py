# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Trajectory compensation, offline: the core of the ``reference_trajectory`` ->
``~/compensated_trajectory`` bridge to a ros2_control ``joint_trajectory_controller``.

:func:`jtc_sample` reads waypoints as the controller's spline interpolation does;
:func:`compensate_trajectory` returns one joint's trajectory densely with the feed-forward
correction added (preview and, with play, the soft crossing); :class:`JointTrajectoryData`
holds a message as arrays and :class:`TrajectoryCompensator` handles several joints and
replacements.  docs/pedestal.md, docs/compensation.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..compensation.play_crossing import seconds_of, soft_feedforward_series
from ..compensation.start_from_rest import (
    START_WINDOW_PERIODS,
    open_mesh_cancel,
    rest_starts,
    start_modes,
    start_ringing_cancel,
)
from ..compensation.streaming import Compensator, centring_preview, with_preview
from ..config.usable import Config
from ..dynamics.model import DriveModel, has_play
from ..dynamics.profiles import SampledProfile
from ..dynamics.simulation import simulate
from ..realtime import feedforward_series
from .rates import consistent_rates
from .timeline import CommandTimeline

__all__ = ['trajectory_feedforward', 'jtc_sample', 'compensate_trajectory', 'trajectory_model',
           'antenna_error',
           'CompensatedTrajectory',
           'JointTrajectoryData',
           'TrajectoryCompensator', 'TrajectoryRejected', 'TRAJECTORY_REJECT_REASONS',
           'MAX_TRAJECTORY_POINTS', 'MAX_TRAJECTORY_DURATION', 'MAX_DENSE_POINTS',
           'MAX_START_AHEAD']

#: Seconds of the replaced trajectory's command the correction's filter runs through at a
#: hand-over (longer than the drive's transients take to decay: 0.2 s at the defaults).
HANDOVER_HISTORY = 1.0
#: The longest trajectory accepted: waypoints, and seconds (a tracking pass is minutes).
MAX_TRAJECTORY_POINTS = 100_000
MAX_TRAJECTORY_DURATION = 3600.0
#: The most points of a compensated (dense) trajectory: 10 min at 1 kHz (a 38 MB message,
#: ~5 s to build, ~0.8 GB peak).  Longer: stream overlapping trajectories (docs/pedestal.md).
MAX_DENSE_POINTS = 600_000
#: The furthest a trajectory's stamp may lie ahead of now [s] (``future_stamp`` beyond).
MAX_START_AHEAD = 3600.0
#: Seconds of what was sent kept for the next start (a stamp further back reads the oldest).
TIMELINE_KEEP = 10.0


class TrajectoryRejected(ValueError):
    """A trajectory refused whole: ``reason`` (one of :data:`TRAJECTORY_REJECT_REASONS`,
    the node's counter ``rejected_trajectory_<reason>``) and a one-line message."""

    def __init__(self, reason: str, text: str) -> None:
        super().__init__(f'trajectory: {text}')
        self.reason = reason


#: Why a trajectory is refused (each a counter of the node).
TRAJECTORY_REJECT_REASONS = ('empty', 'unknown_joint', 'duplicate_joint', 'length_mismatch',
                             'not_finite', 'not_increasing', 'too_long', 'past_stamp',
                             'future_stamp', 'command_limits', 'busy')


def _check(times: np.ndarray, pos: np.ndarray, vel: np.ndarray | None,
           acc: np.ndarray | None) -> None:
    """Waypoints of one or more joints (``pos``: (n,) or (n, joints)); TrajectoryRejected
    naming the first problem."""
    n = times.size
    if n == 0:
        raise TrajectoryRejected('empty', 'no waypoints')
    if n > MAX_TRAJECTORY_POINTS:
        raise TrajectoryRejected('too_long', f'{n} waypoints, more than '
                                 f'{MAX_TRAJECTORY_POINTS}')
    for name, arr in (('positions', pos), ('velocities', vel), ('accelerations', acc)):
        if arr is None:
            continue
        if arr.shape[:1] != times.shape or arr.shape != pos.shape:
            raise TrajectoryRejected('length_mismatch', f'{arr.shape[0]} {name} for {n} '
                                     'waypoints' if arr.shape[:1] != times.shape else
                                     f'{name} of shape {arr.shape}, positions {pos.shape}')
        bad = np.flatnonzero(~np.isfinite(arr.reshape(n, -1)).all(axis=1))
        if bad.size:
            raise TrajectoryRejected('not_finite', f'{name}[{int(bad[0])}] is not finite')
    if acc is not None and vel is None:
        raise TrajectoryRejected('length_mismatch', 'accelerations without velocities')
    if not np.all(np.isfinite(times)) or times[0] < 0:
        raise TrajectoryRejected('not_increasing',
                                 'time_from_start must be finite and >= 0')
    back = np.flatnonzero(np.diff(times) <= 0)
    if back.size:
        raise TrajectoryRejected('not_increasing', f'time_from_start[{int(back[0]) + 1}] '
                                 'does not increase')
    if times[-1] > MAX_TRAJECTORY_DURATION:
        raise TrajectoryRejected('too_long', f'{times[-1]:g} s, longer than '
                                 f'{MAX_TRAJECTORY_DURATION:g} s')


def jtc_sample(times: ArrayLike, positions: ArrayLike, t: ArrayLike,
               velocities: ArrayLike | None = None, accelerations: ArrayLike | None = None,
               start_position: float | None = None) -> tuple[np.ndarray, np.ndarray,
                                                             np.ndarray]:
    """(position, velocity, acceleration) at times ``t`` of the trajectory as the
    controller's ``splines`` interpolation reads it (module docstring).  The start state is
    ``start_position`` at rest at t = 0 (default: the first waypoint's position)."""
    tw = np.asarray(times, float).reshape(-1)
    p = np.asarray(positions, float).reshape(-1)
    v = None if velocities is None else np.asarray(velocities, float).reshape(-1)
    a = None if accelerations is None else np.asarray(accelerations, float).reshape(-1)
    _check(tw, p, v, a)
    p0 = float(p[0]) if start_position is None else float(start_position)
    # the start state at t = 0 as a waypoint (unless the first waypoint is at 0)
    if tw[0] > 0:
        tw = np.concatenate(([0.0], tw))
        p = np.concatenate(([p0], p))
        v = None if v is None else np.concatenate(([0.0], v))
        a = None if a is None else np.concatenate(([0.0], a))
    tq = np.asarray(t, float)
    pos = np.empty_like(tq)
    vel = np.zeros_like(tq)
    accl = np.zeros_like(tq)
    before = tq <= tw[0]
    after = tq >= tw[-1]
    pos[before], pos[after] = p[0], p[-1]
    inside = ~(before | after)
    k = np.clip(np.searchsorted(tw, tq[inside], side='right') - 1, 0, tw.size - 2)
    T = tw[k + 1] - tw[k]
    s = tq[inside] - tw[k]
    pa, pb = p[k], p[k + 1]
    if v is None:                                     # linear
        slope = (pb - pa) / T
        pos[inside] = pa + slope * s
        vel[inside] = slope
        return pos, vel, accl
    va, vb = v[k], v[k + 1]
    if a is None:                                     # cubic Hermite
        c2 = (3 * (pb - pa) - (2 * va + vb) * T) / T ** 2
        c3 = (2 * (pa - pb) + (va + vb) * T) / T ** 3
        pos[inside] = pa + va * s + c2 * s ** 2 + c3 * s ** 3
        vel[inside] = va + 2 * c2 * s + 3 * c3 * s ** 2
        accl[inside] = 2 * c2 + 6 * c3 * s
        return pos, vel, accl
    aa, ab = a[k], a[k + 1]                           # quintic
    c0, c1, c2 = pa, va, 0.5 * aa
    h = pb - (c0 + c1 * T + c2 * T ** 2)
    hv = vb - (c1 + 2 * c2 * T)
    ha = ab - 2 * c2
    c3 = (10 * h - 4 * hv * T + 0.5 * ha * T ** 2) / T ** 3
    c4 = (-15 * h + 7 * hv * T - ha * T ** 2) / T ** 4
    c5 = (6 * h - 3 * hv * T + 0.5 * ha * T ** 2) / T ** 5
    pos[inside] = c0 + s * (c1 + s * (c2 + s * (c3 + s * (c4 + s * c5))))
    vel[inside] = c1 + s * (2 * c2 + s * (3 * c3 + s * (4 * c4 + s * 5 * c5)))
    accl[inside] = 2 * c2 + s * (6 * c3 + s * (12 * c4 + s * 20 * c5))
    return pos, vel, accl


@dataclass
class CompensatedTrajectory:
    """The compensated trajectory at the command rate: ``t`` [s from start], ``position``,
    ``velocity``, ``acceleration`` of theta1 (reference + correction), ``reference`` and
    ``delta`` [rad], and the antenna error the model predicts for it at ``t`` [rad]
    (theta4 - reference l_w / r_g), with ``raw_error`` for the uncompensated reference."""

    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    reference: np.ndarray
    delta: np.ndarray
    predicted_error: np.ndarray | None = None
    raw_error: np.ndarray | None = None


def trajectory_model(model: DriveModel) -> DriveModel:
    """The model a known trajectory is compensated with: ``model``, or, for a drive with
    play whose backlash inverse is on and whose ``compensation.preview_time`` is 0, the
    same with the centring preview (the trajectory's future is known: no latency)."""
    cs = model.config.compensation
    if has_play(model.p) and cs.backlash_inverse and cs.quasi_static and cs.enabled \
            and cs.preview_time == 0.0:
        return DriveModel(with_preview(model.config, centring_preview(model)))
    return model


def compensate_trajectory(model: DriveModel | Config, times: ArrayLike,
                          positions: ArrayLike, velocities: ArrayLike | None = None,
                          accelerations: ArrayLike | None = None,
                          start_position: float | None = None, settle: float = 0.1,
                          predict: bool = True, rate: float | None = None,
                          history: tuple[ArrayLike, ArrayLike] | None = None
                          ) -> CompensatedTrajectory:
    """Compensate a trajectory (module docstring).  The dense output runs from 0 to the
    last waypoint plus ``settle`` seconds (the correction's filter and the ringing after
    the move) at ``rate`` [Hz] (default: the drive's ``node.publish_rate_hz``).
    ``history``: (times [s, < 0, increasing], reference) the drive was commanded before
    this trajectory's start (a replaced trajectory): the correction's filter runs through
    them first, so a hand-over in the middle of a move continues the correction instead of
    restarting it from rest.  ``predict`` also simulates the drive on the raw and the
    compensated command (the antenna errors; from rest at the start)."""
    m = trajectory_model(DriveModel.of(model))
    rate = m.config.node.publish_rate_hz if rate is None else float(rate)
    tw = np.asarray(times, float).reshape(-1)
    if tw.size == 0:
        raise TrajectoryRejected('empty', 'no waypoints')
    if not (math.isfinite(settle) and settle >= 0):
        raise ValueError(f'settle = {settle!r} s: must be >= 0')
    t_end = float(tw[-1]) + settle
    n = int(math.floor(t_end * rate + 1e-9)) + 1
    t = np.arange(n) / rate
    ref, vref, aref = jtc_sample(tw, positions, t, velocities, accelerations, start_position)
    if history is not None and np.size(history[0]):
        th = np.asarray(history[0], float).reshape(-1)
        xh = np.asarray(history[1], float).reshape(-1)
        if th.shape != xh.shape or not th[-1] < 0:
            raise ValueError('history: equal-length times < 0 and references')
        ns = np.round(np.concatenate((th, t)) * 1e9).astype(np.int64)
        delta = trajectory_feedforward(m, ns, np.concatenate((xh, ref)))[th.size:]
    else:
        delta = trajectory_feedforward(m, t, ref)
    dt = 1.0 / rate
    ddelta = np.gradient(delta, dt) if n > 2 else np.zeros(n)
    dddelta = np.gradient(ddelta, dt) if n > 2 else np.zeros(n)
    pos = ref + delta
    vel, acc = consistent_rates(pos, vref + ddelta, aref + dddelta, dt)
    out = CompensatedTrajectory(t, pos, vel, acc, ref, delta)
    if predict and n > 1:
        out.predicted_error = antenna_error(m, t, ref + delta, ref)
        out.raw_error = antenna_error(m, t, ref, ref)
    return out


def antenna_error(model: DriveModel | Config, t: np.ndarray, command: np.ndarray,
                  reference: np.ndarray) -> np.ndarray:
    """The antenna error theta4 - reference l_w / r_g [rad] at the uniform times ``t``
    when the drive, at rest at ``command[0]``, is driven by ``command`` (straight lines
    between the samples, as the node applies commands)."""
    m = DriveModel.of(model)
    every = max(1, int(round((t[1] - t[0]) / m.config.integrator.time_step)))
    tr = simulate(m, SampledProfile(t, command), t_end=float(t[-1]), record_every=every,
                  theta1_initial=float(command[0]))
    return np.interp(t, tr.t, tr.theta[:, 2]) - reference * m.output_per_input


@dataclass(frozen=True)
class JointTrajectoryData:
    """A ``trajectory_msgs/JointTrajectory`` as arrays: ``time_from_start`` (n,) [s],
    ``positions`` (n, joints) [rad], ``velocities`` and ``accelerations`` (n, joints) or
    None, ``stamp_ns`` the header stamp (0: start on reception, the controller's rule)."""

    joint_names: tuple[str, ...]
    time_from_start: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray | None = None
    accelerations: np.ndarray | None = None
    stamp_ns: int = 0

    @classmethod
    def from_points(cls, joint_names: Sequence[str], times: Sequence[float],
                    positions: Sequence[Sequence[float]],
                    velocities: Sequence[Sequence[float]] | None = None,
                    accelerations: Sequence[Sequence[float]] | None = None,
                    stamp_ns: int = 0) -> JointTrajectoryData:
        """From per-point lists as a message carries them.  A point's velocities
        (accelerations) are empty or one per joint, and given on every point or on none:
        else TrajectoryRejected ``length_mismatch`` (the controller would reject it too)."""
        names = tuple(joint_names)
        n, nj = len(times), len(names)
        if nj == 0:
            raise TrajectoryRejected('empty', 'no joint names')

        def table(rows: Sequence[Sequence[float]] | None, what: str,
                  optional: bool) -> np.ndarray | None:
            if rows is None:
                return None
            sizes = {len(r) for r in rows}
            if optional and sizes == {0}:
                return None
            if sizes != {nj}:
                bad = next(i for i, r in enumerate(rows) if len(r) != nj)
                raise TrajectoryRejected('length_mismatch', f'point {bad} has '
                                         f'{len(rows[bad])} {what} for {nj} joints')
            return np.array(rows, float).reshape(n, nj)

        if len(positions) != n:
            raise TrajectoryRejected('length_mismatch', f'{len(positions)} points of '
                                     f'positions for {n} times')
        if n > MAX_TRAJECTORY_POINTS:
            raise TrajectoryRejected('too_long', f'{n} waypoints, more than '
                                     f'{MAX_TRAJECTORY_POINTS}')
        pos = table(positions, 'positions', False) if n else None
        return cls(names, np.asarray(times, float).reshape(n),
                   pos if pos is not None else np.empty((0, nj)),
                   table(velocities, 'velocities', True) if n else None,
                   table(accelerations, 'accelerations', True) if n else None,
                   int(stamp_ns))


def _check_jumps(model: DriveModel, ct: CompensatedTrajectory, start: float | None) -> None:
    """ValueError when the compensated command steps more than ``node.max_command_jump``
    between two dense points, or its reference starts further than that from ``start``
    (the position commanded before): the limit the drive node puts on what it receives
    holds for what it sends."""
    limit = model.config.node.max_command_jump
    steps = np.abs(np.diff(ct.position))
    if steps.size and steps.max() > limit:
        i = int(np.argmax(steps))
        raise ValueError(f'the compensated command would step {float(steps[i]):.6g} rad '
                         f'at {float(ct.t[i + 1]):.6g} s (reference step '
                         f'{float(abs(ct.reference[i + 1] - ct.reference[i])):.6g} rad), '
                         f'more than node.max_command_jump = {limit:g} rad')
    if start is not None and abs(ct.reference[0] - start) > limit:
        raise ValueError(f'the reference starts {float(abs(ct.reference[0] - start)):.6g} '
                         f'rad from the position commanded before ({start:.6g} rad), '
                         f'more than node.max_command_jump = {limit:g} rad')


def _column(a: np.ndarray | None, k: int) -> np.ndarray | None:
    return None if a is None else a[:, k]


@dataclass
class TrajectoryResult:
    """What :meth:`TrajectoryCompensator.compensate` returns: the dense compensated
    ``trajectory`` (same joints in the same order, same stamp), the start instant it was
    timed from (``start_ns``) and each joint's :class:`CompensatedTrajectory`."""

    trajectory: JointTrajectoryData
    start_ns: int
    axes: dict[str, CompensatedTrajectory]


class TrajectoryCompensator:
    """Compensated trajectories for one drive or several (a pedestal): ``drives`` maps each
    drive's worm input joint name to its model (or Config).  Built once; the node and the
    offline tools call the same :meth:`compensate`.

    A trajectory may name any of the drives' joints, each once (a subset is allowed: the
    others keep what they do).  It is split by joint, each joint compensated with its own
    drive (:func:`compensate_trajectory` on a common grid at the highest
    ``node.publish_rate_hz`` of the drives) and merged back in the trajectory's order.

    Replacement, as the controller does it: a trajectory starts at its header stamp (0:
    at ``now_ns``, its reception) and takes over there (a splice,
    :class:`~worm_gear_sim.joint_trajectory.timeline.CommandTimeline`: what was sent before runs
    until then, whatever was sent to start at or after it is dropped); each joint starts
    from the position commanded for it at that instant by the trajectories sent before,
    or from the trajectory's first waypoint when nothing was sent.  A stamp more than
    :data:`MAX_START_AHEAD` ahead of ``now_ns`` is refused (``future_stamp``).  The
    correction continues through a hand-over: its filter first runs
    through the last ``history`` seconds of the reference sent before (at rest when
    nothing was sent), so trajectories streamed back to back, each replacing the last in
    the middle of a move, are compensated as one long trajectory would be (the difference
    is what is left after ``history`` seconds of the drive's transients; measured in
    test/joint_trajectory/test_compensate.py).
    """

    def __init__(self, drives: Mapping[str, DriveModel | Config], settle: float = 0.1,
                 history: float = HANDOVER_HISTORY) -> None:
        if not drives:
            raise ValueError('TrajectoryCompensator: no drives')
        self.drives = {str(j): DriveModel.of(m) for j, m in drives.items()}
        self.rate = max(m.config.node.publish_rate_hz for m in self.drives.values())
        self.settle = float(settle)
        self.history = float(history)
        # per joint: the reference commanded over time by the trajectories sent
        self._sent: dict[str, CommandTimeline] = {}

    @property
    def joints(self) -> tuple[str, ...]:
        return tuple(self.drives)

    def check(self, traj: JointTrajectoryData, now_ns: int | None = None) -> None:
        """TrajectoryRejected naming the first problem (:data:`TRAJECTORY_REJECT_REASONS`):
        no joints or points, unknown or repeated joints, ragged or non-finite values,
        time_from_start not increasing, too long, or wholly in the past of ``now_ns``."""
        names = traj.joint_names
        if not names:
            raise TrajectoryRejected('empty', 'no joint names')
        seen: set[str] = set()
        for name in names:
            if name in seen:
                raise TrajectoryRejected('duplicate_joint', f'joint {name!r} named twice')
            seen.add(name)
            if name not in self.drives:
                raise TrajectoryRejected('unknown_joint', f'unknown joint {name!r} (this '
                                         f'node drives {", ".join(self.drives)})')
        _check(traj.time_from_start, traj.positions, traj.velocities, traj.accelerations)
        dense = self.dense_points(traj)
        if dense > MAX_DENSE_POINTS:
            raise TrajectoryRejected('too_long', f'{dense} compensated points at '
                                     f'{self.rate:g} Hz, more than {MAX_DENSE_POINTS}: send '
                                     'it as overlapping shorter trajectories')
        if traj.stamp_ns < 0:
            raise TrajectoryRejected('past_stamp', f'negative stamp {traj.stamp_ns} ns')
        if now_ns is not None and traj.stamp_ns and \
                traj.stamp_ns + int(traj.time_from_start[-1] * 1e9) < now_ns:
            late = (now_ns - traj.stamp_ns) / 1e9 - traj.time_from_start[-1]
            raise TrajectoryRejected('past_stamp', f'ends {late:.3g} s before now')
        if now_ns and traj.stamp_ns > now_ns + MAX_START_AHEAD * 1e9:
            ahead = (traj.stamp_ns - now_ns) / 1e9
            raise TrajectoryRejected('future_stamp', f'starts {ahead:.6g} s after now, '
                                     f'more than {MAX_START_AHEAD:g} s ahead')

    def with_drives(self, drives: Mapping[str, DriveModel | Config]) -> TrajectoryCompensator:
        """The same with new models (a parameter set), keeping what was sent."""
        new = TrajectoryCompensator(drives, self.settle, self.history)
        new._sent = {j: v for j, v in self._sent.items() if j in new.drives}
        return new

    def dense_points(self, traj: JointTrajectoryData) -> int:
        """Points of the compensated trajectory (per joint) of a checked ``traj``."""
        return int(math.floor((traj.time_from_start[-1] + self.settle) * self.rate)) + 1

    def start_position(self, joint: str, start_ns: int) -> float | None:
        """The position commanded for ``joint`` at ``start_ns`` by the trajectories sent
        that start before it (None: nothing sent)."""
        sent = self._sent.get(joint)
        return None if sent is None else sent.position(start_ns)

    def commanded_before(self, joint: str, start_ns: int
                         ) -> tuple[np.ndarray, np.ndarray] | None:
        """(times [s, < 0], reference) sent for ``joint`` in the ``history`` seconds before
        ``start_ns``, on the command grid (None: nothing sent, or at rest then)."""
        sent = self._sent.get(joint)
        if sent is None or self.history <= 0:
            return None
        k = np.arange(-int(round(self.history * self.rate)), 0)
        th = k / self.rate
        at = start_ns + np.round(th * 1e9).astype(np.int64)
        keep = at >= (sent.first_ns or 0)               # not before the first start
        th, at = th[keep], at[keep]
        if th.size == 0:
            return None
        xh = sent.at(at)
        if np.ptp(xh) == 0.0:
            return None                                 # held: at rest, nothing to carry
        return th, xh

    def compensate(self, traj: JointTrajectoryData, now_ns: int = 0, predict: bool = False,
                   run: Callable[..., CompensatedTrajectory] | None = None
                   ) -> TrajectoryResult:
        """Check, split, compensate and merge ``traj`` (class docstring); remembers what it
        sent for the next trajectory's start.  ``predict``: also the antenna errors.
        ``run``: calls :func:`compensate_trajectory` with the same arguments (e.g. in a
        worker process, with the model's Config; default: here)."""
        self.check(traj, now_ns)
        start_ns = traj.stamp_ns or now_ns
        axes: dict[str, CompensatedTrajectory] = {}
        for k, joint in enumerate(traj.joint_names):
            try:
                start = self.start_position(joint, start_ns)
                axes[joint] = ct = (run or compensate_trajectory)(
                    self.drives[joint], traj.time_from_start, traj.positions[:, k],
                    _column(traj.velocities, k), _column(traj.accelerations, k),
                    start_position=start,
                    settle=self.settle, predict=predict, rate=self.rate,
                    history=self.commanded_before(joint, start_ns))
                _check_jumps(self.drives[joint], ct, start)
            except TrajectoryRejected:
                raise
            except ValueError as exc:      # node.max_command_abs / max_command_jump
                raise TrajectoryRejected('command_limits', f'joint {joint!r}: {exc}') \
                    from None
        for joint, ct in axes.items():
            self._sent.setdefault(joint, CommandTimeline(TIMELINE_KEEP + self.history)
                                  ).splice(start_ns, ct.t, ct.reference)
        first = axes[traj.joint_names[0]]
        dense = JointTrajectoryData(traj.joint_names, first.t,
                           np.column_stack([axes[j].position for j in traj.joint_names]),
                           np.column_stack([axes[j].velocity for j in traj.joint_names]),
                           np.column_stack([axes[j].acceleration for j in traj.joint_names]),
                           traj.stamp_ns)
        return TrajectoryResult(dense, start_ns, axes)


def trajectory_feedforward(model: DriveModel | Config, t: ArrayLike, theta1_ref: ArrayLike
                           ) -> np.ndarray:
    """The correction of a known trajectory (``compensate_trajectory``, the trajectory
    bridge): with play and the backlash inverse, :func:`soft_feedforward_series` with the
    free vibration of every start from rest cancelled (:func:`rest_starts`,
    :func:`start_ringing_cancel`, :func:`open_mesh_cancel`); else
    :func:`~worm_gear_sim.realtime.feedforward_series` (the same corrections without play)."""
    m = DriveModel.of(model)
    cs = m.config.compensation
    if has_play(m.p) and cs.backlash_inverse and cs.quasi_static and cs.enabled:
        delta, plans = soft_feedforward_series(m, t, theta1_ref)
        delta = np.array(delta, float)
        # the modes left at rest after each start (docs/compensation.md): unless the play
        # is crossed during the rest before it or the start transient (not linear then)
        fs_t = seconds_of(t)
        x = np.asarray(theta1_ref, float).reshape(-1)
        window = START_WINDOW_PERIODS / Compensator(m).mode_frequency_hz
        for r, k in rest_starts(x, x + delta):
            if x.size - k < 3 or any(p.start < fs_t[k] + window and p.end >= fs_t[r]
                                     for p in plans):
                continue
            tk = fs_t[k:]
            slow, fast, window_k = start_modes(m, tk, x[k:] + delta[k:])
            delta[k:] += start_ringing_cancel(tk, x[k:] + delta[k:], slow, fast, window_k)
            delta[k:] += open_mesh_cancel(m, tk, x[k:] + delta[k:], slow, len(fast),
                                          window_k)
        return delta
    return feedforward_series(m, t, theta1_ref)
