# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Golden feed-forward corrections of the drive without play, written by the code before
the backlash inverse existed (commit 6f642f2): ``python test/data/make_ff_golden.py
test/data/ff_golden.npz``.  test/compensation/test_backlash_inverse.py checks that with
``mesh.backlash: 0`` the compensator (``compensation.backlash_inverse`` on or off) reproduces them
within a stated rounding tolerance (numba compiles for the host CPU; other CPUs round otherwise):
the paper's move and the radar slew under the radar load, both friction laws, causal and
with a preview, and with the dynamic inverse."""
import sys

import numpy as np

from worm_gear_sim import Config
from worm_gear_sim.realtime import feedforward_series
from worm_gear_sim.studies.compensation_eval import (
    RADAR_LOAD,
    paper_step_scenario,
    radar_slew_scenario,
)

CASES = {
    'causal': {},
    'preview': {'compensation.preview_time': 0.0025},
    'dynamic': {'compensation.model_inverse': True},
}

out = {}
for fric in ('set_valued', 'regularized'):
    for name, extra in CASES.items():
        cfg = Config().replace({'friction.direction': fric, **extra})
        sc = paper_step_scenario(cfg)
        out[f'paper_{fric}_{name}'] = feedforward_series(cfg, sc.times, sc.theta1_ref)
        c2 = cfg.replace(RADAR_LOAD)
        sc = radar_slew_scenario(c2)
        out[f'slew_{fric}_{name}'] = feedforward_series(c2, sc.times, sc.theta1_ref)
np.savez_compressed(sys.argv[1], **out)
print({k: v.shape for k, v in out.items()})
