# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Demo servo for the worm_gear_sim node: streams a reference, shows the predicted antenna
error live and sums it up move by move.

Two interfaces to the node (``--interface``):

* ``stamped`` (default): behaves like a tracking servo.  Each reference sample is a
  ``sensor_msgs/JointState`` on ``worm_angle_reference`` whose ``header.stamp`` is the
  instant it applies (samples on an exact ``--rate`` grid, streamed ahead by the node's
  ``compensation.preview_time`` (``--preview``) plus ``--lead``, so that each correction
  arrives before its instant), ``name[0]`` the worm input
  joint, ``position[0]`` theta1_ref [rad].  It consumes the node's
  ``~/compensated_command`` (theta1_ref + delta for the same stamp: what a servo would
  command) and its ``joint_states``, stamped with the instant they predict, from which the
  live residual e = theta4 - theta1_ref(stamp) l_w/r_g is computed here, sample by sample.
* ``float64``: the simple interface, ``worm_angle_command`` (std_msgs/Float64) at
  ``--rate``; the error is the node's ``~/positioning_error``, timed on arrival.

Patterns (:mod:`worm_gear_sim.studies.demo_moves`, built from the core's profiles):
``paper``, the paper's 18-step move (0.1131 rad of worm in 20 ms, trapezoidal) forward then
back every ``--move-period`` seconds; ``slew``, a radar slew at ``--slew-rate`` with a sharp
reversal every ``--slew-period`` seconds.

Output (:mod:`.demo_report`): on a terminal ONE status line (at most 80 columns) refreshed
10 times a second; otherwise one line per completed move: peak error, ringing once the
applied command rests, settling to 10 urad
(:func:`worm_gear_sim.studies.compensation_eval.move_metrics`, the rules of the offline
evaluation).  At the end, a summary and the same moves run offline through the core
(``run_scenario``, with and without the feed-forward), so the live figures stand next to
what the model says with and without compensation.  Exit code 0 after ``--duration``
seconds of streaming, 1 if the node never answers.

    python -m worm_gear_sim.ros.demo_commander --duration 20 --pattern paper
"""

from __future__ import annotations

import argparse
import math
import shutil
import sys
import time
from typing import Any, TextIO

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.srv import GetParameters
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from rclpy.utilities import remove_ros_args
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from ..config_io import load_config
from ..params import Config
from ..studies.demo_moves import (
    MoveSummary,
    MoveTracker,
    demo_plan,
)
from ..topics import (
    COMMAND_TOPIC,
    COMPENSATED_COMMAND_TOPIC,
    DIAGNOSTICS_TOPIC,
    JOINT_STATES_TOPIC,
    POSITIONING_ERROR_TOPIC,
    REFERENCE_TOPIC,
    private_topic,
)
from .demo_report import LINE_WIDTH, MOVE_HEADER, fit, format_move, format_status, summary, urad
from .interface import REFERENCE_DEPTH

__all__ = ['DemoCommander', 'main']

MAX_BURST = 100                 # samples per timer call after a stall (the node queues 1000)
NODE_WAIT_S = 10.0              # stamped: wait for the node's /diagnostics at most this long
HOLD_PERIOD_NS = 20_000_000     # the first sample is repeated every 20 ms until the node answers


# ---- the ROS node ----------------------------------------------------------------------------
class DemoCommander(Node):
    """Streams the pattern and tracks what the node predicts."""

    def __init__(self, pattern: str = 'paper', rate: float = 1000.0,
                 node_under_test: str = 'worm_gear_sim', move_period: float = 0.5,
                 slew_rate: float = 2.0, slew_period: float = 2.0,
                 interface: str = 'stamped', preview: float = 0.0, lead: float = 0.0,
                 config: Config | None = None, **kwargs: Any):
        super().__init__('demo_commander', **kwargs)
        if interface not in ('stamped', 'float64'):
            raise ValueError(f'interface must be stamped or float64, got {interface!r}')
        self.cfg = config if config is not None else load_config()
        plan = demo_plan(pattern, self.cfg, move_period, slew_rate, slew_period)
        self.model = plan.model             # one model: ratio, ringing period, offline moves
        self.output_per_input = plan.model.output_per_input
        self.theta1, self.segments = plan.theta1, plan.segments
        # float64: samples timed on arrival, which a busy machine delays by tens of ms
        self.tracker = MoveTracker(self.segments, plan.mode_hz,
                                   max_gap=0.02 if interface == 'stamped' else 0.1)
        self.tracker.use_commands = False   # until the node says its feed-forward is applied
        self.pattern, self.interface, self.rate = pattern, interface, rate
        self.preview = preview              # s: the node's preview: stream this far ahead
        self.lead = lead                    # s: ... plus this, so corrections come in time
        self.node_preview: float | None = None   # the node's compensation.preview_time
        self.period_ns = int(round(1e9 / rate))
        self.target = node_under_test
        self.joint = self.cfg.node.joint_names[0]
        self.t0_ns: int | None = None       # stamp of grid sample 0 (stream running)
        self.t0_mono: float | None = None
        self.k_next = 0                     # next grid sample to publish
        self.sent = self.held = 0
        self.n_js = self.n_cc = self.n_err = 0
        self.error = math.nan
        self.t_error = 0.0
        self.peak_all = 0.0
        self.latency_ns: list[int] = []     # stamp - reception of compensated commands
        self.delta = math.nan
        self.diag: dict[str, str] = {}
        self.last_move: MoveSummary | None = None
        self.new_moves: list[MoveSummary] = []
        self._last_hold = -math.inf
        self._grid0: int | None = None      # stamp of the first sample sent
        self.node_alive = False             # the node's /diagnostics seen: it is spinning
        self._created = time.monotonic()
        reliable = QoSProfile(depth=REFERENCE_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
        if interface == 'stamped':
            self.pub = self.create_publisher(JointState, REFERENCE_TOPIC, reliable)
            self._ref_msg = JointState(name=[self.joint], position=[0.0])
            self.create_subscription(
                JointState, '/' + private_topic(COMPENSATED_COMMAND_TOPIC, node_under_test),
                self._on_compensated, reliable)
        else:
            self.pub = self.create_publisher(Float64, COMMAND_TOPIC, QoSProfile(depth=10))
            self.create_subscription(
                Float64, '/' + private_topic(POSITIONING_ERROR_TOPIC, node_under_test),
                self._on_error, 100)
        self.create_subscription(JointState, JOINT_STATES_TOPIC, self._on_js, reliable)
        self.create_subscription(DiagnosticArray, DIAGNOSTICS_TOPIC, self._on_diag, 10)
        self.create_timer(1.0 / rate, self._on_timer)

    # -- streaming --
    def elapsed(self) -> float:
        return 0.0 if self.t0_mono is None else time.monotonic() - self.t0_mono

    def started(self) -> bool:
        return self.t0_ns is not None

    def _on_timer(self) -> None:
        now = self.get_clock().now().nanoseconds
        if self.interface == 'float64':
            v = float(self.theta1(self.elapsed()))
            self.pub.publish(Float64(data=v))
            if self.t0_ns is None:
                self.held += 1                  # the first sample, until the node answers
            else:
                self.sent += 1
            return
        if self.t0_ns is None:
            if not self.node_alive and time.monotonic() - self._created < NODE_WAIT_S:
                return      # samples queued while the node starts up would be stale
            # Until the node answers, hold the first sample (it starts the simulation
            # there at rest) 50 times a second.  Every stamp lies on one grid of the
            # sample period from the first one on: the node's time base and its dt steps
            # then line up with the stream's, as in the offline run of the same samples.
            if self._grid0 is None:
                self._grid0 = now
            if now - self._last_hold >= HOLD_PERIOD_NS:
                stamp = self._grid0 + (now - self._grid0) // self.period_ns * self.period_ns
                if stamp > self._last_hold:
                    self._publish_ref(stamp, float(self.theta1(0.0)))
                    self._last_hold = stamp
                    self.held += 1
            return
        # every grid sample whose instant is at most preview + lead ahead, in stamp order
        horizon = now + int((self.preview + self.lead) * 1e9)
        n = 0
        while n < MAX_BURST:
            stamp = self.t0_ns + self.k_next * self.period_ns
            if stamp > horizon:
                break
            self._publish_ref(stamp, float(self.theta1(self.k_next * self.period_ns * 1e-9)))
            self.k_next += 1
            self.sent += 1
            n += 1

    def _publish_ref(self, stamp_ns: int, value: float) -> None:
        m = self._ref_msg
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
        m.position[0] = value
        self.pub.publish(m)

    def _start(self) -> None:
        now = self.get_clock().now().nanoseconds
        self.t0_mono = time.monotonic()
        if self.interface == 'stamped' and self._grid0 is not None:
            # the stream starts on the hold samples' grid, after the last of them
            k = -(-(now - self._grid0) // self.period_ns)
            self.t0_ns = max(self._grid0 + k * self.period_ns,
                             int(self._last_hold) + self.period_ns)
        else:
            self.t0_ns = now

    # -- what the node says --
    def _pattern_time(self, stamp: Any) -> float:
        ns = stamp.sec * 1_000_000_000 + stamp.nanosec
        return (ns - self.t0_ns) * 1e-9 if self.t0_ns is not None else -1.0

    def _on_js(self, msg: JointState) -> None:
        self.n_js += 1
        if self.t0_ns is None:
            self._start()
            return
        if self.interface != 'stamped' or len(msg.position) < 4:
            return
        t = self._pattern_time(msg.header.stamp)
        if t < 0.0:
            return                          # a prediction of the hold phase
        e = msg.position[3] - self.output_per_input * float(self.theta1(t))
        self._record(t, e)

    def _on_error(self, msg: Float64) -> None:
        self.n_err += 1
        if self.t0_ns is not None:
            self._record(self.elapsed(), msg.data)

    def _record(self, t: float, e: float) -> None:
        self.error, self.t_error = e, t
        self.peak_all = max(self.peak_all, abs(e))
        done = self.tracker.add(t, e)
        if done is not None:
            self.last_move = done
            self.new_moves.append(done)

    def _on_compensated(self, msg: JointState) -> None:
        if self.t0_ns is None or not msg.position:
            return
        now = self.get_clock().now().nanoseconds
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        if stamp < self.t0_ns:
            return
        self.n_cc += 1
        self.latency_ns.append(stamp - now)       # > 0: arrived before its instant
        self.tracker.add_command((stamp - self.t0_ns) * 1e-9, msg.position[0])
        self.delta = msg.position[0] - float(self.theta1((stamp - self.t0_ns) * 1e-9))

    def _on_diag(self, msg: DiagnosticArray) -> None:
        for s in msg.status:
            if s.name.startswith(f'{self.target}:'):
                self.node_alive = True
            if s.name.endswith(': simulation'):
                self.diag = {kv.key: kv.value for kv in s.values}

    def status_line(self, width: int = LINE_WIDTH) -> str:
        if self.t0_ns is None:
            return fit(f'waiting for the {self.target} node (joint_states) ...', width - 1)
        extra = f' ff{urad(self.delta, 8, True)}' if self.interface == 'stamped' else ''
        return format_status(self.t_error, self.error, max(50e-6, self.peak_all),
                             self.last_move, extra, width)


def node_parameters(node: Node, ex: Any, target: str, names: list[str],
                    timeout: float = 5.0) -> dict[str, Any]:
    """Values of the target node's parameters (empty if it does not answer)."""
    cli = node.create_client(GetParameters, f'/{target}/get_parameters')
    try:
        if not cli.wait_for_service(timeout_sec=timeout):
            return {}
        fut = cli.call_async(GetParameters.Request(names=names))
        ex.spin_until_future_complete(fut, timeout_sec=timeout)
        if not fut.done() or fut.result() is None:
            return {}
        out = {}
        for name, v in zip(names, fut.result().values):
            out[name] = {1: v.bool_value, 2: v.integer_value, 3: v.double_value,
                         4: v.string_value}.get(v.type)
        return out
    finally:
        node.destroy_client(cli)


def _parse(argv: list[str]) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog='demo_commander', description=__doc__.split('\n\n')[0])
    ap.add_argument('--pattern', choices=('paper', 'slew'), default='paper')
    ap.add_argument('--interface', choices=('stamped', 'float64'), default='stamped',
                    help='stamped: worm_angle_reference + ~/compensated_command (default); '
                         'float64: worm_angle_command')
    ap.add_argument('--duration', type=float, default=20.0,
                    help='seconds of streaming after the node answers [20]')
    ap.add_argument('--rate', type=float, default=1000.0, help='reference rate [Hz] (1000)')
    ap.add_argument('--preview', type=float, default=None,
                    help='stamped: stream this many seconds ahead [default: the node\'s '
                         'compensation.preview_time]')
    ap.add_argument('--lead', type=float, default=0.05,
                    help='stamped: stream this much further ahead, so that each correction '
                         'arrives before its instant and a late timer of this process (a '
                         'loaded machine) does not pause the stream [0.05 s]')
    ap.add_argument('--move-period', type=float, default=0.5,
                    help='paper: seconds between moves [0.5]')
    ap.add_argument('--slew-rate', type=float, default=2.0,
                    help='slew: worm rate [rad/s] (2.0: antenna ~2 deg/s)')
    ap.add_argument('--slew-period', type=float, default=2.0,
                    help='slew: seconds between reversals [2.0]')
    ap.add_argument('--startup-timeout', type=float, default=120.0,
                    help='seconds to wait for the node (first start compiles numba) [120]')
    ap.add_argument('--node-name', default='worm_gear_sim')
    ap.add_argument('--config', default=None,
                    help='the node\'s parameter file (ratio, joint names, model for the '
                         'offline comparison) [config/worm_gear_sim.yaml]')
    ap.add_argument('--no-offline', action='store_true',
                    help='skip the offline comparison at the end')
    opts = ap.parse_args(argv)
    if not (opts.rate > 0 and opts.duration > 0 and opts.move_period > 0
            and opts.slew_period > 0):
        ap.error('--rate, --duration, --move-period and --slew-period must be > 0')
    if opts.preview is not None and not 0.0 <= opts.preview <= 1.0:
        ap.error('--preview must be within [0, 1] s')
    if not 0.0 <= opts.lead <= 0.5:
        ap.error('--lead must be within [0, 0.5] s')
    return opts



def main(args: list[str] | None = None, out: TextIO | None = None) -> int:
    argv = sys.argv if args is None else args
    opts = _parse(remove_ros_args(args=argv)[1:])
    out = out or sys.stdout
    tty = out.isatty()
    width = min(LINE_WIDTH, shutil.get_terminal_size((LINE_WIDTH, 24)).columns) if tty \
        else LINE_WIDTH
    from .run import after_shutdown, leave, make_executor
    cfg = load_config(opts.config) if opts.config else load_config()
    # rclpy.init() as a context manager exists only from Kilted (rclpy 9) on: on Jazzy
    # (rclpy 7.1) it returns None, so init, then try_shutdown in a finally.
    rclpy.init(args=argv)
    node = ex = None
    try:
        node = DemoCommander(opts.pattern, opts.rate, opts.node_name, opts.move_period,
                             opts.slew_rate, opts.slew_period, opts.interface,
                             opts.preview or 0.0, opts.lead, cfg)
        ex = make_executor('events')
        ex.add_node(node)
        never = Future()
        topic = REFERENCE_TOPIC if opts.interface == 'stamped' else COMMAND_TOPIC
        print(fit(f'demo: {opts.pattern} pattern, {node.resolve_topic_name(topic)} at '
                  f'{opts.rate:g} Hz'), file=out, flush=True)
        ratio = 1 / node.output_per_input
        print(fit(f'      antenna error e = theta4 - theta1 l_w/r_g (ratio 1:{ratio:.4g})'
                  + ('' if tty else '; one line per move')), file=out, flush=True)
        t_start = time.monotonic()
        last_print = 0.0
        compensated: bool | None = None
        asked = False
        while True:
            ex.spin_until_future_complete(never, timeout_sec=0.05)
            now = time.monotonic()
            if not node.started() and now - t_start > opts.startup_timeout:
                print(fit(f'no joint_states within {opts.startup_timeout:g} s: is the node '
                          'running (same ROS_DOMAIN_ID)?'), file=out, flush=True)
                return 1
            if node.started() and not asked:
                asked = True
                p = node_parameters(node, ex, opts.node_name,
                                    ['node.compensation_applied',
                                     'compensation.preview_time'])
                compensated = p.get('node.compensation_applied')
                node.tracker.use_commands = bool(compensated)
                if p.get('compensation.preview_time') is not None:
                    node.node_preview = float(p['compensation.preview_time'])
                    if opts.preview is None:
                        node.preview = node.node_preview
                if not tty:
                    state = {True: 'applied', False: 'not applied',
                             None: 'unknown'}[compensated]
                    print(fit(f'      node {opts.node_name}: feed-forward {state}'
                              + (f', preview {node.preview * 1e3:g} ms, '
                                 f'{(node.preview + node.lead) * 1e3:g} ms ahead'
                                 if opts.interface == 'stamped' else '')), file=out,
                          flush=True)
            ending = node.started() and node.elapsed() >= opts.duration
            if tty and now - last_print >= 0.1 and not ending:
                out.write('\r' + node.status_line(width) + '\x1b[K')
                out.flush()
                last_print = now
            elif not tty:   # before the end test: a move completed in the last spin is listed
                for m in node.new_moves:
                    if m is node.tracker.moves[0]:
                        print(MOVE_HEADER, file=out, flush=True)
                    print(format_move(m), file=out, flush=True)
            node.new_moves.clear()
            if ending:
                break
        if tty:
            out.write('\r' + node.status_line(width) + '\x1b[K\n')
        ex.shutdown(1.0)
        summary(node, opts, compensated, out)
    except (KeyboardInterrupt, ExternalShutdownException):
        print('', file=out)
    except Exception:
        if not after_shutdown(ex):      # e.g. the executor's registration cut short
            raise
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return leave(0)


if __name__ == '__main__':
    sys.exit(main())
