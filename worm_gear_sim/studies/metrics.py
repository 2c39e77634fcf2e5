# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Oscillation metrics of one run and the rows of a study: as CSV, as a text table.

The end of the move, the equilibrium, the oscillation amplitude, the dynamic error and the
frequency, as defined in docs/studies.md.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from ..config.usable import Config
from ..dynamics.modal import static_equilibrium
from ..dynamics.model import DriveModel
from ..dynamics.profiles import Profile, SampledProfile, motion_span
from ..dynamics.spectrum import dominant_frequency
from ..dynamics.trajectory import Trajectory

__all__ = ['METRIC_COLUMNS', 'move_end_time', 'equilibrium', 'oscillation_metrics',
           'zero_crossing_frequency', 'rows_to_csv', 'fmt_table']


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


def fmt_table(rows: Sequence[Mapping[str, Any]], cols: Sequence[tuple[str, str, str]]) -> str:
    """A right-aligned text table: ``cols`` are (key, heading, float format)."""
    head = [h for _, h, _ in cols]
    body = []
    for r in rows:
        line = []
        for key, _, fmt in cols:
            v = r.get(key, '')
            line.append(format(v, fmt) if isinstance(v, float) else str(v))
        body.append(line)
    widths = [max(len(h), *(len(b[i]) for b in body)) for i, h in enumerate(head)]
    fmt_line = lambda cells: '  '.join(c.rjust(w) for c, w in zip(cells, widths))  # noqa: E731
    return '\n'.join([fmt_line(head)] + [fmt_line(b) for b in body])


def _fmt(v: Any) -> str:
    if isinstance(v, bool):
        return 'true' if v else 'false'
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, Mapping):
        return ';'.join(f'{k}={_fmt(x)}' for k, x in v.items())
    return str(v)
