# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Commanded worm-angle profiles theta1(t) and their rates, vectorised over time."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..schema.sections import InputProfile
from ..schema.validation import ConfigError

__all__ = ['Profile', 'StepProfile', 'RampProfile', 'TrapezoidalProfile', 'SCurveProfile',
           'SampledProfile', 'make_profile', 'motion_span']


def motion_span(times: np.ndarray, values: np.ndarray,
                tol: float = 0.0) -> tuple[float, float] | None:
    """When a sampled command moves: (time of the last sample before its first change, time
    of the sample that ends its last change); the values are constant before the first and
    after the second.  A change is a step between samples larger than ``tol``.  None when
    the command never moves."""
    moving = np.flatnonzero(np.abs(np.diff(np.asarray(values, float))) > tol)
    if moving.size == 0:
        return None
    t = np.asarray(times, float)
    return float(t[moving[0]]), float(t[moving[-1] + 1])


class Profile:
    """theta1(t) [rad] and d theta1/dt [rad/s]; subclasses implement both on arrays."""

    name = 'profile'

    def theta1(self, t: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def theta1_dot(self, t: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def describe(self) -> str:
        return self.name

    @property
    def final_value(self) -> float:
        return float(self.theta1(np.array([1e12]))[0])


@dataclass(frozen=True)
class StepProfile(Profile):
    """Ideal step of ``amplitude`` just after ``t0``: theta1(t0) = 0, later amplitude."""

    amplitude: float
    t0: float = 0.0
    name = 'step'

    def theta1(self, t):
        return np.where(np.asarray(t, float) > self.t0, self.amplitude, 0.0)

    def theta1_dot(self, t):
        return np.zeros_like(np.asarray(t, float))

    def describe(self):
        return f'step {self.amplitude:.9g} rad at {self.t0:g} s'


@dataclass(frozen=True)
class RampProfile(Profile):
    """Constant rate from 0 to ``amplitude`` over [t0, t0 + duration]."""

    amplitude: float
    duration: float
    t0: float = 0.0
    name = 'ramp'

    def theta1(self, t):
        s = np.clip((np.asarray(t, float) - self.t0) / self.duration, 0.0, 1.0)
        return self.amplitude * s

    def theta1_dot(self, t):
        t = np.asarray(t, float)
        inside = (t > self.t0) & (t < self.t0 + self.duration)
        return np.where(inside, self.amplitude / self.duration, 0.0)

    def describe(self):
        return f'ramp {self.amplitude:.9g} rad in {self.duration:g} s from {self.t0:g} s'


@dataclass(frozen=True)
class TrapezoidalProfile(Profile):
    """Trapezoidal velocity: accelerate for ``accel_time``, cruise, decelerate; reaches
    ``amplitude`` at t0 + duration (the default of docs/model-notes.md: 20 ms with 4 ms ramps)."""

    amplitude: float
    duration: float
    accel_time: float
    t0: float = 0.0
    name = 'trapezoidal'

    @property
    def peak_rate(self) -> float:
        return self.amplitude / (self.duration - self.accel_time)

    @property
    def cruise(self) -> tuple[float, float]:
        """(start, end) [s] of the constant-rate part, between the two ramps."""
        return self.t0 + self.accel_time, self.t0 + self.duration - self.accel_time

    def theta1(self, t):
        tau = np.clip(np.asarray(t, float) - self.t0, 0.0, self.duration)
        ta, T, w = self.accel_time, self.duration, self.peak_rate
        acc = 0.5 * w / ta * tau ** 2
        cru = w * (tau - 0.5 * ta)
        dec = self.amplitude - 0.5 * w / ta * (T - tau) ** 2
        return np.where(tau < ta, acc, np.where(tau <= T - ta, cru, dec))

    def theta1_dot(self, t):
        tau = np.asarray(t, float) - self.t0
        ta, T, w = self.accel_time, self.duration, self.peak_rate
        out = np.where(tau < ta, w * tau / ta, np.where(tau <= T - ta, w, w * (T - tau) / ta))
        return np.where((tau <= 0.0) | (tau >= T), 0.0, out)

    def describe(self):
        return (f'trapezoidal {self.amplitude:.9g} rad in {self.duration:g} s '
                f'({self.accel_time:g} s ramps) from {self.t0:g} s')


@dataclass(frozen=True)
class SCurveProfile(Profile):
    """Jerk-limited move: the rate rises along a raised cosine over ``accel_time``, cruises,
    and falls symmetrically (continuous acceleration)."""

    amplitude: float
    duration: float
    accel_time: float
    t0: float = 0.0
    name = 's_curve'

    @property
    def peak_rate(self) -> float:
        return self.amplitude / (self.duration - self.accel_time)

    def theta1_dot(self, t):
        tau = np.asarray(t, float) - self.t0
        ta, T, w = self.accel_time, self.duration, self.peak_rate
        up = 0.5 * w * (1.0 - np.cos(math.pi * tau / ta))
        down = 0.5 * w * (1.0 - np.cos(math.pi * (T - tau) / ta))
        out = np.where(tau < ta, up, np.where(tau <= T - ta, w, down))
        return np.where((tau <= 0.0) | (tau >= T), 0.0, out)

    def theta1(self, t):
        tau = np.clip(np.asarray(t, float) - self.t0, 0.0, self.duration)
        ta, T, w = self.accel_time, self.duration, self.peak_rate
        acc = 0.5 * w * (tau - ta / math.pi * np.sin(math.pi * tau / ta))
        cru = 0.5 * w * ta + w * (tau - ta)
        r = T - tau
        dec = self.amplitude - 0.5 * w * (r - ta / math.pi * np.sin(math.pi * r / ta))
        return np.where(tau < ta, acc, np.where(tau <= T - ta, cru, dec))

    def describe(self):
        return (f's-curve {self.amplitude:.9g} rad in {self.duration:g} s '
                f'({self.accel_time:g} s ramps) from {self.t0:g} s')


class SampledProfile(Profile):
    """A sampled command series; linear interpolation (rate = slope) or zero-order hold.

    With ``interpolation='hold'`` a sample takes effect at its own time stamp; with
    ``'linear'`` theta1 moves linearly between samples.  Before the first sample theta1
    equals the first value, after the last it stays at the last value.
    """

    name = 'sampled'

    def __init__(self, times, values, interpolation: str = 'linear', source: str = '',
                 remember: bool = False):
        """``remember``: keep the values on the last time grid asked for (read-only arrays;
        asked again for an equal grid, the same numbers without interpolating): for a
        caller that simulates the same command many times, e.g. a fit's evaluations."""
        t = np.asarray(times, float)
        y = np.asarray(values, float)
        if t.ndim != 1 or y.shape != t.shape or t.size == 0:
            raise ConfigError('input.csv_path', 'need equal-length 1-D time and value series')
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(y))):
            raise ConfigError('input.csv_path', 'samples must be finite')
        if np.any(np.diff(t) <= 0):
            raise ConfigError('input.csv_path', 'sample times must increase strictly')
        if interpolation not in ('linear', 'hold'):
            raise ConfigError('interpolation', f'must be linear or hold, got {interpolation!r}')
        self.times, self.values, self.interpolation, self.source = t, y, interpolation, source
        self.remember = bool(remember)
        self._grids: dict[str, tuple[np.ndarray, np.ndarray]] = {}

    def _remembered(self, what: str, t: np.ndarray,
                    compute: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        if not self.remember or t.ndim != 1:
            return compute(t)
        last = self._grids.get(what)          # one tuple, replaced whole: thread-safe
        if last is not None and last[0].shape == t.shape and np.array_equal(last[0], t):
            return last[1]
        out = compute(t)
        out.flags.writeable = False
        grid = t.copy()
        grid.flags.writeable = False
        self._grids[what] = (grid, out)
        return out

    def theta1(self, t):
        return self._remembered('theta1', np.asarray(t, float), self._theta1)

    def theta1_dot(self, t):
        return self._remembered('theta1_dot', np.asarray(t, float), self._theta1_dot)

    def _theta1(self, t: np.ndarray) -> np.ndarray:
        if self.interpolation == 'linear':
            return np.interp(t, self.times, self.values)
        idx = np.searchsorted(self.times, t, side='right') - 1
        return self.values[np.clip(idx, 0, None)]

    def _theta1_dot(self, t: np.ndarray) -> np.ndarray:
        if self.interpolation == 'hold' or self.times.size < 2:
            return np.zeros_like(t)
        slopes = np.diff(self.values) / np.diff(self.times)
        idx = np.searchsorted(self.times, t, side='right') - 1
        inside = (idx >= 0) & (idx < slopes.size)
        return np.where(inside, slopes[np.clip(idx, 0, slopes.size - 1)], 0.0)

    @classmethod
    def from_csv(cls, path: str | Path, interpolation: str = 'linear') -> SampledProfile:
        """The ``t``, ``theta1`` columns of a CSV named by its header, with units, times
        relative to the first sample (see :func:`worm_gear_sim.records.read_csv`)."""
        from ..records import RecordError, read_csv
        try:
            rec = read_csv(path)
        except RecordError as exc:
            raise ConfigError('input.csv_path', str(exc)) from None
        return cls(rec.t, rec.theta1, interpolation, source=str(path))

    def describe(self):
        src = f' from {self.source}' if self.source else ''
        return f'sampled {self.times.size} points ({self.interpolation}){src}'


def make_profile(inp: InputProfile) -> Profile:
    """Build the profile described by the ``input`` section of the config."""
    if inp.profile == 'step':
        return StepProfile(inp.target_angle, inp.start_time)
    if inp.profile == 'ramp':
        return RampProfile(inp.target_angle, inp.move_time, inp.start_time)
    if inp.profile == 'trapezoidal':
        return TrapezoidalProfile(inp.target_angle, inp.move_time, inp.accel_time,
                                  inp.start_time)
    if inp.profile == 's_curve':
        return SCurveProfile(inp.target_angle, inp.move_time, inp.accel_time, inp.start_time)
    return SampledProfile.from_csv(inp.csv_path)
