# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Runs on a Dask cluster: the client (given, a remote scheduler's or a local cluster's) and
the warm-up each worker runs before its first case."""

from __future__ import annotations

import os
import time
from typing import Any

from ..config.usable import Config
from ..dynamics.modal import static_equilibrium
from ..dynamics.model import DriveModel
from ..dynamics.profiles import make_profile
from ..dynamics.simulation import Simulator

__all__ = ['dask_client', 'local_cluster_client', 'warm_worker', 'WORKER_ENV']


# Dask's nanny sets MALLOC_TRIM_THRESHOLD_ in its workers, which also switches off glibc's
# dynamic mmap threshold: every ~1 MB record array of a case is then mmap'ed and unmapped
# (8000 page faults, ~10 ms of system time per 0.5 s case, a third of the kernel time).
# A fixed 16 MB mmap threshold keeps them in the heap.  Set the same variables on the
# workers of a remote cluster (see docs/studies.md).
WORKER_ENV = {
    'distributed.nanny.pre-spawn-environ.MALLOC_MMAP_THRESHOLD_': 1 << 24,
    'distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_': 1 << 28,
}


def warm_worker() -> float:
    """Import the model and load its compiled (cached) kernels in this process; returns the
    seconds it took.  Run on every Dask worker before the cases so that the first case of each
    worker does not pay for imports and numba cache loading."""
    t0 = time.perf_counter()
    cfg = Config()
    model = DriveModel(cfg)
    Simulator(model).run(make_profile(cfg.input), 10 * cfg.integrator.time_step)
    static_equilibrium(model, 0.0)
    return time.perf_counter() - t0


class dask_client:
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
    return dask_client(None, None, workers)
