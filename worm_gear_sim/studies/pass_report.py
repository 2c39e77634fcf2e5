# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""What a tracking pass reports, the same from the command line (``worm-gear-sim pass``) and
through the ROS nodes: the per-axis table, pass.csv and the figure pass.png of a pass
streamed as trajectories (:mod:`.tracking_pass`) and of a pass with live adaptation
(:mod:`.adaptive_pass`), with the values in use and the adaptation's counters."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..records import write_csv_columns
from .adaptive_pass import TAIL_S, AxisPass, tail_table
from .figures import plot_adaptive_pass, plot_pass
from .metrics import fmt_table
from .tracking_pass import PassResult

__all__ = ['PASS_COLUMNS', 'ADAPTIVE_COLUMNS', 'pass_table', 'write_pass', 'adaptive_table',
           'in_use_lines', 'write_adaptive_pass']

PASS_COLUMNS = [('joint', 'worm input joint', ''), ('rms_raw_urad', 'RMS raw [urad]', '.4g'),
                ('rms_compensated_urad', 'RMS comp. [urad]', '.4g'),
                ('max_raw_urad', 'max raw [urad]', '.4g'),
                ('max_compensated_urad', 'max comp. [urad]', '.4g'),
                ('rms_ratio', 'RMS ratio', '.4g')]
ADAPTIVE_COLUMNS = [('axis', 'axis', ''),
                    ('rms_uncompensated_urad', 'RMS uncomp. [urad]', '.4g'),
                    ('rms_nominal_urad', 'RMS nominal [urad]', '.4g'),
                    ('rms_adapted_urad', 'RMS adapting [urad]', '.4g'),
                    ('nominal_ratio', 'ratio nominal', '.4g'),
                    ('adapted_ratio', 'ratio adapting', '.4g')]


def pass_table(result: PassResult) -> str:
    """The pass's pointing error per axis (:data:`PASS_COLUMNS`) as a text table."""
    return fmt_table(result.table(), PASS_COLUMNS)


def write_pass(result: PassResult, out: Path, title: str) -> tuple[Path, Path]:
    """pass.csv (t, then per axis: antenna reference, raw and compensated error) and
    pass.png under ``out``."""
    names, cols = ['t'], [result.t]
    for j in result.raw_error:
        names += [f'{j}_antenna_reference', f'{j}_raw_error', f'{j}_compensated_error']
        cols += [result.reference[j], result.raw_error[j], result.compensated_error[j]]
    csv = write_csv_columns(out / 'pass.csv', names, np.column_stack(cols),
                            comment=f'{title}; SI units, rad')
    return csv, plot_pass(result, out / 'pass.png', title)


def adaptive_table(axes: list[AxisPass], seconds: float = TAIL_S) -> str:
    """The pointing error of each axis over the last ``seconds`` (:data:`ADAPTIVE_COLUMNS`)
    as a text table."""
    return fmt_table(tail_table(axes, seconds), ADAPTIVE_COLUMNS)


def in_use_lines(axes: list[AxisPass]) -> list[str]:
    """Per axis: the values in use at the end and the adaptation's counters."""
    lines = []
    for a in axes:
        c = a.run.counters
        lines.append(f'{a.name}: {c.get("switches", 0)} steps applied; '
                     f'samples used {c.get("used", 0)}, rejected {c.get("rejected", 0)}, '
                     f'late samples {c.get("late_samples", 0)}, late steps '
                     f'{c.get("late_steps", 0)}')
        lines += [f'  in use {k} = {v}' for k, v in a.run.in_use.items()]
    return lines


def write_adaptive_pass(axes: list[AxisPass], out: Path, title: str) -> tuple[Path, Path]:
    """pass.csv (t, then per axis: theta1_ref and the three pointing errors) and pass.png
    under ``out``."""
    names, cols = ['t'], [axes[0].t]
    for a in axes:
        names += [f'{a.name}_theta1_ref', f'{a.name}_uncompensated_error',
                  f'{a.name}_nominal_error', f'{a.name}_adapted_error']
        cols += [a.theta1_ref, a.uncompensated, a.nominal, a.adapted]
    csv = write_csv_columns(out / 'pass.csv', names, np.column_stack(cols),
                            comment=f'{title}; SI units, rad')
    return csv, plot_adaptive_pass(axes, out / 'pass.png', title)
