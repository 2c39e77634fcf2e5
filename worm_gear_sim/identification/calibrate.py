# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Calibration in one call: design an excitation within the user's limits, run it on the
drive, fit, validate on held-out moves, and say whether the result is accepted.

The excitation (:func:`design_excitation`), all within ``max_angle`` of worm angle around the
start, ``max_rate`` and ``max_accel``:

* training moves, each a record starting at rest and ending with ``RING_TIME`` of rest:
  ``step_out`` (trapezoid of the full amplitude at the rate and acceleration limits: the
  stop rings the antenna mode, whose frequency and decay set the stiffness / inertia /
  damping parameters), ``step_back`` (the same move reversed: the mesh changes flank, which
  shows the play and the friction's direction) and ``small_step`` (a quarter of the
  amplitude: friction does not scale with the amplitude, the elastic terms do, so two
  amplitudes separate them);
* a held-out move of another shape, ``validate_scurve`` (a jerk-limited S-curve of half the
  amplitude back towards the start), never seen by the fit: the prediction error there is
  the acceptance test.

Steps and reversals rather than a chirp: the antenna mode is lightly damped, so a stop
excites it fully in one move and the ring-down is a clean free response; a chirp through
95 Hz needs seconds of motion (beyond an antenna's allowed travel at these rates) and mixes
the friction's stick-slip into the forced response.

:func:`calibrate` runs the moves on a drive given as a callable ``run(profile, t_end) ->
Record`` (``plant_runner`` wraps a simulated drive: a params file like the one ``-o``
writes), fits with :func:`~.fit.identify`, validates with
:func:`~.report.prediction_errors`, and returns a :class:`CalibrationResult`.  Nothing is
applied anywhere: the caller writes the YAML or sets the node's parameters only when
``accepted``.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..dynamics.profiles import Profile, SCurveProfile, TrapezoidalProfile
from ..params import Config
from ..records import Record
from .data import IdentificationError, record_from_model
from .fit import FitOptions, identify
from .report import FitResult, prediction_errors

__all__ = ['Limits', 'Move', 'design_excitation', 'plant_runner', 'calibrate',
           'CalibrationResult', 'excitation_series', 'RING_TIME', 'ACCEPT_REL']

#: Rest after each move [s]: the antenna mode (~95 Hz) rings ~14 periods.
RING_TIME = 0.15
#: Rest before each move [s].
LEAD_TIME = 0.005
#: Accepted when every held-out move's theta4 RMS error is within this share of its
#: oscillation amplitude (and the fit itself is trustworthy).
ACCEPT_REL = 0.05


@dataclass(frozen=True)
class Limits:
    """The excitation's limits, in worm angle (theta1): travel ``max_angle`` [rad] each way
    from ``start`` [rad], ``max_rate`` [rad/s], ``max_accel`` [rad/s^2], and ``duration``
    [s], the longest total time of all moves."""

    max_angle: float
    max_rate: float
    max_accel: float
    duration: float = 2.0
    start: float = 0.0

    def check(self) -> None:
        for name in ('max_angle', 'max_rate', 'max_accel', 'duration'):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise IdentificationError(f'calibration limit {name} = {v!r}: must be a '
                                          'positive number')
        if not math.isfinite(self.start):
            raise IdentificationError(f'calibration start {self.start!r} rad: not finite')


@dataclass(frozen=True)
class Move:
    """One move of the excitation: a record of its own, starting at rest."""

    name: str
    role: str                 # 'train' | 'validate'
    profile: Profile
    t_end: float

    @property
    def amplitude(self) -> float:
        return float(self.profile.theta1(np.array([self.t_end]))[0]
                     - self.profile.theta1(np.array([0.0]))[0])


class _Offset(Profile):
    """A profile shifted by a constant angle (moves start at the current position)."""

    def __init__(self, base: Profile, offset: float) -> None:
        self.base, self.offset = base, float(offset)
        self.name = base.name

    def theta1(self, t):
        return self.base.theta1(t) + self.offset

    def theta1_dot(self, t):
        return self.base.theta1_dot(t)

    def describe(self) -> str:
        return f'{self.base.describe()} from {self.offset:.6g} rad'


def _trapezoid(amplitude: float, rate: float, accel: float) -> tuple[float, float]:
    """(duration, accel_time) of the fastest trapezoid of ``amplitude`` within the limits
    (a triangle when the rate limit is not reached)."""
    a = abs(amplitude)
    ta = rate / accel
    if a <= rate * ta:                 # triangular: accelerate to the middle, decelerate
        ta = math.sqrt(a / accel)
        return 2 * ta, ta
    return a / rate + ta, ta


def design_excitation(limits: Limits) -> list[Move]:
    """The moves of the calibration (module docstring), within ``limits``; raises
    IdentificationError when they do not fit in ``limits.duration``."""
    limits.check()
    a, w, acc = limits.max_angle, limits.max_rate, limits.max_accel
    moves = []
    for name, role, amp, shape in (('step_out', 'train', a, 'trap'),
                                   ('step_back', 'train', -a, 'trap'),
                                   ('small_step', 'train', 0.25 * a, 'trap'),
                                   ('validate_scurve', 'validate', -0.5 * a, 'scurve')):
        dur, ta = _trapezoid(amp, w, acc)
        if shape == 'scurve':            # raised-cosine ramps: peak acceleration pi/2 x
            dur, ta = _trapezoid(amp, w, acc / (0.5 * math.pi))
            prof: Profile = SCurveProfile(amp, dur, ta, LEAD_TIME)
        else:
            prof = TrapezoidalProfile(amp, dur, ta, LEAD_TIME)
        # 'step_back' starts where 'step_out' ended: the reversal happens on the drive
        start = limits.start + (a if name == 'step_back' else 0.0)
        moves.append(Move(name, role, _Offset(prof, start), LEAD_TIME + dur + RING_TIME))
    total = sum(m.t_end for m in moves)
    if total > limits.duration:
        raise IdentificationError(
            f'the excitation needs {total:.3g} s (4 moves with {RING_TIME * 1e3:.0f} ms of '
            f'ring-down each) but the limit is {limits.duration:g} s: allow more time, or '
            'raise the rate / acceleration limits')
    return moves


def excitation_series(moves: Sequence[Move], sample_rate: float) -> tuple[np.ndarray,
                                                                            np.ndarray]:
    """The moves one after the other as one command series (t [s], theta1 [rad]) sampled at
    ``sample_rate``: what a servo outside ROS streams (``calibrate --export-excitation``).
    Each move starts where the previous one ended, so ``step_back`` and the held-out move
    go back towards the start."""
    ts: list[np.ndarray] = []
    xs: list[np.ndarray] = []
    t0 = 0.0
    offset = 0.0
    for m in moves:
        n = int(math.floor(m.t_end * sample_rate + 1e-9)) + 1
        t = np.arange(n) / sample_rate
        x = m.profile.theta1(t)
        if xs:
            offset = xs[-1][-1] - x[0]
        ts.append(t0 + t)
        xs.append(x + offset)
        t0 += m.t_end + 1.0 / sample_rate
    return np.concatenate(ts), np.concatenate(xs)


def plant_runner(plant: Config, sample_rate: float, outputs: Sequence[str] = ('theta4',),
                 noise_rad: float = 0.0, resolution_rad: float = 0.0,
                 seed: int = 0) -> Callable[[Move], Record]:
    """A simulated drive standing in for the real one: each move is a record of ``plant``
    sampled at ``sample_rate`` with Gaussian noise and encoder steps."""
    def run(move: Move) -> Record:
        return record_from_model(plant, move.profile, move.t_end, sample_rate, outputs,
                                 noise_rad=noise_rad, resolution_rad=resolution_rad,
                                 seed=seed + zlib.crc32(move.name.encode()) % 1000,
                                 name=move.name)
    return run


@dataclass
class CalibrationResult:
    """What :func:`calibrate` did: the moves, the fit, the held-out errors and the verdict."""

    moves: list[Move]
    train: list[Record]
    held_out: list[Record]
    fit: FitResult
    validation_before: list[dict[str, Any]]
    validation_after: list[dict[str, Any]]
    accepted: bool
    reasons: list[str] = field(default_factory=list)     # why not accepted
    #: the 95 % bound on the held-out moves' theta4 RMS prediction error (.uncertainty)
    bounds: list[Any] = field(default_factory=list)

    @property
    def config(self) -> Config:
        return self.fit.config

    def worst_held_out(self, output: str = 'theta4') -> float:
        """The largest held-out RMS error of ``output`` as a share of its amplitude."""
        rel = [r[output]['rel'] for r in self.validation_after if output in r]
        return max(rel) if rel else math.nan


def calibrate(base: Config, keys: Sequence[str], limits: Limits,
              run: Callable[[Move], Record], *, options: FitOptions | None = None,
              outputs: Sequence[str] | None = None,
              accept_rel: float = ACCEPT_REL) -> CalibrationResult:
    """Design the excitation, run it (``run(move) -> Record``), fit ``keys`` of ``base`` on
    the training moves, validate on the held-out ones; accepted when the fit is
    trustworthy and every held-out theta4 error is within ``accept_rel`` of its amplitude.
    Raises IdentificationError (nothing fitted) when the limits or the records are
    unusable: no motion measured, motion unrelated to the command, a record that stops."""
    moves = design_excitation(limits)
    records = []
    for m in moves:
        rec = run(m)
        _check_followed(rec, m)
        records.append(rec)
    train = [r for r, m in zip(records, moves) if m.role == 'train']
    held = [r for r, m in zip(records, moves) if m.role == 'validate']
    res = identify(base, train, keys, options=options, outputs=outputs)
    before = prediction_errors(base, held)
    after = prediction_errors(res.config, held)
    reasons = list(res.problems)
    for row in after:
        for o, e in row.items():
            if o == 'name' or o not in res.output_verdicts or \
                    res.output_verdicts[o] != 'matched':
                continue
            if not e['rel'] <= accept_rel:
                reasons.append(f'held-out {row["name"]}: {o} RMS {100 * e["rel"]:.2f} % of '
                               f'its amplitude (> {100 * accept_rel:g} %)')
    bounds = []
    if 'theta4' in res.output_verdicts and res.output_verdicts['theta4'] == 'matched':
        from .uncertainty import prediction_bound
        bounds = [prediction_bound(res, train, h) for h in held]
    return CalibrationResult(moves, train, held, res, before, after, not reasons, reasons,
                             bounds)


def _check_followed(rec: Record, move: Move) -> None:
    """A servo that did not follow the excitation: records that stop early, no measured
    motion, or motion unrelated to the command (IdentificationError naming the move)."""
    if rec.t.size < 16 or rec.t[-1] - rec.t[0] < 0.9 * move.t_end:
        raise IdentificationError(f'{move.name}: the record stops after '
                                  f'{(rec.t[-1] - rec.t[0]) if rec.t.size else 0:.3g} s of '
                                  f'{move.t_end:.3g} s: the drive did not run the whole move')
    if not rec.measured:
        raise IdentificationError(f'{move.name}: no measured angle in the record')
    for o, y in rec.measured.items():
        if not float(np.ptp(y)) > 0:
            raise IdentificationError(f'{move.name}: {o} did not move (the drive did not '
                                      'follow the excitation)')
        c = np.corrcoef(rec.theta1, y)[0, 1] if np.ptp(rec.theta1) > 0 else math.nan
        if not c > 0.5:
            raise IdentificationError(f'{move.name}: {o} is unrelated to the command '
                                      f'(correlation {c:.2f}): the drive did not follow '
                                      'the excitation')
