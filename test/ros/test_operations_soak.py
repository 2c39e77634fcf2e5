# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The operations soak (benchmarks/bench_operations.py) for 45 s: the node and a plant node
as processes, this process the operator (pauses, parameter sets, toggles, encoder glitches
and a flood, a write and a restart of the node from the file written, trajectories
replaced).  No process ends by itself, no traceback, no silent reset; every stamped
reference sent outside the pauses is answered but those in flight when the node was stopped
for its restart and those sent to the restarted node before its first answer (its
publisher not yet matched by the plant's subscription); the learnt load is within 10 % of
the plant's after every operation; the node compensates the trajectories."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

pytest.importorskip('rclpy')

pytestmark = pytest.mark.ros

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / 'benchmarks'))


def test_the_node_in_operation_keeps_its_invariants(ros_dds_context, ros_subprocess_env,
                                                    tmp_path):
    from bench_operations import run_operations
    lines: list[str] = []
    f = run_operations(0.75, context=ros_dds_context, env=ros_subprocess_env,
                       workdir=tmp_path, log=lines.append)
    text = '\n'.join(lines) + f'\n{f}'
    assert 'stopped' not in f, text
    assert f['crashes'] == 0 and f['tracebacks'] == 0, text
    assert f['operations'] >= 8 and f['restarts_of_node'] >= 1, text
    assert f['silent_resets'] == 0, text
    assert f['failed_calls'] == 0, text
    assert f['sent'] > 10_000, text
    assert f['answered'] + f['in_flight'] + f['before_first_answer'] == f['sent'], text
    assert f['load_within'] == f['operations'], f['loads']
    assert f['trajectories_sent'] >= 5 and f['trajectories_answered'] >= 1, text
