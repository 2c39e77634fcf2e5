# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The robust search: :func:`identify` fits the keys to the records with
``scipy.optimize.least_squares`` (Jacobian by finite differences, :mod:`.problem`).

Oscillatory records defeat a plain local fit; a frequency start, growing windows and a
multi-start make it robust (docs/identification.md, "Why the fit is robust").
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from ..config.usable import Config
from ..dynamics.modal import modes
from ..dynamics.stepping import SimulationError
from ..parallel.processes import can_fork, fork_is_safe
from ..parallel.threads import default_workers, map_like_serial
from ..records import Record
from ..schema.validation import ConfigError
from .data import IdentificationError, measured_frequencies, normalised
from .direct import (
    DIRECT_KEYS,
    LOAD,
    PLAY,
    best_of,
    best_on_family,
    direct_estimates,
    lag_table,
    scan_play,
)
from .parameters import fit_parameters
from .problem import DIFF_STEP, Problem
from .report import FitResult, assess, residual_rms

__all__ = ['STRATEGIES', 'FitOptions', 'frequency_start', 'identify']


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

    lo, hi = problem.x_bounds
    res = least_squares(fres, np.clip(x0, lo, hi), bounds=(lo, hi), diff_step=1e-6,
                        max_nfev=200)
    f_after = np.asarray(modes(problem.config(res.x)).undamped_hz, float)
    info.update(model_hz_after=f_after.tolist(), matched_modes=[k + 1 for k in idx],
                target_hz=np.exp(goal).tolist())
    return res.x, info


# ---- one local fit -------------------------------------------------------------------------
STRATEGIES: dict[str, dict[str, Any]] = {
    'local': dict(frequency_start=False, growing_windows=False, n_starts=1),
    'frequency': dict(frequency_start=True, growing_windows=False, n_starts=1),
    'windows': dict(frequency_start=False, growing_windows=True, n_starts=1),
    'frequency+windows': dict(frequency_start=True, growing_windows=True, n_starts=1),
    'multistart': dict(frequency_start=False, growing_windows=False, n_starts=8),
    'robust': dict(frequency_start=True, growing_windows=True, n_starts=4),
}


@dataclass(frozen=True)
class LocalSettings:
    """What one local fit needs (sent to the Dask workers)."""

    max_nfev: int
    diff_step: float
    method: str
    ftol: float
    xtol: float
    #: (index, sigma in the fitted coordinate) of each key held near its start (:data:`PRIORS`)
    priors: tuple[tuple[int, float], ...] = ()
    #: threads of the finite-difference Jacobian's columns (:attr:`Problem.threads`)
    threads: int = 1
    #: ftol and xtol of the growing windows before the last (:attr:`FitOptions.window_tol`)
    window_tol: float = 0.0


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
    diff_step: float = DIFF_STEP   # finite-difference step in the fitted coordinate
    ftol: float = 1e-8             # least_squares' tolerances of each local fit
    xtol: float = 1e-8
    #: ftol and xtol (at least) of the growing windows before the last: an early window only
    #: has to bring the start into the basin of the longer ones, the last keeps ftol and xtol.
    #: 1e-4 took the 4-key fit of benchmarks/bench_identify.py from 1262 to ~800 evaluations
    #: with the same held-out error (docs/identification.md); 0: every window to ftol, xtol
    window_tol: float = 1e-4
    method: str = 'dogbox'     # least_squares method; trf creeps away from a start near a
    #                            bound (its step scales with the distance to the bound)
    #: the global stage (:mod:`.direct`) when play, load or drag is fitted: direct estimates
    #: from the records' constant-rate segments and a scan of the play, before the local fit
    global_stage: bool = True
    #: key -> sigma in the fitted coordinate of a prior holding the key near its start value
    #: in the local fit (None: :data:`PRIORS` when the global stage estimated the load)
    priors: Mapping[str, float] | None = None
    workers: int | None = None
    scheduler: str | None = None
    serial: bool = False
    client: Any = None
    progress: bool = False
    #: threads of the finite-difference Jacobian's columns when the local fits run in this
    #: process, and of the report's Jacobian (None: the cores, ``default_workers()``; the
    #: same numbers for any count); a local fit on a Dask worker process uses 1
    threads: int | None = None
    #: worker processes forked for the evaluations (the Jacobian's columns and the rest) when
    #: the local fits run in this process (:meth:`Problem.on_processes`; the starts then run
    #: at once, on threads that wait for the processes).  None:
    #: as many as ``threads`` where forking is safe (Linux, no other thread in this process:
    #: :func:`~worm_gear_sim.parallel.processes.fork_is_safe`) and ``threads`` > 1, else none;
    #: 0: none (the columns on threads).  The same numbers either way.
    processes: int | None = None

    def local(self, priors: tuple[tuple[int, float], ...] = (), threads: int = 1
              ) -> LocalSettings:
        if not (math.isfinite(self.window_tol) and 0.0 <= self.window_tol < 1.0):
            raise IdentificationError(f'window_tol = {self.window_tol!r}: must be in [0, 1)')
        return LocalSettings(self.max_nfev, self.diff_step, self.method, self.ftol, self.xtol,
                             priors, threads, self.window_tol)

    def in_process_threads(self) -> int:
        n = default_workers() if self.threads is None else int(self.threads)
        if n < 1:
            raise IdentificationError(f'threads = {self.threads!r}: must be >= 1')
        return n

    def in_process_workers(self) -> int:
        """Worker processes of the evaluations (0: in the calling threads, the columns on
        threads)."""
        if self.processes is None:
            n = self.in_process_threads()
            return n if n > 1 and fork_is_safe() else 0
        n = int(self.processes)
        if n < 0:
            raise IdentificationError(f'processes = {self.processes!r}: must be >= 0')
        if n and not can_fork():
            raise IdentificationError(f'processes = {n}: forked worker processes need Linux; '
                                      'use processes=0 (threads)')
        return n

    def resolved(self) -> tuple[bool, bool, int]:
        if self.strategy not in STRATEGIES:
            raise IdentificationError(f'unknown strategy {self.strategy!r} (known: '
                                      f'{", ".join(STRATEGIES)})')
        s = STRATEGIES[self.strategy]
        fs = s['frequency_start'] if self.frequency_start is None else self.frequency_start
        gw = s['growing_windows'] if self.growing_windows is None else self.growing_windows
        ns = s['n_starts'] if self.n_starts is None else int(self.n_starts)
        return bool(fs), bool(gw), max(1, ns)


#: A local fit that used up its evaluations counts as converged when its cost fell by less
#: than STALL_COST over its last STALL_EVALS evaluations: statistically nothing (a change of
#: one standard deviation in any parameter changes the cost by 0.5).  With the set-valued
#: friction law the cost is noisy at its last digits and least_squares' own tolerances may
#: never be met while it creeps along a flat valley.
STALL_EVALS = 10
STALL_COST = 0.1

#: Keys held near their base value when the global stage estimated the load and saw the play
#: (key -> sigma in the fitted coordinate, here log(value / base)).  The records show the
#: gear teeth only through the compliance C of the wind-up, which they show as T C and c C:
#: a local fit free to move C trades it against the load torque T and the drag c (measured:
#: teeth x0.17 and load -17 % from direct estimates within 1 %, docs/identification.md).  The
#: direct estimates use the base compliance, so the teeth stay near their base value unless the
#: records demand otherwise: a prior residual (x - x_base) / sigma * sqrt(max(2 cost_start,
#: m)), i.e. a move of one sigma costs as much as the whole misfit at the start of the local
#: fit, and at least as much as the noise of the m weighted residuals (m / 2).
PRIORS: dict[str, float] = {'mesh.gear_tooth_stiffness_multiplier': 0.05}


def _local_fit(problem: Problem, x0: np.ndarray, windows: Sequence[float | None],
               settings: LocalSettings) -> dict[str, Any]:
    lo, hi = problem.x_bounds
    x = _interior(problem, x0)
    problem.threads = settings.threads
    t0 = time.perf_counter()
    res = None
    stages: list[dict[str, Any]] = []
    costs: list[float] = []

    x_prior = np.zeros(problem.n)     # the start values of the local fit: x = 0
    idx = [i for i, _ in settings.priors]
    weight = np.zeros(len(idx))
    if idx:     # a move of one sigma costs the misfit at the start, at least the noise's
        r0 = problem.residuals(x, windows[0])
        weight = math.sqrt(max(float(r0 @ r0), float(r0.size))) / np.array(
            [s for _, s in settings.priors])

    def fun(xf: np.ndarray, window: float | None) -> np.ndarray:
        r = problem.residuals(xf, window)
        if idx:
            r = np.concatenate([r, weight * (xf[idx] - x_prior[idx])])
        costs.append(0.5 * float(r @ r))
        return r

    def jac(xj: np.ndarray, window: float | None) -> np.ndarray:
        J = problem.jacobian(xj, window, settings.diff_step)
        if idx:
            P = np.zeros((len(idx), problem.n))
            P[np.arange(len(idx)), idx] = weight
            J = np.vstack([J, P])
        return J

    for i, w in enumerate(windows):
        costs.clear()
        early = settings.window_tol if i < len(windows) - 1 else 0.0
        res = least_squares(fun, x, jac=jac, bounds=(lo, hi), args=(w,),
                            method=settings.method, max_nfev=settings.max_nfev, x_scale=1.0,
                            xtol=max(settings.xtol, early), ftol=max(settings.ftol, early),
                            gtol=1e-8)
        x = res.x
        last = (min(costs[:-STALL_EVALS]) - min(costs) if len(costs) > STALL_EVALS
                else math.inf)
        stages.append({'window_s': w, 'cost': float(res.cost), 'nfev': int(res.nfev),
                       'njev': int(res.njev or 0), 'status': int(res.status),
                       'last_decrease': last})
    assert res is not None
    final = stages[-1]
    return {'x0': np.asarray(x0, float).tolist(), 'x': res.x.tolist(), 'cost': float(res.cost),
            'status': int(res.status), 'message': str(res.message),
            'converged': final['status'] > 0 or final['last_decrease'] < STALL_COST,
            'nfev': sum(s['nfev'] + problem.n * s['njev'] for s in stages), 'stages': stages,
            'seconds': time.perf_counter() - t0}


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


def _start_task(problem: Problem, x0: list[float], windows: list[float | None],
                settings: LocalSettings, index: int) -> dict[str, Any]:
    out = _local_fit(problem, np.asarray(x0), windows, settings)
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


# ---- the global stage ------------------------------------------------------------------------
def _global_stage(base: Config, records: Sequence[Record], keys: Sequence[str]
                  ) -> tuple[Config, dict[str, Any]]:
    """The base with the direct estimates of play, load and drag (:mod:`.direct`) when the
    records allow them (else ``base`` itself), and what was found."""
    if not any(k in DIRECT_KEYS for k in keys):
        return base, {}
    recs = [normalised(r, i) for i, r in enumerate(records)]
    try:
        est = direct_estimates(base, recs, keys)
    except (ConfigError, SimulationError, ValueError) as exc:
        return base, {'note': f'direct estimates failed: {exc}'}
    if est is None:
        return base, {'note': 'no constant-rate segments both ways: no direct estimates'}
    family_rows: list[dict[str, float]] = []
    if est.family:                      # play and drag along a line: simulate to choose
        est.values, family_rows = best_on_family(base, recs, est.family)
    elif est.alternatives:              # a floating segment: several flank patterns fit
        est.values, family_rows = best_of(base, recs, [est.values] + est.alternatives)
    vals = dict(est.values)
    if PLAY in vals and not est.play_seen:
        vals.pop(PLAY)                      # not seen: keep the base's play
    info: dict[str, Any] = {'values': dict(est.values), 'play_seen': est.play_seen,
                            'compliance_rad_per_Nm': est.compliance,
                            'misfit_rad': est.misfit_rad, 'notes': est.notes,
                            'segments': lag_table(est.segments)}
    if family_rows:
        info['family_scan'] = family_rows
    if PLAY in vals and not vals[PLAY] > 0:
        vals.pop(PLAY)
    try:
        return (base.replace(vals) if vals else base), info
    except ConfigError as exc:
        info['note'] = f'direct estimates not usable: {exc}'
        return base, info


def _priors(opt: FitOptions, keys: Sequence[str], direct_info: Mapping[str, Any]
            ) -> dict[str, float]:
    """key -> sigma of the priors of the local fit: ``opt.priors``, or :data:`PRIORS` of the
    fitted keys when the global stage estimated the load torque (and saw the play, if it is
    fitted: a play hidden by the load leaves only b / 2 + T C to the direct stage, and the
    local fit then needs every fitted key free; measured: seed 1 drive 2 of
    bench_calibration lost its play, 0 against 1.98 arcmin, with the teeth held)."""
    if opt.priors is not None:
        chosen = dict(opt.priors)
    elif LOAD in direct_info.get('values', {}) and (direct_info.get('play_seen')
                                                     or PLAY not in keys):
        chosen = dict(PRIORS)
    else:
        chosen = {}
    for k, sg in chosen.items():
        if not (math.isfinite(sg) and sg > 0):
            raise IdentificationError(f'prior of {k}: sigma must be > 0, got {sg!r}')
    return {k: float(sg) for k, sg in chosen.items() if k in keys}


# ---- the fit ---------------------------------------------------------------------------------
def identify(base: Config, records: Sequence[Record], keys: Sequence[str], *,
             bounds: Mapping[str, tuple[float, float]] | None = None,
             options: FitOptions | None = None,
             on_start_done: Callable[[dict], None] | None = None,
             outputs: Sequence[str] | None = None) -> FitResult:
    """Fit ``keys`` of ``base`` to the records jointly (see the module docstring).
    ``outputs``: the measured outputs to fit (default: those observable at their sampling;
    the others are named in the result's ``output_verdicts``)."""
    t_begin = time.perf_counter()
    keys = [str(k).strip() for k in keys]
    opt = options or FitOptions()
    use_freq, use_windows, n_starts = opt.resolved()
    params = fit_parameters(base, keys, bounds)
    fit_base: Config = base
    direct_info: dict[str, Any] = {}
    if opt.global_stage:
        fit_base, direct_info = _global_stage(base, records, keys)
        if fit_base is not base:     # the fitted coordinates start from the estimates
            params = fit_parameters(fit_base, keys, bounds)
    problem = Problem(fit_base, params, records, outputs)
    x_base = np.zeros(problem.n)
    if direct_info.get('play_seen') and PLAY in keys:
        x_base, direct_info['play_scan'] = scan_play(problem, x_base,
                                                          [p.key for p in params].index(PLAY))
    freq_info: dict[str, Any] = {}
    first = []
    if use_freq:
        x_f, freq_info = frequency_start(problem, x_base)
        first.append(x_f)
    first.append(x_base)
    starts = _starts(problem, first, n_starts, opt.seed)
    windows = problem.windows() if use_windows else [None]
    prior_sigma = _priors(opt, keys, direct_info)
    priors = tuple((keys.index(k), float(sg)) for k, sg in prior_sigma.items())
    in_process = opt.serial or (len(starts) == 1 and opt.client is None
                                and opt.scheduler is None)
    n_proc = opt.in_process_workers() if in_process else 0
    with problem.on_processes(n_proc) if n_proc else contextlib.nullcontext():
        results = _run_starts(problem, starts, windows, opt, priors, on_start_done, in_process)
        results.sort(key=lambda r: r['index'])
        problem.threads = opt.in_process_threads()
        best, stats = assess(problem, results, opt.max_nfev)
    if fit_base is not base:   # 'before' and the base values: the caller's base
        rms_before, per_before = residual_rms(problem, base)
        stats['rms_before'] = rms_before
        for row, b in zip(stats['per_record'], per_before):
            row['rms_before_rad'] = {k: v for k, v in b.items() if k != 'name'}
        stats['base_values'] = [p.base for p in fit_parameters(base, keys, bounds)]
        stats['base_config'] = base
    if direct_info:
        freq_info = dict(freq_info, direct=direct_info)
    result = FitResult(
        **stats,
        strategy={'name': opt.strategy, 'frequency_start': use_freq,
                  'growing_windows': use_windows, 'n_starts': n_starts,
                  'windows_s': windows, 'priors': prior_sigma},
        starts=results, frequency_info=freq_info, seconds=time.perf_counter() - t_begin)
    for k, sg in prior_sigma.items():    # a held key is not measured: say so, and how
        wind_up_only(result, k, f'held near its base value by a prior ({100 * sg:.3g} % in '
                     'log)')
    return result


def wind_up_only(result: FitResult, key: str, how: str) -> None:
    """``key`` (a key of :data:`PRIORS`) is not seen in ``result``: one line naming ``how``
    it was set, why the records cannot show it and the move that would, in ``not_seen``
    and the warnings.  The one rule for the three fits that set it (held by the prior;
    fitted free after the prior was refused; fitted free after the dither's split)."""
    line = (f'{key}: not seen: {how}, because the records show it only through the wind-up '
            'compliance, which trades with the load torque and the drag; to measure it, '
            'record the sweeps again with a known extra load torque on the axis (the change '
            'of the wind-up gives the compliance)')
    result.not_seen.setdefault(key, line)
    result.warnings.append(line)


def _run_starts(problem: Problem, starts: Sequence[np.ndarray],
                windows: Sequence[float | None], opt: FitOptions,
                priors: tuple[tuple[int, float], ...],
                on_done: Callable[[dict], None] | None, in_process: bool
                ) -> list[dict[str, Any]]:
    """Local fits from every start: ``in_process`` (``serial`` or a single start; the starts
    and each Jacobian's columns on ``FitOptions.threads`` threads, or every evaluation on
    the problem's worker processes; every start computed as in a serial loop, so the same
    numbers) or on Dask (the sweeps' engine: a LocalCluster by default, ``scheduler`` for a
    cluster)."""
    out: list[dict[str, Any]] = []
    bar = None

    def start_bar() -> None:   # after the engine is up: no bar before a connection error
        nonlocal bar
        if opt.progress:
            from .._support.progress import progress_bar
            bar = progress_bar(len(starts), 'identify', 'start')

    def done(r: dict[str, Any]) -> None:
        out.append(r)
        if bar is not None:
            bar.set_postfix(best=f'{min(o["cost"] for o in out):.4g}')
            bar.update()
        if on_done:
            on_done(r)

    try:
        if in_process:
            start_bar()
            threads = opt.in_process_threads()
            local = opt.local(priors, threads)
            # the starts on threads too: one start's columns use the cores another left idle;
            # with worker processes, every start at once (its thread only waits for them)
            on_processes = problem.on_processes_now()
            map_like_serial(lambda i: _start_task(problem, list(starts[i]), list(windows),
                                                  local, i),
                            range(len(starts)),
                            workers=len(starts) if on_processes else threads,
                            on_result=lambda _, r: done(r))
        else:
            from ..parallel.cluster import dask_client, warm_worker
            with dask_client(opt.client, opt.scheduler, opt.workers) as cl:
                from distributed import as_completed
                if len(cl.run(warm_worker)) == 0:
                    raise ConnectionError('the Dask cluster has no workers')
                pf = cl.scatter(problem, broadcast=True)
                start_bar()
                futs = [cl.submit(_start_task, pf, list(x0), list(windows), opt.local(priors), i,
                                  pure=False)
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
