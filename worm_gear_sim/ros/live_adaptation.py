# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The live counterpart of the offline twin (``worm-gear-sim adapt``): the node, a plant
node and a commander as separate ROS processes over DDS (the wiring only; the scenario,
the plant and the adaptation are the core's, the ones the twin runs).

:func:`run_live` starts

* the node (``python -m worm_gear_sim.ros``) from the start set as the twin runs it
  (:func:`~worm_gear_sim.adaptation.twin.prepare_start`: adaptation on, the compensation
  applied, the preview), on the simulated clock (``use_sim_time``), with its
  ``measured_joint_states`` subscription made reliable, keep last 1000 (a QoS override: no
  encoder sample is lost);
* the plant node (``python -m worm_gear_sim.ros.plant``), the drive's stand-in:
  the node's ``~/compensated_command`` steps it, its encoder comes back on
  ``measured_joint_states`` stamped with the command's stamp;

and is itself the commander (:class:`ScenarioCommander`, in the caller's process): it waits
until both are up and connected, then makes a handshake: it holds the first sample (a grid
step later every 20 ms of wall time, the clock held behind them, 10 s of stream time after
the run's start) until the plant's first encoder sample comes back and nothing more comes
for SETTLE_S (a command published before the node's publisher has matched the plant would
be lost, and the clock would wait for it for ever: measured).  Then the clock goes back to
the run's start: the node's pipeline restarts (a clock going back), its adaptation with it
(:mod:`worm_gear_sim.adaptation.live`), and the plant node restarts at the first reference
of the run (a reference going back), as the twin starts.  Then it streams the scenario's
references (the twin's :func:`~worm_gear_sim.adaptation.twin.scenario`, the same samples)
on ``worm_angle_reference``, ``preview + lead`` ahead of ``/clock``, which it advances at
the wall clock's rate (``speed``) but never more than ``max_lag`` past the last encoder
sample it has seen.  The node releases a command (and its prediction) ``preview`` after the
reference of its stamp, so its predictions run at most ``lead + max_lag`` past that encoder
sample: with ``max_lag`` = (``adaptation.sample_delay`` - ``lead``) / 2 (the default), less
than the sample delay by as much again, every encoder sample reaches the node before its
entry step (:mod:`worm_gear_sim.adaptation.live`; ``late_samples`` counts the others).
On a machine that keeps up this is real time; on a starved one (2 shared cores: the plant
with play and the node each cost a few hundred us per 1 ms sample) the clock slows down
instead of a sample coming late, so the result measures the adaptation, not the
machine.  It waits until the plant has answered the last sample,
keeps the node's last ``~/adapted_parameters`` (published on every applied step and every
``node.diagnostic_period`` of the simulated clock), stops both (SIGINT) and reads the
plant's record.  The result is a :class:`~worm_gear_sim.adaptation.twin.TwinRun` like the
twin's: the antenna error of the plant driven by the live node's adapting feed-forward,
beside the uncompensated one (the same offline computation as the twin's).

Only the timing differs from the twin: there each encoder sample reaches the adaptation
right after the prediction of its stamp; here it comes back through two processes, up to
``lead + max_lag`` of stream time later.  Each sample enters the estimate at a step fixed by
its stamp, so this does not change what a decision sees while ``late_samples`` and
``late_steps`` stay 0, and the handshake leaves nothing behind the restart: then the live
run and ``run_twin(...)`` with the same plant, start set, scenario and seed are the same
computation on the same samples (``test/test_adaptation_live.py``: bit for bit).
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

from ..adaptation.twin import (
    HANDSHAKE_AFTER_NS,
    TwinRun,
    plant_errors,
    prepare_start,
    scenario,
)
from ..config_io import params_document, params_yaml_text
from ..params import Config
from ..schema import NODE_NAME
from ..topics import (
    COMPENSATED_COMMAND_TOPIC,
    DIAGNOSTICS_TOPIC,
    MEASURED_TOPIC,
    REFERENCE_TOPIC,
    private_topic,
)
from .adaptation import ADAPTED_TOPIC
from .interface import REFERENCE_DEPTH

__all__ = ['ScenarioCommander', 'LiveRun', 'run_live', 'node_command', 'plant_command']

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


class ScenarioCommander(Node):
    """Streams stamped references (t, theta1_ref) once started; keeps the node's last
    ``~/adapted_parameters`` and the stamp of the last encoder sample seen."""

    def __init__(self, t: np.ndarray, theta1: np.ndarray, joint: str, ahead: float,
                 node_under_test: str = NODE_NAME, speed: float = 1.0, max_lag: float = 0.015,
                 **kwargs: Any) -> None:
        super().__init__('adaptation_commander', **kwargs)
        self.t, self.theta1, self.ahead = t, theta1, ahead
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
        self._settle_seen = 0
        self._stream_after = -math.inf
        self.clock_ns = CLOCK_START_NS + HANDSHAKE_AFTER_NS      # the handshake's clock
        self._wall = time.monotonic()
        self.node_alive = False
        self.adapted: dict[str, Any] = {}
        self.adapted_count = 0
        self.last_measured_ns = 0
        self.measured_count = 0
        reliable = QoSProfile(depth=REFERENCE_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
        self.pub = self.create_publisher(JointState, REFERENCE_TOPIC, reliable)
        self._msg = JointState(name=[joint], position=[0.0])
        self.pub_clock = self.create_publisher(Clock, '/clock', QoSProfile(depth=1))
        self._clock_msg = Clock()
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                             reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(String, private_topic(ADAPTED_TOPIC, node_under_test),
                                 self._on_adapted, latched)
        self.create_subscription(JointState, MEASURED_TOPIC, self._on_measured, reliable)
        self.create_subscription(DiagnosticArray, DIAGNOSTICS_TOPIC, self._on_diag, 10)
        self.create_timer(1e-3, self._on_timer)

    def connected(self) -> bool:
        """The node is spinning (its /diagnostics seen), and the node and the plant are
        subscribed to the references, the plant to the node's commands, the node to the
        plant's encoder."""
        return (self.node_alive and self.pub.get_subscription_count() >= 2
                and self.count_subscribers(private_topic(COMPENSATED_COMMAND_TOPIC,
                                                         self.target)) >= 1
                and self.count_subscribers(MEASURED_TOPIC) >= 2)

    def start(self) -> None:
        """The handshake: hold the first sample (repeated every HOLD_PERIOD_S of wall time,
        on the stream's grid, HANDSHAKE_AFTER_NS after the run's clock) until the first
        encoder sample comes back and nothing more comes for SETTLE_S; then the clock goes
        back to CLOCK_START_NS and the stream starts there: the node's pipeline and its
        adaptation and the plant restart at rest at its first sample, as the twin starts,
        and no sample of the run is streamed into a connection that is not matched yet (a
        lost command would stall the clock)."""
        self.holding = True

    def streaming(self) -> bool:
        return self.t0_ns is not None

    def stamp(self, k: int) -> int:
        assert self.t0_ns is not None
        return self.t0_ns + int(round(self.t[k] * 1e9))

    def done(self) -> bool:
        return self.k_next >= self.t.size

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
        m = self._msg
        for _ in range(MAX_BURST):
            if self.done() or self.stamp(self.k_next) > horizon:
                break
            m.header.stamp.sec, m.header.stamp.nanosec = divmod(self.stamp(self.k_next),
                                                                1_000_000_000)
            m.position[0] = float(self.theta1[self.k_next])
            self.pub.publish(m)
            self.k_next += 1

    def _hold(self, wall: float) -> None:
        m = self._msg
        if self.last_measured_ns > 0 and self._hold_ns is not None:
            # the chain answers: let what is in flight arrive, then the clock goes back and
            # the stream starts afresh (the node, its adaptation and the plant restart)
            if self._settle_from is None or self.last_measured_ns != self._settle_seen:
                self._settle_from, self._settle_seen = wall, self.last_measured_ns
            elif wall - self._settle_from >= SETTLE_S:
                self.holding = False
                self.clock_ns = CLOCK_START_NS
                self.t0_ns = CLOCK_START_NS + int(self.ahead * 1e9) + self.period_ns
                self.last_measured_ns = 0
                # the node and the plant see the clock go back before the first sample
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
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(self._hold_ns, 1_000_000_000)
        m.position[0] = float(self.theta1[0])
        self.pub.publish(m)
        self.held += 1

    def _on_adapted(self, msg: String) -> None:
        self.adapted = json.loads(msg.data)
        self.adapted_count += 1

    def _on_measured(self, msg: JointState) -> None:
        self.measured_count += 1
        self.last_measured_ns = max(self.last_measured_ns,
                                    msg.header.stamp.sec * 1_000_000_000
                                    + msg.header.stamp.nanosec)

    def _on_diag(self, msg: DiagnosticArray) -> None:
        if any(s.name.startswith(f'{self.target}:') for s in msg.status):
            self.node_alive = True


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


def _write_params(cfg: Config, path: Path) -> Path:
    path.write_text(params_yaml_text(params_document(cfg)))
    return path


def node_command(params: Path) -> list[str]:
    """The node's process for ``params`` (encoder subscription reliable, keep last 1000)."""
    return [sys.executable, '-m', 'worm_gear_sim.ros', '--ros-args', '--params-file',
            str(params), '-p', 'use_sim_time:=true', *MEASURED_QOS]


def plant_command(plant: Path, record: Path, *, noise: float, encoder_bits: int,
                  seed: int) -> list[str]:
    """The plant node's process."""
    return [sys.executable, '-m', 'worm_gear_sim.ros.plant', '--plant', str(plant),
            '--noise', repr(noise), '--encoder-bits', str(encoder_bits), '--seed', str(seed),
            '--record', str(record), '--subscribers', '2']


def _start(args: list[str], env: dict[str, str], log: Path) -> tuple[subprocess.Popen, IO]:
    fh = open(log, 'w+')
    return subprocess.Popen(args, env=env, stdout=fh, stderr=subprocess.STDOUT), fh


def _stop(proc: subprocess.Popen, fh: IO, timeout: float = 20.0) -> str:
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


def run_live(plant: Config, start: Config, name: str, duration: float, *, context: Any,
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
    t, x = scenario(cfg, name, duration + ahead + 5.0 / cfg.node.publish_rate_hz)
    keep = t <= duration + 1e-12
    record = workdir / 'plant_record.npz'
    record.unlink(missing_ok=True)
    node_p, node_fh = _start(node_command(_write_params(cfg, workdir / 'start.yaml')), env,
                             workdir / 'node.log')
    plant_p, plant_fh = _start(plant_command(_write_params(plant, workdir / 'plant.yaml'),
                                             record, noise=noise, encoder_bits=encoder_bits,
                                             seed=seed), env, workdir / 'plant.log')
    commander = ScenarioCommander(t, x, cfg.node.joint_names[0], ahead + lead,
                                  speed=speed, max_lag=max_lag, context=context)
    ex = SingleThreadedExecutor(context=context)
    ex.add_node(commander)
    logs = ['', '']
    stalled = False
    try:
        t_wait = time.monotonic()

        def wait(ready: Any, what: str, slice_s: float) -> None:
            while not ready():
                if time.monotonic() - t_wait > startup_timeout or node_p.poll() is not None \
                        or plant_p.poll() is not None:
                    raise RuntimeError(f'{what} within {startup_timeout:g} s')
                ex.spin_once(timeout_sec=slice_s)

        wait(commander.connected, 'the node and the plant did not connect', 0.05)
        commander.start()
        wait(commander.streaming, 'the plant did not answer', 0.01)
        t_stream = time.monotonic()
        last_kept = commander.stamp(int(np.count_nonzero(keep)) - 1)
        deadline = None
        seen, t_seen = commander.last_measured_ns, t_stream
        while commander.last_measured_ns < last_kept:
            ex.spin_once(timeout_sec=0.01)
            now = time.monotonic()
            if commander.last_measured_ns != seen:
                seen, t_seen = commander.last_measured_ns, now
            if commander.done() and deadline is None:
                deadline = now + drain_timeout
            if (deadline is not None and now > deadline) or now - t_seen > stall_timeout:
                stalled = True
                break
            if node_p.poll() is not None or plant_p.poll() is not None:
                stalled = True
                break
        stream_wall = time.monotonic() - t_stream
        _spin_for(ex, 0.2)                       # the last ~/adapted_parameters in flight
    finally:
        logs = [_stop(node_p, node_fh), _stop(plant_p, plant_fh)]
        ex.shutdown()
        commander.destroy_node()
    run = _result(plant, cfg, t[keep], x[keep], commander, record, logs, stream_wall)
    run.stalled, run.held = stalled, commander.held
    run.first_ns, run.t0_ns = commander.first_ns or 0, commander.t0_ns or 0
    return run


def _spin_for(ex: SingleThreadedExecutor, seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        ex.spin_once(timeout_sec=0.01)


def _result(plant: Config, cfg: Config, t: np.ndarray, x: np.ndarray,
            commander: ScenarioCommander, record: Path, logs: list[str],
            stream_wall: float) -> LiveRun:
    """The live run as the twin's record (module docstring)."""
    theta4 = np.full(t.size, np.nan)
    plant_counters: dict[str, int] = {}
    plant_ns = 0
    if record.exists():
        rec = np.load(record)
        assert commander.t0_ns is not None
        rate = cfg.node.publish_rate_hz
        index = np.round((rec['stamp_ns'] - commander.t0_ns) * 1e-9 * rate).astype(np.int64)
        ok = (index >= 0) & (index < t.size)
        theta4[index[ok]] = rec['theta4'][ok]
        plant_counters = {k.removeprefix('counter_'): int(rec[k]) for k in rec.files
                          if k.startswith('counter_')}
        plant_ns = int(rec['base_ns'])
    ad = commander.adapted
    unc, err = plant_errors(plant, cfg, t, x, theta4)
    run = LiveRun(t, x, unc, err,
                  estimates=ad.get('estimate', {}), in_use=ad.get('in_use', {}),
                  counters=ad.get('counters', {}), missing=int(np.count_nonzero(np.isnan(err))),
                  plant_counters=plant_counters, stream_wall_s=stream_wall, plant_ns=plant_ns,
                  node_log=logs[0], plant_log=logs[1])
    return run
