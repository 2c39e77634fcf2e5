# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The stamped path of a drive node *process* while long trajectories are compensated:
the case of test/ros/test_hostile_node.py measured, with the overruns the test does not check.

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

#: counters read from /diagnostics ('inputs' and 'simulation') before and after each run
COUNTED = ('rejected_too_old', 'rejected_out_of_order', 'overruns', 'dropped_time_ns',
           'stale_events', 'stale_retractions')


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
        print('run  sent  answered  too_old  out_of_order  overruns  dropped_ms  stale_events  '
              'retracted  probe_gaps  widest_ms  out_after_s')
        first = 0
        for run in range(opts.runs):
            stamp = p.node.get_clock().now().nanoseconds + 2 * 10**9
            first = first or stamp                  # each continues the first one's curve
            big = big_trajectory(stamp, opts.points, phase=(stamp - first) / 1e9)
            p.stream(lambda: False, 0.5)            # building it paused the stream
            base = p.counters(COUNTED)
            sent0, n_out = p.sent, len(p.out)
            t0 = time.monotonic()
            r = p.stream(lambda n=n_out: len(p.out) > n, 60.0, extra=big)
            out_after = p.out[-1][0] - t0 - 0.1 if len(p.out) > n_out else float('nan')
            p.stream(lambda: False, 0.3)                             # the stream goes on
            now = p.counters(COUNTED)
            sent = p.sent - sent0
            d = {k: now[k] - base[k] for k in COUNTED}
            missing, _ = p.wait_answered(sent0, 5.0)        # answers matched by stamp
            print(f'{run:3d}  {sent:5d}  {sent - missing:8d}  '
                  f'{d["rejected_too_old"]:7d}  {d["rejected_out_of_order"]:12d}  '
                  f'{d["overruns"]:8d}  {d["dropped_time_ns"] / 1e6:10.1f}  '
                  f'{d["stale_events"]:12d}  {d["stale_retractions"]:9d}  '
                  f'{r["probe_gaps"]:10d}  {r["widest_gap_ms"]:9.1f}  {out_after:11.2f}')
            if len(p.out) == n_out:
                print('     no compensated trajectory:', {
                    k: v for k, v in p.fresh_status('trajectories').items() if v != '0'})
    print(f'load: {os.getloadavg()}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
