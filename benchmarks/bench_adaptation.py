# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Live adaptation on drives that differ from the nominal model, and what it costs per sample.

    python benchmarks/bench_adaptation.py [--drives 4] [--seed 1] [--duration 60]
        [--scenario sector] [--stiffness-spread 0.0] [--drag-max 60] [--cost-samples 3000]
        [--no-drives]
        [--latency-seconds 8] [--load-min 0.5] [--load-max 5] [--load-sign positive]
        [--play-max 5] [--error-max 30] [--gear-orders 1] [--known-drive] [--crossing-times]

Each drive: the default set with a random play (0.5-5 arcmin), load torque (0.5-5 N m),
antenna drag (0-60 N m s/rad, capped at ``--drag-max``; 0: the same drives without drag,
the other draws unchanged), worm error orders 1-3 and gear order 1 (each coefficient
2-30 urad, random sign) and, with ``--stiffness-spread s``, teeth and bearing stiffness
multiplied by 1 +- s (not adapted).

Drive families beyond these draws (defaults: the draws above; each option changes a range,
never the number of draws, so a drive's other values stay as in the default draws):

* ``--load-min a --load-max b``: the load's magnitude from [a, b] N m (e.g. 0.05-0.5: a
  small load, which the drag torque outweighs over most of the scan, so the teeth cross the
  play twice per scan period; without drag only a load below the inertia torque, 0.017 N m
  on the sector scan, lets them cross);
* ``--load-sign both``: each load negative with probability 1/2 (the sign from a generator
  of its own, seeded by ``--seed``);
* ``--play-max p``: the play from 0.5-p arcmin;
* ``--error-max e``: each periodic error coefficient from 2-e urad;
* ``--gear-orders 0``: no gear error order (worm orders 1-3 only).

``--crossing-times`` prints every crossing of the play the adapter measured (by the step
detector or at a flank event) against the drive's own: where its torque demand
T + c omega4 + J alpha4 passes zero along the commanded path, in ms and in the time sd the
measurement was weighed with; then a summary per method.

``--known-drive`` also runs each drive with the feed-forward of its own values, never
adapted, and prints the same three figures: what the compensation reaches when the model is
right, the bound of the adaptation on that drive.

The offline twin (``worm-gear-sim adapt``, the node's loop) runs the scenario from the
NOMINAL model; printed per drive (figures, never asserted):

* RMS antenna error uncompensated / with the adapting feed-forward over 10-20 s (target
  >= 10x) and 50-60 s (target >= 30x), and the whole run;
* the worst ratio over the 1 s windows after the first two worm revolutions (target: >= 1,
  never worse than uncompensated);
* the values in use at the end against the drive's.

Cost (``--cost-samples``): the node's per-sample work (``RealtimePredictor.push`` and, with
adaptation, the prediction kept, the switching rule and the encoder sample) on the same
recorded samples, alternated five times in one run: off with the start model, off with the
model the adaptation arrives at (a model with play and load costs more in the simulator:
that is the model's cost, not the adaptation's) and on from that model; the ratio of the
medians on / off on the same model (target <= 1.2x) and the absolute figures, with the
machine's load (shared cores: under load).

Latency (``--latency-seconds``): the same per-sample work paced at 1 kHz in real time (each
sample's work starts at its deadline, after a sleep that releases the GIL as the node's
executor does while it waits), from the start model so that steps are decided and applied
(an adapted step every ``adaptation.step_interval`` after the first window); once with each
step prepared inside the sample callback (``submit`` = run at once: how the node did it
before) and once in a worker thread with the swap at the step's fixed stamp (the node now).
Printed: per sample, the time from its deadline (or the previous sample's end, if later) to
the end of its work (the wait for the GIL and preemption by other processes included) and
the work itself; the worst and the 99.9th percentile over all samples, the worst over the
samples where a step was decided or swapped in, the samples over 1 ms.  A third run
prepares in a worker thread at Python's default switch interval (5 ms), for comparison.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from worm_gear_sim.adaptation.live import LiveAdaptation, in_worker  # noqa: E402
from worm_gear_sim.adaptation.twin import (  # noqa: E402
    BASE_NS,
    prepare_start,
    run_twin,
    scenario,
)
from worm_gear_sim.dynamics.inverse import gear_torque_demand  # noqa: E402
from worm_gear_sim.dynamics.model import DriveModel  # noqa: E402
from worm_gear_sim.dynamics.simulation import Simulator  # noqa: E402
from worm_gear_sim.params import Config  # noqa: E402
from worm_gear_sim.realtime.predictor import RealtimePredictor  # noqa: E402
from worm_gear_sim.validation import ConfigError  # noqa: E402

ARCMIN = math.pi / 180.0 / 60.0


def drive(base: Config, rng: np.random.Generator, spread: float, drag_max: float = 60.0,
          family: argparse.Namespace | None = None, sign_rng: np.random.Generator | None = None
          ) -> tuple[dict, Config]:
    """One drawn drive. ``family`` (the options --load-min ... --gear-orders) changes the
    ranges but never the number of draws from ``rng``, so each drive's other values stay
    those of the default draws; the load's sign, with --load-sign both, comes from
    ``sign_rng``, a generator of its own."""
    f = family if family is not None else argparse.Namespace(
        load_min=0.5, load_max=5.0, load_sign='positive', play_max=5.0, error_max=30.0,
        gear_orders=1)
    err_max = f.error_max * 1e-6

    def coef() -> float:
        return float(rng.uniform(2e-6, err_max) * rng.choice([-1.0, 1.0]))

    v = {'mesh.backlash': rng.uniform(0.5, f.play_max) * ARCMIN,
         'load.output_torque': rng.uniform(f.load_min, f.load_max),
         'load.output_viscous_coefficient': min(rng.uniform(0.0, 60.0), drag_max),
         'mesh.worm_error_harmonics': [coef() for _ in range(6)],
         'mesh.gear_error_harmonics': [coef() for _ in range(2)]}
    if f.gear_orders == 0:
        v['mesh.gear_error_harmonics'] = []
    if f.load_sign == 'both' and sign_rng is not None and sign_rng.random() < 0.5:
        v['load.output_torque'] = -v['load.output_torque']
    if spread > 0:
        flat = base.to_flat_dict()
        k_t, k_b = rng.uniform(1 - spread, 1 + spread, 2)
        for k in ('mesh.worm_tooth_stiffness_multiplier',
                  'mesh.gear_tooth_stiffness_multiplier'):
            v[k] = flat[k] * k_t
        for k in ('shafts.worm_bearing_axial_stiffness', 'shafts.gear_bearing_axial_stiffness'):
            v[k] = flat[k] * k_b
    return v, base.replace(v)


def rms(t: np.ndarray, e: np.ndarray, a: float, b: float) -> float:
    m = (t >= a) & (t < b)
    return float(np.sqrt(np.mean(e[m] ** 2))) if np.any(m) else math.nan


def two_revolutions(t: np.ndarray, theta1: np.ndarray) -> float:
    """Time at which the worm has travelled two revolutions (4 pi rad of path)."""
    path = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(theta1)))])
    k = int(np.searchsorted(path, 4 * math.pi))
    return float(t[min(k, t.size - 1)])


def crossing_times(plant: Config, run: Any) -> list[tuple[str, float, float]]:
    """Each crossing the adapter measured (``run.crossings``) against the drive's own: the
    zero of its torque demand T + c omega4 + J alpha4 (its load, drag and J_g + J_4) along
    the commanded antenna path theta1_ref l_w / r_g nearest to it (within 0.5 s). Prints
    one line per crossing; returns (how, error [s], time sd [s])."""
    m = DriveModel.of(plant)
    w4 = np.gradient(m.output_per_input * run.theta1_ref, run.t)
    demand = np.array([gear_torque_demand(m.p, w, a, 0.0, 0.0, False)
                       for w, a in zip(w4, np.gradient(w4, run.t))])
    k = np.nonzero(np.sign(demand[1:]) != np.sign(demand[:-1]))[0]
    zeros = run.t[k] - demand[k] * (run.t[k + 1] - run.t[k]) / (demand[k + 1] - demand[k])
    out = []
    for t_p, _, _, sd, how in run.crossings:
        near = zeros[np.abs(zeros - t_p) < 0.5] if zeros.size else zeros
        err = float(t_p - near[np.argmin(np.abs(near - t_p))]) if near.size else math.nan
        out.append((how, err, sd))
        print(f'   crossing {how:9s} at {t_p:8.3f} s: {err * 1e3:7.1f} ms from the drive\'s '
              f'torque zero, time sd {sd * 1e3:5.1f} ms ({err / sd:6.2f} sd)', flush=True)
    return out


def _setting(text: str) -> tuple[str, Any]:
    """KEY=VALUE (the value read as YAML) -> (key, value)."""
    import yaml
    key, sep, value = text.partition('=')
    if not sep or not key.strip():
        raise SystemExit(f'--start {text!r}: KEY=VALUE, e.g. adaptation.max_step=0.01')
    return key.strip(), yaml.safe_load(value)


def run_drives(args: argparse.Namespace, base: Config) -> None:
    # the start (the nominal model the adaptation begins from), --start KEY=VALUE applied;
    # the drives are drawn around the defaults either way
    start = base.replace(dict(_setting(s) for s in args.start)) if args.start else base
    rng = np.random.default_rng(args.seed)
    sign_rng = np.random.default_rng([args.seed, 1])
    rows = []
    timing: list[tuple[str, float, float]] = []
    for i in range(args.drives):
        try:
            v, plant = drive(base, rng, args.stiffness_spread, args.drag_max, args, sign_rng)
        except ConfigError as exc:          # (a drawn set the model cannot use: say so)
            print(f'drive {i}: not usable, skipped ({exc})', flush=True)
            continue
        t0 = time.perf_counter()
        run = run_twin(plant, start, args.scenario, args.duration, seed=args.seed + i)
        wall = time.perf_counter() - t0
        t, u, c = run.t, run.error_uncompensated, run.error_compensated
        t2 = two_revolutions(t, run.theta1_ref)
        worst = math.inf
        for a in np.arange(math.ceil(t2), args.duration - 0.999, 1.0):
            worst = min(worst, rms(t, u, a, a + 1) / rms(t, c, a, a + 1))
        r = {'drive': i, 'play_arcmin': v['mesh.backlash'] / ARCMIN,
             'load': v['load.output_torque'], 'drag': v['load.output_viscous_coefficient'],
             'x_10_20': rms(t, u, 10, 20) / rms(t, c, 10, 20),
             'x_50_60': rms(t, u, args.duration - 10, args.duration)
             / rms(t, c, args.duration - 10, args.duration),
             'x_all': rms(t, u, 0, args.duration + 1) / rms(t, c, 0, args.duration + 1),
             'worst_1s': worst, 'after_s': t2, 'steps': len(run.steps), 'wall_s': wall,
             'raw_rms_urad': 1e6 * rms(t, u, 0, args.duration + 1)}
        if args.known_drive:
            # the bound: the feed-forward of the drive's own values, never adapted
            ref = run_twin(plant, plant, args.scenario, args.duration, seed=args.seed + i,
                           adapt=False)
            kt, ku, kc = ref.t, ref.error_uncompensated, ref.error_compensated
            kw = min(rms(kt, ku, a, a + 1) / rms(kt, kc, a, a + 1)
                     for a in np.arange(math.ceil(t2), args.duration - 0.999, 1.0))
            end = args.duration
            print(f"   known drive (its own values, not adapted): 10-20 s "
                  f"{rms(kt, ku, 10, 20) / rms(kt, kc, 10, 20):.1f}x | last 10 s "
                  f"{rms(kt, ku, end - 10, end) / rms(kt, kc, end - 10, end):.1f}x"
                  f" | worst 1 s {kw:.4f}x", flush=True)
        rows.append(r)
        if args.crossing_times:
            timing += crossing_times(plant, run)
        fit = run.in_use
        print(f"drive {i}: play {r['play_arcmin']:.2f}' load {r['load']:.2f} N m drag "
              f"{r['drag']:.1f} | raw {r['raw_rms_urad']:.0f} urad | 10-20 s "
              f"{r['x_10_20']:.1f}x | last 10 s {r['x_50_60']:.1f}x | all {r['x_all']:.1f}x | "
              f"worst 1 s after {t2:.1f} s {worst:.4f}x | {r['steps']} steps | {wall:.0f} s",
              flush=True)
        print(f"   in use: play {fit.get('mesh.backlash', math.nan) / ARCMIN:.3f}' load "
              f"{fit.get('load.output_torque', math.nan):.3f} drag "
              f"{fit.get('load.output_viscous_coefficient', math.nan):.2f}; worm "
              f"{np.round(np.array(fit.get('mesh.worm_error_harmonics', [])) * 1e6, 1)} (true "
              f"{np.round(np.array(v['mesh.worm_error_harmonics']) * 1e6, 1)}) urad",
              flush=True)
    if timing:
        print('crossing times against the drive\'s torque zero, per method: n, median |error|,'
              ' RMS and max of |error| / its time sd')
        for how in sorted({h for h, _, _ in timing}):
            err = np.array([e for h, e, _ in timing if h == how and math.isfinite(e)])
            z = np.array([e / sd for h, e, sd in timing if h == how and math.isfinite(e)])
            if err.size:
                print(f'   {how:10s} {err.size:4d} | {np.median(np.abs(err)) * 1e3:6.1f} ms | '
                      f'{np.sqrt(np.mean(z ** 2)):6.2f} | {np.max(np.abs(z)):6.2f}')
    targets = (('x_10_20', 10.0), ('x_50_60', 30.0), ('worst_1s', 1.0)) if rows else ()
    for key, target in targets:
        vals = np.array([r[key] for r in rows])
        print(f'{key}: min {vals.min():.4g} median {np.median(vals):.4g} max {vals.max():.4g};'
              f' target >= {target:g}: met on {int(np.sum(vals >= target))}/{vals.size}')


def encoder_record(args: argparse.Namespace, base: Config, samples: int
                   ) -> tuple[Config, np.ndarray, np.ndarray, dict[int, float]]:
    """(start set, t, theta1_ref, encoder theta4 by stamp) of the first drive driven by the
    nominal feed-forward over ``samples`` samples."""
    rng = np.random.default_rng(args.seed)
    _, plant = drive(base, rng, 0.0)
    cfg = prepare_start(base)
    t, x = scenario(cfg, args.scenario, samples / cfg.node.publish_rate_hz)
    # the encoder record: the plant driven by the nominal feed-forward
    pred = RealtimePredictor(cfg, apply_compensation=True, base_ns=BASE_NS)
    sim = Simulator(plant, theta1=float(x[0]))
    meas: dict[int, float] = {}
    for k in range(t.size):
        for c in pred.push(BASE_NS + int(round(t[k] * 1e9)), float(x[k])).corrections:
            tc = (c.stamp_ns - BASE_NS) * 1e-9
            if tc > sim.t:
                sim.advance_to(tc, c.compensated)
            meas[c.stamp_ns] = sim.joint_state()[0][3]
    return cfg, t, x, meas


def cost(args: argparse.Namespace, base: Config) -> None:
    """Per-sample cost of the node's work with adaptation off and on (module docstring)."""
    cfg, t, x, meas = encoder_record(args, base, args.cost_samples)
    names = cfg.node.joint_names[1:]

    def one(adapt: bool, model: Config, keep: list | None = None) -> float:
        p = RealtimePredictor(model, apply_compensation=True, base_ns=BASE_NS)
        live = LiveAdaptation(p, names) if adapt else None
        t0 = time.perf_counter()
        for k in range(t.size):
            ns = BASE_NS + int(round(t[k] * 1e9))
            if live is None:
                p.push(ns, float(x[k]))
            else:
                _sample(p, live, ns, float(x[k]), names, meas)
        wall = (time.perf_counter() - t0) / t.size
        if keep is not None:
            keep.append(p.config)
        return wall

    adapted: list = []
    one(True, cfg, adapted)                     # compile, warm up; the set it adapts to
    runs: dict[str, list[float]] = {'off, start model': [], 'off, adapted model': [],
                                    'on, from the adapted model': []}
    for _ in range(5):
        runs['off, start model'].append(one(False, cfg))
        runs['off, adapted model'].append(one(False, adapted[0]))
        runs['on, from the adapted model'].append(one(True, adapted[0]))
    med = {k: float(np.median(v)) for k, v in runs.items()}
    for k, v in runs.items():
        print(f'  {k}: median {med[k] * 1e6:.1f} us, min {min(v) * 1e6:.1f} us per sample')
    on, off = med['on, from the adapted model'], med['off, adapted model']
    print(f'cost per 1 kHz sample ({t.size} samples x 5, alternated): adaptation on / off on '
          f'the same model {on / off:.3f} (target <= 1.2; minima '
          f'{min(runs["on, from the adapted model"]) / min(runs["off, adapted model"]):.3f}); '
          f'the adapted model (play, load) itself costs '
          f'{off / med["off, start model"]:.3f}x the start model in the simulator')


def _sample(p: RealtimePredictor, live: LiveAdaptation, ns: int, x: float, names: Any,
            meas: dict) -> None:
    """One 1 kHz sample through the pipeline and the adaptation, as the node's callbacks
    hand them on: the predictions, a step decision at the last, the encoder samples."""
    out = p.push(ns, x)
    for q in out.predictions:
        live.predicted(q.stamp_ns, q.theta)
    if out.predictions:
        live.step(out.predictions[-1].stamp_ns)
    for c in out.corrections:
        live.measured(c.stamp_ns, names[2:], [meas[c.stamp_ns]])


def latency(args: argparse.Namespace, base: Config) -> None:
    """Worst per-sample latency paced at 1 kHz, steps prepared in the callback or in a
    worker thread (module docstring)."""
    cfg, t, x, meas = encoder_record(args, base, int(args.latency_seconds * 1000))
    names = cfg.node.joint_names[1:]
    dt = 1.0 / cfg.node.publish_rate_hz

    def one(worker: str, paced: bool) -> dict[str, Any]:
        pool = concurrent.futures.ThreadPoolExecutor(1) if worker else None
        p = RealtimePredictor(cfg, apply_compensation=True, base_ns=BASE_NS)
        submit = None if pool is None else pool.submit if worker == 'plain' else \
            in_worker(pool)
        live = LiveAdaptation(p, names, submit=submit)
        lat, work = np.zeros(t.size), np.zeros(t.size)
        marked = np.zeros(t.size, bool)
        start = time.perf_counter() + 0.02
        end = start
        for k in range(t.size):
            deadline = start + k * dt
            if paced:
                now = time.perf_counter()
                if deadline > now:
                    time.sleep(deadline - now)
            t0 = time.perf_counter()
            ns = BASE_NS + int(round(t[k] * 1e9))
            pending, switches = live.pending, live.counters['switches']
            _sample(p, live, ns, float(x[k]), names, meas)
            t1 = time.perf_counter()
            lat[k], work[k] = t1 - max(deadline, end) if paced else t1 - t0, t1 - t0
            end = t1
            marked[k] = live.pending is not pending or live.counters['switches'] != switches
        if pool is not None:
            pool.shutdown()
        ok = t >= 0.1                               # the first samples start the pipeline
        worst = np.argsort(np.where(ok, lat, 0.0))[-5:][::-1]
        return {'top': ', '.join(f'{lat[i] * 1e3:.1f}{"*" if marked[i] else ""}'
                                 for i in worst),
                'over_1ms': int(np.sum(lat[ok] > 1e-3)), 'steps': live.counters['switches'],
                'late': live.counters['late_steps'],
                'max': lat[ok].max(), 'p999': float(np.quantile(lat[ok], 0.999)),
                'max_step': lat[ok & marked].max() if np.any(ok & marked) else math.nan,
                'max_other': lat[ok & ~marked].max(), 'work_max': work[ok].max(),
                'work_step': work[ok & marked].max() if np.any(ok & marked) else math.nan,
                'median': float(np.median(work[ok]))}

    one('lowered', False)                           # compile, warm up
    print(f'latency per 1 kHz sample, paced in real time, {t.size} samples '
          f'(load {os.getloadavg()[0]:.2f}):', flush=True)
    for label, worker in (('prepared in the sample callback (before)', ''),
                          ('in a worker thread, default switch interval', 'plain'),
                          ('in a worker thread, swapped at its stamp (now)', 'lowered')):
        r = one(worker, True)
        print(f"  {label}: {r['steps']} steps ({r['late']} late); deadline to end: "
              f"worst {r['max'] * 1e3:.2f} ms, 99.9 % {r['p999'] * 1e3:.2f} ms, worst on the "
              f"step samples {r['max_step'] * 1e3:.2f} ms, on the others "
              f"{r['max_other'] * 1e3:.2f} ms; work alone: median {r['median'] * 1e6:.0f} us,"
              f" worst {r['work_max'] * 1e3:.2f} ms, worst on the step samples "
              f"{r['work_step'] * 1e3:.2f} ms; samples over 1 ms {r['over_1ms']}, the worst 5 "
              f"[ms, * a step's sample] {r['top']}", flush=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--drives', type=int, default=4)
    ap.add_argument('--seed', type=int, default=1)
    ap.add_argument('--duration', type=float, default=60.0)
    ap.add_argument('--scenario', default='sector')
    ap.add_argument('--stiffness-spread', type=float, default=0.0)
    ap.add_argument('--drag-max', type=float, default=60.0,
                    help='cap on the antenna drag drawn in [0, 60] N m s/rad (0: no drag)')
    ap.add_argument('--load-min', type=float, default=0.5,
                    help='smallest load torque magnitude drawn [N m]')
    ap.add_argument('--load-max', type=float, default=5.0,
                    help='largest load torque magnitude drawn [N m]')
    ap.add_argument('--load-sign', choices=('positive', 'both'), default='positive',
                    help='both: each load negative with probability 1/2')
    ap.add_argument('--play-max', type=float, default=5.0,
                    help='largest play drawn (from 0.5) [arcmin]')
    ap.add_argument('--error-max', type=float, default=30.0,
                    help='largest periodic error coefficient drawn (from 2) [urad]')
    ap.add_argument('--gear-orders', type=int, choices=(0, 1), default=1,
                    help='0: no gear error order (worm orders 1-3 only)')
    ap.add_argument('--known-drive', action='store_true',
                    help="also run each drive's own values as the feed-forward, not adapted")
    ap.add_argument('--crossing-times', action='store_true',
                    help="print each crossing the adapter measured against the drive's own "
                         "torque zero, and a summary per method")
    ap.add_argument('--start', action='append', default=[], metavar='KEY=VALUE',
                    help='a parameter of the start (nominal) model, e.g. '
                         'adaptation.max_step=0.01 (repeatable; the drives are unchanged)')
    ap.add_argument('--cost-samples', type=int, default=3000)
    ap.add_argument('--no-drives', action='store_true')
    ap.add_argument('--latency-seconds', type=float, default=8.0)
    args = ap.parse_args()
    base = Config()
    print(f'load average at start: {os.getloadavg()}', flush=True)
    if args.cost_samples > 0:
        cost(args, base)
    if args.latency_seconds > 0:
        latency(args, base)
    if not args.no_drives:
        run_drives(args, base)
    print(f'load average at end: {os.getloadavg()}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
