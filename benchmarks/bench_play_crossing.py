# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Cost of the soft crossing of the play on a known trajectory, side by side in one run:
``feedforward_series`` (the node's pipeline, the step crossing), ``flank_series`` (the
streaming compensator with its flanks and demands) and ``soft_feedforward_series`` (that
plus the planning of every crossing), on a ±5° sector scan of ``--periods`` 4 s periods
at 1 kHz (two crossings per period; 1 arcmin, 0.5 N m, 10 N m s/rad).  Each figure is the
minimum over ``--repeats`` interleaved runs; the load average is printed.

    python benchmarks/bench_play_crossing.py
    python benchmarks/bench_play_crossing.py --periods 15 --repeats 5
"""

from __future__ import annotations

import argparse
import math
import os
import time

from worm_gear_sim import Config
from worm_gear_sim.compensation.play_crossing import flank_series, soft_feedforward_series
from worm_gear_sim.dynamics.model import DriveModel
from worm_gear_sim.joint_trajectory.compensate import trajectory_model
from worm_gear_sim.realtime import feedforward_series
from worm_gear_sim.studies.mismatch import sector_scan

ARCMIN = math.pi / (180 * 60)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--periods', type=float, default=15.0)
    ap.add_argument('--repeats', type=int, default=3)
    args = ap.parse_args()
    plant = Config().replace({'mesh.backlash': ARCMIN, 'load.output_torque': 0.5,
                              'load.output_viscous_coefficient': 10.0})
    m = trajectory_model(DriveModel(plant))
    move = sector_scan(plant, periods=args.periods)
    fns = {'feedforward_series': feedforward_series, 'flank_series': flank_series,
           'soft_feedforward_series': soft_feedforward_series}
    best = dict.fromkeys(fns, math.inf)
    crossings = 0
    for _ in range(args.repeats):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            out = fn(m, move.t, move.theta1)
            best[name] = min(best[name], time.perf_counter() - t0)
            if name == 'soft_feedforward_series':
                crossings = len(out[1])
    n = move.t.size
    print(f'{n} samples ({args.periods:g} periods, {crossings} crossings), min of '
          f'{args.repeats}; load average {os.getloadavg()[0]:.2f}')
    for name, s in best.items():
        print(f'{name:>24}: {s:.3f} s  ({1e6 * s / n:.1f} us/sample, '
              f'{s / best["feedforward_series"]:.2f}x feedforward_series)')


if __name__ == '__main__':
    main()
