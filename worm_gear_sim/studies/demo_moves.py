# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The demo servo's reference patterns and its move-by-move account of a live error trace.

:func:`command_pattern` is theta1(t) of a pattern (``paper``: the paper's 18-step move
forward then back every ``move_period``; ``slew``: a radar slew with a sharp reversal every
``slew_period``), built from the core's profiles; :func:`pattern_segments` cuts it into
moves; :class:`MoveTracker` closes each move as its samples arrive and measures it with
:func:`~worm_gear_sim.studies.compensation_eval.move_metrics` (the rules of the offline
evaluation); :func:`offline_moves` runs the same reference through the core
(:func:`~worm_gear_sim.studies.compensation_eval.run_scenario`) into the same moves.  The
ROS side (streaming, subscriptions) is :mod:`worm_gear_sim.ros.demo_commander`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..config.usable import Config
from ..dynamics.modal import modes
from ..dynamics.model import DriveModel
from ..dynamics.profiles import TrapezoidalProfile
from .compensation_eval import SETTLE_HOLD, Scenario, move_metrics, run_scenario

__all__ = ['PAPER_LEAD', 'command_pattern', 'Segments', 'pattern_segments', 'MoveSummary',
           'MoveTracker', 'offline_moves', 'first_mode_hz', 'DemoPlan', 'demo_plan']

PAPER_LEAD = 0.05               # s of rest before the first paper move


def command_pattern(name: str, cfg: Config, move_period: float = 0.5,
                    slew_rate: float = 2.0, slew_period: float = 2.0
                    ) -> Callable[[Any], np.ndarray]:
    """theta1(t) [rad] of the demo stream, vectorised over t [s]."""
    if name == 'paper':
        inp = cfg.input
        move = TrapezoidalProfile(inp.target_angle, inp.move_time, inp.accel_time, 0.0)

        def theta1(t):
            t = np.asarray(t, float) - PAPER_LEAD
            k = np.floor(np.maximum(t, 0.0) / move_period)
            tau = np.where(t < 0.0, -1.0, t - k * move_period)
            x = move.theta1(tau)
            return np.where(k % 2 == 0, x, inp.target_angle - x)   # forward, back, ...
        return theta1
    if name == 'slew':
        amp = slew_rate * slew_period      # one leg: slew_period at slew_rate

        def theta1(t):
            x = (np.asarray(t, float) / (2.0 * slew_period)) % 1.0
            return np.where(x < 0.5, 2.0 * amp * x, 2.0 * amp * (1.0 - x))
        return theta1
    raise ValueError(f'unknown pattern {name!r} (paper | slew)')


@dataclass(frozen=True)
class Segments:
    """Moves of a pattern: move k spans [first + k period, first + (k+1) period); its
    reference moves until ``motion`` after its start, then rests (paper) or keeps a
    constant rate (slew, ``constant_rate``).  ``rate_spans``: the intervals, from the move's
    start, where the reference moves at a constant rate (the tracking RMS is taken there,
    as the offline evaluation does)."""

    first: float
    period: float
    motion: float
    constant_rate: bool
    labels: tuple[str, str]
    rate_spans: tuple[tuple[float, float], ...] = ()


def pattern_segments(name: str, cfg: Config, move_period: float = 0.5,
                     slew_period: float = 2.0) -> Segments:
    if name == 'paper':
        inp = cfg.input
        cruise = TrapezoidalProfile(inp.target_angle, inp.move_time, inp.accel_time).cruise
        return Segments(PAPER_LEAD, move_period, inp.move_time, False, ('fwd', 'back'),
                        (cruise,))
    if name == 'slew':
        return Segments(0.0, slew_period, 0.0, True, ('up', 'down'), ((0.0, slew_period),))
    raise ValueError(f'unknown pattern {name!r} (paper | slew)')


@dataclass(frozen=True)
class MoveSummary:
    index: int
    label: str
    start: float                  # s of pattern time
    peak: float                   # max |e| over the move [rad]
    ringing: float                # max |e - static| once the applied command rests [rad]
    settling: float               # s from the end of the motion into +-10 urad (inf: not
    #                               within the move, see settling_bound)
    tracking_rms: float           # rad: RMS of e where the reference moves at a constant
    #                               rate (Segments.rate_spans)
    samples: int
    watched: float = math.nan     # s from the end of the motion to the move's last sample

    @property
    def settling_bound(self) -> float:
        """The settling time, or, when the move did not settle (``settling`` inf), the
        lower bound it is known to exceed: the error still left the band within the last
        SETTLE_HOLD of the ``watched`` span."""
        return self.settling if math.isfinite(self.settling) else self.watched - SETTLE_HOLD


class MoveTracker:
    """Collects (t, e) samples in time order and closes each move of the pattern when a
    sample past its end arrives; a move with a gap longer than ``max_gap`` (or not covered
    to within ``max_gap`` of its ends) is dropped and counted in ``incomplete``.

    The metrics are :func:`~worm_gear_sim.studies.compensation_eval.move_metrics`: ``ringing``
    is its ``residual_peak``, measured once the applied command rests.  Without command samples
    (``add_command``) the command is the reference, which rests when its motion ends; with
    a feed-forward applied, the command keeps moving for the correction's span."""

    def __init__(self, seg: Segments, mode_hz: float, max_gap: float = 0.02):
        self.seg, self.mode_hz, self.max_gap = seg, mode_hz, max_gap
        self.moves: list[MoveSummary] = []
        self.incomplete = 0
        self._k = 0
        self._t: list[float] = []
        self._e: list[float] = []
        self._moving: dict[int, float] = {}     # move -> last instant its command moved
        self._last_cmd: tuple[float, float] | None = None
        self.use_commands = True                # False: the command is the reference

    @property
    def next_index(self) -> int:
        """The move whose samples are being collected: every move before it is closed (in
        ``moves``, or counted ``incomplete``)."""
        return self._k

    def _bounds(self, k: int) -> tuple[float, float]:
        a = self.seg.first + k * self.seg.period
        return a, a + self.seg.period

    def add_command(self, t: float, command: float) -> None:
        """A sample of the command applied to the drive (theta1_ref + delta)."""
        last = self._last_cmd
        self._last_cmd = (t, command)
        if last is None or t <= last[0] or abs(command - last[1]) <= 1e-12:
            return
        k = int((t - self.seg.first) // self.seg.period)
        if k >= 0:
            self._moving[k] = t

    def add(self, t: float, e: float) -> MoveSummary | None:
        """Add a sample; returns the move it completed, if any."""
        a, b = self._bounds(self._k)
        if t < a:
            return None
        done = None
        if t >= b:
            done = self._close()
            k = int((t - self.seg.first) // self.seg.period)
            self.incomplete += k - self._k - 1      # moves without a single sample
            self._k = k
        self._t.append(t)
        self._e.append(e)
        return done

    def _close(self) -> MoveSummary | None:
        a, b = self._bounds(self._k)
        t, e = np.asarray(self._t), np.asarray(self._e)
        self._t, self._e = [], []
        moved = self._moving.pop(self._k, None)
        for k in [k for k in self._moving if k < self._k]:
            del self._moving[k]
        if t.size < 3 or t[0] - a > self.max_gap or b - t[-1] > self.max_gap \
                or np.max(np.diff(t)) > self.max_gap:
            self.incomplete += 1
            return None
        tr = t - a
        seg = self.seg
        sc = Scenario(name='demo move', times=tr, theta1_ref=np.zeros_like(tr),
                      move_end=seg.motion, constant_rate=seg.rate_spans)
        command_end = seg.motion
        if moved is not None and self.use_commands and not seg.constant_rate:
            command_end = min(max(moved - a, seg.motion), float(tr[-1]))
        m = move_metrics(tr, e, sc, self.mode_hz, command_end)
        summary = MoveSummary(self._k, seg.labels[self._k % 2], a, float(np.max(np.abs(e))),
                              m['residual_peak'], m['settling_time'], m['tracking_rms'],
                              int(t.size), float(tr[-1]) - seg.motion)
        self.moves.append(summary)
        return summary


def offline_moves(model: DriveModel | Config, theta1: Callable[[Any], np.ndarray],
                  seg: Segments, t_end: float, rate: float,
                  compensated: bool) -> list[MoveSummary]:
    """The same reference, sampled at ``rate`` up to ``t_end``, through the core
    (``run_scenario``: nonlinear plant, feed-forward of the same model when
    ``compensated``), cut into the same moves as the live trace.  ``model``: a
    :class:`DriveModel` or a Config."""
    model = DriveModel.of(model)
    times = np.arange(0.0, t_end + 0.5 / rate, 1.0 / rate)
    x = np.asarray(theta1(times), float)
    sc = Scenario(name='demo', times=times, theta1_ref=x, move_end=float(times[0]),
                  constant_rate=())          # run_scenario's own metrics are not used
    record = max(1, int(round(1.0 / (rate * model.config.integrator.time_step))))
    run = run_scenario(model, sc, model if compensated else None, record_every=record)
    tracker = MoveTracker(seg, first_mode_hz(model))
    if compensated:
        for ti, ci in zip(times, x + run.delta):
            tracker.add_command(float(ti), float(ci))
    for ti, ei in zip(run.trajectory.t, run.error):
        tracker.add(float(ti), float(ei))
    return tracker.moves


def first_mode_hz(model: DriveModel | Config) -> float:
    """The first natural frequency [Hz] of the drive (the metrics' ringing period)."""
    return float(modes(model).frequencies_hz[0])


@dataclass(frozen=True)
class DemoPlan:
    """What the demo servo streams, built once from a Config (:func:`demo_plan`): one
    :class:`DriveModel` (the output ratio, the ringing period, the offline moves), the
    reference theta1(t), its moves and the drive's first natural frequency [Hz]."""

    model: DriveModel
    theta1: Callable[[Any], np.ndarray]
    segments: Segments
    mode_hz: float


def demo_plan(pattern: str, cfg: Config, move_period: float = 0.5, slew_rate: float = 2.0,
              slew_period: float = 2.0) -> DemoPlan:
    """The demo servo's pattern and the one model of ``cfg`` it is measured with."""
    model = DriveModel(cfg)
    return DemoPlan(model, command_pattern(pattern, cfg, move_period, slew_rate, slew_period),
                    pattern_segments(pattern, cfg, move_period, slew_period),
                    first_mode_hz(model))
