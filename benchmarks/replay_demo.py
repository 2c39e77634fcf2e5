# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A bag recorded from the live demo replays to the live node's prediction (issue target:
1e-9 rad).  Starts the node, the bag recorder and the demo commander as processes (domain
$ROS_DOMAIN_ID + 1, localhost), then runs ``worm-gear-sim simulate --bag`` on the bag and
prints its comparison with the node's recorded joint_states.

    python benchmarks/replay_demo.py [--pattern paper|slew] [--interface stamped|float64]
                                     [--compensated] [--duration 10] [--keep DIR]

What bounds it: the replay reproduces the node when the bag holds every sample the node
took and the node took every sample of the bag; on a loaded machine the node's reference
queue (100 samples) or this Python recorder can drop messages, and a recorder that matches
the demo late misses the start of the stream (``simulate --bag`` warns in both cases).
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / 'test'))
from processes import start_logged, stop_and_read  # noqa: E402


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--pattern', choices=('paper', 'slew'), default='paper')
    p.add_argument('--interface', choices=('stamped', 'float64'), default='stamped')
    p.add_argument('--compensated', action='store_true', help='node.compensation_applied')
    p.add_argument('--duration', type=float, default=10.0)
    p.add_argument('--keep', metavar='DIR', help='keep the bag and logs here')
    a = p.parse_args()
    work = Path(a.keep) if a.keep else Path(tempfile.mkdtemp(prefix='replay_demo_'))
    work.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, PYTHONPATH=str(REPO), MPLBACKEND='Agg', PYTHONUNBUFFERED='1',
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_DOMAIN_ID=str(int(os.environ.get('ROS_DOMAIN_ID', '42') or 42) + 1))
    py = sys.executable
    comp = ['-p', 'node.compensation_applied:=true'] if a.compensated else []
    bag = work / 'demo_bag'
    if bag.exists():
        print(f'{bag} exists: choose another --keep directory', file=sys.stderr)
        return 2
    procs = []
    try:
        procs.append(start_logged([py, '-m', 'worm_gear_sim.ros', '--ros-args',
                                   '--params-file', str(REPO / 'config/worm_gear_sim.yaml'),
                                   *comp], env, work / 'node.log'))
        procs.append(start_logged([py, '-m', 'worm_gear_sim.ros.bag_recorder', '-o', str(bag)],
                                  env, work / 'rec.log'))
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline:
            if 'recording' in (work / 'rec.log').read_text() and \
                    'ready' in (work / 'node.log').read_text():
                break
            time.sleep(0.5)
        else:
            print('node or recorder did not start (see the logs in --keep)', file=sys.stderr)
            return 1
        time.sleep(2.0)
        demo = subprocess.run([py, '-m', 'worm_gear_sim.ros.demo_commander', '--duration',
                               str(a.duration), '--no-offline', '--pattern', a.pattern,
                               '--interface', a.interface], env=env, capture_output=True,
                              text=True, timeout=a.duration + 200)
        (work / 'demo.log').write_text(demo.stdout + demo.stderr)
        time.sleep(1.0)
    finally:
        for proc, log in reversed(procs):
            stop_and_read(proc, log, signal.SIGINT, timeout=10.0)
    print((work / 'rec.log').read_text().strip().splitlines()[-1])
    sim = ['simulate', '--bag', str(bag), '-o', str(work / 'replay.csv'), '--no-plot']
    if a.compensated:
        sim += ['--set', 'node.compensation_applied=true']
    out = subprocess.run([py, '-m', 'worm_gear_sim', *sim], env=env, capture_output=True,
                         text=True)
    for line in out.stdout.splitlines():
        if not line.startswith('event:'):
            print(line)
    print(out.stderr, end='')
    with open('/proc/loadavg') as fh:
        print(f'load average while measured: {fh.read().split()[0]} (2-core machine shared '
              'with other jobs)')
    print(f'files: {work}')
    return out.returncode


if __name__ == '__main__':
    sys.exit(main())
