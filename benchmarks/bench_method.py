#!/usr/bin/env python3
# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The fixed and the variable step (``integrator.method: fixed | adaptive``) in what runs
the kernel, side by side in one run: the same work with each method, in alternating rounds
(other load on the machine only makes a round slower, so the minimum over rounds is printed
beside the load average).

* ``pipeline``: the node's per-sample work, ``RealtimePredictor.push`` per stamped 1 kHz
  sample (the correction, 1 ms of physics, a prediction), on five streams: the paper's
  18-step move, the +-5 deg sector scan at the antenna, the 2 rad/s worm slew with
  reversals under a 5 N m load (bench_realtime.py's stream) and 20 s of a satellite pass
  around culmination on both axes of the pedestal, each after a 2 s lead-in from rest
  (azimuth and elevation, one pipeline each: the physics a pedestal process runs per
  sample), on the default drive and on config/pedestal.yaml's drives (azimuth with
  20 N m s/rad of drag, elevation with a 5 N m imbalance and a lighter dish).  Printed:
  microseconds per sample, the ratio, and the largest difference of the predicted
  positioning error between the two methods beside the error's own largest value.
* ``identify``: bench_identify.py's timing fit (4 parameters, robust strategy, 0.15 s at
  10 kHz, 2 threads) from a fixed-step record of a drive variant, fitted with each method:
  wall time, evaluations, the values and the held-out error.
* ``calibrate``: ``--drives`` drives of bench_calibration.py's draw (seed 1), each
  calibrated with each method (one process, serial fit): wall time, accepted, the fitted
  play and load, the worst held-out error.
* ``steps``: what decides it, the variable step's mean step and located events per second at a
  constant worm rate, the drive unloaded and under a steady load; and the worm's speed under
  the same loads with the fixed step at 4 and 1 us (the stick-slip is the model's, not the
  variable step's).

    python benchmarks/bench_method.py                        # all four
    python benchmarks/bench_method.py --only pipeline --rounds 5
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from worm_gear_sim import Config, make_profile  # noqa: E402
from worm_gear_sim.dynamics.model import DriveModel  # noqa: E402
from worm_gear_sim.dynamics.simulation import Simulator  # noqa: E402
from worm_gear_sim.realtime import RealtimePredictor  # noqa: E402

METHODS = ('fixed', 'adaptive')
EPOCH = 1_700_000_000_000_000_000
MS = 1_000_000


def _load() -> str:
    return 'load average ' + ' '.join(f'{x:.2f}' for x in os.getloadavg())


def with_method(cfg: Config, method: str) -> Config:
    return cfg.replace({'integrator.method': method})


def lead_in(x: np.ndarray, seconds: float = 2.0, dt: float = 1e-3) -> np.ndarray:
    """``x`` (every ``dt``) after ``seconds`` that take the axis from rest to its first
    sample and rate, the rate rising as a half cosine (the pedestal starts a pass with a
    lead-in from rest too: tracking_pass.LEAD_IN; a jump from rest to the pass's rate would
    set the worm ringing for seconds, a test of something else)."""
    v0 = (x[1] - x[0]) / dt
    t = np.arange(0.0, seconds, dt)

    def travel(s):
        return v0 * (s / 2 - seconds / (2 * math.pi) * np.sin(math.pi * s / seconds))
    return np.concatenate((x[0] - travel(seconds) + travel(t), x))


Axes = dict[str, tuple[Config, np.ndarray]]


def streams(cfg: Config) -> dict[str, Axes]:
    """name -> {axis: (its configuration, its worm command [rad] every ms)}."""
    from bench_realtime import LOAD, slew

    from worm_gear_sim.config.pedestal import load_pedestal
    from worm_gear_sim.studies.mismatch import sector_scan
    from worm_gear_sim.studies.tracking_pass import pass_window
    t = np.arange(0.0, 0.5, 1e-3)
    move = make_profile(cfg.input)
    scan = sector_scan(cfg)
    _, x = slew(4000)
    ratio = DriveModel(cfg).output_per_input
    _, az, el = pass_window(20.0)
    path = {'azimuth': lead_in((az - az[0]) / ratio), 'elevation': lead_in((el - el[0]) / ratio)}
    pedestal = {d.name: d.config for d in load_pedestal()}
    return {
        '18-step move, 0.5 s': {'worm': (cfg, np.array([move.theta1(s) for s in t]))},
        'sector scan +-5 deg, 4 s': {'worm': (cfg, np.asarray(scan.theta1[:4000]))},
        '2 rad/s slew, 5 N m, 4 s': {'worm': (cfg.replace(LOAD), np.asarray(x))},
        'pass, unloaded, 2 x 22 s': {a: (cfg, c) for a, c in path.items()},
        "pass, pedestal's drives": {a: (pedestal[a], c) for a, c in path.items()},
    }


def run_stream(cfg: Config, command: np.ndarray) -> tuple[float, np.ndarray]:
    """(seconds of push calls, predicted positioning error per sample) of one pipeline."""
    p = RealtimePredictor(cfg)
    err = np.empty(command.size)
    wall = 0.0
    for k, x in enumerate(command.tolist()):
        s = EPOCH + k * MS
        t0 = time.perf_counter()
        out = p.push(s, x, now_ns=s)
        wall += time.perf_counter() - t0
        assert out.accepted, out.rejected
        err[k] = out.predictions[-1].positioning_error
    return wall, err


def pipeline(rounds: int) -> None:
    print(f'RealtimePredictor.push per stamped 1 kHz sample, min of {rounds} alternating '
          f'rounds; {_load()}')
    print(f'  {"stream":<26} {"fixed us":>9} {"adaptive us":>12} {"fixed/adaptive":>15} '
          f'{"max |d error| urad":>19} {"max |error| urad":>17}')
    for name, axes in streams(Config()).items():
        best = {m: math.inf for m in METHODS}
        errs: dict[str, dict[str, np.ndarray]] = {}
        n = sum(c.size for _, c in axes.values())
        for m in METHODS:                # untimed: the kernels loaded, the caches warm
            for cfg, x in axes.values():
                run_stream(with_method(cfg, m), x[:200])
        for _ in range(rounds):
            for m in METHODS:
                runs = {a: run_stream(with_method(cfg, m), x) for a, (cfg, x) in axes.items()}
                best[m] = min(best[m], sum(w for w, _ in runs.values()))
                errs[m] = {a: e for a, (_, e) in runs.items()}
        d = max(float(np.max(np.abs(errs['fixed'][a] - errs['adaptive'][a]))) for a in axes)
        e = max(float(np.max(np.abs(errs['fixed'][a]))) for a in axes)
        f, v = (best[m] / n * 1e6 for m in METHODS)
        print(f'  {name:<26} {f:9.1f} {v:12.1f} {f / v:15.2f} {d * 1e6:19.3f} {e * 1e6:17.1f}',
              flush=True)
    print(f'  {_load()}')


def identify_rows(rounds: int) -> None:
    from bench_identify import KEYS, drives, held_out, records

    from worm_gear_sim.identification import FitOptions, identify
    base = Config()
    truth, _ = drives(base)['variant: lead angle, const mu, mapping']
    train, hold, clean = records(truth, seed=7)
    print(f'identify, 4 parameters, {train.t.size} samples, robust, 2 threads; {_load()}')
    for r in range(rounds):
        for m in METHODS:
            cfg = with_method(base, m)
            t0 = time.perf_counter()
            res = identify(cfg, [train], KEYS, options=FitOptions(serial=True, threads=2))
            wall = time.perf_counter() - t0
            h, c = held_out(res.config, hold, clean)
            nfev = sum(s['nfev'] for s in res.starts)
            print(f'  [{r + 1}] {m:<9} {wall:6.2f} s  nfev {nfev:4d}  values '
                  + ' '.join(f'{v:.5g}' for v in res.values)
                  + f'  held-out theta4 {h:.2f} % (vs truth {c:.2f} %)', flush=True)
    print(f'  {_load()}')


def calibrate_rows(n: int) -> None:
    from bench_calibration import KEYS, LOAD, PLAY, draw

    from worm_gear_sim.identification import FitOptions
    from worm_gear_sim.identification.calibrate import calibrate, plant_runner
    from worm_gear_sim.identification.excitation import Limits
    limits = Limits(0.5, 6.0, 1500.0, 2.0)
    print(f'calibrate (play, load, drag, teeth), drives of bench_calibration.py seed 1, '
          f'serial; {_load()}')
    for i, changes in enumerate(draw(n, 1)):
        plant = Config().replace(changes)
        for m in METHODS:
            run = plant_runner(plant, 1e4, ('theta4',), 1e-6, 2 * math.pi / 2 ** 20, 1 + i)
            t0 = time.perf_counter()
            res = calibrate(with_method(Config(), m), KEYS, limits, run,
                            options=FitOptions(serial=True))
            wall = time.perf_counter() - t0
            print(f'  drive {i} {m:<9} {wall:6.2f} s  accepted {res.accepted!s:<5}  play '
                  f'{res.estimate(PLAY) * 1e6:8.1f} urad (true {changes[PLAY] * 1e6:8.1f})  '
                  f'load {res.estimate(LOAD):6.3f} N m (true {changes[LOAD]:6.3f})  '
                  f'worst held-out {100 * res.worst_held_out():.2f} %', flush=True)
    print(f'  {_load()}')


def constant_rate(t: np.ndarray, rate: float):
    """The worm command on the 1 ms grid ``t``: from rest to ``rate`` [rad/s] over 0.5 s
    (the rate rising as a half cosine), then constant."""
    from worm_gear_sim.dynamics.profiles import SampledProfile
    r = rate * np.where(t < 0.5, 0.5 - 0.5 * np.cos(np.pi * t / 0.5), 1.0)
    return SampledProfile(t, np.concatenate(([0.0], np.cumsum((r[1:] + r[:-1]) / 2 * 1e-3))))


def steps_at_a_constant_rate() -> None:
    """What decides it: the variable step's mean step and located events per second over
    [1, 3] s of a constant worm rate (reached by a 0.5 s half-cosine ramp from rest), the
    drive unloaded and under a steady load (the kernel alone: adaptive_steps.kernel_run)."""
    from adaptive_steps import ADAPTIVE, kernel_run

    from worm_gear_sim.dynamics.integrator import S_ADAPTIVE_STEPS, S_EVENTS
    print('the variable step at a constant worm rate, over [1, 3] s: mean step [us] / '
          'located events per s')
    loads = {'unloaded': {}, '0.01 N m': {'load.output_torque': 0.01},
             '0.1 N m': {'load.output_torque': 0.1}, '5 N m': {'load.output_torque': 5.0},
             '20 N m s/rad': {'load.output_viscous_coefficient': 20.0}}
    rates = (0.5, 2.0, 5.0, 10.0, 20.0)
    print(f'  {"load":<14}' + ''.join(f'{f"{r:g} rad/s":>20}' for r in rates))
    t = np.arange(0.0, 3.0, 1e-3)
    for name, load in loads.items():
        cfg = Config().replace({**ADAPTIVE, **load})
        cells = []
        for rate in rates:
            prof = constant_rate(t, rate)
            (_, a), (_, b) = kernel_run(cfg, prof, 1.0), kernel_run(cfg, prof, 2.999)
            n, ev = b[S_ADAPTIVE_STEPS] - a[S_ADAPTIVE_STEPS], b[S_EVENTS] - a[S_EVENTS]
            cells.append(f'{2e6 / max(n, 1):8.2f} / {ev / 2:8.0f}')
        print(f'  {name:<14}' + ''.join(f'{c:>20}' for c in cells), flush=True)
    print('the fixed step at 5 rad/s, the worm speed omega2 over [1.09, 1.1] s (min, max) '
          '[rad/s]:')
    prof = constant_rate(t, 5.0)
    for name, load in loads.items():
        for dt in (4e-6, 1e-6):
            cfg = Config().replace({**load, 'integrator.time_step': dt})
            tr = Simulator(cfg).run(prof, 1.1)
            w2 = tr.omega[tr.t >= 1.09, 0]
            print(f'  {name:<14} time step {dt * 1e6:g} us: {w2.min():7.3f} {w2.max():7.3f}',
                  flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--only', choices=('pipeline', 'identify', 'calibrate', 'steps'))
    ap.add_argument('--rounds', type=int, default=3, help='rounds of pipeline and identify')
    ap.add_argument('--drives', type=int, default=2, help='drives of calibrate')
    a = ap.parse_args(argv)
    if a.only in (None, 'pipeline'):
        pipeline(a.rounds)
    if a.only in (None, 'identify'):
        identify_rows(a.rounds)
    if a.only in (None, 'calibrate'):
        calibrate_rows(a.drives)
    if a.only in (None, 'steps'):
        steps_at_a_constant_rate()
    return 0


if __name__ == '__main__':
    sys.exit(main())
