# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The live counterpart of the offline twin (``worm-gear-sim adapt``): the node, a plant node
and a commander as separate ROS processes over DDS (the wiring only).

:func:`run_live` starts the node and the plant (:mod:`.plant`) on a simulated clock and is
itself the commander (:class:`ScenarioCommander`): a handshake, then the twin's references,
the clock held at most ``max_lag`` past the last encoder sample, so every sample reaches
the node in time.  With ``late_samples`` and ``late_steps`` 0 the result (a ``TwinRun``)
equals ``run_twin`` on the same samples, bit for bit.  docs/adaptation.md.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from ..config.files import params_document, params_yaml_text
from ..config.usable import Config
from ..records.topics import (
    COMPENSATED_COMMAND_TOPIC,
    DIAGNOSTICS_TOPIC,
    MEASURED_TOPIC,
    REFERENCE_TOPIC,
    private_topic,
)
from ..schema.sections import NODE_NAME
from ..studies.adaptation_twin import (
    HANDSHAKE_AFTER_NS,
    Reference,
    TwinRun,
    plant_errors,
    prepare_start,
    reference_of,
)
from .adaptation import ADAPTED_TOPIC
from .interface import REFERENCE_DEPTH

__all__ = ['ScenarioCommander', 'LiveRun', 'run_live', 'node_command', 'plant_command',
           'stream_through', 'live_result', 'start_process', 'stop_process', 'write_params',
           'MEASURED_QOS']

#: The node's encoder subscription made reliable, keep last 1000 (its default is the
#: sensor-data profile: best effort, keep last 5, which drops samples behind a stall).
MEASURED_QOS = ('-p', f'qos_overrides./{MEASURED_TOPIC}.subscription.reliability:=reliable',
                '-p', f'qos_overrides./{MEASURED_TOPIC}.subscription.depth:=1000')
MAX_BURST = 100          # samples per timer call after a stall of this process
#: The simulated clock's first reading [ns] (any time > 0; the node follows /clock).
CLOCK_START_NS = 1_000_000_000
HOLD_PERIOD_S = 0.02     # wall time between the hold samples (see ScenarioCommander.start)
#: After the handshake's first answer, wall time without a new encoder sample before the
#: clock goes back and the stream starts [s] (nothing of the handshake still in flight).
SETTLE_S = 0.3


class _Stream:
    """One drive the commander streams to: its namespace (``''``: the root), the samples
    of its worm input joint, its reference publisher, what came back from it."""

    def __init__(self, namespace: str, joint: str, theta1: np.ndarray) -> None:
        self.namespace, self.theta1 = namespace, theta1
        self.msg = JointState(name=[joint], position=[0.0])
        self.pub: Any = None
        self.adapted: dict[str, Any] = {}
        self.adapted_count = 0
        self.last_measured_ns = 0
        self.measured_count = 0

    def topic(self, name: str) -> str:
        """``name`` (relative) in the stream's namespace."""
        return f'/{self.namespace}/{name}' if self.namespace else name


class ScenarioCommander(Node):
    """Streams stamped references (t, theta1_ref of each drive in ``streams``: (namespace,
    worm input joint, theta1_ref); one drive in the root namespace for a single node, a
    pedestal's drives in theirs) once started, on one simulated clock; keeps each node's
    last ``~/adapted_parameters`` and the stamp of the last encoder sample seen from each
    drive (the clock follows the drive furthest behind)."""

    def __init__(self, t: np.ndarray, streams: list[tuple[str, str, np.ndarray]], ahead: float,
                 node_under_test: str = NODE_NAME, speed: float = 1.0, max_lag: float = 0.015,
                 **kwargs: Any) -> None:
        super().__init__('adaptation_commander', **kwargs)
        self.t, self.ahead = t, ahead
        self.streams = [_Stream(*s) for s in streams]
        self.target = node_under_test
        self.speed, self.max_lag_ns = speed, int(max_lag * 1e9)
        self.t0_ns: int | None = None
        self.k_next = 0
        self.period_ns = int(round((t[1] - t[0]) * 1e9))
        self.holding = False
        self.held = 0
        self._hold_ns: int | None = None
        self.first_ns: int | None = None          # the first hold sample's stamp
        self._hold_wall = -math.inf
        self._settle_from: float | None = None
        self._settle_seen: tuple[int, ...] = ()
        self._stream_after = -math.inf
        self.clock_ns = CLOCK_START_NS + HANDSHAKE_AFTER_NS      # the handshake's clock
        self._wall = time.monotonic()
        self._alive: set[str] = set()
        self._nodes = {(f'{s.namespace}/' if s.namespace else '') + node_under_test
                       for s in self.streams}
        reliable = QoSProfile(depth=REFERENCE_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                             reliability=ReliabilityPolicy.RELIABLE)
        for s in self.streams:
            s.pub = self.create_publisher(JointState, s.topic(REFERENCE_TOPIC), reliable)
            self.create_subscription(
                String, s.topic(private_topic(ADAPTED_TOPIC, node_under_test)),
                lambda msg, s=s: self._on_adapted(s, msg), latched)
            self.create_subscription(JointState, s.topic(MEASURED_TOPIC),
                                     lambda msg, s=s: self._on_measured(s, msg), reliable)
        self.pub_clock = self.create_publisher(Clock, '/clock', QoSProfile(depth=1))
        self._clock_msg = Clock()
        self.create_subscription(DiagnosticArray, DIAGNOSTICS_TOPIC, self._on_diag, 10)
        self.create_timer(1e-3, self._on_timer)

    # ---- what came back (the first stream's, for a single node) ------------------------
    @property
    def last_measured_ns(self) -> int:
        """The stamp of the newest encoder sample of the drive furthest behind."""
        return min(s.last_measured_ns for s in self.streams)

    @property
    def adapted(self) -> dict[str, Any]:
        return self.streams[0].adapted

    @property
    def adapted_count(self) -> int:
        return self.streams[0].adapted_count

    @property
    def measured_count(self) -> int:
        return sum(s.measured_count for s in self.streams)

    @property
    def node_alive(self) -> bool:
        return self._alive >= self._nodes

    def connected(self) -> bool:
        """Every node is spinning (its /diagnostics seen), and for every drive the node and
        the plant are subscribed to the references, the plant to the node's commands, the
        node to the plant's encoder."""
        return self.node_alive and all(
            s.pub.get_subscription_count() >= 2
            and self.count_subscribers(s.topic(private_topic(COMPENSATED_COMMAND_TOPIC,
                                                             self.target))) >= 1
            and self.count_subscribers(s.topic(MEASURED_TOPIC)) >= 2 for s in self.streams)

    def start(self) -> None:
        """The handshake: hold the first sample (repeated every HOLD_PERIOD_S of wall time,
        on the stream's grid, HANDSHAKE_AFTER_NS after the run's clock) until the first
        encoder sample of every drive comes back and nothing more comes for SETTLE_S; then
        the clock goes back to CLOCK_START_NS and the stream starts there: the nodes'
        pipelines and their adaptation and the plants restart at rest at its first sample,
        as the twin starts, and no sample of the run is streamed into a connection that is
        not matched yet (a lost command would stall the clock)."""
        self.holding = True

    def streaming(self) -> bool:
        return self.t0_ns is not None

    def stamp(self, k: int) -> int:
        assert self.t0_ns is not None
        return self.t0_ns + int(round(self.t[k] * 1e9))

    def done(self) -> bool:
        return self.k_next >= self.t.size

    def _send(self, ns: int, k: int) -> None:
        """Sample ``k`` of every drive, stamped ``ns``."""
        for s in self.streams:
            m = s.msg
            m.header.stamp.sec, m.header.stamp.nanosec = divmod(ns, 1_000_000_000)
            m.position[0] = float(s.theta1[k])
            s.pub.publish(m)

    def _on_timer(self) -> None:
        """Advance /clock by the wall time since the last call times ``speed`` (never more
        than ``max_lag`` past the last encoder sample once streaming), then publish every
        sample stamped at most ``ahead`` past it."""
        wall = time.monotonic()
        step = int((wall - self._wall) * self.speed * 1e9)
        self._wall = wall
        clock = self.clock_ns + step
        if self.t0_ns is not None:
            clock = min(clock, max(self.last_measured_ns, self.t0_ns) + self.max_lag_ns)
        if self._hold_ns is not None and self.t0_ns is None:    # holding: see _hold
            clock = min(clock, self._hold_ns - int(self.ahead * 1e9))
        if wall < self._stream_after:                 # the clock just went back: held
            clock = self.clock_ns
        if not self.done():           # then held: the node never sees the stream pause
            self.clock_ns = max(self.clock_ns, clock)
        c = self._clock_msg
        c.clock.sec, c.clock.nanosec = divmod(self.clock_ns, 1_000_000_000)
        self.pub_clock.publish(c)
        if self.holding:
            self._hold(wall)
        if self.t0_ns is None or self.done() or wall < self._stream_after:
            return
        horizon = self.clock_ns + int(self.ahead * 1e9)
        for _ in range(MAX_BURST):
            if self.done() or self.stamp(self.k_next) > horizon:
                break
            self._send(self.stamp(self.k_next), self.k_next)
            self.k_next += 1

    def _hold(self, wall: float) -> None:
        if self.last_measured_ns > 0 and self._hold_ns is not None:
            # every chain answers: let what is in flight arrive, then the clock goes back
            # and the stream starts afresh (the nodes, their adaptation and the plants
            # restart)
            seen = tuple(s.last_measured_ns for s in self.streams)
            if self._settle_from is None or seen != self._settle_seen:
                self._settle_from, self._settle_seen = wall, seen
            elif wall - self._settle_from >= SETTLE_S:
                self.holding = False
                self.clock_ns = CLOCK_START_NS
                self.t0_ns = CLOCK_START_NS + int(self.ahead * 1e9) + self.period_ns
                for s in self.streams:
                    s.last_measured_ns = 0
                # the nodes and the plants see the clock go back before the first sample
                self._stream_after = wall + SETTLE_S
            return
        if wall - self._hold_wall < HOLD_PERIOD_S:
            return
        # one grid step of stream time per hold message, the clock ``ahead`` behind it: the
        # hold lasts a few ms of the node's time however long the chain takes to answer
        if self._hold_ns is None:
            self._hold_ns = self.first_ns = self.clock_ns + int(self.ahead * 1e9)
        else:
            self._hold_ns += self.period_ns
        self._hold_wall = wall
        self._send(self._hold_ns, 0)
        self.held += 1

    def _on_adapted(self, s: _Stream, msg: String) -> None:
        s.adapted = json.loads(msg.data)
        s.adapted_count += 1

    def _on_measured(self, s: _Stream, msg: JointState) -> None:
        s.measured_count += 1
        s.last_measured_ns = max(s.last_measured_ns, msg.header.stamp.sec * 1_000_000_000
                                 + msg.header.stamp.nanosec)

    def _on_diag(self, msg: DiagnosticArray) -> None:
        for st in msg.status:
            name = st.name.split(':', 1)[0]
            if name in self._nodes:
                self._alive.add(name)


@dataclass
class LiveRun(TwinRun):
    """A :class:`TwinRun` from the live processes, plus: stamps kept without a plant sample
    (``missing``), whether the encoder stopped coming (``stalled``: no progress for
    ``stall_timeout`` s, a process ended, or the drain timed out), the handshake's hold
    messages (``held``, the first stamped ``first_ns``; the run's t = 0 is ``t0_ns``; the
    plant (re)started last at ``plant_ns``: ``t0_ns`` after the handshake),
    the plant's counters, the wall time of the stream and the logs."""

    missing: int = 0
    stalled: bool = False
    held: int = 0
    first_ns: int = 0
    t0_ns: int = 0
    plant_ns: int = 0
    plant_counters: dict[str, int] = field(default_factory=dict)
    stream_wall_s: float = math.nan
    node_log: str = ''
    plant_log: str = ''


def write_params(cfg: Config, path: Path) -> Path:
    """``cfg`` as a params file at ``path`` (the node and the plant start from it)."""
    path.write_text(params_yaml_text(params_document(cfg)))
    return path


def node_command(params: Path) -> list[str]:
    """The node's process for ``params`` (encoder subscription reliable, keep last 1000)."""
    return [sys.executable, '-m', 'worm_gear_sim.ros', '--ros-args', '--params-file',
            str(params), '-p', 'use_sim_time:=true', *MEASURED_QOS]


def plant_command(plant: Path, record: Path, *, noise: float, encoder_bits: int,
                  seed: int, namespace: str = '') -> list[str]:
    """The plant node's process (in ``namespace``: a pedestal's drive)."""
    ns = ['--ros-args', '-r', f'__ns:=/{namespace}'] if namespace else []
    return [sys.executable, '-m', 'worm_gear_sim.ros.plant', '--plant', str(plant),
            '--noise', repr(noise), '--encoder-bits', str(encoder_bits), '--seed', str(seed),
            '--record', str(record), '--subscribers', '2', *ns]


def start_process(args: list[str], env: dict[str, str], log: Path, cwd: Path | None = None
                  ) -> tuple[subprocess.Popen, IO]:
    """``args`` started with stdout and stderr in ``log`` (kept open for
    :func:`stop_process`)."""
    fh = open(log, 'w+')
    return subprocess.Popen(args, env=env, stdout=fh, stderr=subprocess.STDOUT, cwd=cwd), fh


def stop_process(proc: subprocess.Popen, fh: IO, timeout: float = 20.0) -> str:
    """SIGINT to ``proc`` (killed after ``timeout`` s), then its log."""
    import signal
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    fh.seek(0)
    text = fh.read()
    fh.close()
    return text


def run_live(plant: Config, start: Config, name: str | Reference, duration: float, *,
             context: Any,
             env: dict[str, str], workdir: Path, noise: float = 1e-6, encoder_bits: int = 20,
             seed: int = 0, lead: float = 0.02, speed: float = 1.0,
             max_lag: float | None = None,
             startup_timeout: float = 120.0, drain_timeout: float = 30.0,
             stall_timeout: float = 20.0) -> LiveRun:
    """Scenario ``name`` for ``duration`` s through the live processes (module docstring);
    ``context``: an initialised rclpy Context on the processes' domain (``env``: theirs,
    ROS_DOMAIN_ID and discovery range); ``workdir``: params files, record and logs;
    ``noise``, ``encoder_bits``, ``seed``: the plant's encoder (as :func:`~worm_gear_sim.
    adaptation.twin.run_twin`); ``lead``: streamed this much further ahead than the
    preview; ``speed``: the simulated clock's rate against the wall clock (at most);
    ``max_lag``: how far [s] the clock may run past the last encoder sample (None:
    (``adaptation.sample_delay`` - ``lead``) / 2, module docstring).  Raises
    RuntimeError if the processes do not connect within ``startup_timeout`` s (the logs are
    in ``workdir``)."""
    workdir.mkdir(parents=True, exist_ok=True)
    cfg = prepare_start(start)
    ahead = cfg.compensation.preview_time
    if max_lag is None:
        max_lag = 0.5 * (cfg.adaptation.sample_delay - lead)
    if not max_lag > 0.0:
        raise ValueError(f'max_lag {max_lag!r}: must be > 0 s (adaptation.sample_delay '
                         f'{cfg.adaptation.sample_delay!r} s must exceed lead {lead!r} s)')
    t, x = reference_of(name)(cfg, duration + ahead + 5.0 / cfg.node.publish_rate_hz)
    keep = t <= duration + 1e-12
    record = workdir / 'plant_record.npz'
    record.unlink(missing_ok=True)
    node_p, node_fh = start_process(node_command(write_params(cfg, workdir / 'start.yaml')),
                                    env, workdir / 'node.log')
    plant_p, plant_fh = start_process(
        plant_command(write_params(plant, workdir / 'plant.yaml'), record, noise=noise,
                      encoder_bits=encoder_bits, seed=seed), env, workdir / 'plant.log')
    commander = ScenarioCommander(t, [('', cfg.node.joint_names[0], x)], ahead + lead,
                                  speed=speed, max_lag=max_lag, context=context)
    ex = SingleThreadedExecutor(context=context)
    ex.add_node(commander)
    try:
        stalled, stream_wall = stream_through(
            commander, ex, [node_p, plant_p], int(np.count_nonzero(keep)) - 1,
            startup_timeout=startup_timeout, drain_timeout=drain_timeout,
            stall_timeout=stall_timeout)
    finally:
        logs = [stop_process(node_p, node_fh), stop_process(plant_p, plant_fh)]
        ex.shutdown()
        commander.destroy_node()
    run = live_result(plant, cfg, t[keep], x[keep], commander.t0_ns or 0, commander.adapted,
                      record, logs, stream_wall)
    run.stalled, run.held = stalled, commander.held
    run.first_ns, run.t0_ns = commander.first_ns or 0, commander.t0_ns or 0
    return run


def stream_through(commander: ScenarioCommander, ex: SingleThreadedExecutor,
                   procs: list[subprocess.Popen], last: int, *, startup_timeout: float,
                   drain_timeout: float, stall_timeout: float) -> tuple[bool, float]:
    """Spin ``commander`` (in ``ex``) until the processes ``procs`` (the nodes and the
    plants) are connected, through the handshake, and until every drive's encoder has
    answered the sample ``last``; returns (stalled, the stream's wall time [s]): stalled
    when the encoder made no progress for ``stall_timeout`` s, a process ended, or the
    drain after the last sample sent took over ``drain_timeout`` s.  RuntimeError if the
    processes do not connect or answer the handshake within ``startup_timeout`` s."""
    t_wait = time.monotonic()

    def wait(ready: Any, what: str, slice_s: float) -> None:
        while not ready():
            if time.monotonic() - t_wait > startup_timeout or \
                    any(p.poll() is not None for p in procs):
                raise RuntimeError(f'{what} within {startup_timeout:g} s')
            ex.spin_once(timeout_sec=slice_s)

    wait(commander.connected, 'the nodes and the plants did not connect', 0.05)
    commander.start()
    wait(commander.streaming, 'the plants did not answer', 0.01)
    t_stream = time.monotonic()
    last_kept = commander.stamp(last)
    deadline = None
    stalled = False
    seen, t_seen = commander.last_measured_ns, t_stream
    while commander.last_measured_ns < last_kept:
        ex.spin_once(timeout_sec=0.01)
        now = time.monotonic()
        if commander.last_measured_ns != seen:
            seen, t_seen = commander.last_measured_ns, now
        if commander.done() and deadline is None:
            deadline = now + drain_timeout
        if (deadline is not None and now > deadline) or now - t_seen > stall_timeout \
                or any(p.poll() is not None for p in procs):
            stalled = True
            break
    stream_wall = time.monotonic() - t_stream
    _spin_for(ex, 0.2)                       # the last ~/adapted_parameters in flight
    return stalled, stream_wall


def _spin_for(ex: SingleThreadedExecutor, seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        ex.spin_once(timeout_sec=0.01)


def live_result(plant: Config, cfg: Config, t: np.ndarray, x: np.ndarray, t0_ns: int,
                adapted: dict[str, Any], record: Path, logs: list[str], stream_wall: float
                ) -> LiveRun:
    """A drive's live run as the twin's record (module docstring): the stream's kept
    times ``t`` and references ``x`` (t = 0 stamped ``t0_ns``), the node's last
    ``~/adapted_parameters`` ``adapted``, the plant's ``record`` file, the ``logs`` of the
    node and the plant."""
    theta4 = np.full(t.size, np.nan)
    plant_counters: dict[str, int] = {}
    plant_ns = 0
    if record.exists():
        rec = np.load(record)
        rate = cfg.node.publish_rate_hz
        index = np.round((rec['stamp_ns'] - t0_ns) * 1e-9 * rate).astype(np.int64)
        ok = (index >= 0) & (index < t.size)
        theta4[index[ok]] = rec['theta4'][ok]
        plant_counters = {k.removeprefix('counter_'): int(rec[k]) for k in rec.files
                          if k.startswith('counter_')}
        plant_ns = int(rec['base_ns'])
    unc, err = plant_errors(plant, cfg, t, x, theta4)
    return LiveRun(t, x, unc, err, estimates=adapted.get('estimate', {}),
                   in_use=adapted.get('in_use', {}), counters=adapted.get('counters', {}),
                   missing=int(np.count_nonzero(np.isnan(err))), plant_counters=plant_counters,
                   stream_wall_s=stream_wall, plant_ns=plant_ns, node_log=logs[0],
                   plant_log=logs[1])
