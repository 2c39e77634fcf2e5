# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The small fit the evaluation-engine tests share (threads, forked processes): the default
model fitted to 0.04 s of a drive 10 % stiffer and damped, theta4 at 10 kHz with encoder
steps and noise."""

from __future__ import annotations

import math

from worm_gear_sim import load_config
from worm_gear_sim.config.usable import Config
from worm_gear_sim.dynamics.profiles import TrapezoidalProfile
from worm_gear_sim.identification import Record, record_from_model

KG = 'materials.gear_shaft_shear_modulus'
ZETA = 'damping.modal_damping_ratios[0]'
MOVE = TrapezoidalProfile(0.11309733552923255, 0.020, 0.004, 0.005)


def fit_case() -> tuple[Config, Record]:
    """(the base model, the record)."""
    base = load_config()
    truth = base.replace({KG: base.materials.gear_shaft_shear_modulus * 1.1,
                          'damping.modal_damping_ratios': [0.01, 0.0, 0.0]})
    rec = record_from_model(truth, MOVE, 0.04, 1e4, ('theta4',), noise_rad=1e-6,
                            resolution_rad=2 * math.pi / 2 ** 20, seed=3)
    return base, rec
