# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Fit model parameters to measured records; the live model check is in
:mod:`worm_gear_sim.model_check`.

Pure core (no rclpy, no plotting).  A *record* is one measured run of the drive: sample times
``t`` [s], the commanded worm angle ``theta1`` [rad] at those times and at least one measured
angle ``theta2``/``theta3``/``theta4`` [rad].  The model predicts a record by starting at rest
in static equilibrium at ``theta1[0]`` and integrating the command interpolated linearly between
the samples (:class:`~worm_gear_sim.profiles.SampledProfile`), exactly as ``simulate --csv``.

The fit (:func:`identify`) minimises, with ``scipy.optimize.least_squares``, the residuals
(predicted - measured) of every measured output of every record, each output divided by its
noise level (estimated from 4th differences of the measured angle, pooled over the records;
at least 1e-3 of its *scale*, the RMS of the measured angle minus the rigid kinematic motion
theta1 * u_rigid), so that theta2 (~0.1 rad) and theta4 (~1e-3 rad) weigh by their
information.  Parameters
are fitted in normalised coordinates x: ``log(value / base)`` for positive quantities,
``(value - base) / scale`` otherwise; bounds come from the parameter metadata.

Oscillatory records defeat a plain local fit (it locks onto the wrong period).  Three measures,
compared in docs/identification.md, make it robust:

* **frequency start**: the dominant frequency of each measured output (FFT after the move) is
  matched to the nearest linearised mode of the model (:func:`worm_gear_sim.modal.modes`) by a
  minimum-change Gauss-Newton step on the fitted keys before the time-domain fit;
* **growing windows**: the fit runs on the first few periods after motion starts, then on
  longer windows, each starting from the previous estimate;
* **multi-start**: several starts (the frequency start, the base, a scrambled Sobol set over
  the start box) run in parallel on the Dask engine of the sweeps; the lowest cost wins.

The report holds 95 % confidence intervals from the Jacobian (s^2 (J^T J)^-1, white-noise
assumption), the correlation matrix (pairs above 0.95 flagged), residual RMS per output before
and after, and a verdict: a fit that did not converge, cannot determine a parameter or leaves a
residual far above the noise is marked not trustworthy, with the reason.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from .modal import modes
from .model import DriveModel
from .params import Config, ConfigError, suggest
from .profiles import SampledProfile, motion_span
from .records import Record
from .simulation import SimulationError, Simulator
from .studies import dominant_frequency

__all__ = [
    'OUTPUTS', 'FITTABLE_SECTIONS', 'IdentificationError', 'Record', 'FitParameter',
    'fit_parameters', 'apply_values', 'check_record', 'predict', 'Problem', 'FitOptions',
    'FitResult', 'identify', 'validate', 'prediction_errors', 'measured_frequencies',
    'frequency_start', 'STRATEGIES', 'record_from_model',
    'jacobian',
]

OUTPUTS: tuple[str, ...] = ('theta2', 'theta3', 'theta4')
#: Sections that describe the drive itself (integrator, input, node, compensation do not).
FITTABLE_SECTIONS: tuple[str, ...] = ('geometry', 'materials', 'shafts', 'mesh', 'friction',
                                      'damping', 'load')
MIN_SAMPLES = 20
CORRELATION_WARN = 0.95
Z95 = 1.959963984540054


class IdentificationError(ValueError):
    """Bad records, bad fit keys or a failed fit: one line naming the cause."""


# ---- records -----------------------------------------------------------------------------------
def _name(rec: Any, i: int | None = None) -> str:
    n = getattr(rec, 'name', '') or ''
    return n if n else (f'record {i + 1}' if i is not None else 'record')


def check_record(rec: Any, index: int | None = None) -> None:
    """Raise IdentificationError unless the record is usable: 1-D finite arrays of equal length,
    strictly increasing times, at least MIN_SAMPLES samples, at least one measured output among
    theta2/theta3/theta4 (any other name is refused)."""
    nm = _name(rec, index)
    t = np.asarray(rec.t, float)
    th1 = np.asarray(rec.theta1, float)
    if t.ndim != 1 or th1.shape != t.shape:
        raise IdentificationError(f'{nm}: t and theta1 must be 1-D series of equal length')
    if t.size < MIN_SAMPLES:
        raise IdentificationError(f'{nm}: too short ({t.size} samples, need >= {MIN_SAMPLES})')
    for label, arr in (('t', t), ('theta1', th1)):
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            raise IdentificationError(f'{nm}: {label} is not finite at sample {bad[0]}')
    dt = np.diff(t)
    if np.any(dt <= 0):
        k = int(np.flatnonzero(dt <= 0)[0])
        what = 'duplicated' if dt[k] == 0 else 'decreasing'
        raise IdentificationError(f'{nm}: {what} time at sample {k + 1} (t = {t[k + 1]:.9g} s);'
                                  ' times must increase strictly')
    meas = dict(rec.measured)
    if not meas:
        raise IdentificationError(f'{nm}: no measured output (need one of '
                                  f'{", ".join(OUTPUTS)})')
    for key, arr in meas.items():
        if key not in OUTPUTS:
            raise IdentificationError(f'{nm}: unknown measured output {key!r} (known: '
                                      f'{", ".join(OUTPUTS)})')
        a = np.asarray(arr, float)
        if a.shape != t.shape:
            raise IdentificationError(f'{nm}: {key} has {a.size} samples, t has {t.size}')
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            raise IdentificationError(f'{nm}: {key} is not finite at sample {bad[0]}')


def _motion_times(t: np.ndarray, th1: np.ndarray) -> tuple[float, float]:
    """First and last time at which the command changes (relative tolerance 1e-9 of its range
    or 1e-12 rad)."""
    span = motion_span(t, th1, tol=max(1e-12, 1e-9 * float(np.ptp(th1))))
    return (float(t[0]), float(t[0])) if span is None else span


def record_from_model(cfg: Config, profile: Any, t_end: float, sample_rate: float = 1e4,
                      outputs: Sequence[str] = ('theta4',), noise_rad: float = 0.0,
                      resolution_rad: float = 0.0, seed: int = 0, name: str = '') -> Record:
    """A synthetic record of the model (for tests, benchmarks and trying the fit): the profile
    sampled at ``sample_rate`` from 0 to ``t_end``, each output plus Gaussian noise
    ``noise_rad`` (RMS) and quantised to ``resolution_rad`` (an encoder's step; 0: none)."""
    n = int(math.floor(t_end * sample_rate + 1e-9)) + 1
    t = np.arange(n) / sample_rate
    th1 = np.asarray(profile.theta1(t), float)
    rec0 = Record(t=t, theta1=th1, measured={'theta4': th1}, t0_ns=0, name=name)
    pred = predict(cfg, rec0)
    rng = np.random.default_rng(seed)
    meas = {}
    for o in outputs:
        y = pred[o] + noise_rad * rng.standard_normal(n)
        if resolution_rad > 0:
            y = np.round(y / resolution_rad) * resolution_rad
        meas[o] = y
    return Record(t=t, theta1=th1, measured=meas, t0_ns=0, name=name)


# ---- parameters --------------------------------------------------------------------------------
_KEY_RE = re.compile(r'^([a-z_]+\.[a-z0-9_]+)(?:\[(\d+)\])?$')


@dataclass(frozen=True)
class FitParameter:
    """One fitted quantity: a numeric parameter key (``damping.modal_damping_ratios[0]`` for an
    entry of a list), its base value, physical bounds and normalised coordinate x."""

    key: str
    path: str
    index: int | None
    base: float
    lo: float
    hi: float
    log: bool
    scale: float        # linear keys: x = (value - base) / scale
    unit: str
    box: tuple[float, float]   # multi-start box in x

    def to_x(self, value: float) -> float:
        if self.log:
            return math.log(value / self.base)
        return (value - self.base) / self.scale

    def from_x(self, x: float) -> float:
        if self.log:
            return self.base * math.exp(min(x, 700.0))   # an interval may be unbounded
        return self.base + x * self.scale

    @property
    def x_bounds(self) -> tuple[float, float]:
        if self.log:
            lo = math.log(self.lo / self.base) if self.lo > 0 else -np.inf
            hi = math.log(self.hi / self.base) if math.isfinite(self.hi) else np.inf
            return lo, hi
        return (self.to_x(self.lo) if math.isfinite(self.lo) else -np.inf,
                self.to_x(self.hi) if math.isfinite(self.hi) else np.inf)


def fit_parameters(base: Config, keys: Sequence[str],
                   bounds: Mapping[str, tuple[float, float]] | None = None,
                   start_factor: float = 2.0) -> list[FitParameter]:
    """Resolve the ``--fit`` keys against the base config.  Bounds: the parameter metadata,
    narrowed by ``bounds`` (key -> (lo, hi)).  Positive quantities (lower bound >= 0, base > 0)
    are fitted in log scale; their multi-start box is base / start_factor ... base *
    start_factor (or the given bounds).  Unknown, non-numeric, integer or non-drive keys raise
    IdentificationError."""
    flat = base.to_flat_dict()
    meta = Config.metadata()
    out: list[FitParameter] = []
    bounds = dict(bounds or {})
    if not keys:
        raise IdentificationError('--fit: give at least one parameter key')
    for key in keys:
        key = key.strip()
        m = _KEY_RE.match(key)
        path, idx = (m.group(1), m.group(2)) if m else (key, None)
        if path not in flat:
            raise IdentificationError(f'--fit {key}: unknown parameter' + suggest(path, flat))
        sec = path.split('.', 1)[0]
        value = flat[path]
        md = meta[path]
        if sec not in FITTABLE_SECTIONS:
            raise IdentificationError(f'--fit {key}: not a parameter of the drive (section '
                                      f'{sec}); fittable sections: {", ".join(FITTABLE_SECTIONS)}')
        if isinstance(value, list):
            if not value or not all(isinstance(v, float) for v in value):
                raise IdentificationError(f'--fit {key}: not a numeric parameter')
            if idx is None:
                raise IdentificationError(f'--fit {key}: a list of {len(value)} numbers; fit '
                                          f'one entry, e.g. {path}[0]')
            i = int(idx)
            if i >= len(value):
                raise IdentificationError(f'--fit {key}: index out of range (0..'
                                          f'{len(value) - 1})')
            v = float(value[i])
        else:
            if idx is not None:
                raise IdentificationError(f'--fit {key}: {path} is not a list')
            if isinstance(value, bool) or not isinstance(value, float):
                kind = 'an integer setting' if isinstance(value, int) and not \
                    isinstance(value, bool) else f'not numeric ({type(value).__name__})'
                raise IdentificationError(f'--fit {key}: {kind}, cannot be fitted')
            v = float(value)
            i = None
        lo = -np.inf if md.get('lo') is None else float(md['lo'])
        hi = np.inf if md.get('hi') is None else float(md['hi'])
        if md.get('lo_open') and lo == 0.0:
            lo = 0.0
        user = bounds.pop(key, None)
        if user is not None:
            ulo, uhi = float(user[0]), float(user[1])
            if not (ulo < uhi):
                raise IdentificationError(f'--bounds {key}: need LO < HI, got {ulo:g}:{uhi:g}')
            if ulo < lo or uhi > hi:
                raise IdentificationError(f'--bounds {key}: {ulo:g}:{uhi:g} leaves the '
                                          f'parameter range {lo:g}..{hi:g}')
            lo, hi = ulo, uhi
            if not (lo <= v <= hi):
                v = math.sqrt(lo * hi) if lo > 0 else 0.5 * (lo + hi)
        use_log = lo >= 0.0 and v > 0.0
        if use_log:
            scale = 1.0
            if user is not None and lo > 0:
                box = (math.log(lo / v), math.log(hi / v))
            else:
                box = (max(-math.log(start_factor), math.log(lo / v) if lo > 0 else -np.inf),
                       min(math.log(start_factor), math.log(hi / v)))
        else:
            if v != 0.0:
                scale = abs(v)
            elif math.isfinite(hi - lo):
                scale = 0.1 * min(hi - lo, 1.0)
            else:
                scale = 0.1
            if user is not None:
                box = ((lo - v) / scale, (hi - v) / scale)
            else:
                box = (max(-1.0, (lo - v) / scale), min(1.0, (hi - v) / scale))
        out.append(FitParameter(key=key, path=path, index=i, base=v, lo=lo, hi=hi,
                                log=use_log, scale=scale, unit=str(md.get('unit', '')),
                                box=(float(box[0]), float(box[1]))))
    if bounds:
        raise IdentificationError(f'--bounds {next(iter(bounds))}: not among the --fit keys')
    if len({p.key for p in out}) != len(out):
        raise IdentificationError('--fit: a key is given twice')
    return out


def apply_values(base: Config, params: Sequence[FitParameter],
                 values: Sequence[float]) -> Config:
    """The base config with the fitted values (validated, all or nothing)."""
    flat = base.to_flat_dict()
    changes: dict[str, Any] = {}
    for p, v in zip(params, values):
        if p.index is None:
            changes[p.path] = float(v)
        else:
            lst = list(changes.get(p.path, flat[p.path]))
            lst[p.index] = float(v)
            changes[p.path] = lst
    return base.replace(changes)


# ---- prediction --------------------------------------------------------------------------------
def predict(cfg: Config, rec: Any, t_end: float | None = None) -> dict[str, np.ndarray]:
    """The model's theta2, theta3, theta4 at the record's sample times up to ``t_end``.

    Starts at rest in static equilibrium at theta1[0], command interpolated linearly between
    the samples.  Raises SimulationError if the integration fails."""
    t = np.asarray(rec.t, float)
    th1 = np.asarray(rec.theta1, float)
    if t_end is not None:
        n = int(np.searchsorted(t, t_end, side='right'))
        t, th1 = t[:max(n, 2)], th1[:max(n, 2)]
    dt = cfg.integrator.time_step
    steps = (t - t[0]) / dt
    ks = np.rint(steps)
    sim = Simulator(cfg, theta1=float(th1[0]), t0=float(t[0]), interpolation='linear')
    prof = SampledProfile(t, th1, 'linear')
    if np.all(np.abs(steps - ks) < 1e-6):
        k = ks.astype(np.int64)
        stride = int(np.gcd.reduce(np.diff(k))) if k.size > 1 else 1
        stride = max(stride, 1)
        traj = sim.run(prof, t[0] + (k[-1] + 0.5) * dt, record_every=stride)
        rows = k // stride
        th = traj.theta[rows]
    else:
        traj = sim.run(prof, float(t[-1]) + dt, record_every=1)
        th = np.column_stack([np.interp(t, traj.t, traj.theta[:, j]) for j in range(3)])
    return {name: th[:, j] for j, name in enumerate(OUTPUTS)}


def _rigid(cfg: Config) -> np.ndarray:
    return DriveModel(cfg).rigid_motion


# ---- the least-squares problem -----------------------------------------------------------------
class Problem:
    """Records + base config + fitted keys -> scaled residual vector r(x)."""

    def __init__(self, base: Config, params: Sequence[FitParameter], records: Sequence[Any]):
        if not records:
            raise IdentificationError('no records to fit')
        for i, r in enumerate(records):
            check_record(r, i)
        self.base = base
        self.params = list(params)
        self.records = [_as_arrays(r, i) for i, r in enumerate(records)]
        rigid = _rigid(base)
        self.outputs = [o for o in OUTPUTS if any(o in r['measured'] for r in self.records)]
        self.scale: dict[str, float] = {}
        for o in self.outputs:
            j = OUTPUTS.index(o)
            dev = np.concatenate([r['measured'][o] - rigid[j] * r['theta1']
                                  for r in self.records if o in r['measured']])
            s = float(np.sqrt(np.mean((dev - dev.mean()) ** 2)))
            if not s > 0:
                raise IdentificationError(f'{o}: the measured angle follows the command '
                                          'exactly; nothing to fit')
            self.scale[o] = s
        # white-noise level of each output from 4th differences (a 100 Hz mode sampled at
        # 10 kHz contributes (2 pi f dt)^4 = 2e-5 of its amplitude): var(d4 x) = 70 sigma^2
        self.noise: dict[str, float] = {}
        for o in self.outputs:
            d4 = np.concatenate([np.diff(r['measured'][o], 4) for r in self.records
                                 if o in r['measured']])
            self.noise[o] = float(np.sqrt(np.mean(d4 ** 2) / 70.0)) if d4.size else 0.0
        # residual weights: 1 / noise level (maximum likelihood for white Gaussian noise; a
        # noisy output such as a worm encoder that hardly sees the mesh wind-up cannot drown
        # the antenna's), at most 1000 / scale for noise-free data
        self.sigma = {o: max(self.noise[o], 1e-3 * self.scale[o]) for o in self.outputs}
        period = self.dominant_period()
        self.period = period
        self.n_evals = 0

    def dominant_period(self) -> float:
        """Period [s] of the lowest measured oscillation (for time windows)."""
        freqs = [f for f, _, _, fs in measured_frequencies(self.base, self.records)
                 if f < 0.4 * fs]
        if freqs:
            return 1.0 / min(freqs)
        return 1.0 / float(modes(self.base).frequencies_hz[0] or 1.0)

    @property
    def n(self) -> int:
        return len(self.params)

    def config(self, x: np.ndarray) -> Config:
        return apply_values(self.base, self.params, [p.from_x(v) for p, v in zip(self.params, x)])

    def windows(self, n_periods: Sequence[float] = (4.0, 10.0, 25.0)) -> list[float | None]:
        """Growing window lengths after the start of motion (None: whole records)."""
        start = min(_motion_times(r['t'], r['theta1'])[0] - r['t'][0] for r in self.records)
        longest = max(r['t'][-1] - r['t'][0] for r in self.records)
        out: list[float | None] = [start + k * self.period for k in n_periods
                                   if start + k * self.period < 0.8 * longest]
        return out + [None]

    def residuals(self, x: np.ndarray, window: float | None = None) -> np.ndarray:
        """Scaled residuals (predicted - measured) / scale over every record and output."""
        self.n_evals += 1
        parts = []
        try:
            cfg = self.config(np.asarray(x, float))
        except ConfigError:
            cfg = None
        for r in self.records:
            t_end = None if window is None else r['t'][0] + window
            n = r['t'].size if t_end is None else max(2, int(np.searchsorted(r['t'], t_end,
                                                                             side='right')))
            pred = None
            if cfg is not None:
                try:
                    pred = predict(cfg, r['rec'], t_end)
                except (SimulationError, ValueError):
                    pred = None
            for o in self.outputs:
                if o not in r['measured']:
                    continue
                meas = r['measured'][o][:n]
                if pred is None:   # failed run: a large, smooth penalty
                    parts.append(np.full(n, 10.0 * self.scale[o] / self.sigma[o]))
                else:
                    parts.append((pred[o][:n] - meas) / self.sigma[o])
        return np.concatenate(parts)

    def cost(self, x: np.ndarray, window: float | None = None) -> float:
        r = self.residuals(x, window)
        return 0.5 * float(r @ r)


def _as_arrays(rec: Any, i: int) -> dict[str, Any]:
    t = np.ascontiguousarray(rec.t, float)
    th1 = np.ascontiguousarray(rec.theta1, float)
    meas = {k: np.ascontiguousarray(v, float) for k, v in dict(rec.measured).items()}
    return {'t': t, 'theta1': th1, 'measured': meas, 'name': _name(rec, i),
            'rec': Record(t=t, theta1=th1, measured=meas, t0_ns=getattr(rec, 't0_ns', 0),
                          name=_name(rec, i))}


# ---- frequency start ---------------------------------------------------------------------------
def measured_frequencies(base: Config, records: Sequence[Any]
                         ) -> list[tuple[float, str, float, float]]:
    """(frequency [Hz], output, amplitude [rad], sample rate [Hz]) of the dominant
    oscillation of each measured output of each record: FFT of the measured angle minus the
    rigid motion after the command stops (after it starts if the rest is shorter than 16
    samples), resampled uniformly."""
    rigid = _rigid(base)
    out = []
    for r in records:
        rr = r if isinstance(r, dict) else _as_arrays(r, 0)
        t, th1 = rr['t'], rr['theta1']
        t_start, t_stop = _motion_times(t, th1)
        for o, meas in rr['measured'].items():
            j = OUTPUTS.index(o)
            y = meas - rigid[j] * th1
            for t_from in (t_stop, t_start):
                sel = t >= t_from
                if np.count_nonzero(sel) >= 16:
                    break
            ts, ys = t[sel], y[sel]
            if ts.size < 16:
                continue
            tu = np.linspace(ts[0], ts[-1], ts.size)
            yu = np.interp(tu, ts, ys)
            f = dominant_frequency(tu, yu, f_min=2.0 / max(ts[-1] - ts[0], 1e-9))
            if math.isfinite(f) and f > 0:
                fs = (ts.size - 1) / (ts[-1] - ts[0])
                out.append((f, o, 0.5 * float(np.ptp(ys)), float(fs)))
    return out


def frequency_start(problem: Problem, x0: np.ndarray | None = None,
                    regularization: float = 1e-3) -> tuple[np.ndarray, dict[str, Any]]:
    """Move the fitted keys (minimum change, within bounds) so that the model's linearised
    modes match the measured dominant frequencies; returns (x, info)."""
    x0 = np.zeros(problem.n) if x0 is None else np.asarray(x0, float)
    meas = measured_frequencies(problem.base, problem.records)
    base_f = np.asarray(modes(problem.config(x0)).undamped_hz, float)
    targets: dict[int, list[float]] = {}
    skipped = []
    for f, o, _, fs in meas:   # nearest model mode in log-frequency
        k = int(np.argmin(np.abs(np.log(base_f / f))))
        # A mode above Nyquist shows up aliased: a peak near such an alias is ambiguous; so is
        # a match to a mode the sampling cannot resolve or more than a factor 2 away.
        aliases = [abs(fm - round(fm / fs) * fs) for fm in base_f if fm > 0.5 * fs]
        if base_f[k] > 0.4 * fs or not (0.5 < f / base_f[k] < 2.0) or \
                any(abs(f - a) < 0.15 * a for a in aliases):
            skipped.append((round(f, 4), o))
            continue
        targets.setdefault(k, []).append(f)
    info: dict[str, Any] = {'measured_hz': sorted({round(f, 4) for f, _, _, _ in meas}),
                            'model_hz_before': base_f.tolist(),
                            'skipped_peaks': skipped}
    if not targets:
        info['note'] = 'no measured oscillation found'
        return x0, info
    idx = sorted(targets)
    goal = np.log([float(np.median(targets[k])) for k in idx])

    def fres(x: np.ndarray) -> np.ndarray:
        try:
            f = np.asarray(modes(problem.config(x)).undamped_hz, float)[idx]
        except (ConfigError, np.linalg.LinAlgError, ValueError):
            return np.full(len(idx) + problem.n, 1e3)
        return np.concatenate([np.log(np.maximum(f, 1e-9)) - goal,
                               math.sqrt(regularization) * (x - x0)])

    lo, hi = (np.array(b) for b in zip(*[p.x_bounds for p in problem.params]))
    res = least_squares(fres, np.clip(x0, lo, hi), bounds=(lo, hi), diff_step=1e-6,
                        max_nfev=200)
    f_after = np.asarray(modes(problem.config(res.x)).undamped_hz, float)
    info.update(model_hz_after=f_after.tolist(), matched_modes=[k + 1 for k in idx],
                target_hz=np.exp(goal).tolist())
    return res.x, info


# ---- one local fit -----------------------------------------------------------------------------
STRATEGIES: dict[str, dict[str, Any]] = {
    'local': dict(frequency_start=False, growing_windows=False, n_starts=1),
    'frequency': dict(frequency_start=True, growing_windows=False, n_starts=1),
    'windows': dict(frequency_start=False, growing_windows=True, n_starts=1),
    'frequency+windows': dict(frequency_start=True, growing_windows=True, n_starts=1),
    'multistart': dict(frequency_start=False, growing_windows=False, n_starts=8),
    'robust': dict(frequency_start=True, growing_windows=True, n_starts=4),
}


@dataclass
class FitOptions:
    """How :func:`identify` searches.  ``strategy`` presets (STRATEGIES) fill the three flags;
    ``n_starts`` counts every start (frequency start and base included)."""

    strategy: str = 'robust'
    frequency_start: bool | None = None
    growing_windows: bool | None = None
    n_starts: int | None = None
    seed: int = 0
    max_nfev: int = 100
    diff_step: float = 1e-6
    method: str = 'dogbox'     # least_squares method; trf creeps away from a start near a
    #                            bound (its step scales with the distance to the bound)
    workers: int | None = None
    scheduler: str | None = None
    serial: bool = False
    client: Any = None
    progress: bool = False

    def resolved(self) -> tuple[bool, bool, int]:
        if self.strategy not in STRATEGIES:
            raise IdentificationError(f'unknown strategy {self.strategy!r} (known: '
                                      f'{", ".join(STRATEGIES)})')
        s = STRATEGIES[self.strategy]
        fs = s['frequency_start'] if self.frequency_start is None else self.frequency_start
        gw = s['growing_windows'] if self.growing_windows is None else self.growing_windows
        ns = s['n_starts'] if self.n_starts is None else int(self.n_starts)
        return bool(fs), bool(gw), max(1, ns)


def _local_fit(problem: Problem, x0: np.ndarray, windows: Sequence[float | None],
               max_nfev: int, diff_step: float, method: str = 'dogbox') -> dict[str, Any]:
    lo, hi = (np.array(b) for b in zip(*[p.x_bounds for p in problem.params]))
    x = _interior(problem, x0)
    t0 = time.perf_counter()
    res = None
    stages = []
    for w in windows:
        res = least_squares(problem.residuals, x, bounds=(lo, hi), args=(w,), method=method,
                            diff_step=diff_step, max_nfev=max_nfev, x_scale=1.0,
                            xtol=1e-8, ftol=1e-8, gtol=1e-8)
        x = res.x
        stages.append({'window_s': w, 'cost': float(res.cost), 'nfev': int(res.nfev),
                       'status': int(res.status)})
    assert res is not None
    return {'x0': np.asarray(x0, float).tolist(), 'x': res.x.tolist(), 'cost': float(res.cost),
            'status': int(res.status), 'message': str(res.message), 'nfev':
            sum(s['nfev'] for s in stages), 'stages': stages, 'seconds': time.perf_counter() - t0}


def _interior(problem: Problem, x0: np.ndarray) -> np.ndarray:
    """x0 moved 1 % of the start box inside finite bounds: least_squares' trf scales a step by
    the distance to an active bound, so a start on a bound (a damping ratio of 0) never
    leaves it."""
    x = np.asarray(x0, float).copy()
    for i, p in enumerate(problem.params):
        lo, hi = p.x_bounds
        margin = 0.01 * (p.box[1] - p.box[0])
        if math.isfinite(lo):
            x[i] = max(x[i], lo + margin)
        if math.isfinite(hi):
            x[i] = min(x[i], hi - margin)
    return x


def jacobian(problem: Problem, x: np.ndarray, h: float = 1e-5) -> np.ndarray:
    """d residuals / dx by central differences (one-sided next to a bound)."""
    x = np.asarray(x, float)
    r0 = problem.residuals(x)
    J = np.empty((r0.size, x.size))
    for i, p in enumerate(problem.params):
        lo, hi = p.x_bounds
        e = np.zeros_like(x)
        e[i] = h
        if x[i] + h <= hi and x[i] - h >= lo:
            J[:, i] = (problem.residuals(x + e) - problem.residuals(x - e)) / (2 * h)
        elif x[i] + h <= hi:
            J[:, i] = (problem.residuals(x + e) - r0) / h
        else:
            J[:, i] = (r0 - problem.residuals(x - e)) / h
    return J


def _start_task(problem: Problem, x0: list[float], windows: list[float | None], max_nfev: int,
                diff_step: float, index: int, method: str = 'dogbox') -> dict[str, Any]:
    out = _local_fit(problem, np.asarray(x0), windows, max_nfev, diff_step, method)
    out['index'] = index
    return out


def _starts(problem: Problem, x_first: list[np.ndarray], n_starts: int, seed: int) -> list:
    starts = [np.asarray(x, float) for x in x_first][:n_starts]
    n_more = n_starts - len(starts)
    if n_more > 0:
        from scipy.stats import qmc
        box_lo = np.array([p.box[0] for p in problem.params])
        box_hi = np.array([p.box[1] for p in problem.params])
        m = max(1, math.ceil(math.log2(n_more)))
        u = qmc.Sobol(problem.n, scramble=True, seed=seed).random_base2(m)[:n_more]
        starts += list(box_lo + u * (box_hi - box_lo))
    return starts


# ---- result ------------------------------------------------------------------------------------
@dataclass
class FitResult:
    """Estimates, uncertainty, residuals and verdict of :func:`identify` (``to_dict`` for
    JSON)."""

    keys: list[str]
    units: list[str]
    base_values: list[float]
    values: list[float]
    ci95: list[tuple[float, float]]
    std_x: list[float]                    # standard deviation in the fitted coordinate
    log_scale: list[bool]
    correlation: list[list[float]]
    rms_before: dict[str, float]          # [rad], pooled over the records
    rms_after: dict[str, float]
    scale: dict[str, float]               # [rad] residual scale per output
    noise: dict[str, float]               # [rad] white-noise estimate per output
    per_record: list[dict[str, Any]]
    cost: float
    converged: bool
    trustworthy: bool
    problems: list[str]                   # why it is not trustworthy
    warnings: list[str]
    strategy: dict[str, Any]
    starts: list[dict[str, Any]]
    frequency_info: dict[str, Any]
    seconds: float
    config: Config = field(repr=False)
    base_config: Config = field(repr=False)

    def to_dict(self) -> dict[str, Any]:
        return {
            'parameters': [
                {'key': k, 'unit': u, 'base': b, 'estimate': v, 'ci95': list(ci),
                 'log_scale': lg, 'std_fitted_coordinate': s}
                for k, u, b, v, ci, lg, s in zip(self.keys, self.units, self.base_values,
                                                 self.values, self.ci95, self.log_scale,
                                                 self.std_x)],
            'correlation': self.correlation, 'rms_before_rad': self.rms_before,
            'rms_after_rad': self.rms_after, 'residual_scale_rad': self.scale,
            'noise_estimate_rad': self.noise,
            'records': self.per_record, 'cost': self.cost, 'converged': self.converged,
            'trustworthy': self.trustworthy, 'problems': self.problems,
            'warnings': self.warnings, 'strategy': self.strategy, 'starts': self.starts,
            'frequency_start': self.frequency_info, 'seconds': self.seconds,
        }

    def table(self) -> str:
        lines = [f'{"parameter":<44} {"base":>12} {"estimate":>12} {"95 % CI":>27}  unit']
        for k, u, b, v, (lo, hi) in zip(self.keys, self.units, self.base_values, self.values,
                                        self.ci95):
            lines.append(f'{k:<44} {b:>12.6g} {v:>12.6g} [{lo:>11.6g}, {hi:>11.6g}]  {u}')
        lines.append('residual RMS per output [rad] (before -> after, % of the residual scale):')
        for o in self.rms_after:
            s = self.scale[o]
            lines.append(f'  {o}: {self.rms_before[o]:.4g} -> {self.rms_after[o]:.4g} '
                         f'({100 * self.rms_before[o] / s:.1f} % -> '
                         f'{100 * self.rms_after[o] / s:.2f} %; noise level '
                         f'{self.noise[o]:.3g})')
        if len(self.keys) > 1:
            lines.append('correlation:')
            for k, row in zip(self.keys, self.correlation):
                lines.append(f'  {k:<44} ' + ' '.join(f'{c:+.3f}' for c in row))
        for w in self.warnings:
            lines.append(f'WARNING: {w}')
        for p in self.problems:
            lines.append(f'NOT TRUSTWORTHY: {p}')
        return '\n'.join(lines)


def _rms(problem: Problem, cfg: Config) -> tuple[dict[str, float], list[dict[str, Any]]]:
    """Pooled and per-record RMS of predicted - measured [rad] per output."""
    pooled: dict[str, list[np.ndarray]] = {o: [] for o in problem.outputs}
    per = []
    for r in problem.records:
        try:
            pred = predict(cfg, r['rec'])
        except (SimulationError, ValueError):
            pred = None
        row: dict[str, Any] = {'name': r['name']}
        for o, meas in r['measured'].items():
            e = (pred[o] - meas) if pred is not None else np.full(meas.size, np.nan)
            pooled[o].append(e)
            row[o] = float(np.sqrt(np.mean(e ** 2)))
        per.append(row)
    return ({o: float(np.sqrt(np.mean(np.concatenate(v) ** 2))) for o, v in pooled.items()},
            per)


def identify(base: Config, records: Sequence[Any], keys: Sequence[str], *,
             bounds: Mapping[str, tuple[float, float]] | None = None,
             options: FitOptions | None = None,
             on_start_done: Callable[[dict], None] | None = None) -> FitResult:
    """Fit ``keys`` of ``base`` to the records jointly (see the module docstring)."""
    t_begin = time.perf_counter()
    opt = options or FitOptions()
    use_freq, use_windows, n_starts = opt.resolved()
    params = fit_parameters(base, keys, bounds)
    problem = Problem(base, params, records)
    x_base = np.zeros(problem.n)
    freq_info: dict[str, Any] = {}
    first = []
    if use_freq:
        x_f, freq_info = frequency_start(problem, x_base)
        first.append(x_f)
    first.append(x_base)
    starts = _starts(problem, first, n_starts, opt.seed)
    windows = problem.windows() if use_windows else [None]
    results = _run_starts(problem, starts, windows, opt, on_start_done)
    results.sort(key=lambda r: r['index'])
    best = min(results, key=lambda r: r['cost'] if math.isfinite(r['cost']) else np.inf)
    x = np.asarray(best['x'])
    # Jacobian at the estimate (full records) for the uncertainty; least_squares' own jac is
    # scaled by the distance to active bounds and unusable for that
    J = jacobian(problem, x)
    r = problem.residuals(x)
    m, n = r.size, problem.n
    s2 = float(r @ r) / max(m - n, 1)
    problems: list[str] = []
    warnings: list[str] = []
    if base.friction.direction == 'set_valued':
        # Measured: with exact stick-slip the residual is not smooth in the parameters and
        # least squares stops far from the optimum (48 % residual on the test drives).
        warnings.append('friction.direction = set_valued: the residual is not smooth in the '
                        'parameters and the fit may stall; fit with --set '
                        'friction.direction=regularized (see docs/identification.md)')
    U, sv, Vt = np.linalg.svd(J, full_matrices=False)
    rank_tol = sv[0] * 1e-10 if sv.size and sv[0] > 0 else 0.0
    if sv.size == 0 or sv[-1] <= rank_tol:
        weakest = params[int(np.argmax(np.abs(Vt[-1])))].key if sv.size else '?'
        problems.append(f'the data do not determine {weakest} (singular Jacobian)')
        cov = np.full((n, n), np.nan)
    else:
        cov = s2 * (Vt.T / sv ** 2) @ Vt
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid='ignore', divide='ignore'):
        corr = cov / np.outer(std, std)
    values, ci = [], []
    for p, xi, si in zip(params, x, std):
        values.append(p.from_x(float(xi)))
        if not math.isfinite(si):
            ci.append((math.nan, math.nan))
        elif p.log:
            ci.append((p.from_x(xi - Z95 * si), p.from_x(xi + Z95 * si)))
        else:
            ci.append((p.from_x(xi - Z95 * si), p.from_x(xi + Z95 * si)))
    cfg_fit = problem.config(x)
    rms_before, per_before = _rms(problem, base)
    rms_after, per_after = _rms(problem, cfg_fit)
    per_record = [{'name': a['name'],
                   'rms_before_rad': {k: v for k, v in a.items() if k != 'name'},
                   'rms_after_rad': {k: v for k, v in b.items() if k != 'name'}}
                  for a, b in zip(per_before, per_after)]
    converged = best['status'] > 0
    if not converged:
        problems.append(f'the fit did not converge within {opt.max_nfev} evaluations '
                        f'({best["message"]})')
    for o in problem.outputs:
        rel = rms_after[o] / problem.scale[o]
        if not math.isfinite(rel):
            problems.append(f'the fitted model cannot be simulated on every record ({o})')
        elif rel > 0.25 and rms_after[o] > 3.0 * problem.noise[o]:
            problems.append(f'{o}: residual RMS {100 * rel:.0f} % of the measured motion '
                            f'(> 25 %) and {rms_after[o] / max(problem.noise[o], 1e-300):.1f}'
                            ' x the noise level: the model does not match the records')
        elif rms_after[o] > rms_before[o] * 1.0001:
            warnings.append(f'{o}: residual RMS grew ({rms_before[o]:.3g} -> '
                            f'{rms_after[o]:.3g} rad)')
    for i in range(n):
        for j in range(i + 1, n):
            c = corr[i, j]
            if math.isfinite(c) and abs(c) > CORRELATION_WARN:
                warnings.append(f'{params[i].key} and {params[j].key} are correlated '
                                f'({c:+.3f}): the data can hardly separate them')
    for p, v, (clo, chi), si in zip(params, values, ci, std):
        bx = p.x_bounds
        xi = p.to_x(v)
        if (math.isfinite(bx[0]) and xi - bx[0] < 1e-6) or \
                (math.isfinite(bx[1]) and bx[1] - xi < 1e-6):
            warnings.append(f'{p.key} = {v:.6g} sits on a bound: the optimum may lie outside')
        if math.isfinite(si) and p.log and si > 0.5:
            warnings.append(f'{p.key}: 95 % interval {clo:.3g} .. {chi:.3g} spans more than '
                            f'a factor {math.exp(2 * Z95 * 0.5):.0f}: hardly determined by the '
                            'data (its value in the YAML is arbitrary; fix it or record a move '
                            'that excites it)')
        elif math.isfinite(si) and not p.log and Z95 * si * p.scale > max(abs(v), p.scale):
            warnings.append(f'{p.key}: 95 % interval {clo:.3g} .. {chi:.3g} is wider than the '
                            'value: poorly determined')
    # Another start that fits statistically as well (cost within the 95 % confidence region,
    # 0.5 s^2 chi2(0.95, n)) but lies far outside the linearised region (Mahalanobis distance
    # > 2 sqrt(chi2)): a second minimum, the optimum is not unique.
    from scipy.stats import chi2
    c95 = float(chi2.ppf(0.95, n))
    JtJ = J.T @ J
    for rr in results:
        if rr is best or not math.isfinite(rr['cost']):
            continue
        dx = np.asarray(rr['x']) - x
        if rr['cost'] - best['cost'] <= 0.5 * s2 * c95 and \
                float(dx @ JtJ @ dx) / s2 > 4.0 * c95:
            far = [f'{p.key} = {p.from_x(float(xi)):.4g}' for p, xi, d, si in
                   zip(params, rr['x'], dx, std) if abs(d) > 2 * Z95 * max(si, 1e-300)]
            warnings.append(f'start {rr["index"] + 1} fits as well with '
                            f'{", ".join(far) or "other values"}: the data do not fix '
                            'these values (both fit the records equally well)')
            break
    return FitResult(
        keys=[p.key for p in params], units=[p.unit for p in params],
        base_values=[p.base for p in params], values=values, ci95=ci,
        std_x=[float(s) for s in std], log_scale=[p.log for p in params],
        correlation=np.where(np.isfinite(corr), corr, np.nan).tolist(),
        rms_before=rms_before, rms_after=rms_after, scale=dict(problem.scale),
        noise=dict(problem.noise),
        per_record=per_record, cost=float(0.5 * r @ r), converged=converged,
        trustworthy=not problems, problems=problems, warnings=warnings,
        strategy={'name': opt.strategy, 'frequency_start': use_freq,
                  'growing_windows': use_windows, 'n_starts': n_starts,
                  'windows_s': windows},
        starts=results, frequency_info=freq_info, seconds=time.perf_counter() - t_begin,
        config=cfg_fit, base_config=base)


def _run_starts(problem: Problem, starts: Sequence[np.ndarray],
                windows: Sequence[float | None], opt: FitOptions,
                on_done: Callable[[dict], None] | None) -> list[dict[str, Any]]:
    """Local fits from every start: in this process (``serial`` or a single start) or on Dask
    (the sweeps' engine: a LocalCluster by default, ``scheduler`` for a cluster)."""
    out: list[dict[str, Any]] = []
    bar = None

    def start_bar() -> None:   # after the engine is up: no bar before a connection error
        nonlocal bar
        if opt.progress:
            import sys

            from tqdm import tqdm
            bar = tqdm(total=len(starts), desc='identify', unit='start', file=sys.stderr,
                       dynamic_ncols=True)

    def done(r: dict[str, Any]) -> None:
        out.append(r)
        if bar is not None:
            bar.set_postfix(best=f'{min(o["cost"] for o in out):.4g}')
            bar.update()
        if on_done:
            on_done(r)

    try:
        if opt.serial or (len(starts) == 1 and opt.client is None and opt.scheduler is None):
            start_bar()
            for i, x0 in enumerate(starts):
                done(_start_task(problem, list(x0), list(windows), opt.max_nfev,
                                 opt.diff_step, i, opt.method))
        else:
            from .studies.engine import _dask_client, warm_up
            with _dask_client(opt.client, opt.scheduler, opt.workers) as cl:
                from distributed import as_completed
                if len(cl.run(warm_up)) == 0:
                    raise ConnectionError('the Dask cluster has no workers')
                pf = cl.scatter(problem, broadcast=True)
                start_bar()
                futs = [cl.submit(_start_task, pf, list(x0), list(windows), opt.max_nfev,
                                  opt.diff_step, i, opt.method, pure=False)
                        for i, x0 in enumerate(starts)]
                try:
                    for fut in as_completed(futs):
                        done(fut.result())
                finally:
                    for f in futs:
                        f.cancel()
    finally:
        if bar is not None:
            bar.close()
    return out


# ---- validation on held-out records ------------------------------------------------------------
def prediction_errors(cfg: Config, records: Sequence[Any]) -> list[dict[str, Any]]:
    """Per record and measured output: RMS of predicted - measured [rad], the oscillation
    amplitude (half the peak-to-peak range of the measured angle minus the rigid motion
    theta1 * u_rigid [rad]) and their ratio ``rel``."""
    rigid = _rigid(cfg)
    out = []
    for i, rec in enumerate(records):
        check_record(rec, i)
        rr = _as_arrays(rec, i)
        try:
            pred = predict(cfg, rr['rec'])
        except SimulationError as exc:
            raise IdentificationError(f'{rr["name"]}: the model cannot be simulated ({exc})'
                                      ) from None
        row: dict[str, Any] = {'name': rr['name']}
        for o, meas in rr['measured'].items():
            e = pred[o] - meas
            amp = 0.5 * float(np.ptp(meas - rigid[OUTPUTS.index(o)] * rr['theta1']))
            rms = float(np.sqrt(np.mean(e ** 2)))
            row[o] = {'rms_rad': rms, 'amplitude_rad': amp,
                      'rel': rms / amp if amp > 0 else math.inf}
        out.append(row)
    return out


def validate(cfg: Config, records: Sequence[Any]) -> list[dict[str, Any]]:
    """Alias of :func:`prediction_errors` (the ``--validate`` report)."""
    return prediction_errors(cfg, records)
