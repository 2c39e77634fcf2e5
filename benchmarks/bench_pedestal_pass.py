# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The pedestal's pass with live adaptation on both axes, live and in its twin.

    ROS_DOMAIN_ID=180 python benchmarks/bench_pedestal_pass.py [--duration 60]
        [--pedestal PEDESTAL.yaml] [--plant config/pedestal_plant.yaml] [--seed 0]
        [--no-live] [--workdir DIR]

* live (:func:`~worm_gear_sim.ros.live_pedestal.run_live_pedestal`): the pedestal process
  (``worm_gear_sim_pedestal``, adaptation on both drives), a plant node per drive and this
  process as the commander, the pass streamed at 1 kHz on a simulated clock that follows
  the encoders (ROS_DOMAIN_ID from the environment, discovery LOCALHOST);
* the twin (:func:`~worm_gear_sim.studies.adaptive_pass.run_adaptive_pass`, ``worm-gear-sim
  pass --adapt``), from the live run's start stamp, with the nominal feed-forward beside.

Printed per axis (figures, never asserted): the pointing error's RMS over the last 10 s
uncompensated, with the nominal feed-forward and with the adapting one, live and twin, and
the ratios (target: adapting >= 30x below uncompensated, live and twin); whether the live
run equals the twin bit for bit (it must, with no late encoder sample and no late step);
the steps, late counters and values in use; wall times and the load average.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from worm_gear_sim.config.pedestal import load_pedestal  # noqa: E402
from worm_gear_sim.studies.adaptive_pass import (  # noqa: E402
    TAIL_S,
    pedestal_plants,
    run_adaptive_pass,
)

TARGET = 30.0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--duration', type=float, default=60.0)
    ap.add_argument('--pedestal', default=None)
    ap.add_argument('--plant', default=str(ROOT / 'config' / 'pedestal_plant.yaml'))
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--no-live', action='store_true', help='the twin only')
    ap.add_argument('--workdir', default=None)
    args = ap.parse_args()
    drives = load_pedestal(args.pedestal)
    plants = pedestal_plants(drives, args.plant)
    tail = min(TAIL_S, args.duration)
    print(f'load average at start: {os.getloadavg()}; pass {args.duration:g} s, figures '
          f'over the last {tail:g} s; plants {args.plant}', flush=True)
    live = None
    base = {}
    if not args.no_live:
        import rclpy

        from worm_gear_sim.ros.live_pedestal import run_live_pedestal
        domain = int(os.environ.get('ROS_DOMAIN_ID', '0'))
        env = dict(os.environ, ROS_DOMAIN_ID=str(domain),
                   ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', PYTHONUNBUFFERED='1')
        env.pop('ROS_STATIC_PEERS', None)
        os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
        ctx = rclpy.context.Context()
        rclpy.init(context=ctx, domain_id=domain)
        work = Path(args.workdir or tempfile.mkdtemp(prefix='bench_pedestal_pass_'))
        t0 = time.perf_counter()
        try:
            live = run_live_pedestal(drives, plants, args.duration, context=ctx, env=env,
                                     workdir=work, seed=args.seed, write=True)
        finally:
            rclpy.try_shutdown(context=ctx)
        print(f'live: {time.perf_counter() - t0:.0f} s wall, stream '
              f'{live.drives[0][1].stream_wall_s:.0f} s; first sample held {live.held}x; '
              f'stalled {live.stalled}; work {work}; load {os.getloadavg()}', flush=True)
        base = {'base_ns': live.t0_ns}
    t0 = time.perf_counter()
    twin = run_adaptive_pass(drives, plants, args.duration, seed=args.seed, **base)
    print(f'twin: {time.perf_counter() - t0:.0f} s wall (adapting and nominal, both axes); '
          f'load {os.getloadavg()}', flush=True)
    live_axes = live.axes({d.name: d.joint for d in drives}) if live is not None else []
    print(f'{"axis":>10} {"uncomp. [urad]":>15} {"nominal [urad]":>15} '
          f'{"twin [urad]":>12} {"live [urad]":>12} {"nominal x":>10} {"twin x":>8} '
          f'{"live x":>8}')
    for k, tw in enumerate(twin):
        f = tw.tail(tail)
        lv = live_axes[k].tail(tail) if live_axes else {'adapted': math.nan,
                                                          'adapted_ratio': math.nan}
        print(f'{tw.name:>10} {f["uncompensated"] * 1e6:15.2f} {f["nominal"] * 1e6:15.2f} '
              f'{f["adapted"] * 1e6:12.3f} {lv["adapted"] * 1e6:12.3f} '
              f'{f["nominal_ratio"]:10.2f} {f["adapted_ratio"]:8.1f} '
              f'{lv["adapted_ratio"]:8.1f}')
    for k, tw in enumerate(twin):
        c = tw.run.counters
        print(f'{tw.name} twin: {c.get("switches", 0)} steps; in use '
              + ', '.join(f'{key} {v:.4g}' for key, v in tw.run.in_use.items()
                          if not isinstance(v, list)))
        if live_axes:
            la = live_axes[k]
            lc = la.run.counters
            same = bool(np.array_equal(la.adapted, tw.adapted))
            diff = float(np.nanmax(np.abs(la.adapted - tw.adapted)))
            print(f'{tw.name} live: {lc.get("switches", "?")} steps, late samples '
                  f'{lc.get("late_samples", "?")}, late steps {lc.get("late_steps", "?")}, '
                  f'rejected {lc.get("rejected", "?")}, {la.run.missing} stamps unanswered; '
                  f'equals the twin bit for bit: {same} (largest difference {diff:.3g} rad)'
                  f'; write: {live.written.get(tw.name)}')
    met = [tw.tail(tail)['adapted_ratio'] >= TARGET for tw in twin] + \
        [la.tail(tail)['adapted_ratio'] >= TARGET for la in live_axes]
    print(f'target >= {TARGET:g}x over the last {tail:g} s: {sum(met)} of {len(met)} met; '
          f'load average at end: {os.getloadavg()}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
