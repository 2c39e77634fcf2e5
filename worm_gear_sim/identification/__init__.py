# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Fit model parameters to measured records (pure core; figures in :mod:`.plot`).

:mod:`.data` (records, predictions, synthetic records), :mod:`.parameters` (``--fit`` keys,
bounds, the fitted coordinate), :mod:`.problem` (weighted residuals and Jacobian),
:mod:`.fit` (:func:`identify`), :mod:`.report` (intervals, verdict, held-out errors).  The
live model check is :mod:`worm_gear_sim.realtime.model_check`.  docs/identification.md.
"""

from typing import TYPE_CHECKING

from .._support.lazy import lazy_exports

#: public name -> the module that defines it (imported on first use: a user of one part,
#: e.g. observability, does not pay for the fit's scipy.stats and Dask)
_EXPORTS: dict[str, str] = {
    'Record': '..records',
    'IdentificationError': '.data',
    'MAX_FIT_SAMPLES': '.data',
    'MIN_SAMPLES': '.data',
    'OUTPUTS': '.data',
    'check_record': '.data',
    'decimation': '.data',
    'measured_frequencies': '.data',
    'predict': '.data',
    'record_from_model': '.data',
    'FitOptions': '.fit',
    'STRATEGIES': '.fit',
    'frequency_start': '.fit',
    'identify': '.fit',
    'FITTABLE_SECTIONS': '.parameters',
    'FitParameter': '.parameters',
    'apply_values': '.parameters',
    'fit_parameters': '.parameters',
    'DIFF_STEP': '.problem',
    'Problem': '.problem',
    'jacobian': '.problem',
    'FitResult': '.report',
    'prediction_errors': '.report',
    'validate': '.report',
}

__all__ = [
    'OUTPUTS', 'FITTABLE_SECTIONS', 'MIN_SAMPLES', 'IdentificationError', 'Record',
    'FitParameter', 'fit_parameters', 'apply_values', 'check_record', 'predict', 'Problem',
    'FitOptions', 'FitResult', 'identify', 'validate', 'prediction_errors',
    'measured_frequencies', 'frequency_start', 'STRATEGIES', 'record_from_model', 'jacobian',
    'DIFF_STEP', 'MAX_FIT_SAMPLES', 'decimation',
]

if TYPE_CHECKING:  # static analysers see the eager imports
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

__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
