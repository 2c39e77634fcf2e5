#!/usr/bin/env python3
# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The variable step (``integrator.method: adaptive``) beside the fixed step: the kernel's
cost on the paper's 18-step move (0.5 s) and on a +-5 deg sector scan at the antenna (4 s,
the command streamed at 1 kHz: ``studies.mismatch.sector_scan``), and the step-size history
of both runs as a figure.

    python benchmarks/adaptive_steps.py                  # the side-by-side table
    python benchmarks/adaptive_steps.py --figure docs/figures/adaptive_steps.png

``benchmarks/bench_core.py`` prints the same table in its run (``--adaptive``: only it).
Both kernels get the command on the 4 us grid; the variable step ends a step on every 1 ms
tick (as in the node, and as ``run`` with a record every tick).  Timings: minimum over
rounds that alternate the two methods (other load on the machine only makes them slower).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..'))

from worm_gear_sim import Config, Simulator, make_profile  # noqa: E402
from worm_gear_sim.dynamics.adaptive import advance_adaptive  # noqa: E402
from worm_gear_sim.dynamics.integrator import (  # noqa: E402
    N_STATS,
    S_ADAPTIVE_STEPS,
    S_EVALS,
    S_EVENTS,
    S_REJECTED,
    advance,
)
from worm_gear_sim.dynamics.profiles import Profile, SampledProfile  # noqa: E402

ADAPTIVE = {'integrator.method': 'adaptive'}
TICK = 1e-3


def scan_profile(cfg: Config) -> SampledProfile:
    """The +-5 deg sector scan at the antenna (4 s period, from rest at one edge) as the node
    receives it: 1 kHz samples, linear between them."""
    from worm_gear_sim.studies.mismatch import sector_scan
    move = sector_scan(cfg)
    return SampledProfile(move.t, move.theta1)


def cases(cfg: Config) -> list[tuple[str, Profile, float]]:
    """(name, command, simulated time) of the two benchmark runs."""
    return [('18-step move, 0.5 s', make_profile(cfg.input), 0.5),
            ('sector scan +-5 deg, 4 s', scan_profile(cfg), 4.0)]


def kernel_run(cfg: Config, prof: Profile, t_end: float) -> tuple[float, np.ndarray]:
    """(seconds, stats) of one kernel call over the run from rest: the fixed kernel on the
    grid, or the variable step ending its steps on every tick (``cfg``'s method)."""
    dt = cfg.integrator.time_step
    n = int(round(t_end / dt))
    grid = np.arange(n + 1) * dt
    th, td = prof.theta1(grid), prof.theta1_dot(grid)
    sim = Simulator(cfg, theta1=float(th[0]))
    st = np.zeros(N_STATS, dtype=np.int64)
    ctl = sim._ctl.copy()
    u, v, a = sim._u.copy(), sim._v.copy(), sim._a.copy()
    no_load = np.empty(0)
    if sim._ap is None:
        e3, ea = np.empty((0, 3)), np.empty((0, 8))
        t0 = time.perf_counter()
        advance(sim.p, sim.C, u, v, a, th, td, dt, np.int64(0), e3, e3, e3, ea, st, ctl,
                no_load)
        return time.perf_counter() - t0, st
    stride = int(round(TICK / dt))
    m = n // stride
    r3, ra = np.empty((m, 3)), np.empty((m, 8))
    t0 = time.perf_counter()
    advance_adaptive(sim.p, sim._ap, sim.C, u, v, a, th, td, dt, 0.0, np.int64(stride), r3,
                     r3.copy(), r3.copy(), ra, st, ctl, no_load, np.empty((0, 10)))
    return time.perf_counter() - t0, st


def side_by_side(rounds: int = 3) -> None:
    """The table: per run, fixed and variable step alternating, min over ``rounds``."""
    fixed, adaptive = Config(), Config().replace(ADAPTIVE)
    print(f'# fixed step (4 us) and variable step (integrator.method: adaptive, tolerances '
          f'{adaptive.integrator.adaptive_tolerance_worm:g} / '
          f'{adaptive.integrator.adaptive_tolerance_gear:g} rad), kernel only, min of '
          f'{rounds} alternating rounds; load {os.getloadavg()[0]:.2f}')
    print(f'{"run":26s} {"method":9s} {"ns/us sim":>10s} {"x real":>7s} {"steps":>8s} '
          f'{"mean step":>10s} {"evals/ms":>9s} {"rejected":>9s} {"events":>7s}')
    for name, prof, t_end in cases(fixed):
        best = {'fixed': np.inf, 'adaptive': np.inf}
        stats = {}
        for _ in range(rounds):
            for method, cfg in (('fixed', fixed), ('adaptive', adaptive)):
                s, st = kernel_run(cfg, prof, t_end)
                best[method] = min(best[method], s)
                stats[method] = st
        for method in ('fixed', 'adaptive'):
            st, s = stats[method], best[method]
            steps = int(st[S_ADAPTIVE_STEPS]) if method == 'adaptive' else \
                int(round(t_end / fixed.integrator.time_step))
            print(f'{name:26s} {method:9s} {s / t_end * 1e3:10.1f} {t_end / s:7.1f} '
                  f'{steps:8d} {t_end / steps * 1e6:8.2f}us {st[S_EVALS] / t_end / 1e3:9.1f} '
                  f'{int(st[S_REJECTED]):9d} {int(st[S_EVENTS]):7d}')
        print(f'{"":26s} ratio fixed / adaptive {best["fixed"] / best["adaptive"]:.2f} '
              f'(load {os.getloadavg()[0]:.2f})', flush=True)


def step_history(cfg: Config, prof: Profile, t_end: float) -> dict[str, np.ndarray]:
    """The variable step's log over a run recorded on the 1 ms ticks."""
    sim = Simulator(cfg, theta1=float(prof.theta1(np.array([0.0]))[0]))
    sim.log_steps(2_000_000)
    sim.run(prof, t_end, record_every=int(round(TICK / cfg.integrator.time_step)))
    return sim.step_log


def figure(path: str, t_move: float = 0.5, t_scan: float = 4.0) -> None:
    """Step size against time for the move and the scan (stuck and sliding steps, the
    located friction events), and the fixed step for comparison."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    cfg = Config().replace(ADAPTIVE)
    runs = [(name, step_history(cfg, prof, min(t, t_move if 'move' in name else t_scan)))
            for name, prof, t in cases(cfg)]
    fig = Figure(figsize=(10, 7.5))
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(runs), 1)
    for ax, (name, log) in zip(axes, runs):
        t, h = log['t'], log['h'] * 1e6
        stuck = log['mode'] == 0
        ax.semilogy(t[~stuck], h[~stuck], '.', ms=1.5, color='tab:red', label='sliding')
        ax.semilogy(t[stuck], h[stuck], '.', ms=1.5, color='tab:blue', label='stuck')
        ev = log['event'] > 0
        ax.semilogy(t[ev], h[ev], 'x', ms=3, color='k', label='ends at a located event')
        ax.axhline(cfg.integrator.time_step * 1e6, color='0.4', lw=0.8, ls='--',
                   label='fixed step (4 us)')
        ax.set_ylabel('step [us]')
        ax.set_title(f'{name}: {len(t)} steps, mean {t[-1] / len(t) * 1e6:.1f} us '
                     f'(fixed: {round(t[-1] / cfg.integrator.time_step)})', fontsize=10)
        ax.legend(loc='lower right', fontsize=8, markerscale=4)
        ax.grid(True, which='both', lw=0.3)
    axes[-1].set_xlabel('time [s]')
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    for name, log in runs:
        t, h = log['t'], log['h']
        print(f'{name}: {len(t)} steps, mean {t[-1] / len(t) * 1e6:.2f} us, median '
              f'{np.median(h) * 1e6:.2f} us, stuck {np.mean(log["mode"] == 0):.2f} of the '
              f'steps, {int(np.sum(log["event"] > 0))} located events')
    print(f'wrote {path}')


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--figure', metavar='PNG', help='write the step-size history there')
    ap.add_argument('--rounds', type=int, default=3)
    args = ap.parse_args(argv)
    if args.figure:
        figure(args.figure)
        return 0
    side_by_side(args.rounds)
    return 0


if __name__ == '__main__':
    sys.exit(main())
