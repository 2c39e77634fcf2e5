# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A tracking pass over a two-axis pedestal (``worm-gear-sim pass``, ``scripts/run_pass.sh``).

:func:`satellite_pass` (a circular orbit's azimuth and elevation), :func:`pass_window`,
and :func:`stream_pass` (the pass sent as overlapping trajectories through the node's
``TrajectoryCompensator``, the drives simulated on the stitched commands).
docs/pedestal.md.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..config.usable import Config
from ..dynamics.model import DriveModel
from ..joint_trajectory.compensate import (
    JointTrajectoryData,
    TrajectoryCompensator,
    antenna_error,
    jtc_sample,
)

__all__ = ['satellite_pass', 'pass_window', 'pass_waypoints', 'stream_pass', 'PassResult',
           'EARTH_RADIUS', 'EARTH_MU']

EARTH_RADIUS = 6_371_000.0      # m
EARTH_MU = 3.986004418e14       # m^3 / s^2
LEAD_IN = 2.0                   # s: from rest to the pass's rate before its first point


def satellite_pass(t: np.ndarray, altitude: float = 500e3, max_elevation: float =
                   math.radians(85.0)) -> tuple[np.ndarray, np.ndarray]:
    """(azimuth, elevation) [rad] at times ``t`` [s from culmination] (module docstring)."""
    r_orbit = EARTH_RADIUS + altitude
    # central angle between the station and the orbit's closest point for max_elevation
    beta0 = math.pi / 2 - max_elevation - math.asin(EARTH_RADIUS / r_orbit *
                                                     math.cos(max_elevation))
    phi = np.sqrt(EARTH_MU / r_orbit ** 3) * np.asarray(t, float)
    # east-north-up at the station (up = z); the orbit passes east of the zenith, northwards
    sat = r_orbit * np.stack((np.cos(phi) * math.sin(beta0), np.sin(phi),
                              np.cos(phi) * math.cos(beta0)), axis=-1)
    d = sat - np.array([0.0, 0.0, EARTH_RADIUS])
    rng = np.linalg.norm(d, axis=-1)
    el = np.arcsin(d[..., 2] / rng)
    az = np.unwrap(np.arctan2(d[..., 0], d[..., 1]))
    return az, el


def pass_window(duration: float, altitude: float = 500e3,
                max_elevation: float = math.radians(85.0), step: float = 0.001
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t from the window's start, azimuth, elevation) of the ``duration`` seconds centred
    on culmination, every ``step`` s."""
    t = np.arange(0.0, duration + step / 2, step)
    az, el = satellite_pass(t - duration / 2, altitude, max_elevation)
    return t, az, el


def pass_waypoints(t: np.ndarray, angle: np.ndarray, ratio: float, period: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Waypoints of the worm input angle (antenna angle / ``ratio``, ratio = l_w / r_g)
    every ``period`` s: (times, positions, velocities), velocities by central
    differences of the dense path."""
    k = np.unique(np.round(np.arange(0.0, t[-1] + 1e-9, period) / (t[1] - t[0])).astype(int))
    k = k[k < t.size]
    worm = angle / ratio
    vel = np.gradient(worm, t)
    return t[k], worm[k], vel[k]


@dataclass
class PassResult:
    """Per axis (worm input joint): the dense time ``t`` [s], the antenna's reference
    ``reference`` [rad], and the pointing errors [rad] ``raw_error`` / ``compensated_error``;
    ``trajectories``: how many were sent; ``table()``: the per-axis summary."""

    t: np.ndarray
    reference: dict[str, np.ndarray]
    raw_error: dict[str, np.ndarray]
    compensated_error: dict[str, np.ndarray]
    trajectories: int
    settle_from: float

    def table(self) -> list[dict[str, float | str]]:
        rows: list[dict[str, float | str]] = []
        keep = self.t >= self.settle_from
        for j in self.raw_error:
            raw, comp = self.raw_error[j][keep], self.compensated_error[j][keep]
            rms_raw, rms_comp = float(np.sqrt(np.mean(raw ** 2))), \
                float(np.sqrt(np.mean(comp ** 2)))
            rows.append({'joint': j, 'rms_raw_urad': rms_raw * 1e6,
                         'rms_compensated_urad': rms_comp * 1e6,
                         'max_raw_urad': float(np.max(np.abs(raw))) * 1e6,
                         'max_compensated_urad': float(np.max(np.abs(comp))) * 1e6,
                         'rms_ratio': rms_raw / rms_comp if rms_comp > 0 else math.inf})
        return rows


def stream_pass(drives: Mapping[str, DriveModel | Config], angles: Mapping[str, np.ndarray],
                t: np.ndarray, waypoint_period: float = 1.0, chunk: float = 20.0,
                every: float = 10.0, compensator: TrajectoryCompensator | None = None
                ) -> tuple[list[JointTrajectoryData], list[JointTrajectoryData]]:
    """The pass as overlapping trajectories (module docstring) and their compensated twins
    (through ``compensator``, default: a new one over ``drives``).  ``angles``: antenna
    angle [rad] per worm input joint on the dense times ``t`` [s].  The first trajectory
    starts with a lead-in of LEAD_IN s from rest; each stamp is its trajectory's start
    [ns], the first at 1 s (a stamp of 0 would mean "on reception")."""
    comp = compensator or TrajectoryCompensator(drives)
    joints = tuple(angles)
    models = {j: DriveModel.of(comp.drives[j]) for j in joints}
    wps = {j: pass_waypoints(t, angles[j], models[j].output_per_input, waypoint_period)
           for j in joints}
    tw = wps[joints[0]][0]
    base_ns = 1_000_000_000
    sent: list[JointTrajectoryData] = []
    out: list[JointTrajectoryData] = []
    start = 0.0
    while start < tw[-1] - 1e-9:
        sel = (tw >= start - 1e-9) & (tw <= start + chunk + 1e-9)
        times = tw[sel] - start
        pos = np.column_stack([wps[j][1][sel] for j in joints])
        vel = np.column_stack([wps[j][2][sel] for j in joints])
        offset = 0.0
        if not sent:        # lead-in: from rest, a cubic to the pass's first state
            offset = LEAD_IN
            times = np.concatenate(([0.0], times + offset))
            pos = np.vstack((pos[0] - vel[0] * offset / 2, pos))
            vel = np.vstack((np.zeros(len(joints)), vel))
        if start + chunk >= tw[-1] - 1e-9:    # the last: a lead-out to rest
            times = np.concatenate((times, [times[-1] + LEAD_IN]))
            pos = np.vstack((pos, pos[-1] + vel[-1] * LEAD_IN / 2))
            vel = np.vstack((vel, np.zeros(len(joints))))
        stamp = base_ns + int(round((start + (LEAD_IN if sent else 0.0)) * 1e9))
        traj = JointTrajectoryData(joints, times, pos, vel, None, stamp)
        sent.append(traj)
        out.append(comp.compensate(traj).trajectory)
        start += every
    return sent, out


def stitch(trajs: Sequence[JointTrajectoryData], joint: int, t_ns: np.ndarray,
           velocities: bool = True) -> np.ndarray:
    """The command a controller executes from back-to-back trajectories (each from its
    stamp until the next one's), read with its spline rule, at times ``t_ns``."""
    out = np.empty(t_ns.size)
    starts = [tr.stamp_ns for tr in trajs] + [np.iinfo(np.int64).max]
    for k, tr in enumerate(trajs):
        sel = (t_ns >= starts[k]) & (t_ns < starts[k + 1])
        if k == 0:
            sel |= t_ns < starts[0]
        if not sel.any():
            continue
        rel = (t_ns[sel] - tr.stamp_ns) / 1e9
        v = tr.velocities[:, joint] if (velocities and tr.velocities is not None) else None
        out[sel] = jtc_sample(tr.time_from_start, tr.positions[:, joint], rel, v)[0]
    return out


def evaluate_pass(drives: Mapping[str, DriveModel | Config], sent: Sequence[JointTrajectoryData],
                  compensated: Sequence[JointTrajectoryData], settle_from: float = LEAD_IN + 1.0
                  ) -> PassResult:
    """Simulate each drive on the stitched raw and compensated commands (linear reading of
    the dense compensated points, as the node applies commands; the raw trajectories with
    the controller's cubic rule) and return the pointing errors."""
    joints = sent[0].joint_names
    t0 = sent[0].stamp_ns
    last = compensated[-1]
    t_end = (last.stamp_ns - t0) / 1e9 + float(last.time_from_start[-1])
    rate = max(DriveModel.of(drives[j]).config.node.publish_rate_hz for j in joints)
    t = np.arange(0.0, t_end + 0.5 / rate, 1.0 / rate)
    t_ns = t0 + np.round(t * 1e9).astype(np.int64)
    ref, raw_e, comp_e = {}, {}, {}
    for k, j in enumerate(joints):
        m = DriveModel.of(drives[j])
        raw = stitch(sent, k, t_ns)
        cmd = stitch(compensated, k, t_ns, velocities=False)
        ref[j] = raw * m.output_per_input
        raw_e[j] = antenna_error(m, t, raw, raw)
        comp_e[j] = antenna_error(m, t, cmd, raw)
    return PassResult(t, ref, raw_e, comp_e, len(sent), settle_from)
