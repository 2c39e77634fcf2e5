# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""How much the adaptation's outcome on a drive depends on its start: the twin's three
targets per drive, started plainly and with a few samples of rest before the scan.

    python benchmarks/bench_adaptation_spread.py [--seeds 1 2 3] [--drives 4]
        [--only SEED:DRIVE ...] [--holds 0 6] [--noise-seeds 0] [--noise-hold 0]
        [--duration 60]
        [--workers 2] [--json out.json]

The drives are those of ``bench_adaptation.py`` (the same random draws per seed). Each
drive runs the offline twin (``sector``, from the nominal model) once per ``--holds`` value
(``run_twin(..., hold=h)``: h samples of the first reference before t = 0, the live
harness's start) and per extra encoder-noise seed (``--noise-seeds k``: the encoder noise
drawn from seed + drive + 100 k as well, with ``--noise-hold``). Printed per drive and
variant (figures, never asserted): the RMS ratio uncompensated / compensated over 10-20 s
(target >= 10x), over the last 10 s (>= 30x), the worst 1 s window after two worm
revolutions (>= 1x) and the steps applied; then the spread per target, max / min over the
variants (1 when the start does not matter), the targets met per variant and in all
variants, and where the step sequences of the first two variants first differ. ``--json``
keeps the figures and the step sequences. At most ``--workers`` processes (each ~1 core for
~1 s per simulated s).
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_adaptation import drive, rms, two_revolutions  # noqa: E402

from worm_gear_sim.config.usable import Config  # noqa: E402
from worm_gear_sim.studies.adaptation_twin import run_twin  # noqa: E402

TARGETS = (('x_10_20', 10.0, '10-20 s'), ('x_last', 30.0, 'last 10 s'),
           ('worst_1s', 1.0, 'worst 1 s'))


def plant_of(seed: int, index: int) -> Config:
    """Drive ``index`` of ``seed`` as bench_adaptation.py draws it."""
    rng = np.random.default_rng(seed)
    base = Config()
    for _ in range(index + 1):
        _, plant = drive(base, rng, 0.0)
    return plant


def one(job: tuple[int, int, int, int, float]) -> dict[str, Any]:
    seed, index, hold, extra, duration = job
    plant = plant_of(seed, index)
    t0 = time.perf_counter()
    run = run_twin(plant, Config(), 'sector', duration, seed=seed + index + 100 * extra,
                   hold=hold)
    wall = time.perf_counter() - t0
    t, u, c = run.t, run.error_uncompensated, run.error_compensated
    t2 = two_revolutions(t, run.theta1_ref)
    worst = math.inf
    for a in np.arange(math.ceil(t2), duration - 0.999, 1.0):
        worst = min(worst, rms(t, u, a, a + 1) / rms(t, c, a, a + 1))
    return {'seed': seed, 'drive': index, 'hold': hold, 'noise': extra,
            'x_10_20': rms(t, u, 10, 20) / rms(t, c, 10, 20),
            'x_last': rms(t, u, duration - 10, duration) / rms(t, c, duration - 10, duration),
            'worst_1s': worst, 'steps': [[s, {k: v for k, v in d.items()}]
                                         for s, d in run.steps],
            'in_use': run.in_use, 'wall_s': wall}


def first_difference(a: list, b: list) -> str:
    for k, (sa, sb) in enumerate(zip(a, b)):
        if abs(sa[0] - sb[0]) > 1e-9 or sa[1] != sb[1]:
            return f'step {k}: {sa[0]:.3f} s / {sb[0]:.3f} s'
    if len(a) != len(b):
        return f'step {min(len(a), len(b))}: one sequence ends'
    return 'none'


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seeds', type=int, nargs='+', default=[1, 2, 3])
    ap.add_argument('--drives', type=int, default=4)
    ap.add_argument('--only', nargs='*', default=[], help='SEED:DRIVE pairs')
    ap.add_argument('--holds', type=int, nargs='*', default=[0, 6])
    ap.add_argument('--noise-seeds', type=int, default=0)
    ap.add_argument('--noise-hold', type=int, default=0, help='hold of the noise variants')
    ap.add_argument('--duration', type=float, default=60.0)
    ap.add_argument('--workers', type=int, default=2)
    ap.add_argument('--json', default='')
    args = ap.parse_args()
    pairs = [tuple(int(v) for v in p.split(':')) for p in args.only] or \
        [(s, i) for s in args.seeds for i in range(args.drives)]
    variants = [(h, 0) for h in args.holds] + [(args.noise_hold, k + 1)
                                                for k in range(args.noise_seeds)]
    jobs = [(s, i, h, e, args.duration) for s, i in pairs for h, e in variants]
    print(f'load average at start: {os.getloadavg()}; {len(jobs)} twin runs of '
          f'{args.duration:g} s on {args.workers} processes', flush=True)
    t0 = time.perf_counter()
    if args.workers > 1:
        with multiprocessing.get_context('fork').Pool(args.workers) as pool:
            results = pool.map(one, jobs, chunksize=1)
    else:
        results = [one(j) for j in jobs]
    by = {(r['seed'], r['drive'], r['hold'], r['noise']): r for r in results}
    names = ', '.join(f'hold {h}' + (f' noise {e}' if e else '') for h, e in variants)
    print(f'per drive: 10-20 s / last 10 s / worst 1 s [steps] for {names}; spread max/min')
    met = {v: [0, 0, 0] for v in variants}
    met_all = [0, 0, 0]
    spreads: list[list[float]] = [[], [], []]
    for s, i in pairs:
        rows = [by[(s, i, h, e)] for h, e in variants]
        cells = ' | '.join(f"{r['x_10_20']:7.1f} {r['x_last']:7.1f} {r['worst_1s']:6.3f} "
                           f"[{len(r['steps'])}]" for r in rows)
        sp = []
        for k, (key, target, _) in enumerate(TARGETS):
            vals = [r[key] for r in rows]
            sp.append(max(vals) / min(vals))
            spreads[k].append(sp[-1])
            met_all[k] += all(v >= target for v in vals)
            for v, r in zip(variants, rows):
                met[v][k] += r[key] >= target
        diff = first_difference(rows[0]['steps'], rows[1]['steps']) if len(rows) > 1 \
            else ''
        print(f"seed {s} drive {i}: {cells} | spread {sp[0]:.2f} {sp[1]:.2f} {sp[2]:.3f} | "
              f"first difference {diff}", flush=True)
    n = len(pairs)
    for v in variants:
        print(f'met, hold {v[0]} noise {v[1]}: ' + ', '.join(
            f'{lab} {m}/{n}' for (_, _, lab), m in zip(TARGETS, met[v])))
    print('met in every variant: ' + ', '.join(f'{lab} {m}/{n}'
                                                for (_, _, lab), m in zip(TARGETS, met_all)))
    for (_, _, lab), sp in zip(TARGETS, spreads):
        a = np.array(sp)
        print(f'spread {lab}: median {np.median(a):.3f}, geometric mean '
              f'{math.exp(np.mean(np.log(a))):.3f}, max {a.max():.3f}')
    print(f'wall {time.perf_counter() - t0:.0f} s; load average at end: {os.getloadavg()}')
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
