# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A load beyond what the drive carries elastically: the static wind-up against the held
worm (checked against the nonlinear static equilibrium solved by Newton's method, an
independent computation), the limit from ``load.max_elastic_windup``, and the node's
counted, throttled warning on the load_torque topic (the sample is still taken).  The
back-drive margin does not depend on the load (what docs/load.md now says)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worm_gear_sim import Config, DriveModel, load_config
from worm_gear_sim.dynamics.load import (
    ElasticLimitCheck,
    ElasticLoadWarning,
    SampledLoad,
    elastic_load_limit,
    elastic_windup,
)
from worm_gear_sim.dynamics.modal import static_equilibrium
from worm_gear_sim.dynamics.model import with_load_torque, without_play
from worm_gear_sim.schema.validation import ConfigError

try:
    from rclpy.parameter import Parameter
except ImportError:  # the offline tests run without ROS
    Parameter = None


@pytest.fixture(scope='module')
def model() -> DriveModel:
    return DriveModel(load_config())


@pytest.mark.parametrize('torque', [10.0, 541.0, -2e4])
def test_the_windup_is_the_static_equilibrium_under_the_load(model, torque):
    p = without_play(model.p)
    rest = static_equilibrium(p, 0.0)
    loaded = static_equilibrium(with_load_torque(p, torque), 0.0)
    assert elastic_windup(model, torque) == pytest.approx(abs(loaded[2] - rest[2]), rel=2e-3)


def test_the_limit_follows_the_parameter_and_bad_values_are_refused(model):
    limit = elastic_load_limit(model)
    assert elastic_windup(model, limit) == pytest.approx(0.02, rel=1e-12)
    wider = DriveModel(load_config().replace({'load.max_elastic_windup': 0.04}))
    assert elastic_load_limit(wider) == pytest.approx(2 * limit, rel=1e-12)
    for bad in (0.0, -1.0, math.nan, math.inf, 11.0):
        with pytest.raises(ConfigError, match='max_elastic_windup'):
            Config().replace({'load.max_elastic_windup': bad})


def test_the_check_counts_the_samples_beyond_and_names_the_key(model):
    check = ElasticLimitCheck()
    limit = elastic_load_limit(model)
    assert check(model, 0.99 * limit) is None and check(model, -0.99 * limit) is None
    line = check(model, -1e5)
    assert line is not None and 'load.max_elastic_windup = 0.02 rad' in line
    assert '3.7 rad' in line and '\n' not in line
    assert check(model, 2 * limit) is not None and check.count == 2


def test_offline_runs_warn_of_a_constant_load_or_a_load_column_beyond_the_limit():
    """The constant load.output_torque and a sampled load (a CSV column) beyond what the
    drive carries elastically: one ElasticLoadWarning naming the key / the sample, the
    run made all the same; within the limit, none."""
    import warnings

    from worm_gear_sim.dynamics.simulation import simulate
    base = load_config().replace({'input.end_time': 2e-3})
    limit = elastic_load_limit(DriveModel(base))
    with pytest.warns(ElasticLoadWarning, match=r'load\.output_torque = .*max_elastic_windup'
                      ) as got:
        traj = simulate(base.replace({'load.output_torque': 1.1 * limit}))
    assert len([w for w in got if w.category is ElasticLoadWarning]) == 1
    assert np.isfinite(traj.theta).all()
    t = np.array([0.0, 1e-3, 2e-3])
    beyond = SampledLoad(t, [0.0, -3 * limit, 0.0], source='wind.csv')
    with pytest.warns(ElasticLoadWarning, match=r'sample of wind\.csv at t = 0\.001 s'):
        simulate(base, load=beyond)
    with warnings.catch_warnings():
        warnings.simplefilter('error', ElasticLoadWarning)
        simulate(base.replace({'load.output_torque': 0.9 * limit}))
        simulate(base, load=SampledLoad(t, [0.0, -0.9 * limit, 0.0]))


def test_the_node_warns_of_a_parameter_set_whose_constant_load_is_beyond(ros_harness):
    h = ros_harness()
    limit = elastic_load_limit(h.node.rt.model)
    h.set_parameters([Parameter('load.output_torque', value=2.0 * limit)])
    assert h.spin_until(lambda: 'load.output_torque' in (h.node.last_error or ''))
    assert 'load.max_elastic_windup' in h.node.last_error


def test_the_backdrive_margin_does_not_depend_on_the_load():
    margins = {DriveModel(load_config().replace({'load.output_torque': t})).backdrive_margin()
               for t in (0.0, 1e3, -1e5)}
    assert len(margins) == 1


def test_the_node_warns_once_and_counts_every_load_beyond_the_limit(ros_harness):
    from sensor_msgs.msg import JointState
    h = ros_harness()
    now = 1_795_000_000_123_456_789
    assert h.wait_clock(now)
    pub = h.probe.create_publisher(JointState, 'load_torque', 100)
    assert h.spin_until(lambda: pub.get_subscription_count() > 0)
    for k, value in enumerate((100.0, 1e5, -1e5, 2e3)):
        m = JointState(name=['antenna_joint'], effort=[value])
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(now + k * 10**6, 10**9)
        pub.publish(m)
    rt = h.node.rt
    assert h.spin_until(lambda: rt.counters['load_samples_accepted'] == 4)   # all taken
    assert h.counters()['loads_beyond_elastic_limit'] == 3
    assert 'load.max_elastic_windup' in h.node.last_error
    vals = {kv.key: kv.value for s in h.node.diagnostic_statuses() for kv in s.values}
    assert vals['loads_beyond_elastic_limit'] == '3'
    assert np.isfinite(rt.load_torque)
    # the node's own load rejections (another joint, no effort) count in the inputs' total
    for name, effort in ((['worm_input_joint'], [1.0]), (['antenna_joint'], [])):
        m = JointState(name=name, effort=effort)
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(now + 10 * 10**6, 10**9)
        pub.publish(m)
    assert h.spin_until(lambda: h.counters()['rejected_load_empty_effort'] == 1 and
                        h.counters()['rejected_load_wrong_joint'] == 1)
    inputs = [s for s in h.node.diagnostic_statuses() if s.name.endswith(': inputs')][0]
    assert inputs.message == '2 rejected input(s)', inputs.message
