# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Identification benchmark: robustness of the search strategies and fit time.

The base is the package config (exact stick-slip friction); the test drives differ from it,
and three are model VARIANTS (Table 1 lead angle, constant friction, the sawtooth contact
mapping and another mesh phase; the tanh friction law with its creep and another Stribeck
curve; linear tooth stiffness and soft bearings) so that no fit can be exact.  Each is
recorded as the paper's 18-step move (training) and a held-out S-curve move the other way,
0.15 s at 10 kHz, theta4 measured by a 20-bit encoder (6 urad steps) plus 1 urad RMS noise.

    python benchmarks/bench_identify.py [--threads 2 --repeats 2 --dask]
                                                        # timing: 4-parameter robust fit
    python benchmarks/bench_identify.py --compare       # strategies x drives table
    python benchmarks/bench_identify.py --coverage      # calibration of the 95 % intervals
    python benchmarks/bench_identify.py --evaluation    # CPU of one evaluation, by part
    python benchmarks/bench_identify.py --compare --strategies frequency+windows \
        --diff-steps 1e-6 1e-3 --surrogate              # how to fit the stick-slip model

Printed: per strategy and drive the held-out theta4 error (RMS of predicted - measured, and of
predicted - noise-free truth) as % of the oscillation amplitude (half peak-to-peak of theta4 -
theta1 l_w/r_g), the wall time and the verdict.  Absolute times depend on the machine's load
(printed with ``os.getloadavg``).
"""

from __future__ import annotations

import argparse
import itertools
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from worm_gear_sim import derive, load_config, modes  # noqa: E402
from worm_gear_sim.dynamics.profiles import SCurveProfile, TrapezoidalProfile  # noqa: E402
from worm_gear_sim.identification import (  # noqa: E402
    DIFF_STEP,
    STRATEGIES,
    FitOptions,
    Record,
    identify,
    prediction_errors,
    record_from_model,
)

KEYS = ['materials.gear_shaft_shear_modulus', 'materials.flywheel_density',
        'damping.modal_damping_ratios[0]', 'friction.mu_kinetic']
TRAIN = TrapezoidalProfile(0.11309733552923255, 0.020, 0.004, 0.005)
HOLD = SCurveProfile(-0.06, 0.012, 0.003, 0.002)
DURATION, RATE, RESOLUTION, NOISE = 0.15, 1e4, 2 * math.pi / 2 ** 20, 1e-6


def drives(base):
    """name -> (true config, is a model variant)."""
    kg, rho = base.materials.gear_shaft_shear_modulus, base.materials.flywheel_density
    mu = base.friction.mu_kinetic
    return {
        'stiffer/lighter': (base.replace({'materials.gear_shaft_shear_modulus': kg * 1.25,
                                          'materials.flywheel_density': rho * 0.9,
                                          'damping.modal_damping_ratios': [0.005, 0.0, 0.0],
                                          'friction.mu_kinetic': mu * 1.3}), False),
        'softer/heavier': (base.replace({'materials.gear_shaft_shear_modulus': kg * 0.8,
                                         'materials.flywheel_density': rho * 1.15,
                                         'damping.modal_damping_ratios': [0.02, 0.0, 0.0]}),
                           False),
        'lightly damped, far: stiffer': (base.replace({
            'materials.gear_shaft_shear_modulus': kg * 1.6,
            'materials.flywheel_density': rho * 0.9,
            'damping.modal_damping_ratios': [0.0005, 0.0, 0.0]}), False),
        'lightly damped, far: heavier': (base.replace({
            'materials.flywheel_density': rho * 1.6,
            'damping.modal_damping_ratios': [0.001, 0.0, 0.0],
            'friction.mu_kinetic': mu * 0.7}), False),
        'variant: lead angle, const mu, mapping': (base.replace({
            'geometry.lead_angle': 0.064286, 'friction.model': 'constant',
            'mesh.contact_mapping': 'sawtooth',
            'friction.constant_coefficient': 0.12, 'mesh.phase_offset': 2.0,
            'materials.gear_shaft_shear_modulus': kg * 1.3,
            'materials.flywheel_density': rho * 0.95,
            'damping.modal_damping_ratios': [0.008, 0.0, 0.0]}), True),
        'variant: tanh friction, Stribeck': (base.replace({
            'friction.direction': 'regularized', 'friction.regularization_velocity': 1e-3,
            'friction.mu_stribeck_drop': 0.05, 'friction.stribeck_velocity': 0.2,
            'materials.gear_shaft_shear_modulus': kg * 0.9,
            'materials.flywheel_density': rho * 1.1,
            'damping.modal_damping_ratios': [0.004, 0.0, 0.0]}), True),
        'variant: linear mesh, soft bearings': (base.replace({
            'mesh.stiffness_model': 'linear', 'mesh.worm_tooth_stiffness_multiplier': 0.7,
            'mesh.gear_tooth_stiffness_multiplier': 0.7,
            'shafts.gear_bearing_axial_stiffness': 1.2e8,
            'materials.gear_shaft_shear_modulus': kg * 1.1,
            'materials.flywheel_density': rho * 0.8,
            'damping.modal_damping_ratios': [0.012, 0.0, 0.0]}), True),
    }


def records(truth, seed: int, duration: float = DURATION) -> tuple[Record, Record, Record]:
    kw = dict(sample_rate=RATE, outputs=('theta4',), noise_rad=NOISE,
              resolution_rad=RESOLUTION)
    train = record_from_model(truth, TRAIN, duration, seed=seed, name='train', **kw)
    hold = record_from_model(truth, HOLD, duration, seed=seed + 1, name='held-out', **kw)
    clean = record_from_model(truth, HOLD, duration, sample_rate=RATE, name='held-out clean')
    return train, hold, clean


def held_out(cfg, hold: Record, clean: Record) -> tuple[float, float]:
    e = prediction_errors(cfg, [hold])[0]['theta4']
    c = prediction_errors(cfg, [Record(t=clean.t, theta1=clean.theta1,
                                       measured=clean.measured, name='clean')])[0]['theta4']
    return 100 * e['rel'], 100 * c['rms_rad'] / e['amplitude_rad']


def approaches(args) -> list[tuple[str, str, float, bool, float]]:
    """(label, strategy, finite-difference step, fit on the tanh surrogate, window_tol) per
    table row."""
    out = []
    for s, h, wt in itertools.product(args.strategies or list(STRATEGIES), args.diff_steps,
                                      args.window_tols):
        tag = '' if len(args.diff_steps) == 1 else f' h={h:g}'
        tag += '' if len(args.window_tols) == 1 else f' wtol={wt:g}'
        out.append((s + tag, s, h, False, wt))
        if args.surrogate:
            out.append((s + tag + ' tanh', s, h, True, wt))
    return out


def compare(args) -> None:
    base = load_config(args.config) if args.config else load_config()
    rows = approaches(args)
    print(f'load average {os.getloadavg()}; base: friction.direction '
          f'{base.friction.direction}, antenna mode {modes(base).undamped_hz[0]:.2f} Hz; '
          f'keys {", ".join(KEYS)}')
    print(f'{"drive":<38} {"approach":<24} {"hold %":>7} {"vs truth %":>10} {"train %":>8} '
          f'{"time s":>7}  verdict')
    summary: dict[str, list[float]] = {r[0]: [] for r in rows}
    times: dict[str, list[float]] = {r[0]: [] for r in rows}
    ratio = derive(base).output_per_input
    smooth = base.replace({'friction.direction': 'regularized'})
    chosen = {k: v for k, v in drives(base).items()
              if not args.drives or any(d in k for d in args.drives)}
    for (dname, (truth, _variant)), duration in itertools.product(chosen.items(),
                                                                  args.durations):
        train, hold, clean = records(truth, seed=7, duration=duration)
        f_true = modes(truth).undamped_hz[0]
        h0, c0 = held_out(base, hold, clean)
        print(f'{dname + f" {f_true:.1f} Hz, {duration:g} s":<38} {"(default config)":<24} '
              f'{h0:>7.1f} {c0:>10.1f}')
        for label, s, step, surrogate, wtol in rows:
            opt = FitOptions(strategy=s, serial=args.serial, workers=args.workers,
                             method=args.method, diff_step=step, window_tol=wtol)
            t0 = time.perf_counter()
            res = identify(smooth if surrogate else base, [train], KEYS, options=opt)
            wall = time.perf_counter() - t0
            # the surrogate's estimates in the base model (the fitted YAML keeps its law)
            fitted = res.config.replace({'friction.direction': base.friction.direction})
            h, c = held_out(fitted, hold, clean)
            tr = 100 * prediction_errors(fitted, [train])[0]['theta4']['rms_rad'] / (
                0.5 * np.ptp(train.measured['theta4'] - train.theta1 * ratio))
            verdict = 'trustworthy' if res.trustworthy else \
                f'NOT trustworthy: {res.problems[0][:60]}'
            summary[label].append(h)
            times[label].append(wall)
            print(f'{"":<38} {label:<24} {h:>7.2f} {c:>10.2f} {tr:>8.2f} {wall:>7.1f}  '
                  f'{verdict}', flush=True)
    print(f'\n{"approach":<24} cases with held-out theta4 error <= 3 %   worst %   '
          'median time s')
    for s, v in summary.items():
        print(f'{s:<24} {sum(x <= 3.0 for x in v)}/{len(v):<35} {max(v):>7.2f}   '
              f'{float(np.median(times[s])):.1f}')
    print(f'load average after {os.getloadavg()}')


def coverage(args) -> None:
    """Calibration of the 95 % intervals: the drive of test/identification/test_fit.py (K_g x 1.3,
    zeta_1 = 0.01) fitted (K_g, zeta_1) from ``--realisations`` noise draws, with Gaussian
    noise and with a 20-bit encoder on top of 1 urad noise."""
    base = load_config(args.config) if args.config else load_config()
    kg, zeta = KEYS[0], KEYS[2]
    truth = base.replace({kg: base.materials.gear_shaft_shear_modulus * 1.3,
                          'damping.modal_damping_ratios': [0.01, 0.0, 0.0]})
    true_values = np.array([truth.materials.gear_shaft_shear_modulus, 0.01])
    print(f'load average {os.getloadavg()}; base friction.direction '
          f'{base.friction.direction}; {args.realisations} noise realisations')
    for label, noise, res_rad in (('Gaussian 2 urad', 2e-6, 0.0),
                                  ('20-bit encoder + 1 urad', 1e-6, RESOLUTION)):
        inside = np.zeros(2)
        z = []
        for seed in range(args.realisations):
            rec = record_from_model(truth, TRAIN, DURATION, RATE, ('theta4',), noise_rad=noise,
                                    resolution_rad=res_rad, seed=seed)
            res = identify(base, [rec], [kg, zeta], options=FitOptions(strategy='frequency'))
            inside += [lo <= v <= hi for v, (lo, hi) in zip(true_values, res.ci95)]
            x = np.array([math.log(res.values[0] / base.materials.gear_shaft_shear_modulus),
                          res.values[1] / 0.1])          # zeta: linear coordinate value / 0.1
            x_true = np.array([math.log(1.3), 0.1])
            z.append((x - x_true) / np.array(res.std_x))
        z_rms = np.sqrt(np.mean(np.square(z), axis=0))
        print(f'  {label:<24} truth inside the 95 % interval: K_g {inside[0]:.0f}/'
              f'{args.realisations}, zeta_1 {inside[1]:.0f}/{args.realisations}; RMS of the '
              f'normalised errors {z_rms[0]:.2f} / {z_rms[1]:.2f}')
    print(f'load average after {os.getloadavg()}')


def _cpu() -> float:
    """CPU seconds of this process and of its children that ended (the worker processes)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def timing(args) -> None:
    """The 4-parameter robust fit in this process on 1 thread, on ``--threads`` threads (the
    starts and the Jacobian's columns, ``FitOptions.threads``) and with the evaluations on as many
    forked worker processes (``FitOptions.processes``), alternating ``--repeats`` times, each
    round between two measurements of the ceiling (what the machine gives this process's
    threads right now, bench_batch.py); then (``--dask``) on a Dask LocalCluster."""
    from bench_batch import QUIET, _load, ceiling
    base = load_config(args.config) if args.config else load_config()
    truth, _ = drives(base)['variant: lead angle, const mu, mapping']
    train, hold, clean = records(truth, seed=7)
    n = args.threads
    print(f'4-parameter fit, {train.t.size} samples ({DURATION} s at {RATE:g} Hz), '
          f'strategy robust, window_tol {args.window_tols[0]:g}; {_load()}')
    first = None
    ways = {'1 thread': (1, 0), f'{n} threads': (n, 0),
            f'{n} worker processes': (n, n)}
    walls: dict[str, list[float]] = {w: [] for w in ways}
    for rep in range(args.repeats):
        c_before = ceiling(n)
        for way, (th, proc) in ways.items():
            t0, c0, p0 = time.perf_counter(), _cpu(), time.process_time()
            res = identify(base, [train], KEYS,
                           options=FitOptions(serial=True, threads=th, processes=proc,
                                              window_tol=args.window_tols[0]))
            wall, cpu = time.perf_counter() - t0, _cpu() - c0
            parent = time.process_time() - p0
            walls[way].append(wall)
            h, c = held_out(res.config, hold, clean)
            nfev = sum(s['nfev'] for s in res.starts)
            same = first is None or (res.values == first.values and res.ci95 == first.ci95)
            first = first or res
            print(f'  [{rep + 1}] {way:<18} {wall:6.2f} s (CPU/wall {cpu / wall:4.2f}, '
                  f'this process {parent / wall:4.2f})  nfev {nfev}  values '
                  + ' '.join(f'{v:.6g}' for v in res.values)
                  + f'  held-out theta4 {h:.2f} % (vs truth {c:.2f} %)  '
                  f'{"trustworthy" if res.trustworthy else "NOT trustworthy"}'
                  f'{"" if same else "  DIFFERENT from the first run"}', flush=True)
        c_after = ceiling(n)
        quiet = min(c_before, c_after) >= QUIET * n
        one, *more = (walls[w][-1] for w in ways)
        print(f'  [{rep + 1}] ratio 1 thread / ' + ' / '.join(
            f'{w} {one / v:.2f}' for w, v in zip(list(ways)[1:], more))
            + f'; ceiling before {c_before:.2f}x after {c_after:.2f}x'
            f'{" (free cores)" if quiet else " (the cores were busy: not conclusive)"}; '
            f'{_load()}', flush=True)
    print('  best: ' + ', '.join(f'{w} {min(v):.2f} s' for w, v in walls.items())
          + '; target <= 5 s')
    if not args.dask:
        return
    from worm_gear_sim.parallel.cluster import local_cluster_client
    for label, opt in ((f'Dask LocalCluster, {args.workers or os.cpu_count()} workers, '
                        'incl. start-up', FitOptions(workers=args.workers)),
                       ('Dask LocalCluster, running', None)):
        t0 = time.perf_counter()
        if opt is None:
            with local_cluster_client(args.workers) as client:
                client.run(lambda: None)
                t0 = time.perf_counter()
                res = identify(base, [train], KEYS, options=FitOptions(client=client))
                wall = time.perf_counter() - t0
        else:
            res = identify(base, [train], KEYS, options=opt)
            wall = time.perf_counter() - t0
        print(f'  {label:<44} {wall:6.1f} s  values '
              + ' '.join(f'{v:.6g}' for v in res.values))
    print(f'  {_load()}')


def evaluation(args) -> None:
    """CPU of one evaluation of the timing fit's cost (``Problem.residuals``) on each of its
    windows, at new candidate sets near the base (min over 5 x 25 sets): the whole
    evaluation, the candidate set (Config, usability check, model) and the kernel."""
    from worm_gear_sim.dynamics import stepping
    from worm_gear_sim.dynamics.usability import usable_model
    from worm_gear_sim.identification import Problem, fit_parameters
    base = load_config(args.config) if args.config else load_config()
    truth, _ = drives(base)['variant: lead angle, const mu, mapping']
    train, _, _ = records(truth, seed=7)
    problem = Problem(base, fit_parameters(base, KEYS), [train])
    kernel = [0.0]
    advance = stepping.advance

    def timed(*a):
        c0 = time.process_time()
        out = advance(*a)
        kernel[0] += time.process_time() - c0
        return out

    stepping.advance = timed        # this process only: a benchmark's probe
    rng = np.random.default_rng(0)
    print(f'one evaluation, CPU ms (min of 5 x 25 new sets); {os.getloadavg()}')
    for w in problem.windows():
        best = None
        for _ in range(5):
            xs = np.abs(rng.normal(0.0, 0.01, (25, len(KEYS))))
            total = cand = 0.0
            kernel[0] = 0.0
            for x in xs:
                c0 = time.process_time()
                usable_model(problem.config(x))
                c1 = time.process_time()
                problem.residuals(x, w)
                cand += c1 - c0
                total += time.process_time() - c0
            row = (total / 25e-3, cand / 25e-3, kernel[0] / 25e-3)
            best = row if best is None or row[0] < best[0] else best
        label = 'whole record' if w is None else f'window {w:.3f} s'
        print(f'  {label:<18} {best[0]:6.2f}  candidate set {best[1]:.2f}  kernel {best[2]:.2f}'
              f'  the rest {best[0] - best[1] - best[2]:.2f}')
    stepping.advance = advance
    print(f'  {os.getloadavg()}')


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--compare', action='store_true', help='strategies x drives table')
    ap.add_argument('--coverage', action='store_true', help='calibration of the intervals')
    ap.add_argument('--realisations', type=int, default=20, help='noise draws (--coverage)')
    ap.add_argument('--strategies', nargs='*', help=f'subset of {", ".join(STRATEGIES)}')
    ap.add_argument('--serial', action='store_true', help='no Dask in --compare')
    ap.add_argument('--workers', type=int, default=None)
    ap.add_argument('--threads', type=int, default=2, help='threads of the timing run')
    ap.add_argument('--repeats', type=int, default=2, help='pairs of the timing run')
    ap.add_argument('--dask', action='store_true', help='also time the fit on Dask')
    ap.add_argument('--evaluation', action='store_true',
                    help='CPU of one evaluation of the timing fit per window, by part')
    ap.add_argument('--durations', type=float, nargs='*', default=[0.15, 0.5],
                    help='record lengths [s] in --compare')
    ap.add_argument('--method', default='dogbox', help='least_squares method (--compare)')
    ap.add_argument('--diff-steps', type=float, nargs='*', default=[DIFF_STEP],
                    help='finite-difference steps in the fitted coordinate (--compare)')
    ap.add_argument('--window-tols', type=float, nargs='*',
                    default=[FitOptions().window_tol],
                    help='ftol/xtol of the growing windows before the last (FitOptions.'
                    'window_tol; 0: the final tolerances throughout); --compare takes several, '
                    'the timing run the first')
    ap.add_argument('--surrogate', action='store_true', help='also fit on the tanh friction '
                    'law and predict with the base law (--compare)')
    ap.add_argument('--drives', nargs='*', help='substrings of drive names in --compare')
    ap.add_argument('--config', help='base YAML (default: the package config)')
    args = ap.parse_args()
    if args.compare:
        compare(args)
    elif args.coverage:
        coverage(args)
    elif args.evaluation:
        evaluation(args)
    else:
        timing(args)


if __name__ == '__main__':
    main()
