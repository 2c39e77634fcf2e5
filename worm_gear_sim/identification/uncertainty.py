# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""How sure a fitted model's prediction is: :func:`prediction_bound`, an upper bound U on the
RMS error of the predicted antenna angle over a move, meant to hold when the model is not
exact.

U = sqrt(misfit^2 + spread^2): the misfit the fit leaves (a windowed quantile of its
residuals) and the spread of parameter sets drawn from the fit's covariance.
docs/identification.md.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.stats import norm

from ..dynamics.model import DriveModel
from ..dynamics.stepping import SimulationError
from ..records import Record
from ..schema.validation import ConfigError
from .data import normalised, predict
from .parameters import apply_values, fit_parameters
from .report import FitResult

__all__ = ['PredictionBound', 'prediction_bound', 'WINDOW_INFLATION']

#: Factor on the window-RMS quantile (the windows of a few training records are few and
#: correlated; an upper quantile estimated from them is biased low).
WINDOW_INFLATION = 1.25


@dataclass
class PredictionBound:
    """Upper bound ``bound_rad`` on the RMS prediction error of ``output`` over a move of
    ``duration`` s, and its parts."""

    output: str
    level: float
    duration: float
    misfit_rad: float           # from the training residuals
    spread_rad: float           # from the parameters' uncertainty
    bound_rad: float
    n_windows: int
    n_draws: int

    def covers(self, rms_error: float) -> bool:
        return bool(rms_error <= self.bound_rad)


def prediction_bound(fit: FitResult, train: Sequence[Record], move: Record,
                     output: str = 'theta4', level: float = 0.95, n_draws: int = 24,
                     seed: int = 0) -> PredictionBound:
    """The bound of the module docstring for predicting ``move`` (its command; its
    measurements are not used) with ``fit``'s model, from the ``train`` records it was
    fitted on."""
    if not 0.5 < level < 1.0:
        raise ValueError(f'level {level!r}: a probability between 0.5 and 1')
    model = DriveModel(fit.config)
    mv = normalised(move, 0)
    duration = float(mv.t[-1] - mv.t[0])
    # 1. misfit: windows of the move's length over the training residuals
    rms_w: list[float] = []
    for i, r in enumerate(train):
        rr = normalised(r, i)
        if output not in rr.measured:
            continue
        e = predict(model, rr)[output] - rr.measured[output]
        dt = float(np.median(np.diff(rr.t)))
        n = max(2, int(round(duration / dt)))
        if e.size <= n:
            rms_w.append(float(np.sqrt(np.mean(e ** 2))))
            continue
        c = np.concatenate(([0.0], np.cumsum(e ** 2)))
        rms_w.extend(np.sqrt((c[n:] - c[:-n]) / n).tolist())
    if not rms_w:
        raise ValueError(f'no training record measures {output}')
    misfit = WINDOW_INFLATION * float(np.quantile(rms_w, level))
    # 2. spread of the prediction over parameter draws from the fit's covariance
    params = fit_parameters(fit.base_config, fit.keys)
    x_hat = np.array([p.to_x(v) for p, v in zip(params, fit.values)])
    std = np.asarray(fit.std_x, float)
    corr = np.nan_to_num(np.asarray(fit.correlation, float), nan=0.0)
    np.fill_diagonal(corr, 1.0)
    cov = corr * np.outer(std, std)
    spread = 0.0
    draws = 0
    if np.all(np.isfinite(std)) and np.any(std > 0):
        rng = np.random.default_rng(seed)
        w, v = np.linalg.eigh(cov)
        root = v * np.sqrt(np.clip(w, 0.0, None))
        base = predict(model, mv)[output]
        dev = []
        for _ in range(n_draws):
            x = x_hat + root @ rng.standard_normal(x_hat.size)
            try:
                cfg = apply_values(fit.base_config, params, [p.from_x(float(xi)) for p, xi
                                                             in zip(params, x)])
                dev.append(predict(cfg, mv)[output] - base)
            except (ConfigError, SimulationError, ValueError):
                continue
        draws = len(dev)
        if dev:
            sd = np.std(np.array(dev), axis=0)
            spread = float(norm.ppf(level) * np.sqrt(np.mean(sd ** 2)))
    bound = math.hypot(misfit, spread)
    return PredictionBound(output, level, duration, misfit, spread, bound, len(rms_w), draws)
