# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Calibration of play and load on N random drives.

Draws N drives with a seed (play 0.5-5 arcmin, load torque 0-5 N m, antenna drag 0-100
N m s/rad, gear teeth stiffness x0.7-1.3, both bearings x0.7-1.3; every third drive with the
regularised (tanh, creeping) friction law instead of the exact stick-slip one the fit
assumes), simulates each as the plant (theta4 at 10 kHz, 1 urad noise, 20-bit encoder
steps), runs :func:`worm_gear_sim.identification.calibrate.calibrate` on it fitting play,
load torque, drag and the teeth multiplier from the package defaults, and prints a table
(true vs fitted, whether the excitation showed the play, held-out theta4 error, accepted,
wall time) and a summary against the targets:

    python benchmarks/bench_calibration.py --drives 20 --seed 1 --jobs 2
    python benchmarks/bench_calibration.py --drives 20 --max-rate 20 --max-accel 5000 \
        --max-angle 1.5
    python benchmarks/bench_calibration.py --drives 20 --seed 2 --drive 6 --jobs 1

Each calibration runs in one process (``--jobs`` drives at a time): its wall time is
measured under that load.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from worm_gear_sim import Config
from worm_gear_sim.identification import FitOptions, IdentificationError
from worm_gear_sim.identification.calibrate import calibrate, plant_runner
from worm_gear_sim.identification.excitation import Limits

ARCMIN = math.pi / 180.0 / 60.0
PLAY, LOAD, DRAG = 'mesh.backlash', 'load.output_torque', 'load.output_viscous_coefficient'
TEETH = 'mesh.gear_tooth_stiffness_multiplier'
KEYS = [PLAY, LOAD, DRAG, TEETH]


def draw(n: int, seed: int) -> list[dict]:
    rng = np.random.default_rng(seed)
    base = Config()
    out = []
    for i in range(n):
        d = {PLAY: rng.uniform(0.5, 5.0) * ARCMIN, LOAD: rng.uniform(0.0, 5.0),
             DRAG: rng.uniform(0.0, 100.0), TEETH: rng.uniform(0.7, 1.3),
             'shafts.worm_bearing_axial_stiffness':
                 base.shafts.worm_bearing_axial_stiffness * rng.uniform(0.7, 1.3),
             'shafts.gear_bearing_axial_stiffness':
                 base.shafts.gear_bearing_axial_stiffness * rng.uniform(0.7, 1.3)}
        if i % 3 == 2:
            d['friction.direction'] = 'regularized'
        out.append(d)
    return out


def one(job: tuple) -> dict:
    i, changes, limits, seed = job
    plant = Config().replace(changes)
    run = plant_runner(plant, 1e4, ('theta4',), 1e-6, 2 * math.pi / 2 ** 20, seed + i)
    t0 = time.perf_counter()
    row = {'i': i, 'changes': changes}
    try:
        res = calibrate(Config(), KEYS, limits, run, options=FitOptions(serial=True))
    except IdentificationError as exc:
        row.update(error=str(exc), wall=time.perf_counter() - t0)
        return row
    row.update(wall=time.perf_counter() - t0, accepted=res.accepted, reasons=res.reasons,
               fit={k: res.estimate(k) for k in KEYS}, held=res.worst_held_out(),
               play_seen=PLAY not in res.not_seen, not_seen=res.not_seen)
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--drives', type=int, default=20)
    ap.add_argument('--seed', type=int, default=1)
    ap.add_argument('--jobs', type=int, default=2)
    ap.add_argument('--max-angle', type=float, default=0.5)
    ap.add_argument('--max-rate', type=float, default=6.0)
    ap.add_argument('--max-accel', type=float, default=1500.0)
    ap.add_argument('--duration', type=float, default=2.0)
    ap.add_argument('--drive', type=int, action='append', metavar='I',
                    help='only drive I of the draw (repeatable): one drive alone')
    a = ap.parse_args()
    limits = Limits(a.max_angle, a.max_rate, a.max_accel, a.duration)
    drives = draw(a.drives, a.seed)
    print(f'load before: {os.getloadavg()}')
    t0 = time.perf_counter()
    jobs = [(i, d, limits, a.seed) for i, d in enumerate(drives)
            if not a.drive or i in a.drive]
    if a.jobs > 1:
        with ProcessPoolExecutor(a.jobs) as ex:
            rows = list(ex.map(one, jobs))
    else:
        rows = [one(j) for j in jobs]
    total = time.perf_counter() - t0
    print(f'{"#":>2} {"law":>5} {"play true":>9} {"fit":>7} {"err":>6} {"seen":>4} '
          f'{"T true":>6} {"fit":>6} {"c true":>6} {"fit":>6} {"teeth":>5} {"fit":>5} '
          f'{"held":>6} {"acc":>3} {"wall":>6}')
    ok = {'accepted': 0, 'play5': 0, 'play5_seen': 0, 'seen': 0, 'load5': 0, 'held3': 0}
    walls = []
    for r in rows:
        c = r['changes']
        law = 'tanh' if c.get('friction.direction') == 'regularized' else 'exact'
        if 'error' in r:
            print(f'{r["i"]:>2} {law:>5} error: {r["error"]}')
            continue
        f = r['fit']
        perr = f[PLAY] / c[PLAY] - 1
        lerr = abs(f[LOAD] - c[LOAD])
        load_ok = lerr <= max(0.05 * abs(c[LOAD]), 0.05)
        walls.append(r['wall'])
        ok['accepted'] += r['accepted']
        ok['play5'] += abs(perr) <= 0.05
        ok['seen'] += r['play_seen']
        ok['play5_seen'] += r['play_seen'] and abs(perr) <= 0.05
        ok['load5'] += load_ok
        ok['held3'] += r['held'] <= 0.03
        print(f'{r["i"]:>2} {law:>5} {c[PLAY] / ARCMIN:>9.3f} {f[PLAY] / ARCMIN:>7.3f} '
              f'{100 * perr:>+5.1f}% {"yes" if r["play_seen"] else "no":>4} '
              f'{c[LOAD]:>6.3f} {f[LOAD]:>6.3f} {c[DRAG]:>6.2f} {f[DRAG]:>6.2f} '
              f'{c[TEETH]:>5.2f} {f[TEETH]:>5.2f} {100 * r["held"]:>5.2f}% '
              f'{"yes" if r["accepted"] else "NO":>3} {r["wall"]:>5.1f}s')
    n = len(walls)
    print(f'\n{n} drives calibrated (limits: max_angle {a.max_angle} rad, max_rate '
          f'{a.max_rate} rad/s, max_accel {a.max_accel} rad/s^2, duration {a.duration} s; '
          f'{a.jobs} at a time), {total:.0f} s in all; load after: {os.getloadavg()}')
    print(f'accepted {ok["accepted"]}/{n}; play seen by the excitation {ok["seen"]}/{n}; play '
          f'within 5 %: {ok["play5"]}/{n} (of the drives where it was seen: '
          f'{ok["play5_seen"]}/{ok["seen"]}); load torque within 5 % or 0.05 N m: '
          f'{ok["load5"]}/{n}; held-out theta4 within 3 %: {ok["held3"]}/{n}; wall per '
          f'drive {min(walls):.0f}-{max(walls):.0f} s (median {np.median(walls):.0f} s)')
    for r in rows:
        for line in (r.get('not_seen') or {}).values():
            print(f'  drive {r["i"]}: {line}')
            break


if __name__ == '__main__':
    main()
