# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The bounded teardown (worm_gear_sim.ros.teardown): a teardown that hangs in C code holding
the GIL, as Fast DDS 2.14 does in its participant's destruction when another participant
leaves at the same moment, ends the process with the status it would have had, every thread's
stack printed first; a teardown that finishes disarms the deadline; every entry point of the
ROS wing shuts rclpy down under one."""

from __future__ import annotations

import ast
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
#: A teardown that hangs: a C call that holds the GIL for two minutes.
HANG = 'import ctypes; ctypes.PyDLL(None).sleep(120)'


def _child(body: str) -> tuple[subprocess.CompletedProcess, float]:
    code = f'import sys\nsys.path.insert(0, {str(ROOT)!r})\n' \
           f'from worm_gear_sim.ros.teardown import teardown_deadline\n{body}\n'
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          timeout=60)
    return proc, time.monotonic() - t0


@pytest.mark.parametrize('rc', [0, 3])
def test_a_hung_teardown_ends_with_its_status_and_the_stacks(rc):
    proc, took = _child(f'with teardown_deadline({rc}, seconds=1.0):\n    {HANG}\n'
                        f'print("not reached")')
    assert proc.returncode == rc, proc.stderr
    assert took < 30, took                      # the hang alone lasts 120 s
    assert 'not reached' not in proc.stdout
    assert 'most recent call first' in proc.stderr and 'line 5 in <module>' in proc.stderr, \
        proc.stderr                             # the hang's line: header 3, with 4


def test_a_hang_while_an_error_propagates_ends_with_status_1():
    proc, took = _child('try:\n    raise RuntimeError("the node failed")\nfinally:\n'
                        f'    with teardown_deadline(seconds=1.0):\n        {HANG}')
    assert proc.returncode == 1, proc.stderr
    assert took < 30, took


def test_a_teardown_that_ends_disarms_the_deadline():
    proc, _ = _child('import time\nwith teardown_deadline(3, seconds=0.3):\n    pass\n'
                     'time.sleep(1.5)\nprint("alive")')
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == 'alive'
    assert proc.stderr == ''


def _inside_deadline(tree: ast.AST) -> list[int]:
    """Lines of ``rclpy.try_shutdown()`` calls outside a ``with teardown_deadline(...)``."""
    bad: list[int] = []

    def visit(node: ast.AST, guarded: bool) -> None:
        if isinstance(node, ast.With) and any(
                isinstance(i.context_expr, ast.Call) and
                getattr(i.context_expr.func, 'id', '') == 'teardown_deadline'
                for i in node.items):
            guarded = True
        if isinstance(node, ast.Call) and getattr(node.func, 'attr', '') == 'try_shutdown' \
                and not guarded:
            bad.append(node.lineno)
        for child in ast.iter_child_nodes(node):
            visit(child, guarded)
    visit(tree, False)
    return bad


def test_every_entry_point_shuts_rclpy_down_under_a_deadline():
    files = sorted((ROOT / 'worm_gear_sim' / 'ros').glob('*.py'))
    outside = {f.name: lines for f in files
               if (lines := _inside_deadline(ast.parse(f.read_text())))}
    assert outside == {}, outside
    assert sum('teardown_deadline(' in f.read_text() for f in files) >= 7
