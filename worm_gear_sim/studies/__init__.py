# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Offline studies: the paper's Sec. 3 experiment and Sec. 4 parametric sweeps, and the
evaluation of the feed-forward compensator (no argparse, no rclpy; matplotlib only in
:mod:`.figures`).

:mod:`.cases`, :mod:`.metrics`, :mod:`.engine`, :mod:`.experiment`,
:mod:`.compensation_eval`, :mod:`.demo_moves`, :mod:`.pass_report`; docs/studies.md.
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
    case_config,
    run_case,
    run_cases,
)
from .experiment import EXPERIMENT_COLUMNS, experiment_cases, experiment_table
from .metrics import (
    METRIC_COLUMNS,
    equilibrium,
    move_end_time,
    oscillation_metrics,
    rows_to_csv,
    zero_crossing_frequency,
)

__all__ = [
    'Case', 'Study', 'PAPER_STUDIES', 'METRIC_COLUMNS', 'move_end_time', 'equilibrium',
    'oscillation_metrics', 'zero_crossing_frequency', 'run_case',
    'run_cases', 'case_config', 'paper_study', 'param_study', 'module_overrides',
    'experiment_cases', 'experiment_table', 'EXPERIMENT_COLUMNS', 'parse_values',
    'envelope_rows', 'ENVELOPE_COLUMNS', 'COMPARE_SEP', 'rows_to_csv', 'ENGINES',
]
