# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Long offline runs are refused up front when they would not fit in memory,
and stream in chunks with bounded memory (Simulator.iter_run, simulate_to_csv)."""

import tracemalloc

import numpy as np
import pytest

from worm_gear_sim.config.usable import Config
from worm_gear_sim.dynamics.profiles import make_profile
from worm_gear_sim.dynamics.simulation import Simulator, simulate, simulate_to_csv
from worm_gear_sim.dynamics.trajectory import ROW_BYTES, Trajectory

FIELDS = ('t', 'theta1', 'theta1_dot', 'theta', 'omega', 'alpha', 'aux')

DT = Config().integrator.time_step          # the default step


def test_iter_run_chunks_equal_run_bit_for_bit():
    cfg = Config()
    prof = make_profile(cfg.input)
    whole = Simulator(cfg).run(prof, 0.03, record_every=3)
    parts = list(Simulator(cfg).iter_run(prof, 0.03, record_every=3, chunk_steps=1000))
    steps = round(0.03 / DT)                  # chunks of 999 steps (a multiple of 3)
    assert len(parts) == -(-steps // 999) > 1 and all(len(p.t) <= 1000 // 3 + 1 for p in parts)
    joined = Trajectory.concatenate(parts)
    for f in FIELDS:
        assert np.array_equal(getattr(joined, f), getattr(whole, f)), f


def test_iter_run_without_steps_yields_the_current_state():
    sim = Simulator(Config())
    parts = list(sim.iter_run(make_profile(Config().input), 0.0))
    assert len(parts) == 1 and len(parts[0].t) == 1 and parts[0].t[0] == 0.0


def test_streamed_csv_equals_in_memory_csv(tmp_path):
    cfg = Config().replace({'input.end_time': 0.025})
    a, b = tmp_path / 'a.csv', tmp_path / 'b.csv'
    simulate(cfg, record_every=2).to_csv(a, header_comment='x')
    thin = simulate_to_csv(cfg, b, record_every=2, header_comment='x', keep_rows=100,
                           chunk_steps=512)
    assert a.read_text() == b.read_text()
    # the thinned copy: every k-th row plus the last, at most ~keep_rows rows
    full = simulate(cfg, record_every=2)
    assert 90 <= len(thin.t) <= 102
    assert thin.t[-1] == full.t[-1] and thin.t[0] == 0.0
    k = int(round(thin.t[1] / (full.t[1] - full.t[0])))
    assert np.array_equal(thin.theta[:-1], full.theta[::k][:len(thin.t) - 1])
    assert thin.stats['steps'] == round(0.025 / DT)


def test_huge_in_memory_run_is_refused_up_front():
    """simulate(t_end=1e4) would record 2.5e9 rows (400 GB at the default 4 us): refused
    at once, naming the estimate, the limit and the ways out; nothing allocated, nothing
    integrated."""
    cfg = Config()
    tracemalloc.start()
    try:
        with pytest.raises(ValueError) as exc:
            simulate(cfg, t_end=1e4)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    msg = str(exc.value)
    assert 'GB' in msg and 'max_bytes' in msg and 'simulate_to_csv' in msg
    assert f'{round(1e4 / DT) * ROW_BYTES / 1e9:.3g} GB' in msg
    assert peak < 20e6
    # the limit is the caller's: a small run under a tiny limit is refused too
    with pytest.raises(ValueError, match='max_bytes'):
        simulate(cfg, t_end=0.01, max_bytes=1000)


def test_streaming_memory_does_not_grow_with_duration(tmp_path):
    """Peak Python allocation of simulate_to_csv for a 4x longer run stays the same (bounded
    by the chunk and the thinned copy), while an in-memory run grows with it."""
    cfg = Config()

    def peak(t_end):
        tracemalloc.start()
        try:
            simulate_to_csv(cfg, tmp_path / 'run.csv', t_end=t_end, keep_rows=1000,
                            chunk_steps=1024)
            return tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()

    # 0.025 s and 0.1 s (25 and 100 chunks; was 0.05 and 0.2 s, at twice the cost)
    short, long_ = peak(0.025), peak(0.1)
    assert long_ < 1.3 * short + 200_000, (short, long_)
    assert long_ < 0.5 * (0.1 / DT) * ROW_BYTES           # below the whole run (4 MB)
    lines = sum(1 for line in open(tmp_path / 'run.csv') if not line.startswith('#'))
    assert lines == round(0.1 / DT) + 1 + 1                # header line + every row


def test_a_record_step_keeps_a_row_per_record_dt(tmp_path):
    """``record_dt`` [s]: a row every whole number of steps nearest to it, in memory and
    streamed alike (the CLI's --output-rate follows the same rule)."""
    from worm_gear_sim.dynamics.simulation import record_stride
    cfg = Config().replace({'input.end_time': 0.03})
    a, b = tmp_path / 'a.csv', tmp_path / 'b.csv'
    mem = simulate(cfg, record_dt=1e-3)
    assert np.allclose(np.diff(mem.t), 1e-3) and len(mem.t) == 31
    mem.to_csv(a)
    simulate_to_csv(cfg, b, record_dt=1e-3, chunk_steps=512)
    assert a.read_text() == b.read_text()
    assert record_stride(DT, 1e-4) == 25 and record_stride(DT, 0.0) == 1
    assert record_stride(DT, 3.9e-6) == 1 and record_stride(DT, None, 7) == 7
    with pytest.raises(ValueError, match='record_dt'):
        record_stride(DT, float('nan'))


def test_the_readme_long_run_writes_a_few_megabytes():
    """The README's streamed example: a few MB of CSV (it was every 4 us step of 600 s,
    ~50 GB), read from the README's own call."""
    import ast
    import re
    from pathlib import Path

    from worm_gear_sim.dynamics.simulation import record_stride
    from worm_gear_sim.dynamics.trajectory import csv_bytes_estimate
    readme = (Path(__file__).resolve().parents[2] / 'README.md').read_text()
    line = next(ln for ln in re.findall(r'^simulate_to_csv\(.*$', readme, re.M))
    call = ast.parse(line.split('#')[0].strip()).body[0].value
    kw = {k.arg: ast.literal_eval(k.value) for k in call.keywords}
    stride = record_stride(DT, kw.get('record_dt'), kw.get('record_every', 1))
    rows = int(kw['t_end'] / DT) // stride + 1
    assert csv_bytes_estimate(rows) <= 10e6, (kw, rows)
    assert kw['t_end'] / DT <= 2e7       # steps: seconds of computation, not minutes
