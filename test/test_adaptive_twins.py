# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The node's paths and their offline twins with the variable step
(``integrator.method: adaptive``): the stamped path's corrections equal feedforward_series
and its predictions the batch simulator's on the same tick boundaries, whatever the arrival;
live adaptation equals its twin.  The step controller's state carries over from tick to
tick, so each path must end its steps on the same ticks as its twin for these to hold."""

from __future__ import annotations

import numpy as np
from test_estimator import _replay, load_drag_case
from test_predictor import EPOCH, LOADED, MS, slew

from worm_gear_sim import Config, SampledProfile
from worm_gear_sim.dynamics.simulation import Simulator
from worm_gear_sim.realtime import RealtimePredictor, feedforward_series
from worm_gear_sim.studies.adaptation_twin import run_twin

ADAPTIVE = {'integrator.method': 'adaptive'}


def _bursts(p: RealtimePredictor, st, x, rng: np.random.Generator) -> list:
    """Push the samples in bursts of 1-12 (the executor stalled); every Output."""
    outs, i = [], 0
    while i < st.size:
        n = int(rng.integers(1, 13))
        outs += [p.push(int(st[j]), float(x[j]), now_ns=int(st[i]) + 5 * MS)
                 for j in range(i, min(i + n, st.size))]
        i += n
    return outs


def test_adaptive_stamped_path_equals_feedforward_series_for_any_arrival():
    """A jittered slew with a reversal, pushed one by one and in bursts: the corrections
    equal feedforward_series bit for bit, and the predictions of both arrivals are the same
    (the simulator steps to each sample's stamp, whenever it came); the variable step ran
    (its statistics count its steps and the friction events it located)."""
    cfg = Config().replace({'compensation.preview_time': 0.002, **LOADED, **ADAPTIVE})
    rng = np.random.default_rng(11)
    st, x = slew(200, rng, jitter_ns=300_000)
    runs = []
    for bursts in (False, True):
        p = RealtimePredictor(cfg, apply_compensation=True)
        outs = _bursts(p, st, x, rng) if bursts else \
            [p.push(int(s), float(v), now_ns=int(s)) for s, v in zip(st, x)]
        outs.append(p.finish())
        assert all(o.rejected is None for o in outs[:-1])
        runs.append(([c.delta for o in outs for c in o.corrections],
                     [(q.stamp_ns, q.theta) for o in outs for q in o.predictions]))
    want = feedforward_series(cfg, st, x)
    np.testing.assert_array_equal(runs[0][0], want)
    np.testing.assert_array_equal(runs[1][0], want)
    assert runs[0][1] == runs[1][1] and len(runs[0][1]) >= 190
    assert p.sim.stats['adaptive_steps'] > 0 and p.sim.stats['located_events'] > 0


def test_adaptive_predictions_equal_the_batch_simulator_on_the_same_ticks():
    """Samples on the 1 kHz grid: the pipeline's predictions equal Simulator.run of the
    same samples joined by straight lines, recorded every tick (the batch steps end on
    the same ticks, with the same controller)."""
    cfg = Config().replace({**LOADED, **ADAPTIVE})
    st, x = slew(150, np.random.default_rng(4), jitter_ns=0)
    p = RealtimePredictor(cfg)
    preds = [q for s, v in zip(st, x) for q in p.push(int(s), float(v), now_ns=int(s)).predictions]
    assert [q.stamp_ns for q in preds] == st[:len(preds)].tolist() and len(preds) >= 140
    t = (st - EPOCH) * 1e-9
    per_tick = int(round(1e-3 / cfg.integrator.time_step))
    sim = Simulator(cfg, theta1=float(x[0]))
    traj = sim.run(SampledProfile(t, x), t[len(preds) - 1], record_every=per_tick)
    got = np.array([q.theta for q in preds])
    want = np.column_stack([traj.theta2, traj.theta3, traj.theta4])[:len(preds)]
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    assert np.ptp(want[:, 2]) > 1e-3                          # the antenna moved


def test_adaptive_live_adaptation_equals_its_twin():
    """The twin's record handed over as a node gets it (each encoder sample 30 ms after its
    prediction), with the variable step in the pipeline and in the plant: the corrections,
    the estimates, the values in use and the counters equal the twin's."""
    base = Config().replace(ADAPTIVE)
    plant, start = load_drag_case(base, 0.3, 0.005)
    twin = run_twin(plant, start, 'sector', 1.0, seed=3, record=True)
    assert twin.counters['late_samples'] == 0 and len(twin.steps) >= 2
    live, deltas = _replay(start, twin.record, lag=30)
    assert deltas == [d for _, _, got in twin.record for _, _, d in got]
    assert live.estimates() == twin.estimates and live.adapter.applied_values() == twin.in_use
    for key in ('used', 'switches', 'refusals', 'rejected', 'late_samples', 'late_steps'):
        assert live.counters[key] == twin.counters[key], key
    assert live.predictor.config.integrator.method == 'adaptive'
