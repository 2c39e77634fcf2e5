# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Running study cases: one case in this process, many cases serially, on threads in this
process (the default: :func:`worm_gear_sim.parallel.threads.map_batch`) or on Dask (a remote
scheduler, a given Client, or a LocalCluster of processes)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from ..config.usable import Config, config_from_mapping
from ..dynamics.modal import amplitude_time_step, static_equilibrium
from ..dynamics.model import DriveModel
from ..dynamics.profiles import Profile, make_profile
from ..dynamics.simulation import Simulator
from ..dynamics.stepping import SimulationError
from ..parallel.cluster import dask_client, warm_worker
from ..parallel.threads import map_like_serial
from .cases import Case
from .metrics import move_end_time, oscillation_metrics

__all__ = ['run_case', 'run_cases', 'case_config', 'ENGINES', 'DEFAULT_ENGINE', 'ENGINE_TEXT',
           'CASE_ERRORS', 'case_error']

#: Engines of :func:`run_cases` on this machine: threads of this process or a Dask
#: LocalCluster of processes; the default is :data:`DEFAULT_ENGINE`.
ENGINES = ('threads', 'dask')
DEFAULT_ENGINE = 'threads'
#: What each engine is, for a person (``sweep --help``).
ENGINE_TEXT = {'threads': 'threads of this process (the kernel releases the interpreter lock)',
               'dask': 'a Dask LocalCluster of worker processes'}


# ---- running one case ---------------------------------------------------------------------
def _as_config(base: Config | Mapping[str, Any]) -> Config:
    return base if isinstance(base, Config) else config_from_mapping(base, source='base')


def case_config(base: Config | Mapping[str, Any], overrides: Mapping[str, Any]) -> Config:
    """The case's config: base (Config or nested dict) with the overrides (validated).
    A case that moves a mode beyond the step (the paper's rigid shafts: G x 10 000) gets
    the step its amplitudes need (:func:`amplitude_time_step`, an integer divisor of the
    base step) unless the overrides set ``integrator.time_step``: a set whose step does
    not resolve its modes is not usable, and the case is run at that step anyway."""
    cfg = _as_config(base)
    if not overrides:
        return cfg
    ov = dict(overrides)
    if 'integrator.time_step' not in ov:
        nested = cfg.to_nested_dict()
        for key, value in ov.items():
            sec, _, name = key.partition('.')
            if sec in nested and name in nested[sec]:
                nested[sec][name] = value
        try:
            trial = config_from_mapping(nested, source='overrides', usable=False)
            dt_amp = amplitude_time_step(DriveModel(trial))
        except (ValueError, ArithmeticError):
            dt_amp = math.inf         # replace() below names what is wrong
        if dt_amp < cfg.integrator.time_step:
            ov['integrator.time_step'] = dt_amp
    return cfg.replace(ov)


def run_case(base: Config | Mapping[str, Any], overrides: Mapping[str, Any] | None = None,
             t_end: float | None = None, profile: Profile | None = None,
             keep_trajectory: bool = False) -> dict[str, Any]:
    """Run one case from rest and return its metrics (small, picklable) plus timings:
    ``kernel_s`` (the Newmark integration itself) and ``case_s`` (everything, including
    config validation, parameter packing, equilibrium and metrics), wall clock, and the same
    as CPU time of this thread (``kernel_cpu_s``, ``case_cpu_s``)."""
    t0, c0 = time.perf_counter(), time.thread_time()
    cfg = case_config(base, overrides or {})
    model = DriveModel(cfg)
    # amplitudes need the worm mode resolved: a step from the model's modes
    dt_amp = amplitude_time_step(model)
    if dt_amp < cfg.integrator.time_step:
        cfg = cfg.replace({'integrator.time_step': dt_amp})
        model = DriveModel(cfg)
    prof = make_profile(cfg.input) if profile is None else profile
    t_end = cfg.input.end_time if t_end is None else float(t_end)
    th0 = float(prof.theta1(np.array([0.0]))[0])
    sim = Simulator(model, theta1=th0)
    tk, ck = time.perf_counter(), time.thread_time()
    traj = sim.run(prof, t_end, record_every=1)
    kernel, kernel_cpu = time.perf_counter() - tk, time.thread_time() - ck
    t_move = move_end_time(cfg, prof)
    eq = static_equilibrium(model, float(traj.theta1[-1]))
    out = oscillation_metrics(traj, t_move, eq)
    d = model.derived
    out.update(t_move=t_move, t_end=float(traj.t[-1]), J_4=d.J_4, ratio=d.ratio,
               steps=traj.stats.get('steps', 0),
               subdivision_events=traj.stats.get('subdivision_events', 0),
               kernel_s=kernel, case_s=time.perf_counter() - t0, kernel_cpu_s=kernel_cpu,
               case_cpu_s=time.thread_time() - c0)
    if keep_trajectory:
        out['trajectory'] = traj
    return out


#: What a case can fail with on its own (a ConfigError naming the key, a SimulationError,
#: a numerically unusable set): with ``failed_rows`` the case's row says it, the others run.
CASE_ERRORS: tuple[type[BaseException], ...] = (ValueError, ArithmeticError, SimulationError)


def case_error(exc: BaseException) -> str:
    """A case's failure in one line (the row's ``error``)."""
    return ' '.join(str(exc).split()) or type(exc).__name__


def _run_payload(payload: tuple) -> dict[str, Any]:
    """Run one case: (index, base nested dict, overrides, t_end, failed_rows) -> result
    dict; with ``failed_rows`` a case that fails returns ``{'error': its reason}``."""
    index, base, overrides, t_end, failed_rows = payload
    try:
        res = run_case(base, overrides, t_end)
    except CASE_ERRORS as exc:
        if not failed_rows:
            raise
        res = {'error': case_error(exc)}
    res['index'] = index
    return res


def _run_chunk(base: Mapping[str, Any], items: Sequence[tuple]) -> list[dict[str, Any]]:
    """Worker entry point: several cases sharing one base config (fewer, larger tasks keep
    the scheduler's per-task cost small against ~50 ms cases)."""
    return [_run_payload((i, base, ov, t_end, rows)) for i, ov, t_end, rows in items]


# ---- running many cases -------------------------------------------------------------------
def _progress(total: int, enabled: bool, desc: str):
    if not enabled:
        return None
    from .._support.progress import progress_bar
    return progress_bar(total, desc, 'case')


def run_cases(base: Config, cases: Sequence[Case], *, workers: int | None = None,
              scheduler: str | None = None, serial: bool = False, progress: bool = False,
              t_end: float | None = None, client: Any = None, chunk_size: int | None = None,
              on_result: Callable[[dict], None] | None = None,
              engine: str = DEFAULT_ENGINE, failed_rows: bool = False
              ) -> list[dict[str, Any]]:
    """Run the cases and return one result dict per case, in case order.

    Engines: ``serial=True`` runs in this process, one case after the other; ``client`` uses
    a given dask.distributed Client; ``scheduler`` connects to a running Dask scheduler
    (``tcp://host:8786``: many machines); otherwise ``engine='threads'`` (default) runs the
    cases on ``workers`` threads of this process (default: all cores;
    :func:`~worm_gear_sim.parallel.threads.map_batch`: the kernel releases the interpreter lock,
    nothing starts up, nothing is pickled) and ``engine='dask'`` starts a Dask LocalCluster
    of ``workers`` processes, one thread each.  On Dask the base config goes to every worker
    once (as a plain dict); each task carries a chunk of cases (their overrides; default
    chunk: about 16 tasks per worker, at most 16 cases) and returns only their metrics.
    A case that fails raises its own error (a ConfigError naming the key, a
    SimulationError) on every engine; with ``failed_rows`` (:data:`CASE_ERRORS`) its row
    holds ``error`` (the reason, one line) instead, and the other cases run.  Results do
    not depend on the engine (same code, same arithmetic, bit for bit).
    """
    if engine not in ENGINES:
        raise ValueError(f'engine {engine!r}: one of {", ".join(ENGINES)}')
    base_map = base.to_nested_dict()
    items = [(i, dict(c.overrides), t_end, failed_rows) for i, c in enumerate(cases)]
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
            for it in items:
                done(_run_payload((it[0], base_map, *it[1:])))
        elif client is None and scheduler is None and engine == 'threads':
            start_bar()
            map_like_serial(lambda it: _run_payload((it[0], base_map, *it[1:])), items,
                            workers=workers, on_result=lambda _, r: done(r))
        else:
            _run_on_dask(client, scheduler, workers, chunk_size, base_map, items,
                         start_bar, done)
    finally:
        if bar:
            bar.close()
    return _case_rows(cases, results)


def _run_on_dask(client: Any, scheduler: str | None, workers: int | None,
                 chunk_size: int | None, base_map: dict[str, Any], items: list[tuple],
                 start_bar: Callable[[], None], done: Callable[[dict], None]) -> None:
    """The cases on Dask: the base config to every worker once, the cases in chunks;
    ``done`` gets each result as it comes."""
    with dask_client(client, scheduler, workers) as cl:
        from distributed import as_completed
        n_workers = len(cl.run(warm_worker))
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


def _case_rows(cases: Sequence[Case], results: Sequence[dict[str, Any] | None]
               ) -> list[dict[str, Any]]:
    """One row per case: its study, series, x, label, results and overrides."""
    out = []
    for c, r in zip(cases, results):
        assert r is not None
        row = {'study': c.study, 'series': c.series, 'x': c.x, 'label': c.label}
        row.update({k: v for k, v in r.items() if k != 'index'})
        row['overrides'] = dict(c.overrides)
        out.append(row)
    return out
