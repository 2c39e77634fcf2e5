#!/usr/bin/env python3
# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Step-size convergence study: which Newmark step puts theta2 and theta4 pointwise within
5 % / 0.1 % of their oscillation amplitudes, on the paper's 18-step move and on variants.

For every case and every step dt in (10, 5, 4, 2.5) us it prints
    max_k |theta(t_k) - theta_ref(t_k)| / max |oscillation of the reference|
for theta2 (oscillation: theta2 - theta1, `worm_error`) and theta4 (theta4 - theta1 l_w/r_g,
`output_error`), over every step of the move and 5 ms of ringing, and the step's resolution
of the highest linearised mode, omega_max dt (`modal.step_resolution`).  The reference is the
same model integrated by Newmark at 0.05 us (the test suite checks that reference against an
independent event-driven scipy Radau solution within 0.1 %, test_against_radau); the column
`ref` is its own error estimate, |Newmark 0.1 us - Newmark 0.05 us|, as a fraction.

    python benchmarks/bench_step.py            # all cases (~1 min on a quiet core)
    python benchmarks/bench_step.py --long     # also 0.1 s horizons (the ringing's phase)

The cases marked * were not used to pick the default step.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..'))

from worm_gear_sim import Config, simulate  # noqa: E402
from worm_gear_sim.dynamics.modal import StepResolutionWarning, step_resolution  # noqa: E402

STEPS = (1e-5, 5e-6, 4e-6, 2.5e-6)
REF_DT = 5e-8
REF_CHECK_DT = 1e-7
LINEAR = {'mesh.stiffness_model': 'linear', 'friction.model': 'constant'}
# (name, overrides, used to pick the default)
CASES = [
    ('18-step move, nonlinear mesh', {}, True),
    ('18-step move, linear mesh', LINEAR, True),
    ('stiffer worm shaft (L1 0.1 m)', {'shafts.worm_shaft_length': 0.1}, False),
    ('softer worm shaft (L1 0.4 m)', {'shafts.worm_shaft_length': 0.4}, False),
    ('stiff worm shaft (R1 20 mm), linear', dict(LINEAR, **{'shafts.worm_shaft_radius': 0.02}),
     False),
    ('module M3', {'geometry.module': 3.0}, False),
    ('module M1, linear', dict(LINEAR, **{'geometry.module': 1.0}), False),
    ('paper lead convention', {'geometry.lead_convention': 'paper'}, False),
    ('no flywheel', {'geometry.flywheel_enabled': False}, False),
    ('move in 16 ms', {'input.move_time': 0.016}, False),
    ('ramp (velocity steps)', {'input.profile': 'ramp'}, False),
    ('load torque 200 N m', {'load.output_torque': 200.0}, False),
    ('sawtooth contact mapping', {'mesh.contact_mapping': 'sawtooth'}, False),
    ('tanh friction (regularized)', {'friction.direction': 'regularized'}, False),
]


def horizon_of(cfg: Config, ringing: float = 0.005) -> float:
    return cfg.input.start_time + cfg.input.move_time + ringing


def errors(over: dict, steps=STEPS, ringing: float = 0.005):
    """(errors {dt: (e2, e4)}, reference self-error (e2, e4), omega_max dt {dt: x})."""
    base = Config().replace(over)
    t_end = horizon_of(base, ringing)
    stride = int(round(5e-7 / REF_DT))                 # reference rows every 0.5 us
    ref = simulate(base.replace({'integrator.time_step': REF_DT}), t_end=t_end,
                   record_every=stride)
    chk = simulate(base.replace({'integrator.time_step': REF_CHECK_DT}), t_end=t_end,
                   record_every=int(round(5e-7 / REF_CHECK_DT)))
    osc2 = np.abs(ref.worm_error).max()
    osc4 = np.abs(ref.output_error).max()
    n = min(len(ref.t), len(chk.t))
    ref_err = (np.abs(chk.theta2[:n] - ref.theta2[:n]).max() / osc2,
               np.abs(chk.theta4[:n] - ref.theta4[:n]).max() / osc4)
    out, res = {}, {}
    for dt in steps:
        cfg = base.replace({'integrator.time_step': dt})
        tr = simulate(cfg, t_end=t_end, record_every=1)
        k = int(round(dt / 5e-7))                      # ref rows per step
        idx = np.arange(len(tr.t)) * k
        keep = idx < len(ref.t)
        r2, r4 = ref.theta2[idx[keep]], ref.theta4[idx[keep]]
        assert np.allclose(ref.t[idx[keep]], tr.t[keep], atol=1e-12)
        out[dt] = (float(np.abs(tr.theta2[keep] - r2).max() / osc2),
                   float(np.abs(tr.theta4[keep] - r4).max() / osc4))
        res[dt] = step_resolution(cfg)
    return out, ref_err, res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--long', action='store_true',
                    help='also the default cases over 0.1 s of ringing')
    args = ap.parse_args(argv)
    # the coarse rows are deliberate: the tables report each step's resolution themselves
    warnings.simplefilter('ignore', StepResolutionWarning)
    print(f'# worm_gear_sim step convergence (load {os.getloadavg()[0]:.2f}); pointwise error '
          'as a fraction of the oscillation amplitude, theta2 / theta4 '
          '(targets 0.05 / 0.001); move + 5 ms ringing')
    head = ' '.join(f'{dt * 1e6:>6.1f}us th2   th4    ' for dt in STEPS)
    print(f'{"case":38s} {"w dt@10us":>9s}  {head} ref th2/th4')
    worst = {dt: [0.0, 0.0] for dt in STEPS}
    cases = list(CASES)
    if args.long:
        cases += [(name + ', 0.1 s ringing', over, False) for name, over, tuned in CASES[:2]]
    for name, over, tuned in cases:
        ringing = 0.1 if name.endswith('0.1 s ringing') else 0.005
        errs, ref_err, res = errors(over, ringing=ringing)
        cells = ' '.join(f'{errs[dt][0]:10.4f} {errs[dt][1]:8.1e}' for dt in STEPS)
        mark = ' ' if tuned else '*'
        print(f'{mark}{name:37s} {res[STEPS[0]]:9.3f}  {cells} {ref_err[0]:.0e}/{ref_err[1]:.0e}',
              flush=True)
        for dt in STEPS:
            worst[dt][0] = max(worst[dt][0], errs[dt][0])
            worst[dt][1] = max(worst[dt][1], errs[dt][1])
    cells = ' '.join(f'{worst[dt][0]:10.4f} {worst[dt][1]:8.1e}' for dt in STEPS)
    print(f'{"worst case":38s} {"":9s}  {cells}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
