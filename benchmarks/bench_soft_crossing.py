# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The streaming soft crossing of the play (``compensation.soft_crossing``) against the step
crossing and the known trajectory's planned crossings, on drives of
``benchmarks/bench_adaptation.py`` with their own values (perfect knowledge, the centring
preview, the +-5 deg sector scan): antenna error RMS per second [urad] of the drive
simulated under each command, and raw / compensated over the whole run.

    python benchmarks/bench_soft_crossing.py --seed 6 --drive 0 --duration 8
"""

from __future__ import annotations

import argparse
import os

import numpy as np
from bench_adaptation import drive

from worm_gear_sim import Config
from worm_gear_sim.compensation.play_crossing import soft_feedforward_series
from worm_gear_sim.joint_trajectory.compensate import antenna_error
from worm_gear_sim.realtime import feedforward_series
from worm_gear_sim.studies.adaptation_twin import prepare_start, scenario


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seed', type=int, default=6, help="bench_adaptation's --seed")
    ap.add_argument('--drive', type=int, default=0, help='which drive of that seed (from 0)')
    ap.add_argument('--duration', type=float, default=8.0)
    args = ap.parse_args()
    print(f'load average at start: {os.getloadavg()}', flush=True)
    base = Config()
    rng = np.random.default_rng(args.seed)
    sign_rng = np.random.default_rng([args.seed, 1])
    for _ in range(args.drive + 1):          # the same draws as bench_adaptation's defaults
        values, plant = drive(base, rng, 0.0, 60.0, None, sign_rng)
    print(f"seed {args.seed} drive {args.drive}: play {values['mesh.backlash']:.4g} rad, load "
          f"{values['load.output_torque']:.4g} N m, drag "
          f"{values['load.output_viscous_coefficient']:.4g} N m s/rad")
    cfg = prepare_start(plant)               # the centring preview, as the twin runs it
    t, x = scenario(cfg, 'sector', args.duration)
    step = cfg.replace({'compensation.soft_crossing': False})
    commands = {'step': feedforward_series(step, t, x),
                'stream': feedforward_series(cfg, t, x),
                'planned': soft_feedforward_series(cfg, t, x)[0]}
    raw = antenna_error(plant, t, x, x)
    errors = {k: antenna_error(plant, t, x + d, x) for k, d in commands.items()}

    def rms(e: np.ndarray, a: float, b: float) -> float:
        w = (t >= a) & (t < b)
        return float(np.sqrt(np.mean(e[w] ** 2)))

    print('second   uncompensated   step crossing   streaming soft   planned (known path)')
    for a in range(int(args.duration)):
        print(f'{a:4d}-{a + 1:<3d} {rms(raw, a, a + 1) * 1e6:12.2f} '
              + ' '.join(f'{rms(errors[k], a, a + 1) * 1e6:15.2f}' for k in errors))
    whole = {k: rms(raw, 0, args.duration) / rms(e, 0, args.duration)
             for k, e in errors.items()}
    print('whole run, raw / compensated: ' + ', '.join(f'{k} {v:.4g}x' for k, v in whole.items()))
    print(f'load average at end: {os.getloadavg()}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
