# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Golden trajectories of the drive without play: ``python test/data/make_no_play_golden.py
test/data/no_play_golden.npz``.  First written by the code before ``mesh.backlash`` existed
(commit 54a0830); rewritten when the kernel's Newton predictor (the acceleration
extrapolated) and early exits (stuck and slipping steps without a verifying evaluation)
changed the numerics at the Newton tolerance: the trajectories agree to 1e-9 of each
column's largest value until a stick-slip decision of the ring-down flips, after which they
differ by up to 5.5e-4 (angles) and 8.3e-3 (speeds); against a 0.25 us reference the new
records are as close as the old ones or closer (set-valued slew: theta4 1.6e-5 against
3.2e-5 of its largest value).  test/dynamics/test_backlash.py checks that ``mesh.backlash: 0``
reproduces them within a stated rounding tolerance (numba compiles for the host
CPU; other CPUs round otherwise): every 25th step of the paper's move and of a slew with
reversals under load, both friction laws: theta and omega)."""
import sys

import numpy as np

from worm_gear_sim import Config, simulate
from worm_gear_sim.dynamics.profiles import SampledProfile

out = {}
for fric in ('set_valued', 'regularized'):
    cfg = Config().replace({'friction.direction': fric})
    tr = simulate(cfg, t_end=0.03, record_every=25)                  # the paper's move
    out[f'paper_{fric}'] = np.column_stack([tr.theta, tr.omega])
    t = np.array([0.0, 0.01, 0.02, 0.03, 0.04])
    th = np.array([0.0, 0.02, -0.01, 0.015, 0.015])                    # slew with reversals
    c2 = cfg.replace({'load.output_torque': 1.5})
    tr = simulate(c2, profile=SampledProfile(t, th, 'linear'), t_end=0.04, record_every=25)
    out[f'slew_{fric}'] = np.column_stack([tr.theta, tr.omega])
np.savez_compressed(sys.argv[1], **out)
print({k: v.shape for k, v in out.items()})
