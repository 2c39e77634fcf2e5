# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Fit model parameters to measured records; the live model check is in
:mod:`worm_gear_sim.realtime.model_check`.  Pure core (no rclpy; figures in :mod:`.plot`).

One module per job:

* :mod:`.data`: the records (checks, the model's prediction of a record, synthetic records,
  measured frequencies);
* :mod:`.parameters`: the ``--fit`` keys, their bounds and the normalised coordinate x
  (``log(value / base)`` for positive quantities, ``(value - base) / scale`` otherwise);
* :mod:`.problem`: the weighted residual vector r(x) and its finite-difference Jacobian;
* :mod:`.fit`: the robust search (:func:`identify`: frequency start, growing windows,
  multi-start on the sweeps' Dask engine);
* :mod:`.report`: estimates with 95 % intervals, correlations, residual RMS, the verdict, and
  the prediction error on held-out records.
"""

from ..records import Record
from .data import (
    MAX_FIT_SAMPLES,
    MIN_SAMPLES,
    OUTPUTS,
    IdentificationError,
    check_record,
    decimation,
    measured_frequencies,
    predict,
    record_from_model,
)
from .fit import STRATEGIES, FitOptions, frequency_start, identify
from .parameters import FITTABLE_SECTIONS, FitParameter, apply_values, fit_parameters
from .problem import DIFF_STEP, Problem, jacobian
from .report import FitResult, prediction_errors, validate

__all__ = [
    'OUTPUTS', 'FITTABLE_SECTIONS', 'MIN_SAMPLES', 'IdentificationError', 'Record',
    'FitParameter', 'fit_parameters', 'apply_values', 'check_record', 'predict', 'Problem',
    'FitOptions', 'FitResult', 'identify', 'validate', 'prediction_errors',
    'measured_frequencies', 'frequency_start', 'STRATEGIES', 'record_from_model', 'jacobian',
    'DIFF_STEP', 'MAX_FIT_SAMPLES', 'decimation',
]
