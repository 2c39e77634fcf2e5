# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Cost of a 1 ms tick of the drive with play against the same drive without, side by side
in one run: the simulator advanced tick by tick (``Simulator.advance_to``, what the node
does per sample) over a worm slew with reversals at +-1 rad/s (each reversal crosses the
play: contact loss, flight, impact), 5 N m antenna load off and on (without load the gear
rattles in the play after each reversal).  Each figure is the minimum over ``--repeats``
runs; the runs of both drives alternate, so machine load affects both alike (the load
average is printed).

    python benchmarks/bench_backlash.py
    python benchmarks/bench_backlash.py --play-arcmin 2 --ticks 2000 --repeats 7
"""

from __future__ import annotations

import argparse
import math
import os
import time

import numpy as np

from worm_gear_sim import Config, Simulator

ARCMIN = math.pi / (180 * 60)


def slew(ticks: int, rate: float = 1.0, period: float = 0.25) -> np.ndarray:
    """Worm command at each 1 ms tick: a triangle at +-rate [rad/s] reversing every
    period/2 seconds."""
    t = np.arange(1, ticks + 1) * 1e-3
    x = (t % period) / period
    return rate * period / 2.0 * np.where(x < 0.5, 2.0 * x, 2.0 - 2.0 * x)


def run(cfg: Config, cmd: np.ndarray) -> tuple[float, dict]:
    sim = Simulator(cfg, 0.0, 0.0)
    t0 = time.perf_counter()
    for k, x in enumerate(cmd):
        sim.advance_to((k + 1) * 1e-3, float(x))
    return (time.perf_counter() - t0) / len(cmd), sim.stats


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--play-arcmin', type=float, default=2.0)
    ap.add_argument('--ticks', type=int, default=2000, help='1 ms ticks per run [2000]')
    ap.add_argument('--repeats', type=int, default=5)
    a = ap.parse_args()
    cmd = slew(a.ticks)
    print(f'load average {os.getloadavg()[0]:.2f}; {a.ticks} ticks of 1 ms, min of '
          f'{a.repeats}; play {a.play_arcmin:g} arcmin')
    for load in (0.0, 5.0):
        base = Config().replace({'load.output_torque': load})
        play = base.replace({'mesh.backlash': a.play_arcmin * ARCMIN})
        best = {'without play': math.inf, 'with play': math.inf}
        stats = {}
        run(base, cmd[:50])
        run(play, cmd[:50])                               # compile / warm up
        for _ in range(a.repeats):
            for name, cfg in (('without play', base), ('with play', play)):
                dt, st = run(cfg, cmd)
                best[name] = min(best[name], dt)
                stats[name] = st
        ratio = best['with play'] / best['without play']
        for name in best:
            st = stats[name]
            print(f'  load {load:g} N m, {name:12s}: {best[name] * 1e6:7.1f} us per tick, '
                  f'{st["newton_solves"] / st["steps"]:.2f} Newton solves per step, '
                  f'{st.get("contact_events", 0)} contact events')
        print(f'  load {load:g} N m: ratio with / without play = {ratio:.2f} (target <= 1.5)')


if __name__ == '__main__':
    main()
