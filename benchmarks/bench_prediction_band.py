# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Coverage of the 95 % prediction bound (worm_gear_sim.identification.uncertainty) and of
the parameter intervals, over simulated drives that differ from the base config in their
parameters and, for a third of them, in structure (friction law, contact mapping, lead
angle, linear mesh, bearing drag).

Each drive is calibrated like ``worm-gear-sim calibrate --plant`` (fitted: gear-shaft
modulus, antenna damping, friction, bearing drag; the flywheel density differs too and is
not fitted), then the held-out move's actual RMS error of theta4 is compared with the bound.

    python benchmarks/bench_prediction_band.py [--drives 21] [--seed 0] [--noise RAD]
        [--encoder-bits N] [--serial]

Prints one line per drive and the coverage; the target is >= 90 % of held-out moves.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from worm_gear_sim import Config
from worm_gear_sim.identification import FitOptions
from worm_gear_sim.identification.calibrate import calibrate, plant_runner
from worm_gear_sim.identification.excitation import Limits
from worm_gear_sim.identification.uncertainty import prediction_bound

KG = 'materials.gear_shaft_shear_modulus'
RHO = 'materials.flywheel_density'
ZETA = 'damping.modal_damping_ratios[0]'
MU = 'friction.mu_kinetic'
COUT = 'load.output_viscous_coefficient'
KEYS = [KG, ZETA, MU, COUT]

STRUCTURES = [
    {'friction.model': 'stribeck', 'friction.direction': 'regularized'},
    {'friction.model': 'constant', 'friction.constant_coefficient': 0.12,
     'mesh.contact_mapping': 'sawtooth', 'mesh.phase_offset': 2.0},
    {'friction.direction': 'regularized', 'friction.regularization_velocity': 1e-3},
    {'geometry.lead_angle': 0.064286},
    {'mesh.stiffness_model': 'linear'},
    {'friction.mu_stribeck_drop': 0.05, 'friction.direction': 'regularized'},
    {'mesh.contact_mapping': 'sawtooth'},
]


def drive(base: Config, i: int, rng: np.random.Generator) -> tuple[str, Config]:
    flat = base.to_flat_dict()
    f = rng.uniform(0.7, 1.4, 3)
    over = {KG: flat[KG] * f[0], RHO: flat[RHO] * f[1], MU: flat[MU] * f[2],
            'damping.modal_damping_ratios': [float(rng.uniform(0.003, 0.03)), 0.0, 0.0],
            COUT: float(rng.uniform(0.0, 2.0))}
    name = 'parameters'
    if i % 3 == 2:
        s = STRUCTURES[(i // 3) % len(STRUCTURES)]
        over.update(s)
        name = ', '.join(f'{k.split(".")[-1]}={v}' for k, v in s.items())
    return name, base.replace(over)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--drives', type=int, default=21)
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--serial', action='store_true')
    ap.add_argument('--noise', type=float, default=1e-6, help='encoder noise RMS [rad]')
    ap.add_argument('--encoder-bits', type=int, default=20, help='0: no quantisation')
    args = ap.parse_args()
    base = Config()
    rng = np.random.default_rng(args.seed)
    limits = Limits(0.12, 6.0, 1500.0)
    covered = ci_cover = ci_total = 0
    t_all = time.perf_counter()
    print(f'{"drive":<4} {"structure":<48} {"held-out":>9} {"bound":>9} {"misfit":>9} '
          f'{"spread":>9} covered  CI(kg)')
    for i in range(args.drives):
        name, truth = drive(base, i, rng)
        t0 = time.perf_counter()
        res = calibrate(base, KEYS, limits, plant_runner(
            truth, 1e4, ('theta4',), args.noise,
            2 * math.pi / 2 ** args.encoder_bits if args.encoder_bits > 0 else 0.0, seed=i),
            options=FitOptions(strategy='robust', serial=args.serial))
        move = res.held_out[0]
        b = prediction_bound(res.fit, res.train, move)
        err = res.validation_after[0]['theta4']['rms_rad']
        ok = b.covers(err)
        covered += ok
        lo, hi = res.fit.ci95[0]
        true_kg = truth.materials.gear_shaft_shear_modulus
        in_ci = lo <= true_kg <= hi
        ci_cover += in_ci
        ci_total += 1
        print(f'{i:<4} {name[:48]:<48} {err:9.3e} {b.bound_rad:9.3e} {b.misfit_rad:9.3e} '
              f'{b.spread_rad:9.3e} {"yes" if ok else "NO":>7}  {"in" if in_ci else "out"}'
              f'  ({time.perf_counter() - t0:.0f} s)', flush=True)
    n = args.drives
    print(f'\n95 % prediction bound covers the held-out RMS error in {covered}/{n} drives '
          f'({100 * covered / n:.0f} %; target >= 90 %)')
    print(f'95 % interval of the gear-shaft modulus contains the true value in '
          f'{ci_cover}/{ci_total} drives (the parameter intervals assume an exact model)')
    print(f'{time.perf_counter() - t_all:.0f} s in all')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
