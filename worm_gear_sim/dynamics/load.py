# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Load torque on the antenna that varies in time, T_load(t) [N m], positive turning the
antenna back.

:class:`SampledLoad` (a series, linear between samples), :class:`WindLoad` (gusts from a
seeded Ornstein-Uhlenbeck gust model), :func:`elastic_windup` and
:func:`elastic_load_limit` (how far a load winds the held antenna up).  The wind model and
its equations: docs/load.md.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from ..schema.sections import LOAD_LIMIT
from .equations import linear_stiffness
from .model import DriveModel, without_play

__all__ = ['LoadSignal', 'SampledLoad', 'WindLoad', 'load_grid', 'elastic_windup',
           'elastic_load_limit', 'ElasticLimitCheck', 'ElasticLoadWarning',
           'elastic_load_warning']


class LoadSignal:
    """T_load(t) [N m] on arrays of times [s]."""

    name = 'load'

    def torque(self, t: ArrayLike) -> np.ndarray:
        raise NotImplementedError

    def describe(self) -> str:
        return self.name


class SampledLoad(LoadSignal):
    """A sampled load torque series: ``interpolation='linear'`` between samples (default),
    or ``'hold'`` (each sample applies from its time to the next: what the node does with
    the live ``load_torque`` topic); before the first sample the first value, after the
    last the last value.  Non-finite values, |T| > LOAD_LIMIT or times that do not
    increase strictly: ValueError naming the sample."""

    name = 'sampled load'

    def __init__(self, times: ArrayLike, values: ArrayLike, source: str = '',
                 interpolation: str = 'linear') -> None:
        if interpolation not in ('linear', 'hold'):
            raise ValueError(f'load torque: interpolation must be linear or hold, got '
                             f'{interpolation!r}')
        self.interpolation = interpolation
        t = np.asarray(times, float).reshape(-1)
        y = np.asarray(values, float).reshape(-1)
        if t.size == 0 or y.shape != t.shape:
            raise ValueError(f'load torque: need equal-length time and torque series, got '
                             f'{t.size} times and {y.size} values')
        bad = np.flatnonzero(~np.isfinite(t) | ~np.isfinite(y) | (np.abs(y) > LOAD_LIMIT))
        if bad.size:
            i = int(bad[0])
            raise ValueError(f'load torque: sample {i} (t = {t[i]!r} s, T = {y[i]!r} N m) is '
                             f'not finite or beyond +-{LOAD_LIMIT:g} N m')
        back = np.flatnonzero(np.diff(t) <= 0)
        if back.size:
            i = int(back[0]) + 1
            raise ValueError(f'load torque: sample {i} at t = {t[i]!r} s does not follow '
                             f'the previous one ({t[i - 1]!r} s); times must increase')
        self.times, self.values, self.source = t, y, source

    def torque(self, t: ArrayLike) -> np.ndarray:
        t = np.asarray(t, float)
        if self.interpolation == 'hold':
            i = np.searchsorted(self.times, t, side='right') - 1
            return self.values[np.clip(i, 0, None)]
        return np.interp(t, self.times, self.values)

    def describe(self) -> str:
        src = f' from {self.source}' if self.source else ''
        return (f'load torque sampled at {self.times.size} points, '
                f'{self.values.min():.4g} to {self.values.max():.4g} N m{src}')


class WindLoad(LoadSignal):
    """Wind gusts on the antenna (module docstring): mean torque ``mean`` [N m],
    turbulence intensity ``intensity`` (sigma_u / U, 0 to 1), correlation time
    ``time_scale`` [s] (L_u / U), random ``seed``."""

    name = 'wind'

    def __init__(self, mean: float, intensity: float, time_scale: float = 1.0,
                 seed: int = 0) -> None:
        mean, intensity, time_scale = float(mean), float(intensity), float(time_scale)
        if not (math.isfinite(mean) and abs(mean) <= LOAD_LIMIT / 4.0):
            raise ValueError(f'wind: mean torque {mean!r} N m must be finite and within '
                             f'+-{LOAD_LIMIT / 4.0:g} N m')
        if not (math.isfinite(intensity) and 0.0 <= intensity <= 1.0):
            raise ValueError(f'wind: gust intensity {intensity!r} must be in [0, 1] '
                             '(sigma_u / U; 0.1 to 0.3 near the ground)')
        if not (math.isfinite(time_scale) and 1e-3 <= time_scale <= 1e4):
            raise ValueError(f'wind: time scale {time_scale!r} s must be in [1e-3, 1e4] s')
        if int(seed) < 0:
            raise ValueError(f'wind: seed {seed!r} must be >= 0')
        self.mean, self.intensity, self.time_scale, self.seed = \
            mean, intensity, time_scale, int(seed)
        self.h = min(time_scale / 50.0, 1e-3)               # grid of the gust process [s]
        self._a = math.exp(-self.h / time_scale)
        self._rng = np.random.default_rng(self.seed)
        self._x = np.array([intensity * float(self._rng.standard_normal())])

    def _extend(self, n: int) -> None:
        """Grow the gust ratio series to at least n points (in order: the same seed gives
        the same series whatever the pieces asked)."""
        have = self._x.size
        if n <= have:
            return
        m = max(n - have, have)                       # amortised doubling
        e = self._rng.standard_normal(m) * (self.intensity * math.sqrt(1.0 - self._a ** 2))
        from scipy.signal import lfilter
        # x_{n+1} = a x_n + e_n, started from the last value
        x, _ = lfilter([1.0], [1.0, -self._a], e, zi=[self._a * self._x[-1]])
        self._x = np.concatenate((self._x, x))

    def gust_ratio(self, t: ArrayLike) -> np.ndarray:
        """x(t) = u(t) / U at times >= 0 (held at x(0) before 0)."""
        tt = np.clip(np.asarray(t, float), 0.0, None)
        if tt.size == 0:
            return tt
        top = float(np.max(tt))
        if not math.isfinite(top) or top > 1e7:
            raise ValueError(f'wind: time {top!r} s out of range (0 to 1e7 s)')
        self._extend(int(math.ceil(top / self.h)) + 2)
        s = tt / self.h
        i = np.minimum(np.floor(s).astype(np.int64), self._x.size - 2)
        f = s - i
        return self._x[i] * (1.0 - f) + self._x[i + 1] * f

    def torque(self, t: ArrayLike) -> np.ndarray:
        x = self.gust_ratio(t)
        return self.mean * (1.0 + x) ** 2 / (1.0 + self.intensity ** 2)

    def spectrum(self, f: ArrayLike) -> np.ndarray:
        """One-sided spectrum of the gust ratio x [1/Hz] at frequencies f [Hz]."""
        f = np.asarray(f, float)
        return 4.0 * self.intensity ** 2 * self.time_scale / \
            (1.0 + (2.0 * math.pi * f * self.time_scale) ** 2)

    def describe(self) -> str:
        return (f'wind: mean {self.mean:.4g} N m, gust intensity {self.intensity:.3g}, time '
                f'scale {self.time_scale:.3g} s, seed {self.seed}')


def load_grid(signal: LoadSignal | None, t_now: float, grid: np.ndarray) -> np.ndarray:
    """The load on the integrator's grid: [T(t_now), T(grid...)], or an empty array for
    the model's constant load (``signal`` None)."""
    if signal is None:
        return np.empty(0)
    out = np.empty(grid.size + 1)
    out[0] = float(signal.torque(np.array([t_now]))[0])
    out[1:] = signal.torque(grid)
    return out


def elastic_windup(model: DriveModel, torque: float) -> float:
    """Static wind-up of the antenna [rad] under a load ``torque`` [N m] with the worm
    held: torque x the theta4 entry of the inverse of Eq. 15's stiffness (frictionless,
    play removed, at the mesh's rest position).  Linear in the torque."""
    k = linear_stiffness(without_play(model.p))
    return abs(float(torque)) * float(np.linalg.inv(k)[2, 2])


def elastic_load_limit(model: DriveModel) -> float:
    """The load [N m] whose static wind-up (:func:`elastic_windup`) is
    ``load.max_elastic_windup``: what the drive carries elastically."""
    return model.config.load.max_elastic_windup / elastic_windup(model, 1.0)


def _beyond(model: DriveModel, what: str, torque: float, limit: float) -> str:
    """The line that says a load is beyond what the drive carries elastically."""
    return (f'{what} {torque:.6g} N m winds the antenna {elastic_windup(model, torque):.3g} '
            f'rad against the held worm, more than load.max_elastic_windup = '
            f'{model.config.load.max_elastic_windup:g} rad (|load| <= {limit:.6g} N m): '
            f'beyond what the drive carries elastically, simulated all the same')


class ElasticLoadWarning(UserWarning):
    """The load of a run is beyond what the drive carries elastically
    (``load.max_elastic_windup``): simulated all the same."""


def elastic_load_warning(model: DriveModel, load: LoadSignal | None = None) -> str:
    """One line when the load of a run is beyond :func:`elastic_load_limit` ('' within
    it): the constant ``load.output_torque`` (``load`` None), the largest |sample| of a
    :class:`SampledLoad`, the mean of a :class:`WindLoad` (its gusts are not known
    before the run)."""
    if load is None:
        what, torque = 'load.output_torque =', float(model.config.load.output_torque)
    elif isinstance(load, SampledLoad):
        i = int(np.argmax(np.abs(load.values)))
        src = f' of {load.source}' if load.source else ''
        what, torque = f'the load sample{src} at t = {load.times[i]:.6g} s,', float(
            load.values[i])
    elif isinstance(load, WindLoad):
        what, torque = 'the mean wind load', float(load.mean)
    else:
        return ''
    limit = elastic_load_limit(model)
    return _beyond(model, what, torque, limit) if abs(torque) > limit else ''


class ElasticLimitCheck:
    """Load samples beyond :func:`elastic_load_limit` of the current model: call with the
    model (a new one, e.g. after a parameter set, recomputes the limit) and the torque;
    returns one line to warn with (None within the limit) and counts them in
    :attr:`count`."""

    def __init__(self) -> None:
        self.count = 0
        self.limit = math.inf
        self._model: DriveModel | None = None

    def __call__(self, model: DriveModel, torque: float) -> str | None:
        if model is not self._model:
            self._model, self.limit = model, elastic_load_limit(model)
        if abs(torque) <= self.limit:
            return None
        self.count += 1
        return f'{_beyond(model, "load", torque, self.limit)}; {self.count} such sample(s)'
