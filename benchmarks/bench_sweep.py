# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Sweep throughput: a 200-case sweep in this process, on 1 and 2 threads of this process
(the default engine, worm_gear_sim.parallel.threads.map_batch) and on a Dask LocalCluster with 1
worker and with 2 workers; cases/second, scaling, and per-case overhead beyond the kernel
time.

    python benchmarks/bench_sweep.py [--cases 200] [--end-time 0.5] [--workers 1,2]

Each case is the default drive with a different mesh phase (``mesh.phase_offset``), run
for ``--end-time`` seconds of simulated time at the default dt (4 us), metrics computed in
the worker (only ~30 numbers come back).  Figures are printed, never asserted.  The machine's
load is printed before and after: other processes on the same cores distort the scaling.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from worm_gear_sim import studies as S  # noqa: E402
from worm_gear_sim.config.usable import Config  # noqa: E402
from worm_gear_sim.parallel.cluster import local_cluster_client, warm_worker  # noqa: E402


def _load() -> str:
    a, b, c = os.getloadavg()
    return f'load average {a:.2f} {b:.2f} {c:.2f} on {os.cpu_count()} cores'


def _summary(label: str, rows: list[dict], wall: float, workers: int,
             main_cpu: float) -> dict:
    n = len(rows)
    mean = lambda key: statistics.fmean(r[key] for r in rows)  # noqa: E731
    kernel, kernel_cpu, case_cpu = mean('kernel_s'), mean('kernel_cpu_s'), mean('case_cpu_s')
    rate = n / wall
    # per-case cost beyond the kernel, seen from outside: busy worker-seconds per case minus
    # the kernel's wall time (includes config, equilibrium, metrics, scheduling, transfer)
    overhead = wall * workers / n - kernel
    print(f'{label:<24s} {n:4d} cases {wall:6.2f} s {rate:7.2f} cases/s | kernel '
          f'{1e3 * kernel:5.1f} ms wall, {1e3 * kernel_cpu:5.1f} ms CPU | overhead beyond '
          f'kernel {1e3 * overhead:5.1f} ms/case ({100 * overhead / kernel:4.1f} %), in-worker '
          f'CPU {1e3 * (case_cpu - kernel_cpu):4.1f} ms, client+scheduler CPU '
          f'{1e3 * main_cpu / n:4.1f} ms')
    util = sum(r['case_cpu_s'] for r in rows) / (wall * workers)
    print(f'{"":24s} worker CPU utilisation {100 * util:.0f} % (below ~90 %: the cores were '
          'shared with other processes)')
    return {'rate': rate, 'kernel': kernel, 'overhead': overhead, 'util': util}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--cases', type=int, default=200)
    ap.add_argument('--end-time', type=float, default=0.5)
    ap.add_argument('--workers', default='1,2', help='comma-separated LocalCluster sizes')
    ap.add_argument('--no-serial', action='store_true', help='skip the in-process run')
    args = ap.parse_args()

    base = Config().replace({'input.end_time': args.end_time})
    values = [2 * 3.141592653589793 * k / args.cases for k in range(args.cases)]
    study = S.param_study(['mesh.phase_offset'], values, name='bench')
    cases = list(study.cases)
    print(f'{args.cases} cases of {args.end_time:g} s simulated at dt = '
          f'{base.integrator.time_step:g} s ({round(args.end_time / base.integrator.time_step)} '
          f'steps each); {_load()}')
    warm_worker()
    res = {}
    if not args.no_serial:
        t0, c0 = time.perf_counter(), time.process_time()
        rows = S.run_cases(base, cases, serial=True)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        res[0] = _summary('serial (this process)', rows, wall, 1,
                          cpu - sum(r['case_cpu_s'] for r in rows))
        ref = rows
    else:
        ref = None
    for n in (int(w) for w in args.workers.split(',')):
        t1, c1 = time.perf_counter(), time.process_time()
        rows = S.run_cases(base, cases, workers=n, engine='threads')
        wall, cpu = time.perf_counter() - t1, time.process_time() - c1
        res[f't{n}'] = _summary(f'threads {n}', rows, wall, n,
                               cpu - sum(r['case_cpu_s'] for r in rows))
        print(f'{"":26s} nothing to start (threads of this process)')
        if ref is not None:
            same = all(a[k] == b[k] for a, b in zip(ref, rows) for k in ('amp2', 'amp4'))
            print(f'{"":26s} amplitudes identical to the serial run: {same}')
    for n in (int(w) for w in args.workers.split(',')):
        t0 = time.perf_counter()
        with local_cluster_client(n) as client:
            client.run(warm_worker)
            startup = time.perf_counter() - t0
            t1, c1 = time.perf_counter(), time.process_time()
            rows = S.run_cases(base, cases, client=client)
            wall, cpu = time.perf_counter() - t1, time.process_time() - c1
        res[n] = _summary(f'LocalCluster {n} worker{"s" if n > 1 else ""}', rows, wall, n, cpu)
        print(f'{"":26s} cluster start + worker warm-up {startup:.2f} s (not in the rate)')
        if ref is not None:
            same = all(a[k] == b[k] for a, b in zip(ref, rows) for k in ('amp2', 'amp4'))
            print(f'{"":26s} amplitudes identical to the serial run: {same}')
    if 0 in res and 't2' in res:
        print(f'threads 2 / serial: {res["t2"]["rate"] / res[0]["rate"]:.2f}x; threads 2 / '
              f'LocalCluster 2: {res["t2"]["rate"] / res[2]["rate"]:.2f}x'
              if 2 in res else '')
    if 1 in res and 2 in res:
        print(f'scaling 2 workers / 1 worker: {res[2]["rate"] / res[1]["rate"]:.2f}x '
              f'(target >= 1.8x); at equal utilisation '
              f'{res[2]["rate"] / res[2]["util"] / (res[1]["rate"] / res[1]["util"]):.2f}x')
    print(_load())
    return 0


if __name__ == '__main__':
    sys.exit(main())
