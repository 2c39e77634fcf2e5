# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Play and load told apart when a load holds the gear on one flank in every sweep.

With one flank throughout, the sweeps show only b / 2 + T C of play b and load torque T (C:
the compliance from the antenna to the worm, :func:`.direct.compliance`).  No constant rate
within the limits separates them when the drag torque c u omega stays below T, and no single
stop does when the antenna's inertia torque (J_4 + J_g) u alpha stays below T (with 0.5 rad,
6 rad/s and 1 500 rad/s^2 of worm: 2.1 N m of inertia torque, rigid).  A move that swings the
worm rate at the antenna mode does: at resonance the shaft torque swing grows each cycle by
about pi times the rigid inertia torque until the mesh unloads; the gear then leaves its
flank (into the play: it need not reach the other one) at a torque that depends on T, not on
b / 2 + T C.  Measured on the drive with 2.80 arcmin, 4.75 N m and 14.4 N m s/rad (benchmark
bench_calibration seed 1 drive 0): 8 cycles at 94.6 Hz with 1 500 rad/s^2 (+-2.5 rad/s of
worm) lift the gear 12 % of the play off its flank; the model with the sweeps' one-flank fit
(0.46 arcmin, 14.0 N m) differs from the truth by 31 urad RMS of theta4 on that move (noise 1
urad), by 0.55 urad on the fast sweep.

:func:`.excitation.dither_profile` is that move (``unload_dither``, kept in reserve by the
excitation); :func:`split_refit` runs when the sweeps' fit says the play is hidden: a scan
along the line b / 2 + T C = const on the time-domain cost of the sweeps and the dither, then
the local fit from the best point with every key free.  :func:`.visibility.mesh_lifts` says
whether a model lifts the gear off its flank in a record (what makes the split seen).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from ..params import Config
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
