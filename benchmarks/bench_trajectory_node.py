# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The stamped path of a drive node *process* while long trajectories are compensated:
the case of test_hostile_node.py measured, with the overruns the test does not check.

A node process (the package's params file) and a probe over DDS (localhost): the probe
streams 1 kHz stamped samples; after 0.1 s of each run it sends a ``--points``-waypoint
trajectory (1 ms apart: 100 s at the default) and streams until the compensated
trajectory comes back.  Per run: samples sent and answered, rejected too_old, the node's
overruns (the simulation more than node.max_catch_up = 50 ms behind a sample) with the
simulated time they dropped, the stale events, the probe's own stamp gaps over
50 ms (a loaded machine pausing the probe), and the seconds from sending to the
compensated trajectory's arrival.  The first run starts the node's worker process (it is
started by the first long trajectory), the next ones find it running.

    python benchmarks/bench_trajectory_node.py [--runs 3] [--points 100000]

Timings depend on the machine's load: print ``uptime`` beside them.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / 'test'))
from trajectory_probe import big_trajectory, node_and_probe  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--runs', type=int, default=3)
    ap.add_argument('--points', type=int, default=100_000)
    opts = ap.parse_args(argv)
    print(f'load: {os.getloadavg()}')
    domain = int(os.environ.get('ROS_DOMAIN_ID', '42') or 42)
    with tempfile.TemporaryDirectory() as tmp, \
            node_and_probe(Path(tmp) / 'node.log', domain,
                           ['-p', 'node.diagnostic_period:=0.1']) as p:
        p.stream(lambda: False, 1.0)                            # the stream runs
        print('run  sent  answered  too_old  overruns  dropped_ms  stale_events  probe_gaps  '
              'out_after_s')
        first = 0
        for run in range(opts.runs):
            old0 = int(p.fresh_status('inputs')['rejected_too_old'])
            sim0 = p.fresh_status('simulation')
            over0, stale0 = int(sim0['overruns']), int(sim0['stale_events'])
            drop0 = int(sim0['dropped_time_ns'])
            answers0, n_out = p.answers, len(p.out)
            stamp = p.node.get_clock().now().nanoseconds + 2 * 10**9
            first = first or stamp                  # each continues the first one's curve
            big = big_trajectory(stamp, opts.points, phase=(stamp - first) / 1e9)
            t0 = time.monotonic()
            r = p.stream(lambda n=n_out: len(p.out) > n, 60.0, extra=big)
            out_after = p.out[-1][0] - t0 - 0.1 if len(p.out) > n_out else float('nan')
            p.spin_until(lambda a=answers0 + r['sent']: p.answers >= a, 5.0)
            old = int(p.fresh_status('inputs')['rejected_too_old']) - old0
            sim1 = p.fresh_status('simulation')
            over = int(sim1['overruns']) - over0
            stale = int(sim1['stale_events']) - stale0
            drop = (int(sim1['dropped_time_ns']) - drop0) / 1e6
            print(f'{run:3d}  {r["sent"]:5d}  {p.answers - answers0:8d}  {old:7d}  '
                  f'{over:8d}  {drop:10.1f}  {stale:12d}  {r["probe_gaps"]:10d}  '
                  f'{out_after:11.2f}')
            if len(p.out) == n_out:
                print('     no compensated trajectory:', {
                    k: v for k, v in p.fresh_status('trajectories').items() if v != '0'})
    print(f'load: {os.getloadavg()}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
