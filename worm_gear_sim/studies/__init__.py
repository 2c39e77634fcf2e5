# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Offline studies: the paper's Sec. 3 experiment and Sec. 4 parametric sweeps, and the
evaluation of the feed-forward compensator.

Pure study logic (no argparse, no rclpy, no plotting), one module per job:

* :mod:`.cases` -- the cases of a study (paper Figs. 12-18, any-parameter sweeps, --compare);
* :mod:`.metrics` -- oscillation metrics of one run (definitions in docs/studies.md), CSV rows;
* :mod:`.engine` -- running one case, many cases serially or on Dask;
* :mod:`.experiment` -- the paper's Sec. 3 experiment (Figs. 9-11);
* :mod:`.compensation_eval` -- scenarios and metrics of the compensator's evaluation;
* :mod:`.demo_moves` -- the demo servo's patterns and its move-by-move metrics.
"""

from .cases import (
    COMPARE_SEP,
    ENVELOPE_COLUMNS,
    PAPER_STUDIES,
    Case,
    Study,
    envelope_rows,
    module_overrides,
    paper_study,
    param_study,
    parse_values,
)
from .engine import (
    ENGINES,
    WORKER_ENV,
    case_config,
    local_cluster_client,
    run_case,
    run_cases,
    warm_up,
)
from .experiment import EXPERIMENT_COLUMNS, experiment_cases, experiment_table
from .metrics import (
    METRIC_COLUMNS,
    dominant_frequency,
    equilibrium,
    move_end_time,
    oscillation_metrics,
    rows_to_csv,
    zero_crossing_frequency,
)

__all__ = [
    'Case', 'Study', 'PAPER_STUDIES', 'METRIC_COLUMNS', 'move_end_time', 'equilibrium',
    'oscillation_metrics', 'dominant_frequency', 'zero_crossing_frequency', 'run_case',
    'run_cases', 'case_config', 'paper_study', 'param_study', 'module_overrides',
    'experiment_cases', 'experiment_table', 'EXPERIMENT_COLUMNS', 'parse_values',
    'envelope_rows', 'ENVELOPE_COLUMNS', 'COMPARE_SEP', 'rows_to_csv', 'warm_up',
    'local_cluster_client', 'WORKER_ENV', 'ENGINES',
]
