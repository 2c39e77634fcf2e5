# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The calibration's excitation: its limits, its moves and the command profiles they use.

:func:`design_excitation` chooses steps (the elastic keys: ``step_out``, ``step_back``,
``small_step``, held-out ``validate_scurve``) or sweeps (play, load or drag fitted:
``slow_sweep``, ``fast_sweep``, held-out ``validate_sweep``, ``unload_dither`` in reserve,
:func:`dither_profile`).  docs/identification.md ("The excitation").
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..config.usable import Config
from ..dynamics.profiles import Profile, SCurveProfile, TrapezoidalProfile
from .data import IdentificationError

__all__ = ['Limits', 'Move', 'RateSchedule', 'design_excitation', 'SWEEP_KEYS', 'RING_TIME',
           'LEAD_TIME', 'DWELL_TIME', 'CRUISE_MIN', 'SLOW_SHARE', 'PLAY_DESIGN',
           'uses_sweeps', 'DITHER_CYCLES', 'dither_profile']

#: Rest after each move [s]: the antenna mode (~95 Hz) rings ~14 periods.
RING_TIME = 0.15
#: Rest before each move [s].
LEAD_TIME = 0.005
#: Rest at a sweep's turning point [s] (the reversal happens there).
DWELL_TIME = 0.05
#: Shortest constant-rate part of a sweep [s] (~5 periods of the antenna mode).
CRUISE_MIN = 0.05
#: The slow sweep's rate as a share of the rate limit.
SLOW_SHARE = 0.25
#: The largest play [rad at the gear] the sweeps are designed to cross (5 arcmin) when the
#: base has less; the slow sweep's constant-rate travel must be twice the play seen at the
#: worm so that the flank has changed before the second half of the segment.
PLAY_DESIGN = 5.0 * math.pi / 180.0 / 60.0
#: Cycles of the unloading dither at the antenna mode (:func:`dither_profile`; the shaft
#: torque swing grows by about pi rigid inertia torques a cycle, :mod:`.unload`).
DITHER_CYCLES = 8
#: Keys for which the sweeps are designed (the drag alone is seen by the steps' stops too:
#: fitted with the elastic keys, it keeps the steps).
SWEEP_KEYS = ('mesh.backlash', 'load.output_torque')


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
    role: str                 # 'train' | 'validate' | 'reserve' (.unload)
    profile: Profile
    t_end: float

    @property
    def amplitude(self) -> float:
        return float(self.profile.theta1(np.array([self.t_end]))[0]
                     - self.profile.theta1(np.array([0.0]))[0])


class RateSchedule(Profile):
    """A worm rate given piecewise: each piece ``(duration, rate_from, rate_to)`` changes the
    rate along a raised cosine (constant when equal; peak acceleration
    pi |rate_to - rate_from| / (2 duration)); theta1 is its exact integral from ``start``."""

    name = 'rate_schedule'

    def __init__(self, pieces: Sequence[tuple[float, float, float]], start: float = 0.0,
                 label: str = '') -> None:
        self.pieces = [(float(d), float(a), float(b)) for d, a, b in pieces]
        if not self.pieces or any(not d > 0 for d, _, _ in self.pieces):
            raise ValueError('RateSchedule: every piece needs a positive duration')
        self.t_knots = np.cumsum([0.0] + [p[0] for p in self.pieces])
        x = [float(start)]
        for d, a, b in self.pieces:
            x.append(x[-1] + 0.5 * (a + b) * d)
        self.x_knots = np.array(x)
        self._d = np.array([p[0] for p in self.pieces])
        self._a = np.array([p[1] for p in self.pieces])
        self._b = np.array([p[2] for p in self.pieces])
        self.label = label

    def _eval(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        t = np.asarray(t, float)
        k = np.clip(np.searchsorted(self.t_knots, t, side='right') - 1, 0, len(self.pieces) - 1)
        d, a, b = self._d[k], self._a[k], self._b[k]
        tau = np.clip(t - self.t_knots[k], 0.0, d)
        x = self.x_knots[k] + a * tau + 0.5 * (b - a) * (tau - d / math.pi
                                                        * np.sin(math.pi * tau / d))
        v = a + 0.5 * (b - a) * (1.0 - np.cos(math.pi * tau / d))
        before, after = t < 0.0, t > self.t_knots[-1]
        x = np.where(before, self.x_knots[0], np.where(after, self.x_knots[-1], x))
        return x, np.where(before | after, 0.0, v)

    def theta1(self, t):
        return self._eval(t)[0]

    def theta1_dot(self, t):
        return self._eval(t)[1]

    @property
    def duration(self) -> float:
        return float(self.t_knots[-1])

    def describe(self) -> str:
        return self.label or f'rate schedule of {len(self.pieces)} pieces'


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


def uses_sweeps(keys: Sequence[str] | None) -> bool:
    """Whether the fitted keys call for the sweeps (module docstring)."""
    return any(str(k).strip() in SWEEP_KEYS for k in (keys or ()))


def design_excitation(limits: Limits, keys: Sequence[str] | None = None,
                      base: Config | None = None) -> list[Move]:
    """The moves of the calibration (module docstring) within ``limits``: the sweeps when
    ``keys`` hold a key of SWEEP_KEYS, else the steps.  Raises IdentificationError (one line
    naming the limit) when they do not fit: no room for a slow reversal, or too long."""
    limits.check()
    if uses_sweeps(keys):
        moves = _sweeps(limits, keys or (), base)
    else:
        moves = _steps(limits)
    total = sum(m.t_end for m in moves)
    if total > limits.duration:
        raise IdentificationError(
            f'calibration limit duration: the excitation needs {total:.3g} s ({len(moves)} '
            f'moves with {RING_TIME * 1e3:.0f} ms of ring-down each) but the limit is '
            f'{limits.duration:g} s: allow more time, or raise the rate / acceleration limits')
    return moves


def _steps(limits: Limits) -> list[Move]:
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
    return moves


def sweep_profile(start: float, travel: float, rate: float, accel: float,
                  label: str) -> RateSchedule:
    """Out by ``travel`` [rad] (signed) at the constant worm ``rate`` and back, raised-cosine
    ramps at the acceleration ``accel`` (peak), DWELL_TIME at the turning point, LEAD_TIME of
    rest before."""
    s = 1.0 if travel >= 0 else -1.0
    ramp = 0.5 * math.pi * rate / accel
    cruise = abs(travel) / rate - ramp          # a ramp pair travels rate * ramp
    w = s * rate
    pieces = [(LEAD_TIME, 0.0, 0.0), (ramp, 0.0, w), (cruise, w, w), (ramp, w, 0.0),
              (DWELL_TIME, 0.0, 0.0), (ramp, 0.0, -w), (cruise, -w, -w), (ramp, -w, 0.0)]
    return RateSchedule(pieces, start, f'{label}: {travel:+.4g} rad out and back at '
                        f'{rate:.4g} rad/s ({ramp * 1e3:.1f} ms ramps) from {start:.6g} rad')


def _fastest_rate(travel: float, rate: float, accel: float) -> float:
    """The highest rate <= ``rate`` whose sweep over ``travel`` cruises >= CRUISE_MIN."""
    # travel = r (CRUISE_MIN + pi r / (2 accel))  ->  quadratic in r
    k = 0.5 * math.pi / accel
    r_max = (-CRUISE_MIN + math.sqrt(CRUISE_MIN ** 2 + 4 * k * travel)) / (2 * k)
    return min(rate, r_max)


def _sweeps(limits: Limits, keys: Sequence[str], base: Config | None) -> list[Move]:
    a, w, acc = limits.max_angle, limits.max_rate, limits.max_accel
    cfg = base if base is not None else Config()
    from ..dynamics.model import DriveModel
    u = DriveModel.of(cfg).output_per_input
    play = max(cfg.mesh.backlash, PLAY_DESIGN)
    w_fast = _fastest_rate(a, w, acc)
    w_slow = SLOW_SHARE * w_fast
    ramp_slow = 0.5 * math.pi * w_slow / acc
    cruise_travel = a - w_slow * ramp_slow
    need = 2.0 * play / u
    if any(str(k).strip() == 'mesh.backlash' for k in keys) and cruise_travel < need:
        raise IdentificationError(
            f'calibration limit max_angle = {a:g} rad leaves no room for a slow reversal: '
            f'crossing {play * 180 * 60 / math.pi:.3g} arcmin of play needs >= '
            f'{need + w_slow * ramp_slow:.3g} rad of worm travel each way')
    moves: list[Move] = []
    for name, role, travel, rate in (('slow_sweep', 'train', a, w_slow),
                                     ('fast_sweep', 'train', a, w_fast),
                                     ('validate_sweep', 'validate', -0.6 * a, 0.5 * w_fast)):
        prof = sweep_profile(limits.start, travel, rate, acc, name)
        moves.append(Move(name, role, prof, prof.duration + RING_TIME))
    if {'mesh.backlash', 'load.output_torque'} <= {str(k).strip() for k in keys}:
        prof = dither_profile(cfg, limits)
        if sum(m.t_end for m in moves) + prof.duration + RING_TIME <= limits.duration:
            moves.append(Move('unload_dither', 'reserve', prof, prof.duration + RING_TIME))
    return moves


def dither_profile(cfg: Config, limits: Limits) -> RateSchedule:
    """The worm rate swinging DITHER_CYCLES times at the antenna mode of ``cfg`` (its lowest
    linearised mode) with the acceleration limit as peak (the rate limit if lower), raised-
    cosine half periods, from rest to rest; LEAD_TIME of rest before."""
    from ..dynamics.modal import modes
    f = float(np.asarray(modes(cfg).undamped_hz, float)[0])
    period = 1.0 / f
    v = min(limits.max_rate, limits.max_accel / (2.0 * math.pi * f))
    pieces = [(LEAD_TIME, 0.0, 0.0), (0.25 * period, 0.0, v)]
    for k in range(2 * DITHER_CYCLES - 1):
        s = 1.0 if k % 2 == 0 else -1.0
        pieces.append((0.5 * period, s * v, -s * v))
    pieces.append((0.25 * period, pieces[-1][2], 0.0))
    return RateSchedule(pieces, limits.start,
                        f'unload_dither: worm rate +-{v:.3g} rad/s at {f:.4g} Hz (the antenna '
                        f'mode), {DITHER_CYCLES} cycles, from {limits.start:.6g} rad')
