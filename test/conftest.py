# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""ROS test set-up only: fixtures that tests request explicitly.

Nothing here runs at import or touches the environment of tests that do not ask for these
fixtures; rclpy is imported lazily, so non-ROS tests run without it.

* ``ros_context``: one rclpy Context per test on $ROS_DOMAIN_ID (42 if unset), discovery OFF (the
  node under test and its probes share the context's participant, nothing leaves it);
* ``ros_harness``: factory of :class:`RosHarness` (node under test + probe node + a
  SingleThreadedExecutor, bounded waits);
* ``ros_dds_context`` / ``ros_subprocess_env``: a Context and a child-process environment
  on the next domain with discovery LOCALHOST (tests that start the node as a process).
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from hypothesis import settings

# The tests mirror the package (test/<folder>/test_<module>.py); the helpers they share
# (processes.py, methods.py, ...) sit in test/ itself, and a few tests reuse another
# folder's cases: every test folder is importable by module name (names are unique).
_TESTS = Path(__file__).resolve().parent
for _folder in [_TESTS, *sorted(p for p in _TESTS.iterdir()
                                if p.is_dir() and p.name not in ('data', '__pycache__'))]:
    if str(_folder) not in sys.path:
        sys.path.insert(0, str(_folder))

# CI (CI=true) replays the same property-based examples on every run (reproducible failures);
# locally each run explores new ones.  Tests keep their own max_examples/deadline.
settings.register_profile('ci', derandomize=True, print_blob=True)
if os.environ.get('CI'):
    settings.load_profile('ci')

# pytest-xdist (scripts/run_tests.sh runs the suite on every core): worker gwN takes the pair of
# domains ROS_DOMAIN_ID + 2N, + 2N + 1, set here before any test or child process reads it,
# so the workers' DDS traffic stays apart.
_WORKER = os.environ.get('PYTEST_XDIST_WORKER', '')
if _WORKER.startswith('gw') and _WORKER[2:].isdigit():
    os.environ['ROS_DOMAIN_ID'] = str(int(os.environ.get('ROS_DOMAIN_ID', '42') or 42)
                                      + 2 * int(_WORKER[2:]))

# The user's ROS_DOMAIN_ID (default 42) for in-process tests, the next one for child processes:
# concurrent test sessions on one machine stay apart when each sets its own domain.
IN_PROCESS_DOMAIN_ID = int(os.environ.get('ROS_DOMAIN_ID', '42') or 42)
SUBPROCESS_DOMAIN_ID = IN_PROCESS_DOMAIN_ID + 1


#: Fixtures that start rclpy: a test that requests one is marked ``ros``.
ROS_FIXTURES = frozenset({'ros_context', 'ros_harness', 'ros_dds_context', 'ros_subprocess_env'})
#: A test module whose text names one of these talks to ROS (rclpy, the ROS wing, an installed
#: executable or a colcon build): all its tests are marked ``ros``.  Deliberately broad: the
#: marker selects what the second ROS distro's CI run must repeat (``-m ros``), and a test
#: wrongly left out of it would go untested on that distro.
ROS_WORDS = ('rclpy', 'worm_gear_sim.ros', 'worm_gear_sim_', 'colcon', 'ros_harness')


def _module_talks_to_ros(path: str, _cache: dict[str, bool] = {}) -> bool:  # noqa: B006
    if not path.endswith('.py'):        # a documented block: the root conftest.py marks it
        return False
    if path not in _cache:
        try:
            text = open(path, encoding='utf-8').read()
        except OSError:
            text = ''
        _cache[path] = any(w in text for w in ROS_WORDS)
    return _cache[path]


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark ``ros`` every test that needs rclpy: see ROS_FIXTURES and ROS_WORDS."""
    for item in items:
        if (ROS_FIXTURES & set(getattr(item, 'fixturenames', ()))
                or _module_talks_to_ros(str(item.path))):
            item.add_marker(pytest.mark.ros)


@pytest.fixture
def ros_context(monkeypatch: pytest.MonkeyPatch):
    """A fresh rclpy Context (IN_PROCESS_DOMAIN_ID, discovery OFF), shut down after the test."""
    rclpy = pytest.importorskip('rclpy')
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'OFF')
    monkeypatch.delenv('ROS_STATIC_PEERS', raising=False)
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=IN_PROCESS_DOMAIN_ID)
    try:
        yield ctx
    finally:
        rclpy.try_shutdown(context=ctx)


@pytest.fixture
def ros_dds_context(monkeypatch: pytest.MonkeyPatch):
    """A Context that talks to child processes: SUBPROCESS_DOMAIN_ID, discovery LOCALHOST."""
    rclpy = pytest.importorskip('rclpy')
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    monkeypatch.delenv('ROS_STATIC_PEERS', raising=False)
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=SUBPROCESS_DOMAIN_ID)
    try:
        yield ctx
    finally:
        rclpy.try_shutdown(context=ctx)


@pytest.fixture
def ros_subprocess_env() -> dict[str, str]:
    """Environment for a node started as a child process (SUBPROCESS_DOMAIN_ID, localhost only)."""
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(SUBPROCESS_DOMAIN_ID)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env.pop('ROS_STATIC_PEERS', None)
    env['PYTHONUNBUFFERED'] = '1'
    return env


#: the bound of the harness's waits [s]: they return as soon as their condition holds (never a
#: timing assertion); the first sample of a fresh install compiles the kernels (~10 s on a
#: loaded 2-core machine)
WAIT = 30.0


class RosHarness:
    """The node under test plus a probe node in one context, spun by one executor.

    Every wait is bounded (``timeout``) and returns whether the condition held; tests
    assert on that, never on elapsed time.
    """

    def __init__(self, ctx: Any, overrides: dict[str, Any] | None = None,
                 sim_time: bool = True, cli_args: list[str] | None = None,
                 node_class: Any = None):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.parameter import Parameter
        from rclpy.qos import QoSProfile
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Float64

        from worm_gear_sim.ros.diagnostics import DiagnosticArray
        from worm_gear_sim.ros.node import WormGearSimNode

        params = [Parameter(k, value=v) for k, v in (overrides or {}).items()]
        if sim_time:
            params.append(Parameter('use_sim_time', value=True))
        self.ctx = ctx
        self.node = (node_class or WormGearSimNode)(context=ctx, parameter_overrides=params,
                                                    cli_args=cli_args)
        self.probe = rclpy.create_node('probe', context=ctx)
        self.executor = SingleThreadedExecutor(context=ctx)
        self.executor.add_node(self.node)
        self.executor.add_node(self.probe)
        self.Float64, self.Clock = Float64, Clock
        self.cmd_pub = self.probe.create_publisher(Float64, 'worm_angle_command',
                                                   QoSProfile(depth=100))
        self.JointState = JointState
        self.ref_pub = self.probe.create_publisher(JointState, 'worm_angle_reference',
                                                   QoSProfile(depth=1000))
        self.compensated: list[Any] = []
        self.clock_pub = self.probe.create_publisher(Clock, '/clock', QoSProfile(depth=10))
        self.joint_states: list[Any] = []
        # the node's scalar answers: their values, and the stamps of the samples they answer
        # (stamped one-joint JointStates; Float64 without stamps with node.float64_outputs)
        self.positioning_error: list[float] = []
        self.worm_error: list[float] = []
        self.feedforward: list[float] = []
        self.answer_stamps: dict[str, list[int]] = {
            'positioning_error': [], 'worm_error': [], 'feedforward': []}
        self.diagnostics: list[Any] = []
        p = self.probe
        p.create_subscription(JointState, 'joint_states', self.joint_states.append, 1000)
        float64 = bool((overrides or {}).get('node.float64_outputs'))
        subs = {name: self._answer(name, values, float64) for name, values in (
            ('positioning_error', self.positioning_error), ('worm_error', self.worm_error),
            ('feedforward', self.feedforward))}
        self.ff_sub = subs['feedforward']
        p.create_subscription(DiagnosticArray, '/diagnostics', self.diagnostics.append, 10)
        p.create_subscription(JointState, '/worm_gear_sim/compensated_command',
                              self.compensated.append, 1000)
        self.clock_ns = 0
        assert self.spin_until(lambda: self.cmd_pub.get_subscription_count() > 0
                               and self.node.count_publishers('/clock') > 0), \
            'probe and node did not match'

    def _answer(self, name: str, values: list[float], float64: bool) -> Any:
        """Subscribe the probe to the node's answer ``~/<name>``."""
        stamps = self.answer_stamps[name]
        topic = f'/worm_gear_sim/{name}'
        if float64:
            return self.probe.create_subscription(
                self.Float64, topic, lambda m: values.append(m.data), 1000)

        def take(m: Any) -> None:
            values.append(m.position[0])
            stamps.append(m.header.stamp.sec * 10**9 + m.header.stamp.nanosec)
        return self.probe.create_subscription(self.JointState, topic, take, 1000)

    # ---- waiting ----------------------------------------------------------------------
    def spin_until(self, pred: Callable[[], bool], timeout: float = WAIT) -> bool:
        deadline = time.monotonic() + timeout
        while not pred():
            if time.monotonic() > deadline:
                return False
            self.executor.spin_once(timeout_sec=0.01)
        return True

    def spin_for(self, duration: float) -> None:
        deadline = time.monotonic() + duration
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.005)

    # ---- driving ------------------------------------------------------------------------
    def command(self, value: float, timeout: float = WAIT) -> bool:
        """Publish one command and wait until the node has processed it."""
        c = self.node.rt.counters
        n = c['commands_received']
        self.cmd_pub.publish(self.Float64(data=float(value)))
        return self.spin_until(lambda: c['commands_received'] > n, timeout)

    def reference_msg(self, stamp_ns: int, value: float | None,
                      name: str | None = 'worm_input_joint') -> Any:
        from builtin_interfaces.msg import Time
        msg = self.JointState()
        msg.header.stamp = Time(sec=int(stamp_ns // 10**9), nanosec=int(stamp_ns % 10**9))
        if name is not None:
            msg.name = [name]
        if value is not None:
            msg.position = [float(value)]
        return msg

    def references_seen(self) -> int:
        """Stamped messages the node has processed (accepted or rejected)."""
        return self.node.rt.counters['samples_received'] + sum(
            v for k, v in self.node.counters.items()
            if k in ('rejected_empty_position', 'rejected_wrong_joint'))

    def reference(self, stamp_ns: int, value: float | None,
                  name: str | None = 'worm_input_joint', timeout: float = WAIT) -> bool:
        """Publish one stamped reference sample and wait until the node has processed it."""
        n = self.references_seen()
        self.ref_pub.publish(self.reference_msg(stamp_ns, value, name))
        return self.spin_until(lambda: self.references_seen() > n, timeout)

    def references(self, samples, timeout: float = 20.0) -> bool:
        """Publish several (stamp_ns, value) samples at once (a burst), wait for all."""
        n = self.references_seen()
        k = 0
        for ns, v in samples:
            self.ref_pub.publish(self.reference_msg(ns, v))
            k += 1
        return self.spin_until(lambda: self.references_seen() >= n + k, timeout)

    def counters(self) -> dict[str, Any]:
        """The pipeline's counters merged with the node's own."""
        return {**self.node.rt.counters, **self.node.counters}

    def set_parameters(self, params: list[Any], timeout: float = 10.0) -> list[Any]:
        """node.set_parameters, then spin until an accepted set is swapped into the
        pipeline (it is prepared in a worker thread)."""
        res = self.node.set_parameters(params)
        assert self.spin_until(lambda: not self.node.parameters_pending, timeout)
        return res

    def set_clock(self, ns: int) -> None:
        from builtin_interfaces.msg import Time
        self.clock_ns = int(ns)
        self.clock_pub.publish(self.Clock(clock=Time(sec=int(ns // 10**9),
                                                     nanosec=int(ns % 10**9))))

    def tick_to(self, ns: int, timeout: float = WAIT) -> bool:
        """Advance /clock to ``ns`` and wait for the JointState stamped with it."""
        self.set_clock(ns)

        def stamped() -> bool:
            if not self.joint_states:
                return False
            s = self.joint_states[-1].header.stamp
            n = len(self.joint_states)
            return s.sec * 10**9 + s.nanosec == ns and len(self.positioning_error) == n \
                and len(self.worm_error) == n and \
                (self.node.compensator is None or self.ff_sub is None or
                 len(self.feedforward) >= n)
        return self.spin_until(stamped, timeout)

    def wait_clock(self, ns: int, timeout: float = WAIT) -> bool:
        """Publish /clock ``ns`` and wait until the node's clock reads it (no tick needed)."""
        self.set_clock(ns)
        return self.spin_until(
            lambda: self.node.get_clock().now().nanoseconds == ns, timeout)

    def close(self) -> None:
        self.executor.shutdown()
        self.probe.destroy_node()
        self.node.destroy_node()


@pytest.fixture
def ros_harness(ros_context):
    """Factory: ``ros_harness(overrides=..., sim_time=True)`` -> RosHarness (closed after)."""
    made: list[RosHarness] = []

    def make(overrides: dict[str, Any] | None = None, sim_time: bool = True,
             cli_args: list[str] | None = None, node_class: Any = None) -> RosHarness:
        h = RosHarness(ros_context, overrides, sim_time, cli_args, node_class)
        made.append(h)
        return h

    yield make
    for h in made:
        h.close()
