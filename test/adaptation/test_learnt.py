# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""What live adaptation learnt is kept through what an operator does (the core's
:class:`LiveAdaptation`, streamed as the twin streams it): a parameter set that leaves the
estimator's inputs keeps everything; another keeps the estimate, its covariance and the
model in use of the keys it shares; an estimated key set explicitly restarts from the
operator's value; a key no longer estimated returns to the declared value, said; a reset
forgets, counted; counters never decrease; a stream resumed after a pause learns on."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worm_gear_sim.adaptation.layout import PRIOR_STD
from worm_gear_sim.adaptation.live import LiveAdaptation
from worm_gear_sim.adaptation.plant import EncoderPlant
from worm_gear_sim.config.usable import Config
from worm_gear_sim.realtime.predictor import RealtimePredictor
from worm_gear_sim.schema.validation import ConfigError
from worm_gear_sim.studies.adaptation_twin import BASE_NS, prepare_start, scenario

LOAD, DRAG, PLAY = ('load.output_torque', 'load.output_viscous_coefficient', 'mesh.backlash')
START = {'adaptation.keys': [LOAD, DRAG], 'adaptation.window': 0.3,
         'adaptation.step_interval': 0.1, 'adaptation.max_step': 0.002}


class Stream:
    """The twin's loop (:func:`~worm_gear_sim.studies.adaptation_twin.run_twin`) that an operator
    can interrupt: a sector scan through the pipeline, the adaptation and a plant with a
    load and drag; ``adapt`` False: the adaptation is not fed (paused)."""

    def __init__(self, start: dict, seconds: float = 6.0) -> None:
        self.cfg = prepare_start(Config().replace(start))
        plant = Config().replace({LOAD: 3.0, DRAG: 10.0})
        self.t, self.x = scenario(self.cfg, 'sector', seconds)
        self.pred = RealtimePredictor(self.cfg, apply_compensation=True, base_ns=BASE_NS)
        self.live = LiveAdaptation(self.pred, self.cfg.node.joint_names[1:])
        self.plant = EncoderPlant(plant, float(self.x[0]), noise=1e-6, encoder_bits=20,
                                  seed=5)
        self.k = 0
        self.names = self.cfg.node.joint_names[1:][2:]

    def run(self, seconds: float, adapt: bool = True) -> None:
        live, pred = self.live, self.pred
        for _ in range(int(round(seconds * self.cfg.node.publish_rate_hz))):
            ns = BASE_NS + int(round(self.t[self.k] * 1e9))
            out = pred.push(ns, float(self.x[self.k]))
            self.k += 1
            if adapt:
                for p in out.predictions:
                    live.predicted(p.stamp_ns, p.theta)
                if out.predictions:
                    live.step(out.predictions[-1].stamp_ns)
            for c in out.corrections:
                _, meas = self.plant.command((c.stamp_ns - BASE_NS) * 1e-9,
                                             c.theta1_ref + c.delta)
                if adapt:
                    live.measured(c.stamp_ns, self.names, [meas])


@pytest.fixture
def learnt() -> Stream:
    """0.8 s into the scan: steps applied, the target not reached yet."""
    s = Stream(START)
    s.run(0.8)
    assert s.live.counters['switches'] >= 2 and s.live.adapter.target is not None
    return s


def snapshot(live: LiveAdaptation) -> dict:
    ad = live.adapter
    return {'theta': ad.theta.copy(), 'P': ad.P.copy(), 'in_use': ad.applied_values(),
            'nominal': ad.nominal_x.copy(), 'counters': dict(live.counters),
            'target': None if ad.target is None else ad.target.copy(), 'keys': ad.layout.keys}


def assert_counters_kept(before: dict, live: LiveAdaptation) -> None:
    for k, v in before.items():
        assert live.counters[k] >= v, k


@pytest.mark.parametrize('overrides', [
    {'adaptation.params_file': 'worm_gear_sim_adapted.yaml'},      # its current value
    {'node.max_command_jump': 2.0}, {'compensation.preview_time': 0.004},
    {'adaptation.sample_delay': 0.06}])
def test_a_set_the_estimator_does_not_read_keeps_everything(learnt, overrides):
    s = learnt
    live = s.live
    before, adapter = snapshot(live), live.adapter
    assert before['in_use'][LOAD] > 0.5                # the model in use is not nominal
    assert live.reconfigure(overrides) == []
    assert live.adapter is adapter                     # estimate, covariance, window, target
    assert s.pred.config.load.output_torque == before['in_use'][LOAD]
    assert s.pred.config.load.output_viscous_coefficient == before['in_use'][DRAG]
    for key, value in overrides.items():
        assert s.pred.config.to_flat_dict()[key] == value
    assert live.declared.load.output_torque == 0.0     # the operator's set: the nominal
    assert_counters_kept(before['counters'], live)
    assert live.counters['parameter_sets'] == before['counters']['parameter_sets'] + 1
    used, switches = live.counters['used'], live.counters['switches']
    s.run(0.5)                                # on towards the kept target
    assert live.counters['used'] > used and live.counters['switches'] > switches


def test_a_set_of_another_model_parameter_keeps_estimate_covariance_and_model_in_use(learnt):
    s = learnt
    live = s.live
    before = snapshot(live)
    mu = s.cfg.friction.mu_kinetic * 1.05
    assert live.reconfigure({'friction.mu_kinetic': mu}) == []
    ad = live.adapter
    np.testing.assert_array_equal(ad.theta, before['theta'])
    np.testing.assert_array_equal(ad.P, before['P'])
    np.testing.assert_array_equal(ad.nominal_x, before['nominal'])
    assert ad.applied_values() == before['in_use']
    assert (ad.target is None) == (before['target'] is None)
    cfg = s.pred.config
    assert cfg.friction.mu_kinetic == mu and cfg.load.output_torque == before['in_use'][LOAD]
    assert_counters_kept(before['counters'], live)
    used, switches = live.counters['used'], live.counters['switches']
    s.run(0.5)
    assert live.counters['used'] > used and live.counters['switches'] > switches


def test_an_estimated_key_set_explicitly_restarts_from_the_operators_value(learnt):
    """The rule: the operator's value becomes the key's nominal value and its value in
    use, its estimate restarts there with the prior, uncorrelated; the other keys keep
    theirs (even when the operator sets the value the key already had)."""
    for value in (1.0, 0.0):
        s = learnt
        live = s.live
        before = snapshot(live)
        notes = live.reconfigure({LOAD: value})
        assert len(notes) == 1 and LOAD in notes[0] and 'restarts' in notes[0]
        ad = live.adapter
        lay = ad.layout
        i, j = lay.i_load, lay.i_drag
        assert s.pred.config.load.output_torque == value == ad.theta[i] == ad.nominal_x[i]
        assert ad.P[i, i] == PRIOR_STD[LOAD] ** 2 and ad.P[i, j] == ad.P[j, i] == 0.0
        assert ad.theta[j] == before['theta'][j] and ad.P[j, j] == before['P'][j, j]
        assert ad.applied_values()[DRAG] == before['in_use'][DRAG] \
            == s.pred.config.load.output_viscous_coefficient
        assert_counters_kept(before['counters'], live)


def test_a_change_of_the_keys_estimated_carries_what_both_share(learnt):
    s = learnt
    live = s.live
    before = snapshot(live)
    old = live.adapter.layout
    notes = live.reconfigure({'adaptation.keys': [LOAD, PLAY]})
    ad = live.adapter
    assert ad.layout.keys == (LOAD, PLAY)
    i_old, i_new = old.i_load, ad.layout.i_load
    assert ad.theta[i_new] == before['theta'][i_old] and \
        ad.P[i_new, i_new] == before['P'][i_old, i_old]
    assert s.pred.config.load.output_torque == before['in_use'][LOAD]
    # the drag is no longer estimated: back to the declared value, said with what it was
    assert s.pred.config.load.output_viscous_coefficient == 0.0
    assert len(notes) == 1 and DRAG in notes[0] and 'no longer estimated' in notes[0]
    assert f'{before["in_use"][DRAG]:.6g}' in notes[0]
    # the play, newly estimated, starts at the declared value with its prior
    k = ad.layout.i_play
    assert ad.theta[k] == 0.0 and ad.P[k, k] == PRIOR_STD[PLAY] ** 2
    assert_counters_kept(before['counters'], live)


def test_orders_of_a_harmonic_key_carry_the_orders_both_estimate():
    worm = 'mesh.worm_error_harmonics'
    s = Stream({**START, 'adaptation.keys': [LOAD, worm], 'adaptation.worm_error_orders': 2})
    s.run(0.5)
    live = s.live
    ad = live.adapter
    # a learnt state of the harmonics (their own values, not a stream's: known answers)
    ad.theta[ad.layout.worm0:ad.layout.worm0 + 4] = [1e-5, 2e-5, 3e-5, 4e-5]
    ad.P[ad.layout.worm0, ad.layout.worm0] = 1e-12
    for orders, kept in ((3, 4), (1, 2)):
        before = snapshot(live)
        old = live.adapter.layout
        notes = live.reconfigure({'adaptation.worm_error_orders': orders})
        lay = live.adapter.layout
        assert lay.worm_orders == orders
        np.testing.assert_array_equal(live.adapter.theta[lay.worm0:lay.worm0 + kept],
                                      before['theta'][old.worm0:old.worm0 + kept])
        assert live.adapter.P[lay.worm0, lay.worm0] == 1e-12
        assert live.adapter.theta[lay.i_load] == before['theta'][old.i_load]
        assert ('fewer orders' in ' '.join(notes)) == (orders < old.worm_orders)


def test_a_set_unusable_with_the_learnt_values_changes_nothing(learnt):
    s = learnt
    live = s.live
    before = snapshot(live)
    cfg = s.pred.config
    with pytest.raises(ConfigError):
        live.reconfigure({'mesh.backlash': 1.0})
    assert s.pred.config is cfg and live.adapter.applied_values() == before['in_use']
    np.testing.assert_array_equal(live.adapter.theta, before['theta'])


def test_a_reset_forgets_explicitly_and_is_counted(learnt):
    s = learnt
    live = s.live
    before = snapshot(live)
    line = live.reset()
    assert 'reset' in line and LOAD in line
    ad = live.adapter
    assert s.pred.config.load.output_torque == 0.0 == ad.applied_values()[LOAD]
    np.testing.assert_array_equal(ad.theta, ad.nominal_x)
    np.testing.assert_array_equal(ad.P, np.diag(ad.layout.prior_std() ** 2))
    assert ad.target is None and live.pending is None and not live.waiting
    assert live.counters['resets'] == 1
    assert_counters_kept(before['counters'], live)


def test_a_paused_adaptation_resumes_with_its_estimate_and_learns_on(learnt):
    """Not fed for 1 s of stream (the node's adaptation.enabled false): the model in use
    stays as it was; fed again, samples are used and steps applied at once, from the
    estimate it had."""
    s = learnt
    live = s.live
    before = snapshot(live)
    s.run(1.0, adapt=False)
    assert s.pred.config.load.output_torque == before['in_use'][LOAD]
    s.run(0.6)
    assert live.counters['used'] > before['counters']['used'] + 100
    assert live.counters['switches'] > before['counters']['switches']
    assert live.counters['restarts'] == before['counters']['restarts']
    assert math.isfinite(live.estimates()[LOAD])
