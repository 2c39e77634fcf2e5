# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Work in steps (worm_gear_sim._support.stepwise): a step's preparation run a slice at a time
gives what the whole run gives, bit for bit: the compensator, the prepared pipeline, and live
adaptation whose steps are prepared in slices on the sample thread (the node) against the
twin, which prepares each at once."""

from __future__ import annotations

import numpy as np
import pytest

from worm_gear_sim._support.stepwise import Stepwise, run_steps
from worm_gear_sim.adaptation.live import LiveAdaptation, in_slices
from worm_gear_sim.compensation.streaming import Compensator
from worm_gear_sim.config.usable import Config
from worm_gear_sim.realtime.predictor import RealtimePredictor
from worm_gear_sim.studies.adaptation_twin import prepare_start, run_twin


def _steps(n: int, fail: bool = False):
    for _ in range(n):
        yield
    if fail:
        raise ValueError('refused on the way')
    return n


def test_stepwise_runs_a_slice_at_a_time_and_keeps_the_result_or_the_error():
    s = Stepwise(_steps(3), budget=0.0)
    with pytest.raises(RuntimeError):
        s.result()
    assert not s.advance() and not s.advance() and not s.advance()   # one step each
    assert s.advance() and s.done() and s.result() == 3 and s.slices == 4
    assert Stepwise(_steps(50), budget=10.0).advance()               # within the budget
    bad = Stepwise(_steps(1, fail=True), budget=10.0)
    assert bad.advance() and bad.done()
    with pytest.raises(ValueError, match='refused'):
        bad.result()
    cut = Stepwise(_steps(5), budget=0.0)
    cut.advance()
    cut.cancel()
    assert cut.done()
    with pytest.raises(RuntimeError):
        cut.result()
    assert run_steps(_steps(4)) == 4


def test_a_compensator_designed_in_steps_is_the_same():
    cfg = Config().replace({'mesh.backlash': 3e-4, 'mesh.worm_error_harmonics': [1e-5, 0.0]})
    whole = Compensator(cfg)
    steps = Compensator.design_steps(cfg)
    n = 0
    while True:
        try:
            next(steps)
            n += 1
        except StopIteration as stop:
            cut = stop.value
            break
    assert n >= 4                                         # cut, not one piece
    for name in ('_W', '_tau', '_flank', 'mode_frequency_hz', 'backlash_inverse'):
        assert np.array_equal(getattr(cut, name), getattr(whole, name)), name
    ts = np.arange(200) * 1e-3
    x = 0.2 * np.sin(3.0 * ts)
    assert [cut.update(t, v) for t, v in zip(ts, x)] == [whole.update(t, v) for t, v in zip(ts, x)]


def test_adaptation_prepared_in_slices_equals_the_twin():
    """The node's order (reference, predictions, the step, then the encoder samples of the
    corrections released), each step's preparation one piece per sample (budget 0: the
    slowest cut): the same corrections, steps, estimate and model in use as the twin."""
    plant = Config().replace({'load.output_torque': 3.0, 'mesh.backlash': 4e-4,
                              'load.output_viscous_coefficient': 10.0})
    start = Config().replace({'adaptation.enabled': True, 'node.compensation_applied': True,
                              'adaptation.window': 0.3, 'adaptation.step_interval': 0.1,
                              'adaptation.max_step': 0.05})
    twin = run_twin(plant, start, 'sector', 1.5, seed=3, record=True)
    pred_cfg = prepare_start(start)                  # the start set as the twin runs it
    pred = RealtimePredictor(pred_cfg, apply_compensation=True,
                             base_ns=twin.record[0][0])
    live = LiveAdaptation(pred, pred_cfg.node.joint_names[1:], submit=in_slices(0.0))
    antenna = [pred_cfg.node.joint_names[3]]
    slices, deltas = 0, []
    for ns, ref, got in twin.record:
        out = pred.push(ns, ref)
        for p in out.predictions:
            live.predicted(p.stamp_ns, p.theta)
        if out.predictions:
            live.step(out.predictions[-1].stamp_ns)
        if live.pending is not None:
            slices = max(slices, live.pending.future.slices)
        deltas += [c.delta for c in out.corrections]
        for stamp, meas, _ in got:
            live.measured(stamp, antenna, [meas])
    assert live.counters['late_steps'] == 0 and slices >= 3
    assert live.counters['switches'] == len(twin.steps) > 0
    assert deltas == [d for _, _, got in twin.record for _, _, d in got]
    assert live.estimates() == twin.estimates
    assert live.adapter.applied_values() == twin.in_use
