# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Live adaptation on drives that differ from the nominal model, and what it costs per sample.

    python benchmarks/bench_adaptation.py [--drives 4] [--seed 1] [--duration 60]
        [--scenario sector] [--stiffness-spread 0.0] [--drag-max 60] [--cost-samples 3000]
        [--no-drives] [--latency-seconds 8] [--latency-rounds 2] [--first-sample-runs 3]
        [--load-min 0.5] [--load-max 5] [--load-sign positive]
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

Latency (``--latency-seconds``, ``--latency-rounds``): the per-sample work paced at 1 kHz in
real time (each sample's work starts at its deadline, after a sleep that releases the GIL as
the node's executor does while it waits), from the start model so that steps are decided and
applied (an adapted step every ``adaptation.step_interval`` after the first window), in one
run, alternated round by round: adaptation off; on with each step prepared in slices on the
sample thread (``in_slices``, the node); on with each step prepared in a worker thread at a
lowered switch interval (how the node prepared before).  Printed per mode: the lateness
(from the sample's deadline to its answer, which the node publishes before the
adaptation's work: a previous sample's work still running, the wait for the GIL and
preemption by other processes included) p99 per round and over all,
p99.9 and the worst; the work's median, its p99 and worst over the samples within
+-NEAR_STEP of a step's decision (wall time: preemption included) and the p99 of its CPU
time there (the sample thread's own: what the preparation adds); the longest slice and step;
the ratio of the p99 lateness on / off per round (target <= 1.5).

First encoder sample (``--first-sample-runs``): in fresh processes built as the node builds
its pipeline, the work of the sample at which the first encoder sample enters the estimate,
with the node's warm-up before "ready" (:mod:`worm_gear_sim.adaptation.warmup`) and without it.
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

from worm_gear_sim.adaptation.live import LiveAdaptation, in_slices, in_worker  # noqa: E402
from worm_gear_sim.config.usable import Config  # noqa: E402
from worm_gear_sim.dynamics.inverse import gear_torque_demand  # noqa: E402
from worm_gear_sim.dynamics.model import DriveModel  # noqa: E402
from worm_gear_sim.dynamics.simulation import Simulator  # noqa: E402
from worm_gear_sim.realtime.predictor import RealtimePredictor  # noqa: E402
from worm_gear_sim.schema.validation import ConfigError  # noqa: E402
from worm_gear_sim.studies.adaptation_twin import (  # noqa: E402
    BASE_NS,
    prepare_start,
    run_twin,
    scenario,
)

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
            meas: dict) -> float:
    """One 1 kHz sample through the pipeline and the adaptation, as the node's callbacks
    hand them on: the predictions, a step decision at the last, the encoder samples.  The
    time (perf_counter) its answer was ready: the node publishes it there, before the
    adaptation's work."""
    out = p.push(ns, x)
    answered = time.perf_counter()
    for q in out.predictions:
        live.predicted(q.stamp_ns, q.theta)
    if out.predictions:
        live.step(out.predictions[-1].stamp_ns)
    for c in out.corrections:
        live.measured(c.stamp_ns, names[2:], [meas[c.stamp_ns]])
    return answered


#: Samples each side of a step's decision whose work is "near a step" (the preparation
#: runs after the decision, the swap APPLY_LEAD later: 50 samples at 1 kHz).
NEAR_STEP = 60
#: How each run prepares an adapted step: 'off' (no adaptation), 'slices' (the node:
#: in_slices, on the sample thread), 'worker' (a worker thread, switch interval lowered:
#: how the node prepared before).
LATENCY_MODES = ('off', 'slices', 'worker')


def latency(args: argparse.Namespace, base: Config) -> None:
    """Lateness per 1 kHz sample paced in real time, adaptation off and on, alternated in
    one run (module docstring)."""
    cfg, t, x, meas = encoder_record(args, base, int(args.latency_seconds * 1000))
    names = cfg.node.joint_names[1:]
    dt = 1.0 / cfg.node.publish_rate_hz
    ok = t >= 0.1                                   # the first samples start the pipeline

    def one(mode: str, paced: bool = True) -> dict[str, Any]:
        pool = concurrent.futures.ThreadPoolExecutor(1) if mode == 'worker' else None
        p = RealtimePredictor(cfg, apply_compensation=True, base_ns=BASE_NS)
        submit = in_worker(pool) if pool is not None else in_slices()
        live = None if mode == 'off' else LiveAdaptation(p, names, submit=submit)
        lat, work, cpu = np.zeros(t.size), np.zeros(t.size), np.zeros(t.size)
        decided: list[int] = []
        longest = longest_step = 0.0
        start = time.perf_counter() + 0.02
        for k in range(t.size):
            deadline = start + k * dt
            if paced:
                now = time.perf_counter()
                if deadline > now:
                    time.sleep(deadline - now)
            t0, c0 = time.perf_counter(), time.thread_time()
            ns = BASE_NS + int(round(t[k] * 1e9))
            if live is None:
                p.push(ns, float(x[k]))
                answered = time.perf_counter()
            else:
                pending = live.pending
                answered = _sample(p, live, ns, float(x[k]), names, meas)
                if live.pending is not None and live.pending is not pending:
                    decided.append(k)
                if pending is not None and hasattr(pending.future, 'longest'):
                    longest = max(longest, pending.future.longest)
                    longest_step = max(longest_step, pending.future.longest_step)
            cpu[k] = time.thread_time() - c0
            t1 = time.perf_counter()
            lat[k], work[k] = answered - deadline if paced else t1 - t0, t1 - t0
        if pool is not None:
            pool.shutdown()
        return {'lat': lat, 'work': work, 'cpu': cpu, 'decided': decided, 'longest': longest,
                'longest_step': longest_step,
                'steps': 0 if live is None else live.counters['switches'],
                'late': 0 if live is None else live.counters['late_steps']}

    one('slices', paced=False)                      # compile, warm up
    rounds: dict[str, list[dict[str, Any]]] = {m: [] for m in LATENCY_MODES}
    for _ in range(args.latency_rounds):            # alternated: the load drifts
        for mode in LATENCY_MODES:
            rounds[mode].append(one(mode))
    decided = rounds['slices'][0]['decided']        # the same samples in every run
    near = np.zeros(t.size, bool)
    for k in decided:
        near[max(k - NEAR_STEP, 0):k + NEAR_STEP + 1] = True
    print(f'latency per 1 kHz sample, paced in real time, {t.size} samples x '
          f'{args.latency_rounds} rounds alternated (load {os.getloadavg()[0]:.2f}); '
          f'{len(decided)} steps decided, {int(np.sum(near & ok))} samples within '
          f'+-{NEAR_STEP} of one:', flush=True)
    p99 = {m: [float(np.quantile(r['lat'][ok], 0.99)) for r in rs] for m, rs in rounds.items()}
    for mode, rs in rounds.items():
        lat = np.concatenate([r['lat'][ok] for r in rs])
        work = np.concatenate([r['work'][ok] for r in rs])
        near_w = np.concatenate([r['work'][ok & near] for r in rs])
        near_c = np.concatenate([r['cpu'][ok & near] for r in rs])
        extra = '' if mode == 'off' else (
            f'; {rs[0]["steps"]} steps ({max(r["late"] for r in rs)} late)' +
            (f', longest slice {max(r["longest"] for r in rs) * 1e3:.3f} ms (wall), longest '
             f'step {max(r["longest_step"] for r in rs) * 1e3:.3f} ms'
             if mode == 'slices' else ''))
        print(f'  {mode:6s}: lateness p99 {np.quantile(lat, 0.99) * 1e3:.3f} ms (per round '
              f'{", ".join(f"{v * 1e3:.3f}" for v in p99[mode])}), p99.9 '
              f'{np.quantile(lat, 0.999) * 1e3:.3f} ms, worst {lat.max() * 1e3:.2f} ms; work '
              f'median {np.median(work) * 1e6:.0f} us, p99 near a step '
              f'{np.quantile(near_w, 0.99) * 1e3:.3f} ms, worst near a step '
              f'{near_w.max() * 1e3:.2f} ms, its CPU time p99 near a step '
              f'{np.quantile(near_c, 0.99) * 1e3:.3f} ms{extra}', flush=True)
    for mode in ('slices', 'worker'):
        ratios = [a / b for a, b in zip(p99[mode], p99['off'])]
        print(f'  p99 lateness {mode} / off: {np.median(ratios):.2f} (per round '
              f'{", ".join(f"{r:.2f}" for r in ratios)}; target <= 1.5 for the node\'s '
              f'way, slices)')


FIRST_SAMPLE = r'''
import sys, time
sys.path.insert(0, sys.argv[2])
from worm_gear_sim.adaptation.live import LiveAdaptation, in_slices
from worm_gear_sim.studies.adaptation_twin import BASE_NS, prepare_start, scenario
from worm_gear_sim.config.usable import Config
from worm_gear_sim.realtime.predictor import RealtimePredictor
from worm_gear_sim.adaptation.warmup import warm_up
cfg = prepare_start(Config())
pred = RealtimePredictor(cfg, apply_compensation=True, base_ns=BASE_NS)
if sys.argv[1] == 'warm':
    warm_up(cfg)                                   # as the node does before "ready"
live = LiveAdaptation(pred, cfg.node.joint_names[1:], submit=in_slices())
antenna = [cfg.node.joint_names[3]]
t, x = scenario(cfg, 'sector', 0.3)
for k in range(t.size):
    t0 = time.perf_counter()
    out = pred.push(BASE_NS + int(round(t[k] * 1e9)), float(x[k]))
    for p in out.predictions:
        live.predicted(p.stamp_ns, p.theta)
    entered = live.adapter.samples_used + live.adapter.samples_skipped
    if out.predictions:
        live.step(out.predictions[-1].stamp_ns)
    first = entered == 0 and live.adapter.samples_used + live.adapter.samples_skipped > 0
    for c in out.corrections:
        live.measured(c.stamp_ns, antenna, [out.predictions[-1].theta[2]])
    if first:
        print((time.perf_counter() - t0) * 1e3)
        break
'''


def first_sample(args: argparse.Namespace) -> None:
    """The work of the sample at which the first encoder sample enters the estimate, in a
    fresh process built as the node builds its pipeline: with the node's warm-up before
    "ready" and without it (the kernels then load at that sample), alternated."""
    import subprocess
    root = str(Path(__file__).resolve().parents[1])
    got: dict[str, list[float]] = {'warm': [], 'cold': []}
    for _ in range(args.first_sample_runs):
        for mode in got:
            out = subprocess.run([sys.executable, '-c', FIRST_SAMPLE, mode, root],
                                 capture_output=True, text=True, check=True)
            got[mode].append(float(out.stdout.strip().splitlines()[-1]))
    print(f'first encoder sample entering the estimate, sample work [ms] in a fresh process '
          f'(load {os.getloadavg()[0]:.2f}): with the warm-up '
          f'{", ".join(f"{v:.3f}" for v in got["warm"])}; without (kernels loaded from the '
          f'cache at that sample) {", ".join(f"{v:.2f}" for v in got["cold"])}')


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
    ap.add_argument('--latency-rounds', type=int, default=2,
                    help='rounds of the latency runs, the modes alternated in each [2]')
    ap.add_argument('--first-sample-runs', type=int, default=3,
                    help='fresh processes per variant for the first encoder sample [3]; 0: none')
    args = ap.parse_args()
    base = Config()
    print(f'load average at start: {os.getloadavg()}', flush=True)
    if args.cost_samples > 0:
        cost(args, base)
    if args.latency_seconds > 0:
        latency(args, base)
    if args.first_sample_runs > 0:
        first_sample(args)
    if not args.no_drives:
        run_drives(args, base)
    print(f'load average at end: {os.getloadavg()}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
