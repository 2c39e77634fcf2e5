# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The ROS 2 node in-process: one Context per test (domain 42, discovery OFF), the node
under test and a probe node spun by one SingleThreadedExecutor, /clock driven by the
test (use_sim_time) so that every tick is deterministic."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip('rclpy')

from rclpy.parameter import Parameter  # noqa: E402

from worm_gear_sim import Config, SampledProfile, Simulator, load_config  # noqa: E402
from worm_gear_sim.dynamics.profiles import make_profile  # noqa: E402
from worm_gear_sim.ros.params_bridge import MODEL_PARAMETER_NAMES  # noqa: E402

pytestmark = pytest.mark.ros

CONFIG = Path(__file__).resolve().parents[2] / 'config' / 'worm_gear_sim.yaml'
T0_NS = 1_000_000_000          # first tick at 1 s of sim time
TICK_NS = 1_000_000            # 1 kHz


def js_pos(h) -> np.ndarray:
    return np.array([list(m.position) for m in h.joint_states])


def run_ticks(h, commands, t0_ns=T0_NS) -> list[int]:
    """Lock-step: command k, then /clock t0 + k ms, then wait for its JointState."""
    stamps = []
    for k, c in enumerate(commands):
        if c is not None:
            assert h.command(c), f'command {k} not received'
        ns = t0_ns + k * TICK_NS
        assert h.tick_to(ns), f'no JointState at tick {k}'
        stamps.append(ns)
    return stamps


def paper_move_samples(n_ticks: int, start: float = 0.002) -> np.ndarray:
    """The paper's 18-step move (trapezoidal, 20 ms) sampled at the 1 kHz tick."""
    cfg = Config().replace({'input.start_time': start})
    return make_profile(cfg.input).theta1(np.arange(n_ticks) * 1e-3)


def batch(cfg: Config, times: np.ndarray, values: np.ndarray, interpolation='linear'):
    prof = SampledProfile(times, values, interpolation)
    sim = Simulator(cfg, theta1=float(values[0]), t0=0.0, interpolation=interpolation)
    return sim.run(prof, t_end=float(times[-1]),
                   record_every=round(1e-3 / cfg.integrator.time_step))      # each 1 ms tick


# --------------------------------------------------------------------------------------
def test_end_to_end_matches_core_batch_simulation(ros_harness):
    """The paper's 18-step move streamed over worm_angle_command with /clock: the node's
    theta1..theta4, positioning and worm errors equal the core's batch run of the same
    samples (same linear interpolation, same dt grid) to round-off.  The tanh friction law:
    the set-valued law's stick/slip decisions amplify a last-bit difference of a sample time
    to ~1e-6 rad of theta2 (measured), which would hide what this test checks."""
    h = ros_harness({'friction.direction': 'regularized'})
    n = 90
    cmds = paper_move_samples(n)
    stamps = run_ticks(h, cmds)
    times = (np.array(stamps) - stamps[0]) * 1e-9      # exactly what the node computes
    traj = batch(h.node.config, times, cmds)
    assert traj.t.size == n
    pos = js_pos(h)
    assert pos.shape == (n, 4)
    assert [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in h.joint_states] \
        == stamps
    tol = 1e-12
    np.testing.assert_allclose(pos[:, 0], traj.theta1, rtol=0, atol=tol)
    np.testing.assert_allclose(pos[:, 1], traj.theta2, rtol=0, atol=tol)
    np.testing.assert_allclose(pos[:, 2], traj.theta3, rtol=0, atol=tol)
    np.testing.assert_allclose(pos[:, 3], traj.theta4, rtol=0, atol=tol)
    np.testing.assert_allclose(h.positioning_error, traj.output_error, rtol=0, atol=tol)
    np.testing.assert_allclose(h.worm_error, traj.worm_error, rtol=0, atol=tol)
    vel = np.array([list(m.velocity) for m in h.joint_states])
    np.testing.assert_allclose(vel[:, 1:], traj.omega, rtol=0, atol=1e-9)
    # the move really happened and the antenna rings (a non-trivial comparison)
    assert pos[-1, 0] == pytest.approx(0.11309733552923255, abs=1e-12)
    assert np.ptp(np.array(h.positioning_error)[40:]) > 1e-5
    eff = np.array([list(m.effort) for m in h.joint_states])
    assert eff.shape == (n, 4) and np.all(np.isfinite(eff)) and np.abs(eff[:, 3]).max() > 1.0
    assert list(h.joint_states[0].name) == list(Config().node.joint_names)
    per_tick = round(1e-3 / h.node.sim.dt)                  # 250 steps at 4 us
    assert h.counters()['ticks'] == n and h.node.rt.counters['steps'] == (n - 1) * per_tick


def test_compensation_applied_drives_reference_plus_feedforward(ros_harness):
    """~/feedforward is the Compensator's output for the streamed reference (not a
    constant); with node.compensation_applied the simulator is driven with
    theta1_ref + delta and ~/positioning_error is measured against theta1_ref l_w/r_g."""
    from worm_gear_sim.compensation.streaming import Compensator
    h = ros_harness({'node.compensation_applied': True})
    n = 60
    cmds = paper_move_samples(n)
    stamps = run_ticks(h, cmds)
    times = (np.array(stamps) - stamps[0]) * 1e-9
    comp = Compensator(h.node.config)
    comp.reset(float(cmds[0]), 0.0)
    expected = np.array([comp.update(float(t), float(c)) for t, c in zip(times, cmds)])
    ff = np.array(h.feedforward)
    assert ff.shape == (n,)
    np.testing.assert_allclose(ff, expected, rtol=0, atol=1e-15)
    assert np.ptp(ff) > 1e-4            # it moves with the command: not a constant
    drive = cmds + ff
    traj = batch(h.node.config, times, drive)
    pos = js_pos(h)
    np.testing.assert_allclose(pos[:, 0], traj.theta1, rtol=0, atol=1e-12)
    np.testing.assert_allclose(pos[:, 3], traj.theta4, rtol=0, atol=1e-12)
    ratio = h.node.sim.derived.output_per_input
    np.testing.assert_allclose(h.positioning_error, traj.theta4 - cmds * ratio, rtol=0,
                               atol=1e-12)


def test_feedforward_follows_parameter_changes(ros_harness):
    """A plant parameter change redesigns the compensator: the published correction at
    rest under a load torque changes with the load."""
    h = ros_harness()
    run_ticks(h, [0.0, 0.0, 0.0])
    ff0 = h.feedforward[-1]
    res = h.set_parameters([Parameter('load.output_torque', value=50.0)])
    assert res[0].successful, res[0].reason
    run_ticks(h, [0.0] * 3, t0_ns=T0_NS + 3 * TICK_NS)   # the next samples: new design
    assert abs(h.feedforward[-1] - ff0) > 1e-6


def test_declares_every_model_parameter_with_descriptor(ros_harness):
    from rcl_interfaces.msg import ParameterType
    h = ros_harness()
    node = h.node
    meta = Config.metadata()
    flat = Config().to_flat_dict()
    assert set(MODEL_PARAMETER_NAMES) == set(flat)
    for name in flat:
        assert node.has_parameter(name), name
        d = node.describe_parameter(name)
        m = meta[name]
        assert m['description'].split()[0] in d.description, name
        if m['unit']:
            assert f'[{m["unit"]}]' in d.description, name
        assert d.read_only == bool(m['read_only']), name
        if m['lo'] is not None and m['hi'] is not None and d.type in (
                ParameterType.PARAMETER_DOUBLE, ParameterType.PARAMETER_INTEGER):
            rng = d.floating_point_range or d.integer_range
            assert len(rng) == 1, name
            assert (rng[0].from_value, rng[0].to_value) == pytest.approx((m['lo'], m['hi']))
    types = {n: node.describe_parameter(n).type for n in flat}
    assert types['geometry.flywheel_enabled'] == ParameterType.PARAMETER_BOOL
    assert types['integrator.newton_max_iterations'] == ParameterType.PARAMETER_INTEGER
    assert types['mesh.worm_fit_a'] == ParameterType.PARAMETER_DOUBLE
    assert types['friction.model'] == ParameterType.PARAMETER_STRING
    assert types['damping.modal_damping_ratios'] == ParameterType.PARAMETER_DOUBLE_ARRAY
    assert types['node.joint_names'] == ParameterType.PARAMETER_STRING_ARRAY
    assert 'one of: stribeck, constant, off' in \
        node.describe_parameter('friction.model').additional_constraints
    for ro in ('integrator.time_step', 'node.publish_rate_hz', 'node.joint_names',
               'node.executor', 'node.diagnostic_period'):
        assert node.describe_parameter(ro).read_only, ro


def test_code_defaults_equal_the_yaml_file(ros_harness):
    """Declared defaults (no params file) equal config/worm_gear_sim.yaml, and loading that
    file with --params-file gives the same values."""
    from worm_gear_sim.ros.node import WormGearSimNode
    file_values = load_config(CONFIG).to_flat_dict()
    h = ros_harness(sim_time=False)
    node_defaults = WormGearSimNode(context=h.ctx, node_name='defaults_only',
                                    defaults=Config())
    with_file = WormGearSimNode(context=h.ctx, node_name='worm_gear_sim',
                                cli_args=['--ros-args', '--params-file', str(CONFIG)])
    try:
        for name, value in file_values.items():
            assert Config().to_flat_dict()[name] == value, name
            for node in (node_defaults, with_file):
                got = node.get_parameter(name).value
                got = list(got) if isinstance(value, list) else got
                assert got == value, (node.get_name(), name)
        assert with_file.config == load_config(CONFIG)
    finally:
        node_defaults.destroy_node()
        with_file.destroy_node()


# ---- parameters at run time -------------------------------------------------------------
def test_parameter_set_accepted_and_applied(ros_harness):
    h = ros_harness()
    run_ticks(h, [0.0, 0.01])
    state_before = h.node.sim.state
    res = h.set_parameters([Parameter('friction.mu_kinetic', value=0.06),
                            Parameter('load.output_torque', value=2)])  # int -> double
    assert all(r.successful for r in res), [r.reason for r in res]
    assert h.node.config.friction.mu_kinetic == 0.06
    assert h.node.sim.config.friction.mu_kinetic == 0.06
    assert h.node.sim.config.load.output_torque == 2.0
    assert h.node.get_parameter('load.output_torque').value == 2.0
    after = h.node.sim.state                        # state kept through reconfigure
    np.testing.assert_array_equal(after.theta, state_before.theta)
    assert h.counters()['accepted_parameter_sets'] == 2
    # interpolation switches at run time too
    assert h.set_parameters([Parameter('node.command_interpolation',
                                       value='hold')])[0].successful
    assert h.node.sim.interpolation == 'hold'
    run_ticks(h, [0.02], t0_ns=T0_NS + 2 * TICK_NS)
    assert h.counters()['rejected_parameter_sets'] == 0


@pytest.mark.parametrize('params, words', [
    ([('geometry.module', 0.0)], ['geometry.module', '> 0']),               # core's open range
    ([('geometry.module', 60.0)], ['geometry.module']),                      # descriptor range
    ([('input.accel_time', 0.015)], ['accel_time', 'move_time']),            # cross-field
    ([('friction.model', 'coulomb')], ['friction.model', 'stribeck']),       # choices
    ([('damping.modal_damping_ratios', [0.1, 0.2])], ['3 entries']),         # length
    ([('mesh.worm_fit_a', 'abc')], ['Wrong parameter type']),                # type (rclpy)
    ([('friction.mu_kinetic', 0.05), ('integrator.newmark_beta', 0.1)],      # atomic
     ['newmark_beta']),
])
def test_invalid_parameter_set_rejected_with_reason(ros_harness, params, words):
    h = ros_harness()
    run_ticks(h, [0.0, 0.01])
    cfg_before = h.node.config
    state_before = h.node.sim.state
    res = h.node.set_parameters_atomically([Parameter(k, value=v) for k, v in params])
    assert not res.successful
    for w in words:
        assert w in res.reason, res.reason
    assert h.node.config is cfg_before and h.node.sim.config is cfg_before
    for k, _ in params:                              # all or nothing
        assert h.node.get_parameter(k).value == pytest.approx(cfg_before.to_flat_dict()[k]) \
            if not isinstance(cfg_before.to_flat_dict()[k], (str, list)) else True
    assert h.node.get_parameter('friction.mu_kinetic').value == \
        cfg_before.friction.mu_kinetic
    np.testing.assert_array_equal(h.node.sim.state.theta, state_before.theta)
    assert h.counters()['rejected_parameter_sets'] == 1
    assert h.node.last_error.startswith('rejected parameter set')
    assert params[-1][0] in h.node.last_error            # the log names the parameter
    run_ticks(h, [0.02], t0_ns=T0_NS + 2 * TICK_NS)     # keeps running


def test_read_only_parameters_rejected(ros_harness):
    h = ros_harness()
    dt0 = h.node.sim.dt
    for name, value in (('integrator.time_step', 2e-5), ('node.publish_rate_hz', 500.0),
                        ('node.joint_names', ['a', 'b', 'c', 'd'])):
        res = h.node.set_parameters([Parameter(name, value=value)])[0]
        assert not res.successful and 'read-only' in res.reason, (name, res.reason)
    assert h.node.sim.dt == dt0 == 4e-6                   # the YAML's step, unchanged
    assert h.counters()['rejected_parameter_sets'] == 3


def test_parameter_service_round_trip(ros_harness):
    """Through the ROS parameter services, as `ros2 param set` would do."""
    from rclpy.parameter_client import AsyncParameterClient
    h = ros_harness()
    client = AsyncParameterClient(h.probe, 'worm_gear_sim')
    assert h.spin_until(lambda: client.services_are_ready())
    fut = client.set_parameters([Parameter('friction.mu_kinetic', value=0.05),
                                 Parameter('geometry.module', value=-1.0)])
    assert h.spin_until(fut.done)
    ok, bad = fut.result().results
    assert ok.successful and h.node.config.friction.mu_kinetic == 0.05
    assert not bad.successful and 'geometry.module' in bad.reason
    fut = client.get_parameters(['mesh.stiffness_model'])
    assert h.spin_until(fut.done)
    assert fut.result().values[0].string_value == 'nonlinear'


# ---- bad input --------------------------------------------------------------------------
@pytest.mark.parametrize('bad, reason', [
    (math.nan, 'nan'), (math.inf, 'inf'), (-math.inf, 'inf'),
    (2.0e4, 'out_of_range'), (-2.0e4, 'out_of_range'), (0.01 + 1.5, 'jump'),
])
def test_bad_command_rejected_state_kept(ros_harness, bad, reason):
    h = ros_harness()
    run_ticks(h, [0.0, 0.01, 0.01])
    before = h.node.sim.state
    assert h.command(bad)
    c = h.counters()
    assert c['rejected_samples'] == 1 and c[f'rejected_{reason}'] == 1
    assert h.node.last_error.startswith('rejected worm_angle_command')
    np.testing.assert_array_equal(h.node.sim.state.theta, before.theta)
    # next tick holds the last good command; the node keeps accepting good ones
    assert h.tick_to(T0_NS + 3 * TICK_NS)
    assert h.joint_states[-1].position[0] == 0.01
    assert np.all(np.isfinite(js_pos(h)))
    run_ticks(h, [0.02], t0_ns=T0_NS + 4 * TICK_NS)
    assert h.joint_states[-1].position[0] == pytest.approx(0.02, abs=1e-15)
    diag = {s.name: s for s in h.node.diagnostic_statuses()}
    vals = {kv.key: kv.value for kv in diag['worm_gear_sim: inputs'].values}
    assert vals['rejected_samples'] == '1' and vals[f'rejected_{reason}'] == '1'


def test_limits_follow_parameters(ros_harness):
    h = ros_harness({'node.max_command_jump': 0.05, 'node.max_command_abs': 0.5})
    run_ticks(h, [0.0])
    assert h.command(0.06) and h.counters()['rejected_jump'] == 1
    assert h.command(0.04) and h.counters()['rejected_samples'] == 1
    assert h.set_parameters([Parameter('node.max_command_jump', value=1.0)])[0].successful
    assert h.command(0.6) and h.counters()['rejected_out_of_range'] == 1


def test_command_burst_costs_one_tick_of_physics(ros_harness):
    """10k commands between two ticks: only the latest is used, physics is one tick."""
    h = ros_harness()
    run_ticks(h, [0.0, 0.0])
    steps = h.node.rt.counters['steps']
    received0 = h.counters()['commands_received']
    values = 1e-3 * np.sin(np.arange(10_000) * 1e-3)
    for v in values:
        h.cmd_pub.publish(h.Float64(data=float(v)))
    last = float(values[-1])
    assert h.spin_until(lambda: h.node.rt._cmd == last, timeout=20.0)
    received = h.counters()['commands_received'] - received0
    assert 1 <= received <= 10_000
    assert h.tick_to(T0_NS + 2 * TICK_NS)
    c = h.counters()
    assert c['steps'] - steps == round(1e-3 / h.node.sim.dt)      # one tick: 250 steps
    assert c['commands_used'] == 3
    assert c['commands_merged'] + c['commands_dropped'] == received - 1
    assert h.joint_states[-1].position[0] == pytest.approx(last, abs=1e-15)


def test_sim_clock_restart_reinitialises(ros_harness):
    """/clock restarting near 0 (a simulator reset, a looping bag): the node
    re-initialises (counted, warned) and keeps predicting on the new timeline, instead of
    going silent until the clock passes the old time."""
    h = ros_harness()
    run_ticks(h, [0.0, 0.01, 0.02, 0.03])
    assert h.wait_clock(5 * TICK_NS)                         # back to 5 ms
    run_ticks(h, [0.05, 0.05, 0.05], t0_ns=6 * TICK_NS)       # JointStates stamped there
    assert h.counters()['clock_restarts'] == 1
    assert 'clock went backwards' in h.node.last_error
    assert h.joint_states[-1].position[0] == pytest.approx(0.05, abs=1e-15)
    assert np.all(np.isfinite(js_pos(h)))


def test_simulation_error_keeps_last_good_state(ros_harness, monkeypatch):
    from worm_gear_sim.dynamics.stepping import SimulationError
    h = ros_harness()
    run_ticks(h, [0.0, 0.01])
    good = h.node.sim.state
    real = h.node.sim.advance_to

    def failing(t, theta1=None):
        raise SimulationError('integration stopped: injected failure')
    monkeypatch.setattr(h.node.sim, 'advance_to', failing)
    assert h.tick_to(T0_NS + 2 * TICK_NS)                   # still publishes
    assert h.counters()['simulation_errors'] == 1
    assert 'injected failure' in h.node.last_error
    np.testing.assert_array_equal(h.node.sim.state.theta, good.theta)
    assert list(h.joint_states[-1].position)[1:] == list(good.theta)
    statuses = {s.name: s for s in h.node.diagnostic_statuses()}
    sim_status = statuses['worm_gear_sim: simulation']
    assert sim_status.level == b'\x02' and 'injected failure' in sim_status.message
    monkeypatch.setattr(h.node.sim, 'advance_to', real)
    run_ticks(h, [0.02], t0_ns=T0_NS + 3 * TICK_NS)        # and recovers
    assert h.node.sim.t == pytest.approx(0.003, abs=1e-12)


# ---- wall time ------------------------------------------------------------------------
def test_wall_time_catch_up_is_capped(ros_harness):
    """Wall clock: a stalled executor leads to one capped catch-up (an overrun)."""
    import time
    h = ros_harness({'node.max_catch_up': 0.02}, sim_time=False)
    assert h.command(0.0)
    assert h.spin_until(lambda: h.counters()['ticks'] >= 20)
    assert not h.node.rt.sim_time
    t_before = h.node.sim.t
    before = h.counters()        # (a loaded machine may have caused overruns already)
    steps_before = before['steps']
    time.sleep(0.3)                                          # stall: no spinning
    assert h.spin_until(lambda: h.counters()['overruns'] > before['overruns'])
    c = h.counters()
    assert (c['dropped_time_ns'] - before['dropped_time_ns']) * 1e-9 >= 0.3 - 0.02 - 0.05
    # the stall was dropped, not integrated: the simulated clock jumps (resync) and the
    # steps taken cover far less than the stalled time
    assert h.node.sim.t - t_before >= 0.3
    assert 0 < c['steps'] - steps_before < 0.3 / h.node.sim.dt / 2


# ---- diagnostics, QoS -------------------------------------------------------------------
def test_diagnostics_follow_diagnostic_updater_conventions(ros_harness):
    from diagnostic_msgs.msg import DiagnosticStatus
    h = ros_harness()
    run_ticks(h, [0.0, 0.01, 0.02])
    h.command(math.nan)
    n_msgs = len(h.diagnostics)          # the 1 s diagnostic timer fired at the first tick
    h.node.publish_diagnostics()
    assert h.spin_until(lambda: len(h.diagnostics) > n_msgs)
    msg = h.diagnostics[-1]
    names = [s.name for s in msg.status]
    assert names == ['worm_gear_sim: simulation', 'worm_gear_sim: inputs',
                     'worm_gear_sim: feedforward', 'worm_gear_sim: trajectories',
                     'worm_gear_sim: model check', 'worm_gear_sim: adaptation',
                     'worm_gear_sim: back-drive']
    for s in msg.status:
        assert s.hardware_id == 'worm_gear_sim'
        assert isinstance(s.level, bytes) and s.level in (
            DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR)
        assert all(isinstance(kv.value, str) for kv in s.values)
    sim = {kv.key: kv.value for kv in msg.status[0].values}
    for key in ('real_time_factor', 'steps_per_prediction', 'overruns',
                'newton_subdivisions', 'last_error', 'missed_ticks', 'compute_load', 'stale'):
        assert key in sim, key
    inputs = {kv.key: kv.value for kv in msg.status[1].values}
    assert inputs['rejected_samples'] == '1' and msg.status[1].level == DiagnosticStatus.WARN
    assert 'nan' in inputs['last_error']
    stamp = msg.header.stamp
    assert stamp.sec * 10**9 + stamp.nanosec == T0_NS + 2 * TICK_NS


def test_command_qos_sensor_data_and_overridable(ros_harness):
    from rclpy.qos import ReliabilityPolicy
    h = ros_harness()
    info = h.probe.get_subscriptions_info_by_topic('/worm_angle_command')
    assert len(info) == 1
    assert info[0].qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
    assert h.node.has_parameter('qos_overrides./worm_angle_command.subscription.reliability')
    h.close()
    h2 = ros_harness({}, cli_args=[
        '--ros-args', '-p',
        'qos_overrides./worm_angle_command.subscription.reliability:=reliable'])
    info = h2.probe.get_subscriptions_info_by_topic('/worm_angle_command')
    assert info[0].qos_profile.reliability == ReliabilityPolicy.RELIABLE
    pubs = h2.probe.get_publishers_info_by_topic('/joint_states')
    assert pubs[0].qos_profile.reliability == ReliabilityPolicy.RELIABLE


def test_waits_for_first_command(ros_harness):
    h = ros_harness()
    h.set_clock(T0_NS)
    h.spin_for(0.1)
    assert h.joint_states == [] and h.counters()['ticks'] == 0
    statuses = h.node.diagnostic_statuses()
    assert statuses[0].level == b'\x01' and 'waiting' in statuses[0].message
    run_ticks(h, [0.3], t0_ns=T0_NS + TICK_NS)   # first command: starts at rest there
    assert h.joint_states[0].position[0] == 0.3
    assert h.joint_states[0].position[1] == pytest.approx(0.3, abs=1e-9)


# ---- command timing: samples at their reception time ------------------------------------
RAMP_RATE = 2.0                                  # rad/s of worm
RAMP_LOAD = {'load.output_torque': 5.0, 'load.output_viscous_coefficient': 2.0}


def unaligned_stream(n_ticks: int) -> np.ndarray:
    """Reception times [ns after the first tick] of a 1 kHz stream 0.4005 ms after the
    ticks, with jitter: sample j early into the previous tick (2 there, 0 in its own) or
    late into the next (0 in its own, 2 there), as an unlocked servo produces."""
    offsets = np.full(n_ticks - 1, 400_500)
    offsets[[8, 9, 20, 31, 32]] = -49_500        # 2 in one tick, then 0
    offsets[[14, 26, 27, 38]] = 1_050_500        # 0 in one tick, then 2
    return np.arange(n_ticks - 1) * TICK_NS + offsets


def stream_ticks(h, recv_ns: np.ndarray, values: np.ndarray, n_ticks: int) -> None:
    """Start at rest at values' ramp origin (0.0), then replay the stream against the
    ticks in time order (each command at its /clock time)."""
    run_ticks(h, [0.0])
    events = [(int(ns), 'cmd', float(v)) for ns, v in zip(recv_ns, values)]
    events += [(k * TICK_NS, 'tick', 0.0) for k in range(1, n_ticks)]
    for ns, kind, v in sorted(events):
        if kind == 'tick':
            assert h.tick_to(T0_NS + ns), f'no JointState at {ns} ns'
        else:
            assert h.wait_clock(T0_NS + ns) and h.command(v)


def tick_samples(recv_ns: np.ndarray, values: np.ndarray, n_ticks: int):
    """Per tick: the samples (t [s], value) the node feeds (those received since the
    previous tick); tick 0 is the start at rest."""
    out = [[(0.0, 0.0)]]
    for k in range(1, n_ticks):
        m = (recv_ns > (k - 1) * TICK_NS) & (recv_ns <= k * TICK_NS)
        out.append([(ns * 1e-9, float(v)) for ns, v in zip(recv_ns[m], values[m])])
    return out


def published_feedforward(cfg: Config, ticks, per_sample: dict | None = None) -> np.ndarray:
    """The correction published at each tick (that of its last sample); ``per_sample``
    receives the correction of every sample time."""
    from worm_gear_sim.compensation.streaming import Compensator
    comp = Compensator(cfg)
    comp.reset(0.0, 0.0)
    out, d = [], 0.0
    for samples in ticks:
        for t, v in samples:
            d = comp.update(t, v)
            if per_sample is not None:
                per_sample[t] = d
        out.append(d)
    return np.array(out)


@pytest.mark.parametrize('interpolation, applied', [('linear', False), ('hold', False),
                                                    ('linear', True)])
def test_unaligned_commands_are_samples_at_their_reception_time(ros_harness, interpolation,
                                                                applied):
    """A constant-rate ramp streamed at 1 kHz, 0.4 ms after the ticks and with jitter (2
    commands in one tick, 0 in the next): each command is a sample at its /clock time.
    ~/feedforward equals a Compensator fed the same samples and stays smooth (its deviation
    from phase-locked samples is < 1 % of what tick-time sampling gave); the simulator
    equals a batch run of the same samples plus a hold up to each tick."""
    h = ros_harness({**RAMP_LOAD, 'node.command_interpolation': interpolation,
                     'node.compensation_applied': applied})
    cfg = h.node.config
    n = 45
    recv = unaligned_stream(n)
    values = RAMP_RATE * recv * 1e-9               # the ramp at the sample times
    ticks = tick_samples(recv, values, n)
    counts = [len(s) for s in ticks[1:]]
    assert counts.count(0) == 6 and counts.count(2) == 6    # the jitter really happened
    stream_ticks(h, recv, values, n)
    c = h.counters()
    assert c['ticks'] == n and c['commands_used'] == n and c['commands_merged'] == 0
    assert c['commands_restamped'] == 0

    # ~/feedforward: the compensator saw exactly these samples, at these times
    ff = np.array(h.feedforward)
    delta: dict[float, float] = {}
    expected = published_feedforward(cfg, ticks, delta)
    np.testing.assert_allclose(ff, expected, rtol=0, atol=1e-15)
    t_tick = np.arange(n) * TICK_NS * 1e-9         # as the node computes tick times
    regular = published_feedforward(cfg, [[(0.0, 0.0)]] + [[(t, RAMP_RATE * t)]
                                                           for t in t_tick[1:]])
    latest, old = 0.0, []                          # the node before: sample at the tick
    for k, samples in enumerate(ticks):
        latest = samples[-1][1] if samples else latest
        old.append([(t_tick[k], latest)])
    old_ff = published_feedforward(cfg, old)
    from worm_gear_sim.compensation.streaming import Compensator
    steady = t_tick > 2 * Compensator(cfg).filter.lag_span + 2e-3
    rms = lambda x: float(np.sqrt(np.mean(x[steady] ** 2)))  # noqa: E731
    assert rms(old_ff - regular) > 1e-3                      # the old spikes: mrad
    assert rms(ff - regular) < 0.01 * rms(old_ff - regular)
    steady_value = float(np.mean(regular[steady]))
    assert abs(steady_value) > 1e-5                          # a real correction
    assert np.max(np.abs(np.diff(ff[steady]))) < 1e-3 * abs(steady_value)

    # the simulator: samples (plus the correction if applied), hold to each tick
    # the start at rest: at theta1_ref + delta when the correction is applied
    times, drive, ref_at_tick = [0.0], [delta[0.0] if applied else 0.0], [0.0]
    for k, samples in enumerate(ticks[1:], start=1):
        for t, v in samples:
            times.append(t)
            drive.append(v + (delta[t] if applied else 0.0))
        ref_at_tick.append(samples[-1][1] if samples else ref_at_tick[-1])
        if times[-1] < t_tick[k]:
            times.append(t_tick[k])
            drive.append(drive[-1])
    traj = batch(cfg, np.array(times), np.array(drive), interpolation)
    assert traj.t.size == n
    np.testing.assert_allclose(traj.t, t_tick, rtol=0, atol=1e-12)
    pos = js_pos(h)
    for j, name in enumerate(('theta1', 'theta2', 'theta3', 'theta4')):
        np.testing.assert_allclose(pos[:, j], getattr(traj, name), rtol=0, atol=1e-12,
                                   err_msg=name)
    vel = np.array([list(m.velocity) for m in h.joint_states])
    np.testing.assert_allclose(vel[:, 1:], traj.omega, rtol=0, atol=1e-9)
    reference = np.array(ref_at_tick) if applied else traj.theta1
    np.testing.assert_allclose(h.positioning_error,
                               traj.theta4 - reference * traj.output_per_input, rtol=0,
                               atol=1e-12)
    assert np.ptp(pos[:, 3]) > 1e-3                          # it moved


def test_command_queue_rules():
    """CommandQueue.take: overflow drops the oldest; stamps not after the previous sample
    merge (newest value); with restamp (sim time) stamps not after the previous tick take
    the next known time; stamps after the tick wait; another time base is restamped."""
    from worm_gear_sim.realtime.command_timing import CommandQueue
    q = CommandQueue(maxlen=4)
    for i in range(6):
        q.push('sim', 100 + i, float(i))
    assert q.dropped == 2 and len(q) == 4
    assert q.take('sim', 50, 200) == [(102, 2.0), (103, 3.0), (104, 4.0), (105, 5.0)]
    assert len(q) == 0
    for ns, v in ((210, 1.0), (210, 2.0), (205, 3.0), (220, 4.0)):
        q.push('sim', ns, v)
    assert q.take('sim', 200, 300) == [(210, 3.0), (220, 4.0)] and q.merged == 2
    q.push('sim', 300, 1.0)
    q.push('sim', 300, 2.0)
    assert q.take('sim', 300, 400) == [(400, 2.0)]
    assert q.restamped == 2 and q.merged == 3
    q.push('sim', 400, 5.0)
    q.push('sim', 450, 6.0)
    assert q.take('sim', 400, 500) == [(450, 6.0)] and q.merged == 4
    q.push('wall', 480, 1.0)                    # a smoothed stream time before the tick
    q.push('wall', 520, 2.0)
    assert q.take('wall', 500, 600, restamp=False) == [(480, 1.0), (520, 2.0)]
    q.push('wall', 650, 1.0)
    q.push('wall', 640, 2.0)
    assert q.take('wall', 600, 620, restamp=False) == [] and len(q) == 2
    assert q.take('wall', 620, 700, restamp=False) == [(650, 2.0)]
    q.push('wall', 10**12, 7.0)                 # stamped before use_sim_time was switched
    assert q.take('sim', 700, 800) == [(800, 7.0)]
    assert q.clear() == 0


def test_stream_clock_recovers_a_steady_grid():
    """A 1 kHz grid (50 ppm off the tick rate) received with 0..300 us of delay: the
    stream clock's sample spacing jitters 20x less than the reception stamps'; late
    callbacks are put on their slot; a 500 Hz stream skips slots; a pause, a 400 Hz
    stream and a burst re-lock it."""
    from worm_gear_sim.realtime.command_timing import StreamClock
    for bad in (dict(period_ns=0.0), dict(period_ns=1e6, gain=0.0),
                dict(period_ns=1e6, window=0.5), dict(period_ns=1e6, max_outlier_rate=1.0)):
        with pytest.raises(ValueError):
            StreamClock(**bad)
    rng = np.random.default_rng(3)
    grid = 5 * 10**9 + 400_000 + np.arange(3000) * 1_000_050
    recv = grid + rng.integers(0, 300_000, grid.size)
    recv[[1000, 2000]] += 2_000_000                  # two callbacks 2 ms late
    clock = StreamClock(1e6)
    out = np.array([clock(int(r)) for r in recv])
    # a late one looks like two lost commands: it takes slot +3, the next two (early on
    # that grid) share its time, the newest value (that of slot +3) wins in the queue
    assert clock.relocks == 0 and clock.outliers == 4 and np.all(np.diff(out) >= 0)
    assert out[1000] == out[1001] == out[1002] and out[1003] > out[1002]
    assert abs(out[1002] - grid[1002] - np.mean(out[500:900] - grid[500:900])) < 50_000
    settled = np.zeros(out.size, bool)
    settled[np.r_[500:990, 1010:1990, 2010:3000]] = True
    ok2 = settled[2:] & settled[:-2]                 # second differences inside those
    assert np.std(np.diff(out, 2)[ok2]) < 0.05 * np.std(np.diff(recv, 2)[ok2])
    assert np.std((out - grid)[settled]) < 0.2 * np.std(recv - grid)
    assert clock.period == pytest.approx(1_000_050, abs=200)
    t = int(recv[-1]) + 100_000_000                  # pause: taken as it is
    assert clock(t) == t and clock.relocks == 1
    jitter = lambda n: rng.integers(0, 300_000, n)  # noqa: E731
    half = [clock(int(x)) for x in t + np.arange(1, 400) * 2_000_000 + jitter(399)]
    assert clock.relocks == 1 and np.all(np.diff(half) > 0)        # 500 Hz: every 2nd slot
    assert np.std(np.diff(half[100:], 2)) < 20_000
    t = half[-1] + 10**6
    slow = [clock(int(x)) for x in t + np.arange(1, 400) * 2_500_000 + jitter(399)]
    assert clock.relocks == 2 and clock.period == pytest.approx(2.5e6, rel=1e-3)
    assert np.all(np.diff(slow[10:]) > 0) and np.std(np.diff(slow[100:], 2)) < 20_000
    [clock(slow[-1] + 10**7 + j * 1000) for j in range(50)]        # 1 MHz burst
    assert clock.relocks == 3 and clock.period == pytest.approx(1000, rel=0.01)


def test_command_queue_bounds_the_physics_of_a_burst(ros_harness):
    """40 commands at distinct /clock times within one tick: the 16 newest are samples,
    the 24 oldest are dropped and counted; the tick makes 17 advance_to calls and one tick
    of Newmark steps (250 at 4 us)."""
    h = ros_harness()
    run_ticks(h, [0.0, 0.0])
    calls = []
    real = h.node.sim.advance_to
    h.node.sim.advance_to = lambda t, th=None: calls.append(t) or real(t, th)
    values = 1e-4 * np.arange(1, 41)
    for i, v in enumerate(values):
        assert h.wait_clock(T0_NS + TICK_NS + (i + 1) * 20_000) and h.command(v)
    assert h.tick_to(T0_NS + 2 * TICK_NS)
    c = h.counters()
    assert c['commands_dropped'] == 24 and (c['commands_merged'] + c['commands_dropped']) == 24
    assert c['commands_used'] == 2 + 16
    assert len(calls) == 17 and c['steps'] == round(2e-3 / h.node.sim.dt)     # two ticks
    assert h.joint_states[-1].position[0] == pytest.approx(values[-1], abs=1e-15)
    vals = {kv.key: kv.value for kv in h.node.diagnostic_statuses()[1].values}
    assert vals['commands_dropped'] == '24'


def test_wall_clock_command_timing(ros_harness):
    """Wall clock (a fake monotonic clock, callbacks called in time order): a 1 kHz
    servo grid 0.9 ms after the ticks, received after 0..300 us, so that commands cross
    ticks (0 or 2 per tick).  Against phase-locked samples, ~/feedforward deviates:
    'reception' by the latency jitter, 'stream' by < 5 % of that (the grid recovered),
    'tick' (default: the newest command at the tick, no sample without one) by less than
    the node before this change (the latest command at every tick)."""
    from std_msgs.msg import Float64

    from worm_gear_sim.compensation.streaming import Compensator
    rng = np.random.default_rng(7)
    n = 400
    grid = (np.arange(n - 1) + 0.9) * 1e-3                  # s after the first tick
    recv = np.round((grid + rng.uniform(0.0, 300e-6, grid.size)) * 1e9).astype(np.int64)
    values = RAMP_RATE * grid
    t0 = 10**12
    events = sorted([(int(r), 1, float(v)) for r, v in zip(recv, values)]
                    + [(k * TICK_NS, 0, 0.0) for k in range(n)])
    published = {}
    for timing in ('tick', 'reception', 'stream'):
        h = ros_harness({**RAMP_LOAD, 'node.command_timing': timing}, sim_time=False)
        node = h.node
        clock = [t0 - 500_000]
        node._monotonic_ns = lambda clock=clock: clock[0]
        node._on_command(Float64(data=0.0))               # start at rest
        ff = []
        for ns, is_cmd, v in events:
            clock[0] = t0 + ns
            if is_cmd:
                node._on_command(Float64(data=v))
            else:
                node._on_tick()
                ff.append(node.rt.last_delta)
        c = {**node.rt.counters, **node.counters}
        assert not node.rt.sim_time and c['ticks'] == n
        if timing == 'tick':                               # 2 in a tick: the newest
            assert c['commands_merged'] > 10
            assert c['commands_restamped'] + len(node.rt._queue) == n - 1
        else:      # every command a sample (the core may merge one at the start)
            assert c['commands_dropped'] == 0 and c['commands_merged'] <= 1
        published[timing] = np.array(ff)
        h.close()
    cfg = Config().replace(RAMP_LOAD)
    t_tick = np.arange(n) * TICK_NS * 1e-9
    regular = published_feedforward(cfg, [[(0.0, 0.0)]] + [[(t, RAMP_RATE * t)]
                                                           for t in t_tick[1:]])
    comp = Compensator(cfg)                                 # the node before: tick samples
    comp.reset(0.0, 0.0)
    old, latest, i = [comp.update(0.0, 0.0)], 0.0, 0
    for k in range(1, n):
        while i < recv.size and recv[i] <= k * TICK_NS:
            latest, i = float(values[i]), i + 1
        old.append(comp.update(t_tick[k], latest))
    settled = t_tick > 0.15                                 # stream clock acquired
    rms = lambda x: float(np.sqrt(np.mean((x - regular)[settled] ** 2)))  # noqa: E731
    assert rms(np.array(old)) > 5e-3
    assert rms(published['reception']) > 1e-3
    assert rms(published['stream']) < 0.05 * rms(published['reception'])
    assert rms(published['stream']) < 0.01 * rms(np.array(old))
    assert rms(published['tick']) < 0.9 * rms(np.array(old))


def test_another_node_with_the_same_name_is_warned_about(ros_harness):
    """Two nodes named /worm_gear_sim on one domain ran silently mixed: the node looks at
    the graph after its start and warns (log, /diagnostics WARN, same_name_nodes)."""
    from worm_gear_sim.ros.node import WormGearSimNode
    h = ros_harness()
    lines: list[str] = []
    logger = h.node.get_logger()
    warn = logger.warning
    logger.warning = lambda m, *a, **k: (lines.append(m), warn(m, *a, **k))  # type: ignore
    h.node.same_names.check()
    assert h.node.counters['same_name_nodes'] == 0 and not lines
    twin = WormGearSimNode(context=h.ctx)
    try:
        h.executor.add_node(twin)
        assert h.spin_until(lambda: sum(1 for n in h.node.get_node_names_and_namespaces()
                                        if n == ('worm_gear_sim', '/')) == 2, 10.0)
        h.node.same_names.check()
        assert h.node.counters['same_name_nodes'] == 1
        assert any('1 other node(s) named /worm_gear_sim' in ln for ln in lines), lines
        sim = h.node.diagnostic_statuses()[0]
        vals = {kv.key: kv.value for kv in sim.values}
        assert vals['same_name_nodes'] == '1'
        assert 'other node(s) with this name' in sim.message
    finally:
        h.executor.remove_node(twin)
        twin.destroy_node()


def test_backdrive_margin_is_published_and_warned_below_the_threshold(ros_harness):
    """~/backdrive_margin and the 'back-drive' status: OK (self-locking, 2.6) with the
    defaults; WARN, the node running, when a parameter set takes the friction below what
    holds the load (margin < 1 is physics, not an error)."""
    h = ros_harness({'load.output_torque': 5.0})
    got: list[float] = []
    h.probe.create_subscription(h.JointState, '/worm_gear_sim/backdrive_margin',
                                lambda m: got.append(m.position[0]), 10)
    assert h.spin_until(
        lambda: h.node.count_subscribers('/worm_gear_sim/backdrive_margin') > 0)
    h.node.publish_diagnostics()
    assert h.spin_until(lambda: got)
    assert 2.0 < got[-1] < 3.0
    st = h.node.diagnostic_statuses()[-1]
    assert st.name.endswith('back-drive') and 'self-locking' in st.message
    res = h.set_parameters([Parameter('friction.mu_kinetic', value=0.001),
                            Parameter('friction.mu_stribeck_drop', value=0.01)])
    assert res[0].successful
    st = h.node.diagnostic_statuses()[-1]
    vals = {kv.key: float(kv.value) for kv in st.values}
    assert vals['margin'] < 1.0 and '< 1' in st.message
    assert st.level in (b'\x01', 1)


def test_play_can_be_set_live_and_the_drive_goes_on(ros_harness):
    """mesh.backlash over the parameter service while commands flow: accepted, swapped in
    between two samples, the simulation goes on through reversals without an error; a play
    beyond half a tooth pitch is rejected naming the key."""
    h = ros_harness(sim_time=False)
    assert h.command(0.0)
    assert h.spin_until(lambda: h.node.counters['ticks'] >= 5)
    res = h.set_parameters([Parameter('mesh.backlash', value=2 * math.pi / (180 * 60) * 2)])
    assert res[0].successful, res
    assert h.node.config.mesh.backlash > 0
    for k in range(1, 40):
        assert h.command(0.02 * math.sin(k / 3.0))          # reversals through the play
    ticks = h.node.counters['ticks']
    assert h.spin_until(lambda: h.node.counters['ticks'] >= ticks + 5)
    assert h.node.rt.counters['simulation_errors'] == 0
    res = h.set_parameters([Parameter('mesh.backlash', value=0.06)])   # pi/z_g = 0.0561
    assert not res[0].successful and 'mesh.backlash' in res[0].reason
