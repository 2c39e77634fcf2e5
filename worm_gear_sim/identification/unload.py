# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Play and load told apart when a load holds the gear on one flank in every sweep.

The sweeps then show only b / 2 + T C; a worm rate swung at the antenna mode
(``unload_dither``) lifts the gear off its flank at a torque that depends on T.
:func:`split_refit` scans along b / 2 + T C = const on the sweeps and the dither, then
fits every key from the best point.  docs/identification.md.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from ..config.usable import Config
from ..records import Record
from .direct import LOAD, PLAY, best_on_family, compliance
from .fit import PRIORS, FitOptions, identify, wind_up_only
from .parameters import fit_parameters
from .problem import Problem
from .report import FitResult, residual_rms

__all__ = ['SPLIT_POINTS', 'split_refit']

#: Points of the scan along b / 2 + T C = const (between T = 0 and b = 0, ends excluded).
SPLIT_POINTS = 12


def split_refit(base: Config, records: Sequence[Record], keys: Sequence[str],
                fitted: FitResult, options: FitOptions,
                outputs: Sequence[str] | None = None) -> FitResult:
    """Fit ``keys`` again on ``records`` (the sweeps and the dither) from the best point of
    the line b / 2 + |T| C = const through ``fitted``'s play and load (module docstring).
    The result's base values and 'before' figures are those of ``base`` (the caller's)."""
    cfg = fitted.config
    b0, t0 = cfg.mesh.backlash, cfg.load.output_torque
    c = compliance(cfg)
    s = 1.0 if t0 >= 0 else -1.0
    total = 0.5 * b0 + abs(t0) * c           # b / 2 + |T| C
    family = []
    for k in range(1, SPLIT_POINTS + 1):
        t = total / c * k / (SPLIT_POINTS + 1)
        family.append({PLAY: 2.0 * (total - t * c), LOAD: s * t})
    best, rows = best_on_family(cfg, records, family)
    opt = dataclasses.replace(options, global_stage=False, priors={}, n_starts=1)
    res = identify(cfg.replace(best), records, keys, options=opt, outputs=outputs)
    res.frequency_info['split_scan'] = rows
    for key in PRIORS:     # free here (no prior), but no better seen than with the prior
        if key in keys:
            wind_up_only(res, key, 'fitted free after the dither split the play from the load')
    res.base_config = base
    res.base_values = [p.base for p in fit_parameters(base, keys)]
    res.rms_before = residual_rms(Problem(base, fit_parameters(base, keys), records, outputs),
                                  base)[0]
    return res
