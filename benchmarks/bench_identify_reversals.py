# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``identify`` on slew-reversal records of a drive with play and load that differs from the
nominal model (teeth and bearings too): the fit of play, teeth, load torque and drag from one
record of slew reversals, then the held-out theta4 error on another reversal move.

    python benchmarks/bench_identify_reversals.py [--rate 1.5] [--seed 0]

The drive: 3 arcmin of play, 1 N m + 50 N m s/rad of load, teeth x0.85, gear bearings
1.5e8 N/m; records at 1 kHz with 1e-6 rad noise and a 20-bit encoder.  Prints the fitted
values against the truth, the held-out error (RMS over the oscillation amplitude, the
convention of ``identify --validate``) and the wall time."""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from worm_gear_sim import Config
from worm_gear_sim.dynamics.profiles import SampledProfile
from worm_gear_sim.identification import FitOptions, identify, prediction_errors
from worm_gear_sim.identification.data import record_from_model

ARCMIN = math.pi / (180 * 60)
KEYS = ['mesh.backlash', 'mesh.gear_tooth_stiffness_multiplier', 'load.output_torque',
        'load.output_viscous_coefficient']


def reversals(rate: float, amplitude: float, legs: int, hold: float = 0.05) -> SampledProfile:
    """Slews at ``rate`` [rad/s of worm] out to +amplitude, back to -amplitude, ..., with a
    short hold at each end (trapezoids: the reversal is a stop and a start)."""
    t, x = [0.0, hold], [0.0, 0.0]
    pos = 0.0
    for k in range(legs):
        target = amplitude if k % 2 == 0 else -amplitude
        t.append(t[-1] + abs(target - pos) / rate)
        x.append(target)
        t.append(t[-1] + hold)
        x.append(target)
        pos = target
    return SampledProfile(np.array(t), np.array(x), 'linear')


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--rate', type=float, default=1.5, help='slew rate [rad/s of worm]')
    ap.add_argument('--seed', type=int, default=0)
    a = ap.parse_args()
    base = Config()
    truth = base.replace({'mesh.backlash': 3 * ARCMIN,
                          'mesh.gear_tooth_stiffness_multiplier': 0.85,
                          'shafts.gear_bearing_axial_stiffness': 1.5e8,
                          'load.output_torque': 1.0, 'load.output_viscous_coefficient': 50.0})
    enc = 2 * math.pi / 2 ** 20
    train = reversals(a.rate, 0.4, 4)
    held = reversals(0.6 * a.rate, 0.25, 3)
    rec = record_from_model(truth, train, float(train.times[-1]), 1000, ('theta4',), 1e-6, enc,
                            a.seed)
    val = record_from_model(truth, held, float(held.times[-1]), 1000, ('theta4',), 1e-6, enc,
                            a.seed + 1)
    t0 = time.perf_counter()
    res = identify(base, [rec], KEYS, options=FitOptions(serial=True))
    wall = time.perf_counter() - t0
    flat = truth.to_flat_dict()
    for k, v in zip(KEYS, res.values):
        print(f'{k:40s} true {flat[k]:.6g}  fitted {v:.6g}  ({(v / flat[k] - 1) * 100:+.2f} %)')
    before = prediction_errors(base, [val])[0]['theta4']['rel']
    after = prediction_errors(res.config, [val])[0]['theta4']['rel']
    print(f'trustworthy: {res.trustworthy}  warnings: {list(res.warnings)}')
    print(f'held-out theta4: nominal {before * 100:.2f} %, fitted {after * 100:.2f} % of its '
          f'amplitude; fit {wall:.1f} s')


if __name__ == '__main__':
    main()
