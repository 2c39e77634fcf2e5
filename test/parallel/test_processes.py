# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The fit's evaluations on forked worker processes (worm_gear_sim.parallel.processes): the same
numbers as in the calling thread, bit for bit, and a failing evaluation raises the error the
serial path raises; no worker process outlives its block."""

from __future__ import annotations

import multiprocessing
import os
import pickle
import threading

import numpy as np
import pytest
from fit_case import KG, ZETA, fit_case

from worm_gear_sim.identification import (
    FitOptions,
    IdentificationError,
    Problem,
    fit_parameters,
    identify,
    jacobian,
)
from worm_gear_sim.parallel.processes import ForkedWorkers, WorkerDied, can_fork, fork_is_safe
from worm_gear_sim.schema.validation import ConfigError

pytestmark = pytest.mark.skipif(not can_fork(), reason='forked worker processes need Linux')

@pytest.fixture(scope='module')
def case():
    return fit_case()


def _children() -> set[int]:
    return {p.pid for p in multiprocessing.active_children()}


def test_the_jacobian_on_processes_equals_the_serial_one(case):
    base, rec = case
    problem = Problem(base, fit_parameters(base, [KG, ZETA]), [rec])
    x = np.array([0.05, 0.02])
    serial, forward, r = jacobian(problem, x), problem.jacobian(x, 0.03), problem.residuals(x)
    before = _children()
    with problem.on_processes(2):
        assert problem.on_processes_now() and len(_children() - before) == 2
        assert '_workers' not in pickle.loads(pickle.dumps(problem)).__dict__   # Dask's copy
        n0 = problem.n_evals
        got = jacobian(problem, x)
        assert problem.n_evals - n0 == 4                 # every column point counted once
        assert np.array_equal(got, serial) and np.isfinite(got).all()
        assert np.array_equal(problem.jacobian(x, 0.03), forward)
        assert np.array_equal(problem.residuals(x + 0.01), Problem(
            base, fit_parameters(base, [KG, ZETA]), [rec]).residuals(x + 0.01))
        assert np.array_equal(problem.residuals(x), r)
    assert not problem.on_processes_now() and _children() <= before


def test_a_multistart_fit_on_processes_is_the_serial_fit(case):
    base, rec = case
    kw = dict(strategy='multistart', n_starts=2, serial=True, max_nfev=5)
    one = identify(base, [rec], [KG], options=FitOptions(threads=1, processes=0, **kw))
    two = identify(base, [rec], [KG], options=FitOptions(threads=2, processes=2, **kw))
    assert one.values == two.values and one.ci95 == two.ci95
    assert [s['x'] for s in one.starts] == [s['x'] for s in two.starts]
    assert [s['cost'] for s in one.starts] == [s['cost'] for s in two.starts]
    with pytest.raises(IdentificationError, match='processes'):
        identify(base, [rec], [KG], options=FitOptions(processes=-1, **kw))


def test_processes_by_default_only_where_forking_is_safe():
    two = FitOptions(threads=2)
    assert two.in_process_workers() == (2 if fork_is_safe() else 0)
    assert FitOptions(threads=1).in_process_workers() == 0
    assert FitOptions(threads=2, processes=0).in_process_workers() == 0
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        assert not fork_is_safe() and two.in_process_workers() == 0
    finally:
        stop.set()
        other.join()


def test_a_failing_evaluation_raises_the_serial_error(case, monkeypatch):
    """An error inside an evaluation (here the simulation, patched before the fork so the
    workers inherit it) surfaces from the workers as the serial path raises it."""
    import worm_gear_sim.identification.problem as problem_module
    base, rec = case

    def broken(*_a, **_k):
        raise FloatingPointError('overflow in the candidate')

    monkeypatch.setattr(problem_module, 'predict', broken)
    problem = Problem(base, fit_parameters(base, [KG, ZETA]), [rec])
    x = np.array([0.05, 0.02])
    with pytest.raises(FloatingPointError) as serial:
        jacobian(problem, x + 0.01)
    before = _children()
    with problem.on_processes(2):
        with pytest.raises(FloatingPointError) as forked:
            jacobian(problem, x)
        with pytest.raises(FloatingPointError):
            problem.residuals(x - 0.01)
    assert str(forked.value) == str(serial.value) == 'overflow in the candidate'
    assert 'forked worker process' in ''.join(forked.value.__notes__)
    assert _children() <= before


def _fails_at(state: int, item: int) -> int:
    if item >= state:
        raise ConfigError('mesh.backlash', f'item {item}', keys=['mesh.backlash', 'x.y'])
    return item * item


def test_workers_map_in_order_and_rebuild_the_lowest_error():
    """An exception whose __init__ differs from its args (ConfigError) comes back whole; the
    lowest failing item's, as a serial loop raises it."""
    with ForkedWorkers(3, 2) as pool:
        assert pool.map(_fails_at, [2, 0, 1]) == [4, 0, 1]
        with pytest.raises(ConfigError) as err:
            pool.map(_fails_at, [0, 5, 4, 1])
    assert err.value.keys == ('mesh.backlash', 'x.y') and err.value.key == 'mesh.backlash'
    assert str(err.value) == 'mesh.backlash: item 5'
    with pytest.raises(RuntimeError, match='closed'):
        pool.map(_fails_at, [0])
    with pytest.raises(ValueError, match='workers'):
        ForkedWorkers(0, 0)


def _dies(_state: None, item: int) -> int:
    if item == 1:
        os._exit(3)
    return item


def test_a_worker_that_dies_stops_the_map_and_the_pool():
    pool = ForkedWorkers(None, 2)
    with pytest.raises(WorkerDied, match='exit codes'):
        pool.map(_dies, [0, 1, 2])
    assert not any(p.is_alive() for p, _ in pool._procs)
    with pytest.raises(RuntimeError, match='closed'):
        pool.map(_dies, [0])


def test_a_progress_bar_leaves_the_fit_free_to_fork():
    """tqdm's monitor thread, started by the first progress bar (identify's, a sweep's) and
    never ended, made fork_is_safe() False for the rest of the process: every later fit ran
    its evaluations on threads.  The package's bars start no thread."""
    import subprocess
    import sys
    code = ('import sys\n'
            'from worm_gear_sim.studies.engine import _progress\n'
            'from worm_gear_sim._support.progress import progress_bar\n'
            'from worm_gear_sim.parallel.processes import fork_is_safe\n'
            'for bar in (_progress(3, True, "sweep"), progress_bar(2, "identify", "start")):\n'
            '    bar.update()\n'
            '    bar.close()\n'
            'print(fork_is_safe())\n')
    run = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == 'True'
