# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Evaluate the feed-forward compensation on the nonlinear model with friction.

Scenarios (worm_gear_sim.studies.compensation_eval): the paper's 18-step move (no load,
as the paper) and
a radar slew with a sharp reversal under the illustrative antenna load RADAR_LOAD (5 N m
wind, 2 N m s/rad bearing drag).  The reference is streamed at 1 kHz; the plant is the
nonlinear model (Eqs. 16-18), nominal or detuned by +-20 % (tooth stiffness, friction,
flywheel inertia); the compensator always uses the NOMINAL config.

Prints (markdown):
  1. cost of Compensator.update (per call) and of the design;
  2. the candidate designs on the nominal plant (the measurement behind the default);
  3. for the default (causal) and the 2 ms preview design: every plant, with and without
     compensation, and the improvement ratios against the issue's targets.

Usage:  python benchmarks/eval_compensation.py [--quick] [--csv FILE] [--plot PNG]
        python benchmarks/eval_compensation.py --design 'inverse + ZVD, delayed (lag_order 0)'
(--design, repeatable: the full every-plant table for these candidates instead of the two
final designs; skips the cost and candidate tables)
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from worm_gear_sim.compensation.streaming import Compensator  # noqa: E402
from worm_gear_sim.config.usable import Config  # noqa: E402
from worm_gear_sim.dynamics.stepping import SimulationError  # noqa: E402
from worm_gear_sim.studies.compensation_eval import (  # noqa: E402
    METRIC_FLOOR,
    METRICS,
    RADAR_LOAD,
    detuned,
    detuning_cases,
    improvement,
    not_worse,
    paper_step_scenario,
    radar_slew_scenario,
    run_scenario,
)

CANDIDATES = {
    'inverse, causal (default)': {},
    'inverse, preview 2 ms': {'compensation.preview_time': 0.002},
    'inverse + ZVD, lag-free': {'compensation.shaper': 'zvd'},
    'inverse + ZV, lag-free': {'compensation.shaper': 'zv'},
    'inverse + EI, lag-free': {'compensation.shaper': 'ei'},
    'inverse + ZVD, delayed (lag_order 0)': {'compensation.shaper': 'zvd',
                                             'compensation.lag_order': 0},
    'ZVD shaping only (no inverse)': {'compensation.shaper': 'zvd',
                                      'compensation.lag_order': 0,
                                      'compensation.quasi_static': False},
    'full inverse (4th derivatives)': {'compensation.model_inverse': True},
}
FINAL = ('inverse, causal (default)', 'inverse, preview 2 ms')
TARGET_NOMINAL, TARGET_DETUNED = 10.0, 3.0
TARGET_METRICS = ('residual_peak', 'static_error', 'tracking_rms')


def scenarios(base: Config):
    step_plant = base
    slew_plant = base.replace(RADAR_LOAD)
    return [('18-step move', step_plant, paper_step_scenario(step_plant)),
            ('radar slew', slew_plant, radar_slew_scenario(slew_plant))]


def fmt_angle(v: float) -> str:
    return f'{v * 1e6:.3g}'


def fmt_time(v: float) -> str:
    return 'never' if math.isinf(v) else f'{v * 1e3:.3g}'


def fmt_ratio(v: float, on: float | None = None) -> str:
    """Ratio; '>=' when the compensated value is at the resolution floor (ratio capped)."""
    if math.isnan(v):
        return 'n/a'
    if math.isinf(v):
        return 'inf'
    return ('>=' if on is not None and on < METRIC_FLOOR else '') + f'{v:.3g}x'


def timing() -> None:
    cfg = Config().replace(RADAR_LOAD)
    Compensator(cfg)                      # first construction loads the compiled model
    t0 = time.perf_counter()
    comp = Compensator(cfg)
    design = time.perf_counter() - t0
    n = 20000
    xs = 0.01 * np.arange(n)
    laps = []
    for _ in range(5):
        comp.reset(0.0, 0.0)
        t0 = time.perf_counter()
        for i in range(1, n):
            comp.update(i * 1e-3, xs[i])
        laps.append((time.perf_counter() - t0) / (n - 1))
    print('## Cost\n')
    print(f'- design (modes, weights) at construction/reconfigure: {design * 1e3:.2f} ms')
    print(f'- Compensator.update: {min(laps) * 1e6:.1f} us per call (best of 5 x {n - 1} '
          f'calls; {comp.describe()})\n')


def run_pair(plant, scen, comp_cfg):
    try:
        return run_scenario(plant, scen, comp_cfg).metrics
    except SimulationError as exc:          # report, do not hide
        return {'error': str(exc)}


def candidates_table(base: Config, quick: bool) -> None:
    print('## Candidate designs, nominal plant (ratios uncompensated / compensated)\n')
    print('| design | scenario | residual | post-move peak | settling [ms] | static | '
          'tracking RMS |')
    print('|---|---|---|---|---|---|---|')
    names = list(CANDIDATES)[:3] if quick else list(CANDIDATES)
    for sname, plant, scen in scenarios(base):
        off = run_scenario(plant, scen, None).metrics
        for name in names:
            on = run_pair(plant, scen, plant.replace(CANDIDATES[name]))
            if 'error' in on:
                print(f'| {name} | {sname} | simulation failed: {on["error"]} |||||')
                continue
            r = {m: improvement(m, off[m], on[m]) for m in METRICS}
            print(f'| {name} | {sname} | {fmt_ratio(r["residual_peak"])} | '
                  f'{fmt_ratio(r["post_move_peak"])} | {fmt_time(on["settling_time"])} | '
                  f'{fmt_ratio(r["static_error"], on["static_error"])} | '
                  f'{fmt_ratio(r["tracking_rms"])} |')
    print()


def full_table(base: Config, design: str, rows: list, quick: bool) -> bool:
    print(f'## {design}: every plant (angles in urad, times in ms)\n')
    print('| scenario | plant | residual off / on | settling off / on | static off / on | '
          'tracking RMS off / on | ratios (residual, static, tracking) | targets |')
    print('|---|---|---|---|---|---|---|---|')
    ok_all = True
    cases = detuning_cases()[:3] if quick else detuning_cases()
    for sname, plant0, scen in scenarios(base):
        comp_cfg = plant0.replace(CANDIDATES[design])
        for cname, factors in cases:
            plant = detuned(plant0, factors)
            off = run_scenario(plant, scen, None).metrics
            on = run_pair(plant, scen, comp_cfg)
            if 'error' in on:
                print(f'| {sname} | {cname} | simulation failed: {on["error"]} |||||||')
                ok_all = False
                continue
            r = {m: improvement(m, off[m], on[m]) for m in METRICS}
            target = TARGET_NOMINAL if cname == 'nominal' else TARGET_DETUNED
            met = all(math.isnan(r[m]) or r[m] >= target for m in TARGET_METRICS)
            worse = [m for m in METRICS if not not_worse(m, off[m], on[m])]
            verdict = ('met' if met else f'< {target:g}x') + \
                (f'; WORSE: {", ".join(worse)}' if worse else '')
            ok_all &= met and not worse
            print(f'| {sname} | {cname} | {fmt_angle(off["residual_peak"])} / '
                  f'{fmt_angle(on["residual_peak"])} | {fmt_time(off["settling_time"])} / '
                  f'{fmt_time(on["settling_time"])} | {fmt_angle(off["static_error"])} / '
                  f'{fmt_angle(on["static_error"])} | {fmt_angle(off["tracking_rms"])} / '
                  f'{fmt_angle(on["tracking_rms"])} | {fmt_ratio(r["residual_peak"])}, '
                  f'{fmt_ratio(r["static_error"], on["static_error"])}, '
                  f'{fmt_ratio(r["tracking_rms"])} | '
                  f'{verdict} |')
            rows.append({'design': design, 'scenario': sname, 'plant': cname,
                         **{f'{m}_off': off[m] for m in METRICS},
                         **{f'{m}_on': on[m] for m in METRICS},
                         **{f'{m}_ratio': r[m] for m in METRICS}})
    print()
    return ok_all


def plot_ratios(rows: list, path: str, designs: tuple[str, ...] = FINAL) -> None:
    """Bars of the residual and tracking ratios per plant, per design, both scenarios."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    scen = list(dict.fromkeys(r['scenario'] for r in rows))
    fig = Figure(figsize=(11.0, 7.5), layout='constrained')
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(scen), 1, squeeze=False)[:, 0]
    series = [(d, m) for d in designs for m in ('residual_peak', 'tracking_rms')]
    for ax, sname in zip(axes, scen):
        plants = list(dict.fromkeys(r['plant'] for r in rows if r['scenario'] == sname))
        x = np.arange(len(plants))
        w = 0.8 / len(series)
        for k, (d, m) in enumerate(series):
            vals = [next(r[f'{m}_ratio'] for r in rows if r['scenario'] == sname
                         and r['plant'] == p and r['design'] == d) for p in plants]
            ax.bar(x + (k - (len(series) - 1) / 2) * w, vals, w,
                   label=f'{d}: {m.replace("_", " ")}')
        for level, ls in ((10.0, '--'), (3.0, ':')):
            ax.axhline(level, color='k', lw=0.8, ls=ls)
        ax.set_yscale('log')
        ax.set_xticks(x, plants, rotation=15, fontsize=8)
        ax.set_ylabel('uncompensated / compensated')
        ax.set_title(f'{sname}: improvement ratios (dashed 10x nominal target, dotted 3x '
                     'detuned target)', fontsize=9)
        ax.grid(alpha=0.3, axis='y')
    axes[0].legend(fontsize=7, ncol=2)
    fig.savefig(path, dpi=100, format='png')


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--quick', action='store_true', help='fewer designs and plants')
    ap.add_argument('--csv', metavar='FILE', help='also write the full tables as CSV')
    ap.add_argument('--plot', metavar='PNG', help='also plot the improvement ratios per plant')
    ap.add_argument('--design', action='append', choices=list(CANDIDATES), metavar='NAME',
                    help='full every-plant table for this candidate design (repeatable; '
                         f'default: {", ".join(FINAL)}); skips the cost and candidate tables')
    args = ap.parse_args(argv)
    designs = tuple(args.design) if args.design else FINAL
    base = Config()
    t0 = time.perf_counter()
    print('# Feed-forward compensation: evaluation on the nonlinear model\n')
    for sname, _, scen in scenarios(base):
        print(f'- {sname}: {scen.description}')
    print(f'- radar load: {RADAR_LOAD}; reference streamed at 1 kHz; metrics: residual = '
          'max |e - static| once the command (with correction) rests, post-move peak = '
          'the same from the reference move end, settling to 10 urad from the reference '
          'move end, static = offset over the last 0.1 s, tracking = RMS over the '
          'constant-rate parts\n')
    if not args.design:
        timing()
        candidates_table(base, args.quick)
    rows: list = []
    ok = True
    for design in designs:
        ok &= full_table(base, design, rows, args.quick)
    if args.csv and rows:
        with open(args.csv, 'w', newline='') as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
        print(f'wrote {args.csv}')
    if args.plot and rows:
        plot_ratios(rows, args.plot, designs)
        print(f'wrote {args.plot}')
    print(f'all targets met by {" and ".join(designs)}: {ok}  ({time.perf_counter() - t0:.1f} s)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
