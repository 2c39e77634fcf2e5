# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Live adaptation in the node equals the offline twin: the same stamped references and
encoder samples, in the order the twin handles them, give the same corrections, the same
estimate and the same model in use; the node publishes ~/adapted_parameters, shows an
``adaptation`` status and writes a params file it can start from."""

from __future__ import annotations

import concurrent.futures
import json

import numpy as np
import pytest

pytest.importorskip('rclpy')

from worm_gear_sim.adaptation.twin import run_twin  # noqa: E402
from worm_gear_sim.config_io import load_config  # noqa: E402
from worm_gear_sim.params import Config  # noqa: E402

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
    for ns, ref, got in twin.record:          # the twin's order: reference, then encoders
        live = node.adaptation.live
        if live is not None and live.pending is not None:   # the worker's time that real
            concurrent.futures.wait([live.pending.future], timeout=30)   # time gives it
        before = node.rt.counters['corrections']
        node._on_reference(h.reference_msg(ns, ref))
        assert node.rt.counters['corrections'] - before == len(got)
        deltas.append(node.rt.last_delta if got else None)
        for stamp, meas, _ in got:
            msg = h.JointState(name=[antenna], position=[meas])
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 10**9)
            node._on_measured(msg)
    live = node.adaptation.live
    assert live is not None and live.counters['rejected'] == 0
    assert live.counters['late_steps'] == 0
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
    res = node.adaptation._on_write(None, type('R', (), {'success': False, 'message': ''})())
    assert res.success, res.message
    cfg = load_config(out_file)
    assert cfg.load.output_torque == pytest.approx(twin.in_use['load.output_torque'],
                                                   rel=1e-12)
    assert cfg.adaptation.enabled
