# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""An operator's sequence against invariants (hypothesis stateful testing, no rclpy): the
node's pipeline, model check and live adaptation with a drive that differs from the model
(test/operator_loop.py) through random sequences of stamped samples, pauses, late samples
after a stale hold, plain and blended parameter sets, toggles of the adaptation, resets,
encoder glitches (finite absurd values, NaN, a joint named twice, another drive, floods),
writes of the adapted parameters and a restart of the node from the file written.

After every action: no exception; every output finite; every reference answered; the
pipeline runs the declared set with the adapted values on top; the model in use never
returns to the declared set unless the action forgets (a reset, a set naming the key, the
key no longer estimated, a restart from a file); counters never decrease; a file written
reloads to the model in use; while nothing but samples streamed, the corrections and the
encoder equal the offline twin's bit for bit.

WORM_GEAR_SIM_OPERATIONS_EXAMPLES and WORM_GEAR_SIM_OPERATIONS_STEPS run it longer
(examples, and actions per example)."""

from __future__ import annotations

import os

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from hypothesis.stateful import (
    RuleBasedStateMachine,
    initialize,
    rule,
    run_state_machine_as_test,
)
from operator_loop import DRAG, GLITCHES, LOAD, PLAY, Operator

WORM = 'mesh.worm_error_harmonics'
EXAMPLES = int(os.environ.get('WORM_GEAR_SIM_OPERATIONS_EXAMPLES') or 50)
STEPS = int(os.environ.get('WORM_GEAR_SIM_OPERATIONS_STEPS') or 15)
#: sets the estimator does not read, and values they take
NEUTRAL = [('node.max_command_jump', [0.5, 1.0, 2.0]),
           ('compensation.preview_time', [0.0, 0.0025, 0.004]),
           ('adaptation.sample_delay', [0.03, 0.05, 0.08])]
KEYS = [[LOAD, DRAG, PLAY], [LOAD, DRAG], [LOAD, PLAY], [LOAD], [LOAD, DRAG, PLAY, WORM]]
ALL = frozenset({LOAD, DRAG, PLAY, WORM})


def machine(workdir):
    """The state machine on the templates made in ``workdir`` (a fresh node, and one
    1.2 s into the scan, steps applied: both checked against the twin)."""
    fresh = Operator(workdir)
    fresh.check()
    learnt = fresh.copy()
    learnt.samples(1200)
    learnt.check()
    assert learnt.live.counters['switches'] >= 2

    class OperatorSequence(RuleBasedStateMachine):
        op: Operator

        @initialize(start=st.sampled_from(['fresh', 'learnt']))
        def begin(self, start):
            self.op = (fresh if start == 'fresh' else learnt).copy()

        def _act(self, action, forgets=frozenset()):
            before = self.op.in_use()
            result = action()
            self.op.check(before, forgets)
            return result

        @rule(n=st.integers(1, 400))
        def samples(self, n):
            self._act(lambda: self.op.samples(n))

        @rule(seconds=st.floats(0.11, 0.6))
        def pause(self, seconds):
            self._act(lambda: self.op.pause(seconds))

        @rule(seconds=st.floats(0.11, 0.5), n=st.integers(1, 80))
        def late_samples(self, seconds, n):
            self._act(lambda: self.op.late(seconds, n))

        @rule(which=st.sampled_from(NEUTRAL), i=st.integers(0, 2),
              blend=st.sampled_from([0.0, 0.05]))
        def neutral_set(self, which, i, blend):
            key, values = which
            self._act(lambda: self._set({key: values[i]}, blend))

        @rule(factor=st.floats(0.97, 1.03), blend=st.sampled_from([0.0, 0.02, 0.1]))
        def model_set(self, factor, blend):
            mu = self.op.live.declared.friction.mu_kinetic * factor
            self._act(lambda: self._set({'friction.mu_kinetic': mu}, blend))

        @rule(key=st.sampled_from([LOAD, DRAG, PLAY]), share=st.floats(0.0, 1.0),
              blend=st.sampled_from([0.0, 0.05]))
        def estimated_key_set(self, key, share, blend):
            value = {LOAD: 4.0, DRAG: 40.0, PLAY: 1e-3}[key] * share
            self._act(lambda: self._set({key: value}, blend), frozenset({key}))

        @rule(keys=st.sampled_from(KEYS), orders=st.integers(1, 3))
        def keys_set(self, keys, orders):
            was = set(self.op.live.adapter.layout.keys)
            self._act(lambda: self._set({'adaptation.keys': keys,
                                         'adaptation.worm_error_orders': orders}),
                      frozenset(was - set(keys)))

        def _set(self, overrides, blend=0.0):
            self.op.parameter_set(overrides, blend)

        @rule()
        def toggle(self):
            self._act(lambda: self.op.parameter_set(
                {'adaptation.enabled': not self.op.enabled}))

        @rule()
        def reset(self):
            self._act(self.op.reset, ALL)

        @rule(kind=st.sampled_from(['value', 'duplicate', 'other', 'flood']),
              value=st.sampled_from(GLITCHES), count=st.integers(2, 40))
        def glitch(self, kind, value, count):
            op = self.op
            live = op.live
            theta, used = live.adapter.theta.copy(), live.counters['used']
            reasons = self._act(lambda: op.glitch(kind, value, count if kind == 'flood'
                                                  else 1))
            if kind != 'flood' and op.enabled and reasons:
                assert all(r is not None for r in reasons), reasons
                assert (live.adapter.theta == theta).all() and live.counters['used'] == used
            if kind == 'flood' and op.enabled and reasons:
                assert sum(r is None for r in reasons) <= 1, reasons

        @rule()
        def write(self):
            self._act(self.op.write)

        @rule()
        def restart_from_the_file(self):
            self._act(self.op.restart, ALL)
            op = self.op
            assert op.pred.config.to_flat_dict() == op.written

    return OperatorSequence


def test_an_operators_sequence_keeps_the_invariants(tmp_path):
    # derandomized, no example database: the same sequences on every run and machine
    run_state_machine_as_test(machine(tmp_path), settings=settings(
        max_examples=EXAMPLES, stateful_step_count=STEPS, deadline=None,
        derandomize=True, database=None, print_blob=False,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                               HealthCheck.filter_too_much]))


# ---- what the machine found, as plain tests -------------------------------------------------
def test_a_step_due_during_a_stale_hold_waits_and_the_late_samples_are_answered(tmp_path):
    """A step is decided; before its stamp the references stall in transport for 0.3 s
    (the stream is held as stale, its held predictions pass the step's stamp); then the
    sample held back arrives.  The step waits for the stream: it is swapped in with the
    first sample at its stamp, not on a held prediction (that swap ended the hold's
    retraction: the late samples were rejected as out of order, never answered)."""
    op = Operator(tmp_path)
    while op.live.pending is None:
        op.samples(1)
    op.late(0.3, 1)                # (asserts that the late sample is accepted)
    assert op.pred.counters['stale_retractions'] == 1
    switches = op.live.counters['switches']
    assert op.live.pending is not None
    op.samples(60)
    assert op.live.counters['switches'] == switches + 1
    assert op.live.counters['late_steps'] == 0
    op.check()


def test_a_late_sample_after_a_stale_hold_keeps_the_estimate(tmp_path):
    """1.5 s into the scan the references stall for 0.2 s, then the 50 held back arrive:
    the adaptation drops the held predictions and goes on with its estimate (it restarted
    from the prior: the prediction went back)."""
    op = Operator(tmp_path)
    op.samples(1500)
    live = op.live
    adapter, used = live.adapter, live.counters['used']
    op.late(0.2, 50)
    assert op.pred.counters['stale_retractions'] == 1
    assert live.counters['restarts'] == 0 and live.adapter is adapter
    assert live.counters['used'] >= used + 40
    op.check()


def test_after_a_reset_to_a_drag_free_set_the_adaptation_learns_again(tmp_path):
    """1.5 s into the scan (load, drag and play learnt and in use), ``~/reset_adaptation``
    returns to the declared set, which has no drag: the swap released the learnt load and
    drag at once and stepped the correction, the drag-free drive rang for ever, the
    estimate's flank (neither load nor drag) followed the ringing and no sample was used
    again (0 of 1 200).  Reseated and blended, the samples enter the estimate again."""
    op = Operator(tmp_path)
    op.samples(1500)
    assert op.live.declared.to_flat_dict()[DRAG] == 0.0
    assert op.live.adapter.applied_values()[LOAD] > 1.0
    op.reset()
    used = op.live.counters['used']
    op.samples(1200)
    assert op.live.counters['resets'] == 1
    assert op.live.counters['used'] - used > 300
    op.check()
