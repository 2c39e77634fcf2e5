# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Live adaptation in the node equals the offline twin: the same stamped references and
encoder samples, in the order the twin handles them, give the same corrections, the same
estimate and the same model in use; the node publishes ~/adapted_parameters, shows an
``adaptation`` status and writes a params file it can start from."""

from __future__ import annotations

import json
import os
import stat

import numpy as np
import pytest

pytest.importorskip('rclpy')

from worm_gear_sim.config.files import load_config  # noqa: E402
from worm_gear_sim.config.usable import Config  # noqa: E402
from worm_gear_sim.studies.adaptation_twin import run_twin  # noqa: E402

pytestmark = pytest.mark.ros

NOW_NS = 1_795_000_000_123_456_789
START = {'adaptation.enabled': True, 'node.compensation_applied': True,
         'compensation.preview_time': 0.0025,
         'adaptation.keys': ['load.output_torque', 'load.output_viscous_coefficient'],
         'adaptation.window': 0.3, 'adaptation.step_interval': 0.1,
         'adaptation.max_step': 0.05}


@pytest.fixture(scope='module')
def twin():
    plant = Config().replace({'load.output_torque': 3.0,
                              'load.output_viscous_coefficient': 10.0})
    start = Config().replace(START)
    # stamps from 0.7 s before the node's /clock: inside its +-1 s stamp window
    return run_twin(plant, start, 'sector', 1.4, seed=7, base_ns=NOW_NS - 700_000_000,
                    record=True)


def test_node_adaptation_equals_the_twin(ros_harness, twin, tmp_path):
    out_file = tmp_path / 'adapted.yaml'
    h = ros_harness({**START, 'adaptation.params_file': str(out_file)})
    assert h.wait_clock(NOW_NS)
    node = h.node
    from std_msgs.msg import String
    adapted: list[dict] = []
    h.probe.create_subscription(String, '/worm_gear_sim/adapted_parameters',
                                lambda m: adapted.append(json.loads(m.data)), 10)
    antenna = node.config.node.joint_names[3]
    deltas = []
    slices = 0
    for ns, ref, got in twin.record:          # the twin's order: reference, then encoders
        before = node.rt.counters['corrections']
        node._on_reference(h.reference_msg(ns, ref))
        assert node.rt.counters['corrections'] - before == len(got)
        live = node.adaptation.live       # a step's preparation: a slice after each sample
        if live is not None and live.pending is not None:
            slices = max(slices, getattr(live.pending.future, 'slices', 0))
        deltas.append(node.rt.last_delta if got else None)
        for stamp, meas, _ in got:
            msg = h.JointState(name=[antenna], position=[meas])
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 10**9)
            node._on_measured(msg)
    live = node.adaptation.live
    assert live is not None and live.counters['rejected'] == 0
    assert live.counters['late_steps'] == 0
    assert slices >= 3            # prepared in slices on the sample thread, not at once
    assert live.counters['switches'] == len(twin.steps) > 0
    # the corrections: the last of each sample equals the twin's (same arithmetic)
    twin_last = [got[-1][2] for _, _, got in twin.record if got]
    node_last = [d for d in deltas if d is not None]
    np.testing.assert_allclose(node_last, twin_last, rtol=0, atol=1e-12)
    for key, value in twin.estimates.items():
        assert live.estimates()[key] == pytest.approx(value, rel=1e-9, abs=1e-15)
    assert live.adapter.applied_values() == pytest.approx(twin.in_use, rel=1e-9)
    # diagnostics, topic and the params file
    names = [s.name for s in node.diagnostic_statuses()]
    assert any(n.endswith('adaptation') for n in names)
    node.publish_diagnostics()
    # one message per applied step, one per diagnostics period: the last is the newest
    assert h.spin_until(lambda: len(adapted) >= len(twin.steps) + 1)
    assert adapted[-1]['in_use'] == pytest.approx(twin.in_use, rel=1e-9)
    # the estimate says whether it is plausible (docs/adaptation.md)
    assert adapted[-1]['plausible'] == live.plausibility()[0] is True, live.plausibility()
    assert adapted[-1]['plausibility'] == ''
    res = node.adaptation._on_write(None, type('R', (), {'success': False, 'message': ''})())
    assert res.success, res.message
    cfg = load_config(out_file)
    assert cfg.load.output_torque == pytest.approx(twin.in_use['load.output_torque'],
                                                   rel=1e-12)
    assert cfg.adaptation.enabled


# ---- what an operator does: the node keeps what it learnt ----------------------------------
LOAD, DRAG = 'load.output_torque', 'load.output_viscous_coefficient'
#: small steps: at 0.8 s steps are applied and the target is not reached yet
LOOP = {**START, 'adaptation.max_step': 0.002}


class Loop:
    """The node in a closed loop with a plant, in-process (the live harness's chain
    without the transport): each stamped reference of a sector scan through
    ``_on_reference``, each correction the node publishes commands the plant, whose encoder
    comes back through ``_on_measured``; a step's preparation runs in slices after the
    samples, as in the node; /clock kept 0.3 s behind the stamps."""

    def __init__(self, h, seconds: float = 6.0) -> None:
        from worm_gear_sim.adaptation.plant import EncoderPlant
        from worm_gear_sim.studies.adaptation_twin import scenario
        self.h, self.node = h, h.node
        cfg = self.node.config
        self.t, self.x = scenario(cfg, 'sector', seconds)
        self.base = NOW_NS - 700_000_000
        plant = Config().replace({LOAD: 3.0, DRAG: 10.0})
        self.plant = EncoderPlant(plant, float(self.x[0]), noise=1e-6, encoder_bits=20, seed=7)
        self.antenna = cfg.node.joint_names[3]
        self.k = 0
        self.got: list = []
        pubs = self.node.publishing
        real = pubs.corrections
        pubs.corrections = lambda cs: (self.got.extend(cs), real(cs))

    def run(self, seconds: float) -> None:
        h, node = self.h, self.node
        for _ in range(int(round(seconds * 1000))):
            ns = self.base + int(round(self.t[self.k] * 1e9))
            if self.k % 200 == 0:
                assert h.wait_clock(ns - 300_000_000)
            self.got.clear()
            node._on_reference(h.reference_msg(ns, float(self.x[self.k])))
            self.k += 1
            for c in list(self.got):
                _, meas = self.plant.command((c.stamp_ns - self.base) * 1e-9,
                                             c.theta1_ref + c.delta)
                msg = h.JointState(name=[self.antenna], position=[meas])
                msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(c.stamp_ns, 10**9)
                node._on_measured(msg)


def learnt_node(ros_harness, **extra):
    from rclpy.parameter import Parameter
    h = ros_harness({**LOOP, **extra})
    assert h.wait_clock(NOW_NS)
    loop = Loop(h)
    loop.run(0.8)
    live = h.node.adaptation.live
    assert live.counters['switches'] >= 2 and live.adapter.target is not None
    assert h.node.rt.config.load.output_torque > 0.5          # not the nominal 0
    return h, loop, live, Parameter


def service(h, name: str):
    from std_srvs.srv import Trigger
    client = h.probe.create_client(Trigger, f'/worm_gear_sim/{name}')
    assert h.spin_until(client.service_is_ready)
    fut = client.call_async(Trigger.Request())
    assert h.spin_until(fut.done)
    return fut.result()


def test_a_parameter_set_keeps_what_the_node_learnt(ros_harness, tmp_path):
    """node.max_command_jump, adaptation.params_file to its current value, a friction
    coefficient: the model in use keeps its adapted values, the estimate and its covariance
    are kept, counters never go back, and learning goes on; the file written holds the
    adapted model.  (Each set restarted the adaptation from the declared set, load 0.)"""
    out_file = tmp_path / 'adapted.yaml'
    h, loop, live, Parameter = learnt_node(ros_harness,
                                           **{'adaptation.params_file': str(out_file)})
    node = h.node
    for p in (Parameter('node.max_command_jump', value=node.config.node.max_command_jump * 2),
              Parameter('adaptation.params_file', value=str(out_file)),
              Parameter('friction.mu_kinetic', value=node.config.friction.mu_kinetic * 1.02)):
        ad = node.adaptation.live.adapter
        theta, P, in_use = ad.theta.copy(), ad.P.copy(), ad.applied_values()
        counters = dict(node.adaptation.live.counters)
        assert h.set_parameters([p])[0].successful
        assert node.adaptation.live is live
        ad = live.adapter
        np.testing.assert_array_equal(ad.theta, theta)
        np.testing.assert_array_equal(ad.P, P)
        assert ad.applied_values() == in_use
        cfg = node.rt.config
        assert (cfg.load.output_torque, cfg.load.output_viscous_coefficient) == \
            (in_use[LOAD], in_use[DRAG])
        assert node.config.load.output_torque == 0.0         # the declared set: nominal
        for k, v in counters.items():
            assert live.counters[k] >= v, k
    used, switches = live.counters['used'], live.counters['switches']
    loop.run(0.5)
    assert live.counters['used'] > used and live.counters['switches'] > switches
    res = service(h, 'write_adapted_parameters')
    assert res.success, res.message
    assert load_config(out_file).load.output_torque == node.rt.config.load.output_torque > 0.5
    # the operator sets the load, and another parameter before that set is swapped in: the
    # operator's load is in use, its estimate restarts there, the drag keeps its own
    drag = live.adapter.applied_values()[DRAG]
    assert node.set_parameters([Parameter(LOAD, value=1.0)])[0].successful
    assert h.set_parameters([Parameter('node.max_command_jump', value=0.5)])[0].successful
    assert node.rt.config.load.output_torque == 1.0 == live.estimates()[LOAD]
    assert node.rt.config.load.output_viscous_coefficient == drag


def test_adaptation_off_freezes_the_model_and_on_resumes_learning(ros_harness):
    """adaptation.enabled false: the model in use stays as adapted, nothing is fed, the
    status says off and frozen; true again: samples are used and steps applied from the
    estimate kept.  (Off then on left it dead: samples counted, none used.)"""
    h, loop, live, Parameter = learnt_node(ros_harness)
    node = h.node
    load = node.rt.config.load.output_torque
    assert h.set_parameters([Parameter('adaptation.enabled', value=False)])[0].successful
    samples = live.counters['samples']
    loop.run(0.5)
    assert node.rt.config.load.output_torque == load and live.counters['samples'] == samples
    st = next(s for s in node.diagnostic_statuses() if s.name.endswith('adaptation'))
    assert 'off' in st.message and 'frozen' in st.message
    used, switches = live.counters['used'], live.counters['switches']
    assert h.set_parameters([Parameter('adaptation.enabled', value=True)])[0].successful
    assert node.adaptation.live is live
    loop.run(1.0)
    assert live.counters['used'] > used + 300 and live.counters['switches'] > switches
    assert live.counters['restarts'] == 0
    st = next(s for s in node.diagnostic_statuses() if s.name.endswith('adaptation'))
    assert 'steps applied' in st.message


def test_reset_adaptation_forgets_explicitly_and_learning_starts_again(ros_harness):
    """~/reset_adaptation: the model in use returns to the declared set (swapped in
    between two samples), the estimate restarts from the prior, counted and logged; then
    it learns again (with a declared drag here; without one:
    test_reset_to_a_declared_set_without_drag_learns_again)."""
    h, loop, live, _ = learnt_node(ros_harness, **{DRAG: 2.0})
    node = h.node
    counters = dict(live.counters)
    res = service(h, 'reset_adaptation')
    assert res.success and 'declared set' in res.message
    assert h.spin_until(lambda: not node.parameters_pending)
    assert node.rt.config.load.output_torque == 0.0
    assert node.rt.config.load.output_viscous_coefficient == 2.0
    ad = live.adapter
    np.testing.assert_array_equal(ad.theta, ad.nominal_x)
    np.testing.assert_array_equal(ad.P, np.diag(ad.layout.prior_std() ** 2))
    assert live.counters['resets'] == 1
    for k, v in counters.items():
        assert live.counters[k] >= v, k
    assert node.counters['accepted_parameter_sets'] == 0     # no parameter was set
    loop.run(1.2)
    assert live.counters['used'] > counters['used'] + 300
    assert live.counters['switches'] > counters['switches']
    assert node.rt.config.load.output_torque > 0.5


def test_the_params_file_is_checked_when_set_and_when_written(ros_harness, tmp_path):
    """adaptation.params_file naming a directory or a FIFO is refused with the reason;
    a file that became a directory after it was set is refused by the write service,
    nothing written beside it; a new file gets the umask's mode."""
    from rclpy.parameter import Parameter
    good = tmp_path / 'adapted.yaml'
    h = ros_harness({**START, 'adaptation.params_file': str(good)})
    node = h.node
    fifo = tmp_path / 'pipe'
    os.mkfifo(fifo)
    for bad, why in ((tmp_path, 'a directory'), (fifo, 'a FIFO')):
        res = h.set_parameters([Parameter('adaptation.params_file', value=str(bad))])
        assert not res[0].successful and why in res[0].reason
        assert 'adaptation.params_file' in res[0].reason
    assert node.config.adaptation.params_file == str(good)
    assert node.counters['rejected_parameter_sets'] == 2
    umask = os.umask(0o027)
    try:
        res = service(h, 'write_adapted_parameters')
    finally:
        os.umask(umask)
    assert res.success, res.message
    assert stat.S_IMODE(good.stat().st_mode) == 0o640
    good.unlink()
    good.mkdir()                             # the target became a directory
    res = service(h, 'write_adapted_parameters')
    assert not res.success and 'is a directory' in res.message
    assert good.is_dir() and not any(p.name.endswith('.tmp') for p in tmp_path.iterdir())
    assert stat.S_ISFIFO(fifo.stat().st_mode)


def test_reset_to_a_declared_set_without_drag_learns_again(ros_harness):
    """~/reset_adaptation to a declared set without drag: the node swaps it back reseated
    and blended (its simulated drive's forces kept), so that the predicted antenna does not
    ring on and the samples enter the estimate again (swapped at once, none was used)."""
    h, loop, live, _ = learnt_node(ros_harness)
    node = h.node
    assert h.node.adaptation.live.declared.load.output_viscous_coefficient == 0.0
    used = live.counters['used']
    assert service(h, 'reset_adaptation').success
    assert h.spin_until(lambda: not node.parameters_pending)
    assert node.rt.config.load.output_torque == 0.0 and live.counters['resets'] == 1
    loop.run(1.2)
    used = live.counters['used']          # (the first 1.2 s after it: the hold-offs)
    loop.run(1.2)
    assert live.counters['used'] > used + 200, live.counters
