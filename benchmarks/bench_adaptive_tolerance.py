#!/usr/bin/env python3
# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The variable step's tolerances (``integrator.adaptive_tolerance_worm`` / ``_gear``) swept:
what each pair costs and what it gives, in one run.

For each pair (multiples of 1e-9 / 3e-8 rad, the defaults 5e-10 / 3e-8 among them, and other
gear / worm ratios) the table gives
  * the kernel's time per simulated us on the paper's 18-step move (0.5 s), on a +-5 deg
    sector scan (4 s) and on a loaded 2 rad/s worm slew with a reversal (0.15 s, the drive of
    test/test_adaptive_twins.py), with the fixed step (4 us) timed in the same rounds;
    accepted steps, rejected steps;
  * the worst theta2 / theta4 error against the event-driven Radau solution on every drive
    the default-accuracy test checks (test_against_radau.py,
    test_default_step_meets_the_pointwise_targets: linear mesh, nonlinear mesh, the stiffer
    worm shaft), pointwise at every step the variable step takes over the move and 4 ms of
    ringing, and the error of the ringing amplitudes the parametric studies report; each as
    a fraction of its target (theta2 5 %, theta4 0.1 % of the oscillation amplitude): 1.0 is
    the test's limit;
  * the range of the worst theta2 error when the step controller's constants change (its
    safety factor, its integral and proportional exponents: a different sequence of steps
    at the same tolerance), and the four errors at the default tolerances per constant;
  * (``--ring-down``) the antenna's ring-down over 0.5 s after the move, which the test
    suite checks within 25 % of the exact-stick limit, beside the fixed step at 1 us.

    python benchmarks/bench_adaptive_tolerance.py                 # the sweep (~1-2 min)
    python benchmarks/bench_adaptive_tolerance.py --pairs 1:1 10:30 --rounds 3

Timings are the minimum over rounds that alternate the configurations (other load on the
machine only makes them slower); the machine load is printed before and after.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, '..'))
sys.path.insert(0, os.path.join(HERE, '..', 'test'))
sys.path.insert(0, os.path.join(HERE, '..', 'test', 'dynamics'))

from adaptive_steps import cases, kernel_run  # noqa: E402

from worm_gear_sim import Config, SampledProfile, Simulator, make_profile  # noqa: E402
from worm_gear_sim.dynamics.integrator import S_ADAPTIVE_STEPS, S_REJECTED  # noqa: E402
from worm_gear_sim.dynamics.step_control import A_KI, A_KP, A_SAFETY  # noqa: E402

ADAPTIVE = {'integrator.method': 'adaptive'}
#: the loaded slow slew of test/test_adaptive_twins.py (test/realtime/test_predictor.py)
LOADED = {'load.output_torque': 5.0, 'load.output_viscous_coefficient': 2.0}
#: the drives of test_default_step_meets_the_pointwise_targets
DRIVES = [('linear', {'mesh.stiffness_model': 'linear', 'friction.model': 'constant'}),
          ('nonlinear', {}),
          ('stiffer worm shaft', {'shafts.worm_shaft_length': 0.1})]
#: the tolerances the multiples below refer to [rad per step]: theta2's, theta3's and theta4's
BASE_WORM, BASE_GEAR = 1e-9, 3e-8
#: (worm, gear) multiples of BASE_WORM, BASE_GEAR
PAIRS = [(0.3, 1), (0.5, 1), (0.7, 1), (1, 1), (1.5, 1), (2, 1), (3, 1), (10, 1), (30, 1),
         (0.5, 10), (0.5, 100), (0.5, 1000), (3, 3), (10, 10)]
#: the step controller's (safety factor, integral and proportional exponents) in use and
#: around it: how much the accuracy at the default tolerances depends on the step sequence
CONTROLLERS = [(0.85, 0.5 / 3, 0.2 / 3), (0.75, 0.5 / 3, 0.2 / 3), (0.95, 0.5 / 3, 0.2 / 3),
               (0.85, 0.3 / 3, 0.1 / 3), (0.85, 0.7 / 3, 0.4 / 3), (0.85, 1 / 3, 0.0)]
T_CHECK = 0.024


def slow_slew(rate: float = 2.0, n: int = 150) -> SampledProfile:
    """The 1 kHz worm slew at ``rate`` with its reversal half way (on the grid)."""
    t = np.arange(n) * 1e-3
    x = rate * t
    r = n // 2
    return SampledProfile(t, np.where(np.arange(n) >= r, 2 * x[r] - rate * t, x))


def tolerances(pair: tuple[float, float]) -> dict:
    """The config overrides of a (worm, gear) pair of multiples of BASE_WORM, BASE_GEAR."""
    return dict(ADAPTIVE, **{'integrator.adaptive_tolerance_worm': BASE_WORM * pair[0],
                             'integrator.adaptive_tolerance_gear': BASE_GEAR * pair[1]})


def accuracy(over: dict, controller: tuple | None = None) -> dict[str, tuple[float, str]]:
    """Worst errors over the drives as fractions of the targets: 'e2', 'e4' pointwise,
    'a2', 'a4' of the studies' ringing amplitudes (the checks of
    test_default_step_meets_the_pointwise_targets), each with the worst drive's name;
    ``controller``: (safety, k_i, k_p) in place of the step controller's constants."""
    from test_against_radau import radau_set_valued
    worst = {'e2': (0.0, ''), 'e4': (0.0, ''), 'a2': (0.0, ''), 'a4': (0.0, '')}
    for name, drive in DRIVES:
        cfg = Config().replace(dict(drive, **over))
        prof = make_profile(cfg.input)
        sim = Simulator(cfg)
        if cfg.integrator.method == 'fixed':                   # every step
            tr = sim.run(prof, T_CHECK)
            t, theta = tr.t, tr.theta
        else:
            if controller is not None:
                sim._ap[A_SAFETY], sim._ap[A_KI], sim._ap[A_KP] = controller
            sim.log_steps(200_000)
            tr = sim.run(prof, T_CHECK, record_every=250)
            t, theta = sim.step_log['t'], sim.step_log['theta']
        th1 = prof.theta1(t)
        ref, _ = radau_set_valued(cfg, t, T_CHECK)
        ratio = tr.output_per_input
        osc2 = np.abs(ref[:, 0] - th1).max()
        osc4 = np.abs(ref[:, 2] - th1 * ratio).max()
        ring = t > cfg.input.move_time
        amp = [np.abs(x[ring, j] - th1[ring] * r).max()
               for x in (theta, ref) for j, r in ((0, 1.0), (2, ratio))]
        got = {'e2': np.abs(theta[:, 0] - ref[:, 0]).max() / osc2 / 0.05,
               'e4': np.abs(theta[:, 2] - ref[:, 2]).max() / osc4 / 1e-3,
               'a2': abs(amp[0] / amp[2] - 1) / 0.05, 'a4': abs(amp[1] / amp[3] - 1) / 1e-3}
        for k, v in got.items():
            if v >= worst[k][0]:
                worst[k] = (float(v), name)
    return worst


def ring_down_of(over: dict) -> float:
    """The antenna's ring-down [fraction] over 0.5 s after the move (trajectory.ring_down)."""
    from test_integrator import _ring_down
    return _ring_down(over, Config().integrator.time_step)


def timings(pairs: list, rounds: int) -> dict:
    """{(pair or 'fixed', case): (best seconds, stats)}: rounds alternate the configurations."""
    base = Config()
    runs = [(name, prof, t) for name, prof, t in cases(base)] + \
        [('loaded slew 2 rad/s, 0.15 s', slow_slew(), 0.149)]
    cfgs = [('fixed', base)] + [(pr, base.replace(tolerances(pr))) for pr in pairs]
    out: dict = {}
    for _ in range(rounds):
        for name, prof, t_end in runs:
            for key, cfg in cfgs:
                c = cfg.replace(LOADED) if name.startswith('loaded') else cfg
                s, st = kernel_run(c, prof, t_end)
                prev = out.get((key, name))
                if prev is None or s < prev[0]:
                    out[(key, name)] = (s, st)
    return {'runs': runs, 'best': out}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--pairs', nargs='*', metavar='W:G',
                    help='(worm, gear) multiples of the default tolerances')
    ap.add_argument('--rounds', type=int, default=3)
    ap.add_argument('--ring-down', action='store_true',
                    help='also the 0.5 s ring-down after the move (fixed 1 us beside)')
    ap.add_argument('--no-controller', action='store_true',
                    help='skip the accuracy under other step-controller constants')
    args = ap.parse_args(argv)
    pairs = [tuple(float(x) for x in s.split(':')) for s in args.pairs] if args.pairs \
        else PAIRS
    d = Config().integrator
    load0 = os.getloadavg()
    print(f'# variable-step tolerance sweep, "worm x" / "gear x": multiples of {BASE_WORM:g} / '
          f'{BASE_GEAR:g} rad (the defaults: {d.adaptive_tolerance_worm:g} / '
          f'{d.adaptive_tolerance_gear:g} rad); load {load0[0]:.2f} {load0[1]:.2f} '
          f'{load0[2]:.2f}; {os.cpu_count()} cores', flush=True)
    t0 = time.perf_counter()
    tm = timings(pairs, args.rounds)
    runs, best = tm['runs'], tm['best']
    print(f'# kernel: ns per simulated us (x real time), accepted / rejected steps; min of '
          f'{args.rounds} alternating rounds ({time.perf_counter() - t0:.0f} s)')
    hdr = ''.join(f' | {n[:22]:>36s}' for n, _, _ in runs)
    print(f'{"worm x":>7s} {"gear x":>7s}{hdr}')
    for key in ['fixed'] + pairs:
        cells = []
        for name, _, t_end in runs:
            s, st = best[(key, name)]
            ns = s / t_end * 1e3
            if key == 'fixed':
                cells.append(f'{ns:7.1f} ({t_end / s:5.1f}x) {"fixed 4 us":>19s}')
            else:
                cells.append(f'{ns:7.1f} ({t_end / s:5.1f}x) {int(st[S_ADAPTIVE_STEPS]):9d} / '
                             f'{int(st[S_REJECTED]):7d}')
        lbl = ('fixed', '') if key == 'fixed' else (f'{key[0]:g}', f'{key[1]:g}')
        print(f'{lbl[0]:>7s} {lbl[1]:>7s}' + ''.join(f' | {c:>36s}' for c in cells))
    print('# fixed / variable kernel time, same rounds')
    for key in pairs:
        r = [best[('fixed', n)][0] / best[(key, n)][0] for n, _, _ in runs]
        print(f'{key[0]:7g} {key[1]:7g} | ' + ' | '.join(f'{x:6.2f}' for x in r))
    print('# accuracy against the event-driven Radau solution, worst over the drives '
          f'{", ".join(n for n, _ in DRIVES)}: error / target (1.0 = the test\'s limit; '
          'theta2 5 %, theta4 0.1 % of the oscillation amplitude), pointwise at every step '
          'and of the ringing amplitudes; the worst drive in brackets; "theta2, ctl": the '
          'range of the worst theta2 under the step-controller constants of the last table',
          flush=True)
    print(f'{"worm x":>7s} {"gear x":>7s} {"theta2":>24s} {"theta4":>24s} '
          f'{"ampl. theta2":>24s} {"ampl. theta4":>24s} {"theta2, ctl":>12s}' +
          ('  ring-down (fixed 1 us)' if args.ring_down else ''))
    rd_fixed = None
    if args.ring_down:
        rd_fixed = _fixed_ring_down()
    w = accuracy({})
    print(f'{"fixed":>7s} {"4 us":>7s}' + ''.join(
        f' {w[k][0]:8.3f} [{w[k][1][:13]:>13s}]' for k in ('e2', 'e4', 'a2', 'a4')), flush=True)
    for pr in pairs:
        w = accuracy(tolerances(pr))
        row = f'{pr[0]:7g} {pr[1]:7g}' + ''.join(
            f' {w[k][0]:8.3f} [{w[k][1][:13]:>13s}]' for k in ('e2', 'e4', 'a2', 'a4'))
        if not args.no_controller:
            ctl = [accuracy(tolerances(pr), c)['e2'][0] for c in CONTROLLERS[1:]]
            row += f' {min(ctl + [w["e2"][0]]):5.2f}-{max(ctl + [w["e2"][0]]):4.2f}'
        if args.ring_down:
            row += f'  {100 * ring_down_of(tolerances(pr)):.3f} % ({100 * rd_fixed:.3f} %)'
        print(row, flush=True)
    if not args.no_controller:
        print('# the same at the default tolerances with other step-controller constants '
              '(safety factor, integral and proportional exponents; the first row: in use)')
        print(f'{"safety":>5s} {"k_i":>5s} {"k_p":>5s}' + ''.join(
            f' {n:>24s}' for n in ('theta2', 'theta4', 'ampl. theta2', 'ampl. theta4')))
        for c in CONTROLLERS:
            w = accuracy(ADAPTIVE, c)
            print(f'{c[0]:5.2f} {c[1]:5.3f} {c[2]:5.3f}' + ''.join(
                f' {w[k][0]:8.3f} [{w[k][1][:13]:>13s}]' for k in ('e2', 'e4', 'a2', 'a4')),
                flush=True)
    load1 = os.getloadavg()
    print(f'# load after {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}; '
          f'{time.perf_counter() - t0:.0f} s')
    return 0


def _fixed_ring_down() -> float:
    from test_integrator import _ring_down
    return _ring_down({}, 1e-6)


if __name__ == '__main__':
    sys.exit(main())
