# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Oscillation metrics of one run and the CSV rows of a study.

Definitions used everywhere (docs/studies.md):

Definitions used everywhere (docs/studies.md):

* **end of the move** ``t_move``: the time after which the command theta1 no longer changes
  (start_time + move_time for ramp/trapezoidal/s-curve, start_time for a step, the last
  change of a sampled series); the post-move window starts at the first recorded step at
  or after ``t_move`` at which theta1 has its final value.
* **equilibrium** ``theta_eq``: the static equilibrium of the drive at the final command
  (:func:`worm_gear_sim.dynamics.modal.static_equilibrium`; at rest the regularised friction is
  zero, so this is the rest point the ringing decays to; it includes shaft/mesh wind-up from an
  external load, if any).
* **oscillation amplitude** of theta_i: ``max |theta_i(t) - theta_i_eq|`` over
  ``t >= t_move`` (every integration step is inspected, not a decimated record).
  ``half_pp`` is half the peak-to-peak range over the same window (independent of the
  reference level), ``mean`` the time average over it.
* **dynamic error** (whole run): ``max |theta2 - theta1|`` and ``max |theta4 - theta1 l_w/r_g|``.
* **frequency**: the dominant spectral peak of theta_i - mean after the move (Hann window,
  zero padding x2, parabolic interpolation of the log magnitude); for theta4 also the
  zero-crossing rate of theta4 - mean.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from ..dynamics.modal import static_equilibrium
from ..dynamics.model import DriveModel
from ..dynamics.profiles import Profile, SampledProfile, motion_span
from ..dynamics.trajectory import Trajectory
from ..params import Config

__all__ = ['METRIC_COLUMNS', 'move_end_time', 'equilibrium', 'oscillation_metrics',
           'dominant_frequency', 'zero_crossing_frequency', 'rows_to_csv']


def move_end_time(cfg: Config, profile: Profile | None = None) -> float:
    """Time after which theta1 stays constant (see module docstring)."""
    inp = cfg.input
    if isinstance(profile, SampledProfile):
        span = motion_span(profile.times, profile.values)
        return float(profile.times[0]) if span is None else span[1]
    if inp.profile == 'step':
        return inp.start_time
    return inp.start_time + inp.move_time


def equilibrium(model: DriveModel | Config, theta1_final: float) -> np.ndarray:
    """Static equilibrium (theta2, theta3, theta4) of ``model`` (a :class:`DriveModel` or a
    Config) at the final command."""
    return static_equilibrium(DriveModel.of(model), theta1_final)


def dominant_frequency(t: np.ndarray, y: np.ndarray, f_min: float = 1.0) -> float:
    """Frequency [Hz] of the largest spectral peak of y - mean (Hann window, zero
    padding x2, parabolic interpolation of the log magnitude). NaN when the series is too
    short or flat."""
    n = y.size
    if n < 16:
        return math.nan
    dt = float(t[1] - t[0])
    yy = (y - y.mean()) * np.hanning(n)
    if not np.any(yy):
        return math.nan
    nfft = 1 << int(math.ceil(math.log2(2 * n)))
    mag = np.abs(np.fft.rfft(yy, nfft))
    freqs = np.fft.rfftfreq(nfft, dt)
    mag[freqs < f_min] = 0.0
    k = int(np.argmax(mag))
    if 0 < k < mag.size - 1 and mag[k - 1] > 0 and mag[k + 1] > 0:
        a, b, c = np.log(mag[k - 1]), np.log(mag[k]), np.log(mag[k + 1])
        den = a - 2 * b + c
        off = 0.5 * (a - c) / den if den != 0 else 0.0
        return float((k + off) * (freqs[1] - freqs[0]))
    return float(freqs[k])


def zero_crossing_frequency(t: np.ndarray, y: np.ndarray) -> float:
    """Mean frequency [Hz] from the crossings of y - mean (linear interpolation); NaN if fewer
    than 3 crossings."""
    z = y - y.mean()
    s = np.signbit(z)
    idx = np.nonzero(s[1:] != s[:-1])[0]
    if idx.size < 3:
        return math.nan
    tc = t[idx] - z[idx] * (t[idx + 1] - t[idx]) / (z[idx + 1] - z[idx])
    return float((idx.size - 1) / (2.0 * (tc[-1] - tc[0])))


METRIC_COLUMNS: tuple[str, ...] = (
    'amp2', 'amp3', 'amp4', 'half_pp2', 'half_pp4', 'eq2', 'eq4', 'mean2', 'mean4',
    'freq2_hz', 'freq4_hz', 'max_err2', 'max_err4', 'decay4',
)


def oscillation_metrics(traj: Trajectory, t_move: float, theta_eq: np.ndarray) -> dict:
    """Metrics of a trajectory recorded at every step (see the module docstring)."""
    t = traj.t
    i0 = int(np.searchsorted(t, t_move - 1e-12))
    moving = np.nonzero(traj.theta1 != traj.theta1[-1])[0]
    if moving.size:                       # e.g. a step: theta1 final only after t0
        i0 = max(i0, int(moving[-1]) + 1)
    if t.size - i0 < 2:
        raise ValueError(f'the run ends ({t[-1]:g} s) before the move does ({t_move:g} s); '
                         'increase input.end_time')
    tp = t[i0:]
    th = np.ascontiguousarray(traj.theta[i0:].T)          # (3, n): theta2, theta3, theta4
    eq = np.asarray(theta_eq, float)
    hi, lo = th.max(axis=1), th.min(axis=1)
    amp = np.maximum(hi - eq, eq - lo)                     # = max |theta - eq|
    n = tp.size
    m = max(2, n // 5)
    d4 = np.abs(th[2] - eq[2])
    first, last = float(d4[:m].max()), float(d4[-m:].max())
    th1 = traj.theta1
    err2 = float(np.max(np.abs(traj.theta[:, 0] - th1)))
    err4 = float(np.max(np.abs(traj.theta[:, 2] - th1 * traj.output_per_input)))
    return {
        'amp2': float(amp[0]), 'amp3': float(amp[1]), 'amp4': float(amp[2]),
        'half_pp2': float(0.5 * (hi[0] - lo[0])), 'half_pp4': float(0.5 * (hi[2] - lo[2])),
        'eq2': float(eq[0]), 'eq4': float(eq[2]),
        'mean2': float(th[0].mean()), 'mean4': float(th[2].mean()),
        'freq2_hz': dominant_frequency(tp, th[0]),
        'freq4_hz': dominant_frequency(tp, th[2]),
        'max_err2': err2, 'max_err4': err4,
        'decay4': last / first if first > 0 else math.nan,
    }


def rows_to_csv(rows: Iterable[Mapping[str, Any]], columns: Sequence[str], path) -> None:
    """Write rows (dicts) as CSV with the given columns; floats with repr precision."""
    import csv
    with open(path, 'w', newline='') as fh:
        w = csv.writer(fh)
        w.writerow(columns)
        for r in rows:
            w.writerow([_fmt(r.get(c, '')) for c in columns])


def _fmt(v: Any) -> str:
    if isinstance(v, bool):
        return 'true' if v else 'false'
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, Mapping):
        return ';'.join(f'{k}={_fmt(x)}' for k, x in v.items())
    return str(v)
