# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Cost of proving a parameter set usable (:func:`worm_gear_sim.config.usable.check_usable`).

Side by side in one run: building a Config from overrides without the check
(``config_from_mapping(..., usable=False)``), the check of a new set (each set distinct, so
nothing is cached), the check of a set already proven (a dictionary look-up), and
``Config.replace`` end to end (what the node's parameter bridge and the CLI call).  Also the
parts of the check: building the model (``DriveModel``: derived quantities, packed vector),
the modes, the 2 ms trial move.

    python benchmarks/bench_usable.py            # 200 sets, minimum of 5 repetitions
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

from worm_gear_sim.config.usable import Config, check_usable, config_from_mapping


def _sets(n: int, offset: int) -> list[dict]:
    return [{'load': {'output_torque': 0.001 * (i + offset)}} for i in range(n)]


def _time(fn, items) -> float:
    t0 = time.perf_counter()
    for it in items:
        fn(it)
    return (time.perf_counter() - t0) / len(items) * 1e6


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--sets', type=int, default=200)
    ap.add_argument('--repeat', type=int, default=5)
    args = ap.parse_args(argv)
    from worm_gear_sim.dynamics.modal import modes
    from worm_gear_sim.dynamics.model import DriveModel
    from worm_gear_sim.dynamics.simulation import Simulator
    from worm_gear_sim.dynamics.usability import TRIAL_ANGLE, TRIAL_TIME
    check_usable(Config().replace({'load.output_torque': -1.0}))      # compile / warm up
    rows: dict[str, list[float]] = {k: [] for k in (
        'build (no check)', 'check, new set', 'check, proven set', 'replace() end to end',
        '  DriveModel', '  modes', '  trial move')}
    base = Config()
    for r in range(args.repeat):
        off = (r + 1) * 10 * args.sets
        cfgs = [config_from_mapping(s, usable=False) for s in _sets(args.sets, off)]
        rows['build (no check)'].append(
            _time(lambda s: config_from_mapping(s, usable=False), _sets(args.sets, off)))
        rows['check, new set'].append(_time(check_usable, cfgs))
        rows['check, proven set'].append(_time(check_usable, cfgs))
        ov = [{'load.output_torque': 0.001 * (i + off + args.sets)} for i in range(args.sets)]
        rows['replace() end to end'].append(_time(base.replace, ov))
        rows['  DriveModel'].append(_time(DriveModel, cfgs))
        rows['  modes'].append(_time(lambda c: modes(c, include_damping=False), cfgs))

        def trial(c):
            sim = Simulator(c, check=False)
            sim.advance_to(0.5 * TRIAL_TIME, TRIAL_ANGLE)
            sim.advance_to(TRIAL_TIME, TRIAL_ANGLE)
        rows['  trial move'].append(_time(trial, cfgs))
    build = min(rows['build (no check)'])
    print(f'check_usable cost, {args.sets} sets x {args.repeat} (minimum; load average '
          f'{os.getloadavg()[0]:.2f}, absolute figures load-contaminated)')
    print(f'{"":24s} {"us/set":>9s} {"x build":>8s} {"median us":>10s}')
    for k, v in rows.items():
        print(f'{k:24s} {min(v):9.1f} {min(v) / build:8.2f} {statistics.median(v):10.1f}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
