# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Offline studies: the paper's Sec. 3 experiment and Sec. 4 parametric sweeps.

Pure study logic (no argparse, no rclpy, no plotting): build cases, run one case, measure
oscillation metrics from a time series, and run many cases serially or on Dask.

Definitions used everywhere (docs/studies.md):

* **end of the move** ``t_move``: the time after which the command theta1 no longer changes
  (start_time + move_time for ramp/trapezoidal/s-curve, start_time for a step, the last
  change of a sampled series); the post-move window starts at the first recorded step at
  or after ``t_move`` at which theta1 has its final value.
* **equilibrium** ``theta_eq``: the static equilibrium of the drive at the final command
  (:func:`worm_gear_sim.modal.static_equilibrium`; at rest the regularised friction is zero,
  so this is the rest point the ringing decays to; it includes shaft/mesh wind-up from an
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
import os
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from .modal import static_equilibrium
from .params import Config, config_from_mapping, derive
from .profiles import Profile, SampledProfile, make_profile
from .simulation import Simulator, Trajectory

__all__ = [
    'Case', 'Study', 'PAPER_STUDIES', 'METRIC_COLUMNS', 'move_end_time', 'equilibrium',
    'oscillation_metrics', 'dominant_frequency', 'zero_crossing_frequency', 'run_case',
    'run_cases', 'paper_study', 'param_study', 'module_overrides', 'experiment_cases',
    'experiment_table', 'EXPERIMENT_COLUMNS', 'parse_values', 'envelope_rows',
    'ENVELOPE_COLUMNS', 'COMPARE_SEP',
]


# ---- cases and studies -------------------------------------------------------------------
@dataclass(frozen=True)
class Case:
    """One run of a study: the base config plus dotted ``overrides``."""

    study: str
    series: str            # one line/bar group of the figure
    x: float               # abscissa (numeric; categorical studies use the index)
    label: str             # human-readable value, e.g. 'G x 10'
    overrides: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Study:
    """A named list of cases plus what the figure needs."""

    name: str
    title: str
    x_label: str
    cases: tuple[Case, ...]
    x_log: bool = False
    categorical: bool = False
    note: str = ''
    paper_figure: str = ''


# Table 1 geometry at module M2 (what the module study scales).
_M_REF = 2.0
_MODULE_SCALED = ('geometry.worm_pitch_radius', 'geometry.gear_pitch_radius', 'geometry.lead',
                  'geometry.worm_length', 'geometry.gear_width')


def module_overrides(base: Config, module: float, scaling: str = 'geometry') -> dict[str, Any]:
    """Overrides that turn the base (M2) drive into module ``module``.

    ``scaling='geometry'``: a geometrically similar worm set.  The worm and gear pitch radii,
    the lead (pi M per revolution) and the worm/gear body lengths scale with M/2, so the
    ratio (1:56), the lead angle and the pressure angle are unchanged; the tooth stiffnesses
    scale with M (``geometry.module``, the M factor of Eqs. 16-17);
    inertias J_w, J_g grow as M^5 (solid cylinders).  Shafts, bearings and flywheel are
    unchanged (they are the radar's, not the gear set's).

    ``scaling='stiffness'``: only the tooth stiffnesses scale with M (the reading of the
    paper's Sec. 4.2: "when the modulus of gear is larger ... the rigidity of the teeth is
    larger"); geometry and inertias stay at M2.
    """
    if scaling not in ('geometry', 'stiffness'):
        raise ValueError(f'module scaling must be geometry or stiffness, got {scaling!r}')
    if not module > 0:
        raise ValueError(f'module must be > 0, got {module!r}')
    f = module / _M_REF
    flat = base.to_flat_dict()
    # tooth stiffness scales with geometry.module itself (the M of Eqs. 16-17)
    out: dict[str, Any] = {'geometry.module': float(module)}
    if scaling == 'geometry':
        for key in _MODULE_SCALED:
            out[key] = flat[key] * f
    return out


def _g_cases(study: str, series: str, keys: Sequence[str], base: Config,
             factors: Sequence[float]) -> list[Case]:
    flat = base.to_flat_dict()
    out = []
    for fac in factors:
        ov = {k: flat[k] * fac for k in keys}
        out.append(Case(study, series, float(fac), f'x{fac:g}', ov))
    return out


SHEAR_FACTORS = (0.25, 0.5, 1.0, 2.0, 5.0, 10.0, 100.0, 1000.0, 10000.0)
TOOTH_FACTORS = (0.25, 0.5, 1.0, 2.0, 4.0, 10.0, 100.0)
FLYWHEEL_RADII = tuple(round(0.01 * k, 2) for k in range(2, 17))   # 0.02 ... 0.16 m
MODULES = (1.0, 2.0, 3.0, 4.0, 5.0)
FRICTION_FACTORS = (0.0, 0.5, 1.0, 1.5, 2.0, 3.0)
CONSTANT_MU = (0.0, 0.05, 0.1, 0.145, 0.2, 0.3, 0.45)


def paper_study(name: str, base: Config) -> Study:
    """The paper's Sec. 4 studies, by name (see :data:`PAPER_STUDIES`)."""
    if name == 'flywheel':
        cases = (Case(name, 'flywheel', 0.0, 'without', {'geometry.flywheel_enabled': False}),
                 Case(name, 'flywheel', 1.0, 'with', {'geometry.flywheel_enabled': True}))
        return Study(name, 'Flywheel off / on (paper Figs. 12-13)', 'flywheel', cases,
                     categorical=True, paper_figure='Figs. 12-13',
                     note='without the flywheel theta4 is the gear-shaft end carrying a third '
                          'of the shaft inertia (core decision, params.derive)')
    if name == 'flywheel_diameter':
        cases = tuple(Case(name, 'flywheel diameter', 2 * r, f'D={2 * r:g} m',
                           {'geometry.flywheel_enabled': True, 'geometry.flywheel_radius': r})
                      for r in FLYWHEEL_RADII)
        return Study(name, 'Flywheel diameter (paper Fig. 14; Table 1: D = 0.24 m)',
                     'flywheel diameter 2 R5 [m]', cases, paper_figure='Fig. 14',
                     note='flywheel length L5 = 0.03 m kept; J_4 grows as D^4')
    if name == 'module':
        cases = []
        for scaling, series in (('geometry', 'similar gear set (r_w r_g lead L2 L3 k ~ M)'),
                                ('stiffness', 'tooth stiffness only (k ~ M)')):
            for m in MODULES:
                cases.append(Case(name, series, m, f'M{m:g}', module_overrides(base, m, scaling)))
        return Study(name, 'Module M1-M5 (paper Fig. 15)', 'module M [mm]', tuple(cases),
                     paper_figure='Fig. 15',
                     note='see module_overrides(): shafts, bearings and flywheel unchanged')
    if name == 'shear_modulus':
        w, g = 'materials.worm_shaft_shear_modulus', 'materials.gear_shaft_shear_modulus'
        cases = (_g_cases(name, 'both shafts (paper)', (w, g), base, SHEAR_FACTORS)
                 + _g_cases(name, 'worm shaft only', (w,), base, SHEAR_FACTORS)
                 + _g_cases(name, 'gear shaft only', (g,), base, SHEAR_FACTORS))
        return Study(name, 'Shaft shear modulus up to rigid (paper Fig. 16)',
                     'G / 77 GPa', tuple(cases), x_log=True, paper_figure='Fig. 16',
                     note='x 10000 is rigid for this drive (shaft modes above 800 kHz)')
    if name == 'tooth_stiffness':
        w, g = 'mesh.worm_tooth_stiffness_multiplier', 'mesh.gear_tooth_stiffness_multiplier'
        cases = (_g_cases(name, 'both teeth (paper)', (w, g), base, TOOTH_FACTORS)
                 + _g_cases(name, 'worm tooth only', (w,), base, TOOTH_FACTORS)
                 + _g_cases(name, 'gear tooth only', (g,), base, TOOTH_FACTORS))
        return Study(name, 'Tooth stiffness multiplier (paper Fig. 17)',
                     'tooth stiffness multiplier', tuple(cases), x_log=True,
                     paper_figure='Fig. 17')
    if name == 'friction':
        flat = base.to_flat_dict()
        mk, md = flat['friction.mu_kinetic'], flat['friction.mu_stribeck_drop']
        cases = []
        for f in FRICTION_FACTORS:
            cases.append(Case(name, 'Eq. 18 scaled', (mk + md) * f, f'Eq.18 x{f:g}',
                              {'friction.model': 'stribeck', 'friction.mu_kinetic': mk * f,
                               'friction.mu_stribeck_drop': md * f}))
        for mu in CONSTANT_MU:
            cases.append(Case(name, 'constant mu', mu, f'mu={mu:g}',
                              {'friction.model': 'constant',
                               'friction.constant_coefficient': mu}))
        return Study(name, 'Friction coefficient (paper Fig. 18)',
                     'friction coefficient at rest mu(0)', tuple(cases),
                     paper_figure='Fig. 18',
                     note='Eq. 18 scaled: mu_kinetic and mu_stribeck_drop times a factor; '
                          'x = mu(0) = factor x 0.1527')
    raise ValueError(f'unknown study {name!r}; known: {", ".join(PAPER_STUDIES)}')


PAPER_STUDIES: tuple[str, ...] = ('flywheel', 'flywheel_diameter', 'module', 'shear_modulus',
                                  'tooth_stiffness', 'friction')


def parse_values(text: str | None = None, range_spec: str | None = None,
                 log: bool = False) -> list[str]:
    """Values of a user sweep: 'a,b,c' or a range 'start:stop:num' (linear or log spaced);
    returned as strings (typed per parameter by the caller)."""
    if (text is None) == (range_spec is None):
        raise ValueError('give exactly one of --values and --range')
    if text is not None:
        vals = [v.strip() for v in text.split(',')]
        if not vals or any(v == '' for v in vals):
            raise ValueError(f'--values: empty entry in {text!r}')
        return vals
    parts = range_spec.split(':')
    if len(parts) != 3:
        raise ValueError(f'--range must be start:stop:num, got {range_spec!r}')
    try:
        a, b, n = float(parts[0]), float(parts[1]), int(parts[2])
    except ValueError:
        raise ValueError(f'--range must be start:stop:num with numbers, got {range_spec!r}') \
            from None
    if n < 1 or n > 100000:
        raise ValueError(f'--range: num must be 1..100000, got {n}')
    if not (math.isfinite(a) and math.isfinite(b)):
        raise ValueError('--range: start and stop must be finite')
    if log:
        if a <= 0 or b <= 0:
            raise ValueError('--log range needs start and stop > 0')
        xs = np.geomspace(a, b, n)
    else:
        xs = np.linspace(a, b, n)
    return [repr(float(x)) for x in xs]


def param_study(paths: Sequence[str], values: Sequence[Any], labels: Sequence[str] | None = None,
                name: str = 'custom') -> Study:
    """A user sweep: every path in ``paths`` set to each value in turn (typed values)."""
    if not paths:
        raise ValueError('no parameter path given')
    labels = list(labels) if labels is not None else [str(v) for v in values]
    numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)
    cases = []
    for i, (v, lab) in enumerate(zip(values, labels)):
        x = float(v) if numeric else float(i)
        cases.append(Case(name, ' = '.join(paths) if len(paths) > 1 else paths[0], x, lab,
                          {p: v for p in paths}))
    positive = numeric and all(float(v) > 0 for v in values)
    spread = numeric and positive and max(values) / min(values) >= 100
    return Study(name, f'Sweep of {", ".join(paths)}', ', '.join(paths), tuple(cases),
                 x_log=bool(spread), categorical=not numeric)


# ---- metrics ------------------------------------------------------------------------------
def move_end_time(cfg: Config, profile: Profile | None = None) -> float:
    """Time after which theta1 stays constant (see module docstring)."""
    inp = cfg.input
    if isinstance(profile, SampledProfile):
        v = profile.values
        changed = np.nonzero(v != v[-1])[0]
        if changed.size == 0:
            return float(profile.times[0])
        return float(profile.times[changed[-1] + 1])
    if inp.profile == 'step':
        return inp.start_time
    return inp.start_time + inp.move_time


def equilibrium(cfg: Config, theta1_final: float, p: np.ndarray | None = None) -> np.ndarray:
    """Static equilibrium (theta2, theta3, theta4) at the final command."""
    from .model import pack_parameters
    return static_equilibrium(pack_parameters(cfg) if p is None else p, theta1_final)


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
    err4 = float(np.max(np.abs(traj.theta[:, 2] - th1 * traj.output_ratio)))
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


# ---- running one case ---------------------------------------------------------------------
def _as_config(base: Config | Mapping[str, Any]) -> Config:
    return base if isinstance(base, Config) else config_from_mapping(base, source='base')


def case_config(base: Config | Mapping[str, Any], overrides: Mapping[str, Any]) -> Config:
    """The case's config: base (Config or nested dict) with the overrides (validated)."""
    cfg = _as_config(base)
    return cfg.replace(dict(overrides)) if overrides else cfg


def run_case(base: Config | Mapping[str, Any], overrides: Mapping[str, Any] | None = None,
             t_end: float | None = None, profile: Profile | None = None,
             keep_trajectory: bool = False) -> dict[str, Any]:
    """Run one case from rest and return its metrics (small, picklable) plus timings:
    ``kernel_s`` (the Newmark integration itself) and ``case_s`` (everything, including
    config validation, parameter packing, equilibrium and metrics), wall clock, and the same
    as CPU time of this thread (``kernel_cpu_s``, ``case_cpu_s``)."""
    t0, c0 = time.perf_counter(), time.thread_time()
    cfg = case_config(base, overrides or {})
    prof = make_profile(cfg.input) if profile is None else profile
    t_end = cfg.input.end_time if t_end is None else float(t_end)
    th0 = float(prof.theta1(np.array([0.0]))[0])
    sim = Simulator(cfg, theta1=th0)
    tk, ck = time.perf_counter(), time.thread_time()
    traj = sim.run(prof, t_end, record_every=1)
    kernel, kernel_cpu = time.perf_counter() - tk, time.thread_time() - ck
    t_move = move_end_time(cfg, prof)
    eq = static_equilibrium(sim.p, float(traj.theta1[-1]))
    out = oscillation_metrics(traj, t_move, eq)
    d = derive(cfg)
    out.update(t_move=t_move, t_end=float(traj.t[-1]), J_4=d.J_4, ratio=d.ratio,
               steps=traj.stats.get('steps', 0),
               subdivision_events=traj.stats.get('subdivision_events', 0),
               kernel_s=kernel, case_s=time.perf_counter() - t0, kernel_cpu_s=kernel_cpu,
               case_cpu_s=time.thread_time() - c0)
    if keep_trajectory:
        out['trajectory'] = traj
    return out


def _run_payload(payload: tuple) -> dict[str, Any]:
    """Run one case: (index, base nested dict, overrides, t_end) -> result dict."""
    index, base, overrides, t_end = payload
    res = run_case(base, overrides, t_end)
    res['index'] = index
    return res


def _run_chunk(base: Mapping[str, Any], items: Sequence[tuple]) -> list[dict[str, Any]]:
    """Worker entry point: several cases sharing one base config (fewer, larger tasks keep
    the scheduler's per-task cost small against ~50 ms cases)."""
    return [_run_payload((i, base, ov, t_end)) for i, ov, t_end in items]


# ---- running many cases -------------------------------------------------------------------
def _progress(total: int, enabled: bool, desc: str):
    if not enabled:
        return None
    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover - tqdm is a declared dependency
        return None
    import sys
    return tqdm(total=total, desc=desc, unit='case', file=sys.stderr, leave=True,
                dynamic_ncols=True)


def run_cases(base: Config, cases: Sequence[Case], *, workers: int | None = None,
              scheduler: str | None = None, serial: bool = False, progress: bool = False,
              t_end: float | None = None, client: Any = None, chunk_size: int | None = None,
              on_result: Callable[[dict], None] | None = None) -> list[dict[str, Any]]:
    """Run the cases and return one result dict per case, in case order.

    Engines: ``serial=True`` runs in this process; ``client`` uses a given
    dask.distributed Client; ``scheduler`` connects to a running Dask scheduler
    (``tcp://host:8786``); otherwise a Dask LocalCluster is started with ``workers``
    processes (default: all cores), one thread each.  The base config goes to every worker
    once (as a plain dict); each task carries a chunk of cases (their overrides; default
    chunk: about 16 tasks per worker, at most 16 cases) and returns only their metrics.
    Results do not depend on the engine (same code, same arithmetic, bit for bit).
    """
    base_map = base.to_nested_dict()
    items = [(i, dict(c.overrides), t_end) for i, c in enumerate(cases)]
    results: list[dict[str, Any] | None] = [None] * len(cases)
    studies = list(dict.fromkeys(c.study for c in cases))
    bar = None

    def start_bar() -> None:   # after the engine is up: no bar before a connection error
        nonlocal bar
        bar = _progress(len(cases), progress, studies[0] if len(studies) == 1 else 'sweep')

    def done(r: dict[str, Any]) -> None:
        results[r['index']] = r
        if on_result:
            on_result(r)
        if bar:
            bar.update()

    try:
        if serial:
            start_bar()
            for i, ov, te in items:
                done(_run_payload((i, base_map, ov, te)))
        else:
            with _dask_client(client, scheduler, workers) as cl:
                from distributed import as_completed
                n_workers = len(cl.run(warm_up))
                if n_workers == 0:
                    raise ConnectionError('the Dask cluster has no workers')
                size = chunk_size if chunk_size else \
                    max(1, min(16, math.ceil(len(items) / (16 * n_workers))))
                chunks = [items[k:k + size] for k in range(0, len(items), size)]
                base_future = cl.scatter(base_map, broadcast=True)
                futures = [cl.submit(_run_chunk, base_future, ch, pure=False)
                           for ch in chunks]
                start_bar()
                try:
                    for fut in as_completed(futures):
                        for r in fut.result():
                            done(r)
                finally:
                    for f in futures:
                        f.cancel()
    finally:
        if bar:
            bar.close()
    out = []
    for c, r in zip(cases, results):
        assert r is not None
        row = {'study': c.study, 'series': c.series, 'x': c.x, 'label': c.label}
        row.update({k: v for k, v in r.items() if k != 'index'})
        row['overrides'] = dict(c.overrides)
        out.append(row)
    return out


# Dask's nanny sets MALLOC_TRIM_THRESHOLD_ in its workers, which also switches off glibc's
# dynamic mmap threshold: every ~1 MB record array of a case is then mmap'ed and unmapped
# (8000 page faults, ~10 ms of system time per 0.5 s case, a third of the kernel time).
# A fixed 16 MB mmap threshold keeps them in the heap.  Set the same variables on the
# workers of a remote cluster (see docs/studies.md).
WORKER_ENV = {
    'distributed.nanny.pre-spawn-environ.MALLOC_MMAP_THRESHOLD_': 1 << 24,
    'distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_': 1 << 28,
}


def warm_up() -> float:
    """Import the model and load its compiled (cached) kernels in this process; returns the
    seconds it took.  Run on every Dask worker before the cases so that the first case of each
    worker does not pay for imports and numba cache loading."""
    t0 = time.perf_counter()
    cfg = Config()
    sim = Simulator(cfg)
    sim.run(make_profile(cfg.input), 10 * cfg.integrator.time_step)
    static_equilibrium(sim.p, 0.0)
    return time.perf_counter() - t0


class _dask_client:
    """Context manager yielding a Client: the given one, a remote scheduler, or a
    LocalCluster of ``workers`` processes (closed on exit)."""

    def __init__(self, client: Any, scheduler: str | None, workers: int | None):
        self.client, self.scheduler, self.workers = client, scheduler, workers
        self._own: list[Any] = []

    def __enter__(self):
        if self.client is not None:
            return self.client
        import logging

        from distributed import Client, LocalCluster
        if self.scheduler:
            try:
                cl = Client(self.scheduler, timeout='5s')
            except OSError as exc:
                raise ConnectionError(f'cannot reach Dask scheduler {self.scheduler}: '
                                      f'{exc}') from None
            self._own.append(cl)
            return cl
        import dask
        n = self.workers or os.cpu_count() or 1
        with dask.config.set(WORKER_ENV):
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                   dashboard_address=None, silence_logs=logging.ERROR)
        self._own.append(cluster)
        cl = Client(cluster)
        self._own.insert(0, cl)
        return cl

    def __exit__(self, *exc):
        for obj in self._own:
            try:
                obj.close()
            except Exception:  # noqa: BLE001 - best effort shutdown
                pass
        return False


def local_cluster_client(workers: int | None = None):
    """A started LocalCluster client (caller closes client and cluster); for benchmarks."""
    return _dask_client(None, None, workers)


COMPARE_SEP = ' | '
ENVELOPE_COLUMNS: tuple[str, ...] = ('study', 'series', 'label', 'x', 'amp2', 'amp4',
                                     'amp2_at', 'amp4_at', 'cases')


def envelope_rows(rows: Sequence[Mapping[str, Any]], sep: str = COMPARE_SEP) -> list[dict]:
    """Worst case over a ``--compare`` family: rows whose series read ``'<base> | k=v'`` are
    grouped by (base series, label) and reduced to the maximum amplitudes, with the compared
    value that produced each maximum (``amp2_at``, ``amp4_at``)."""
    groups: dict[tuple[str, str], list[Mapping[str, Any]]] = {}
    for r in rows:
        base, _, tag = str(r['series']).partition(sep)
        groups.setdefault((base, str(r['label'])), []).append({**r, '_tag': tag})
    out = []
    for (base, label), rs in groups.items():
        i2 = max(range(len(rs)), key=lambda i: rs[i]['amp2'])
        i4 = max(range(len(rs)), key=lambda i: rs[i]['amp4'])
        out.append({'study': rs[0]['study'], 'series': base, 'label': label, 'x': rs[0]['x'],
                    'amp2': rs[i2]['amp2'], 'amp4': rs[i4]['amp4'],
                    'amp2_at': rs[i2]['_tag'], 'amp4_at': rs[i4]['_tag'], 'cases': len(rs)})
    return out


# ---- the paper's Sec. 3 experiment --------------------------------------------------------
def experiment_cases() -> list[tuple[str, str, dict[str, Any]]]:
    """(model, lead convention, overrides) of the Sec. 3 comparison (Figs. 9-11): the
    nonlinear model (Eqs. 16-18) and the paper's linear case (c_w k_w 3.5e8, c_g k_g 2.5e8
    N/m, constant mu 0.145), in the kinematic and the paper lead convention."""
    out = []
    for conv in ('kinematic', 'paper'):
        out.append(('nonlinear', conv, {'geometry.lead_convention': conv}))
        out.append(('linear', conv, {'geometry.lead_convention': conv,
                                     'mesh.stiffness_model': 'linear',
                                     'friction.model': 'constant',
                                     'friction.constant_coefficient': 0.145}))
    return out


EXPERIMENT_COLUMNS: tuple[str, ...] = (
    'model', 'lead_convention', 'theta1_final', 'eq2', 'mean2', 'eq4', 'mean4',
    'paper_level4', 'freq2_hz', 'freq4_hz', 'freq4_zc_hz', 'modal4_hz', 'amp2', 'amp4',
    'half_pp2', 'half_pp4', 'max_err2', 'max_err4', 'decay4',
)

PAPER_THETA4_LEVEL = 0.0127076   # rad, Sec. 3.2
PAPER_THETA2_LEVEL = 0.1130973   # rad, Sec. 3.2


def experiment_table(base: Config, t_end: float | None = None,
                     profile: Profile | None = None) -> tuple[list[dict], dict[str, Trajectory]]:
    """Run the four experiment cases in this process; return the table rows and the
    trajectories keyed 'model/convention'."""
    from .modal import modes
    rows, trajs = [], {}
    for model, conv, ov in experiment_cases():
        res = run_case(base, ov, t_end=t_end, profile=profile, keep_trajectory=True)
        traj = res.pop('trajectory')
        cfg = case_config(base, ov)
        post = traj.t >= res['t_move'] - 1e-12
        zc = zero_crossing_frequency(traj.t[post], traj.theta4[post])
        try:
            f_modal = float(modes(cfg, theta1=float(traj.theta1[-1])).undamped_hz[0])
        except Exception:  # noqa: BLE001 - a diagnostic column only
            f_modal = math.nan
        row = {'model': model, 'lead_convention': conv,
               'theta1_final': float(traj.theta1[-1]), 'paper_level4': PAPER_THETA4_LEVEL,
               'freq4_zc_hz': zc, 'modal4_hz': f_modal}
        row.update({k: res[k] for k in EXPERIMENT_COLUMNS if k in res})
        rows.append({k: row[k] for k in EXPERIMENT_COLUMNS})
        trajs[f'{model}/{conv}'] = traj
    return rows, trajs


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


def case_dict(c: Case) -> dict[str, Any]:
    return asdict(c)
