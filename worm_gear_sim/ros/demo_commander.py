# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Demo servo for the worm_gear_sim nodes (``scripts/run_demo.sh``): streams one reference
pattern to one or more nodes (with and without the feed-forward), once every node is ready,
shows the antenna error each predicts live and sums it up move by move, side by side.

    python -m worm_gear_sim.ros.demo_commander --duration 20 --pattern paper

``--interface stamped`` (default, a tracking servo) or ``float64``; patterns from
:mod:`worm_gear_sim.studies.demo_moves`, text from :mod:`.demo_report`; it stops the
nodes of ``--node-pid`` before its stream ends (a quiet stop); exit code 1 if a node never
answers.
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import signal
import sys
import time
from collections.abc import Sequence
from typing import Any, TextIO

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.srv import GetParameters
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future
from rclpy.utilities import remove_ros_args
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from ..config.files import load_config
from ..config.usable import Config
from ..records.topics import (
    COMMAND_TOPIC,
    COMPENSATED_COMMAND_TOPIC,
    DIAGNOSTICS_TOPIC,
    POSITIONING_ERROR_TOPIC,
    REFERENCE_TOPIC,
)
from ..studies.demo_moves import MoveSummary, MoveTracker, demo_plan
from .demo_report import (
    LINE_WIDTH,
    fit,
    format_row,
    format_status,
    group_label,
    legend,
    node_lines,
    summary,
    table_header,
)
from .interface import REFERENCE_DEPTH
from .teardown import teardown_deadline

__all__ = ['DemoCommander', 'Watched', 'main']

MAX_BURST = 100                 # samples per timer call after a stall (the node queues 1000)
HOLD_PERIOD_NS = 20_000_000     # the first sample is repeated every 20 ms until the node answers
STOP_WAIT_S = 10.0              # at the end, the nodes' processes stop within this


def full_name(name: str) -> str:
    """'worm_gear_sim' -> '/worm_gear_sim'."""
    return '/' + name.strip('/')


class Watched:
    """A node under test, as the demo sees it: its answers, its moves, whether it applies
    the feed-forward (``compensated``, asked once it answers)."""

    def __init__(self, name: str, tracker: MoveTracker) -> None:
        self.name = full_name(name)
        self.tracker = tracker
        self.compensated: bool | None = None
        self.alive = False              # its /diagnostics seen: it runs, it is subscribed
        self.answered = False           # it answered the first (held) sample
        self.n_err = 0
        self.error = math.nan
        self.peak_all = 0.0
        self.last_move: MoveSummary | None = None

    @property
    def label(self) -> str:
        return group_label(self.compensated, self.name)

    def record(self, t: float, e: float) -> None:
        self.error = e
        self.peak_all = max(self.peak_all, abs(e))
        done = self.tracker.add(t, e)
        if done is not None:
            self.last_move = done


# ---- the ROS node ----------------------------------------------------------------------------
class DemoCommander(Node):
    """Streams the pattern and tracks what each node under test predicts."""

    def __init__(self, pattern: str = 'paper', rate: float = 1000.0,
                 nodes: Sequence[str] = ('worm_gear_sim',), move_period: float = 0.5,
                 slew_rate: float = 2.0, slew_period: float = 2.0,
                 interface: str = 'stamped', preview: float = 0.0, lead: float = 0.0,
                 config: Config | None = None, **kwargs: Any):
        super().__init__('demo_commander', **kwargs)
        if interface not in ('stamped', 'float64'):
            raise ValueError(f'interface must be stamped or float64, got {interface!r}')
        if not nodes:
            raise ValueError('at least one node under test')
        self.cfg = config if config is not None else load_config()
        plan = demo_plan(pattern, self.cfg, move_period, slew_rate, slew_period)
        self.model = plan.model             # one model: ratio, ringing period, offline moves
        self.output_per_input = plan.model.output_per_input
        self.theta1, self.segments = plan.theta1, plan.segments
        # the Float64 path's answers carry the stamps of the node's wall-clock ticks, which
        # a busy machine delays by tens of ms
        gap = 0.02 if interface == 'stamped' else 0.1
        self.watched = [Watched(n, MoveTracker(self.segments, plan.mode_hz, max_gap=gap))
                        for n in nodes]
        self.shown = list(self.watched)     # display order: without, then with feed-forward
        self.measuring = True               # False once the demo ends: nothing more counted
        self._t_end: float | None = None
        for w in self.watched:
            w.tracker.use_commands = False  # until the node says its feed-forward is applied
        self.pattern, self.interface, self.rate = pattern, interface, rate
        self.preview = preview              # s: the node's preview: stream this far ahead
        self.lead = lead                    # s: ... plus this, so corrections come in time
        self.node_preview: float | None = None   # the node's compensation.preview_time
        self.period_ns = int(round(1e9 / rate))
        self.joint = self.cfg.node.joint_names[0]
        self.t0_ns: int | None = None       # stamp of grid sample 0 (stream running)
        self.t0_mono: float | None = None
        self.k_next = 0                     # next grid sample to publish
        self.sent = self.held = 0
        self.n_cc = 0
        self.latency_ns: list[int] = []     # stamp - reception of compensated commands
        self._last_hold = -math.inf
        self._grid0: int | None = None      # stamp of the first sample sent
        reliable = QoSProfile(depth=REFERENCE_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
        if interface == 'stamped':
            self.pub = self.create_publisher(JointState, REFERENCE_TOPIC, reliable)
            self._ref_msg = JointState(name=[self.joint], position=[0.0])
            self.create_subscription(
                JointState, self._private(self.watched[0], COMPENSATED_COMMAND_TOPIC),
                self._on_compensated, reliable)
        else:
            self.pub = self.create_publisher(Float64, COMMAND_TOPIC, QoSProfile(depth=10))
        for w in self.watched:
            self.create_subscription(JointState, self._private(w, POSITIONING_ERROR_TOPIC),
                                     lambda m, w=w: self._on_error(w, m), reliable)
        self.create_subscription(DiagnosticArray, DIAGNOSTICS_TOPIC, self._on_diag, 10)
        self.create_timer(1.0 / rate, self._on_timer)

    @staticmethod
    def _private(w: Watched, topic: str) -> str:
        return f'{w.name}/{topic.removeprefix("~/")}'

    # -- streaming --
    def elapsed(self) -> float:
        """Seconds of streaming, up to the end of the measurement (:meth:`stop_measuring`)."""
        if self.t0_mono is None:
            return 0.0
        return (self._t_end if self._t_end is not None else time.monotonic()) - self.t0_mono

    def stop_measuring(self) -> None:
        """The end: nothing more is counted and the streaming time stops."""
        self.measuring = False
        self._t_end = time.monotonic()

    def started(self) -> bool:
        return self.t0_ns is not None

    def ready(self) -> bool:
        """Every node runs (its /diagnostics came)."""
        return all(w.alive for w in self.watched)

    def _on_timer(self) -> None:
        if not self.ready():
            return      # a sample sent to a node still starting is lost or found stale
        now = self.get_clock().now().nanoseconds
        if self.interface == 'float64':
            self.pub.publish(Float64(data=float(self.theta1(self.elapsed()))))
            if self.t0_ns is None:
                self.held += 1                  # the first sample, until the nodes answer
            elif self.measuring:
                self.sent += 1
            return
        if self.t0_ns is None:
            # Until the nodes answer, hold the first sample (it starts the simulation there
            # at rest) 50 times a second.  Every stamp lies on one grid of the sample
            # period from the first one on: the node's time base and its dt steps then line
            # up with the stream's, as in the offline run of the same samples.
            if self._grid0 is None:
                self._grid0 = now
            if now - self._last_hold >= HOLD_PERIOD_NS:
                self._hold_to(self._grid0 + (now - self._grid0) // self.period_ns
                              * self.period_ns)
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
            self.sent += self.measuring
            n += 1

    def _hold_to(self, stamp: int) -> None:
        """The first sample held up to ``stamp`` (on the grid): one every hold period from
        the last one, so that a late timer (a busy machine) leaves no gap between two stamps
        longer than a hold period, which a node would have to skip (node.max_catch_up) with
        a warning."""
        if stamp <= self._last_hold:
            return
        value = float(self.theta1(0.0))
        if math.isfinite(self._last_hold):
            step = max(1, HOLD_PERIOD_NS // self.period_ns) * self.period_ns
            k = int(self._last_hold) + step
            for _ in range(MAX_BURST):
                if k >= stamp:
                    break
                self._publish_ref(k, value)
                self.held += 1
                k += step
        self._publish_ref(stamp, value)
        self._last_hold = stamp
        self.held += 1

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
            self._hold_to(self.t0_ns - self.period_ns)   # no gap before the stream
        else:
            self.t0_ns = now

    # -- what the nodes say --
    def _pattern_time(self, stamp: Any) -> float:
        ns = stamp.sec * 1_000_000_000 + stamp.nanosec
        return (ns - self.t0_ns) * 1e-9 if self.t0_ns is not None else -1.0

    def _on_error(self, w: Watched, msg: JointState) -> None:
        w.n_err += 1
        if self.t0_ns is None:
            w.answered = True
            if all(x.answered for x in self.watched):
                self._start()
            return
        t = self._pattern_time(msg.header.stamp)
        if t >= 0.0 and msg.position and self.measuring:     # t < 0: the hold phase
            w.record(t, msg.position[0])

    def _on_compensated(self, msg: JointState) -> None:
        if self.t0_ns is None or not msg.position or not self.measuring:
            return
        now = self.get_clock().now().nanoseconds
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        if stamp < self.t0_ns:
            return
        self.n_cc += 1
        self.latency_ns.append(stamp - now)       # > 0: arrived before its instant
        t = (stamp - self.t0_ns) * 1e-9
        for w in self.watched:                    # the command applied to the drive
            w.tracker.add_command(t, msg.position[0])

    def _on_diag(self, msg: DiagnosticArray) -> None:
        for s in msg.status:
            for w in self.watched:
                if s.name.startswith(f'{w.name.lstrip("/")}:'):
                    w.alive = True

    def status_line(self, width: int = LINE_WIDTH) -> str:
        errors = [(w.label.split()[0], w.error) for w in self.shown]
        return format_status(self.elapsed(), errors, [w.last_move for w in self.shown], width)


def node_parameters(node: Node, ex: Any, target: str, names: list[str],
                    timeout: float = 5.0) -> dict[str, Any]:
    """Values of the target node's parameters (``target`` its full name; empty if it does
    not answer)."""
    cli = node.create_client(GetParameters, f'{full_name(target)}/get_parameters')
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


def _process_gone(pid: int) -> bool:
    """The process has ended (or is a zombie its parent has not collected yet)."""
    try:
        with open(f'/proc/{pid}/stat', encoding='ascii') as fh:
            return fh.read().rpartition(')')[2].split()[0] in ('Z', 'X')
    except FileNotFoundError:
        return True
    except OSError:
        pass
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        pass
    return False


def stop_nodes(ex: Any, pids: Sequence[int], timeout: float = STOP_WAIT_S) -> None:
    """SIGTERM to the nodes' processes, spinning (the stream goes on) until they are gone:
    a node that saw the stream stop first would report a paused stream."""
    for pid in pids:
        try:
            os.kill(pid, signal.SIGTERM)
        except ProcessLookupError:
            pass
    never = Future()
    deadline = time.monotonic() + timeout
    while not all(_process_gone(p) for p in pids) and time.monotonic() < deadline:
        ex.spin_until_future_complete(never, timeout_sec=0.02)


class StopRequest:
    """SIGINT and SIGTERM set a flag (rclpy runs without its own handlers): the demo then
    ends as at the end of its duration, the nodes first, with exit code 0."""

    def __init__(self) -> None:
        self.requested = False
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._on_signal)

    def _on_signal(self, signum: int, frame: Any) -> None:
        self.requested = True


def _parse(argv: list[str]) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog='demo_commander', description=__doc__.split('\n\n')[0])
    ap.add_argument('--pattern', choices=('paper', 'slew'), default='paper')
    ap.add_argument('--interface', choices=('stamped', 'float64'), default='stamped',
                    help='stamped: worm_angle_reference + ~/compensated_command (default); '
                         'float64: worm_angle_command')
    ap.add_argument('--duration', type=float, default=20.0,
                    help='seconds of streaming after the nodes answer [20]')
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
    ap.add_argument('--startup-timeout', type=float, default=180.0,
                    help='seconds to wait for the nodes (a first start compiles the model\'s '
                         'kernels) [180]')
    ap.add_argument('--node', '--node-name', dest='nodes', action='append', default=None,
                    metavar='NAME', help='a node under test, by its full name (repeatable, '
                    'at most two side by side; the first one\'s corrections are taken) '
                    '[worm_gear_sim]')
    ap.add_argument('--node-pid', type=int, action='append', default=[], metavar='PID',
                    help='a node\'s process, stopped (SIGTERM) at the end while the stream '
                    'still runs (scripts/run_demo.sh; repeatable)')
    ap.add_argument('--config', default=None,
                    help='the node\'s parameter file (ratio, joint names, model for the '
                         'offline comparison) [config/worm_gear_sim.yaml]')
    ap.add_argument('--no-offline', action='store_true',
                    help='skip the offline comparison at the end')
    opts = ap.parse_args(argv)
    opts.nodes = opts.nodes or ['worm_gear_sim']
    if not (opts.rate > 0 and opts.duration > 0 and opts.move_period > 0
            and opts.slew_period > 0):
        ap.error('--rate, --duration, --move-period and --slew-period must be > 0')
    if opts.preview is not None and not 0.0 <= opts.preview <= 1.0:
        ap.error('--preview must be within [0, 1] s')
    if not 0.0 <= opts.lead <= 0.5:
        ap.error('--lead must be within [0, 0.5] s')
    if len(opts.nodes) > 2:
        ap.error('--node: at most two nodes side by side (80 columns)')
    return opts


def _ask_nodes(node: DemoCommander, ex: Any, opts: argparse.Namespace) -> None:
    """Each node's compensation.applied (its tracker then follows the applied command) and
    the first node's preview, which sets how far ahead the stream goes; the nodes are shown
    without the feed-forward first."""
    for i, w in enumerate(node.watched):
        p = node_parameters(node, ex, w.name, ['node.compensation_applied',
                                               'compensation.preview_time'])
        w.compensated = p.get('node.compensation_applied')
        w.tracker.use_commands = bool(w.compensated)
        if i == 0 and p.get('compensation.preview_time') is not None:
            node.node_preview = float(p['compensation.preview_time'])
            if opts.preview is None:
                node.preview = node.node_preview
    node.shown = sorted(node.watched, key=lambda w: {False: 0, True: 1}.get(w.compensated, 2))


def _introduce(node: DemoCommander, opts: argparse.Namespace, say: Any) -> None:
    """The first lines: the pattern and its topic, the error shown, the nodes waited for."""
    topic = REFERENCE_TOPIC if opts.interface == 'stamped' else COMMAND_TOPIC
    say(f'demo: {opts.pattern} pattern, {node.resolve_topic_name(topic)} at {opts.rate:g} Hz')
    ratio = 1 / node.output_per_input
    say(f'      antenna error e = theta4 - theta1_ref l_w/r_g (ratio 1:{ratio:.4g}) of '
        f'{len(node.watched)} node{"s" if len(node.watched) > 1 else ""}')
    say('      waiting for ' + ', '.join(w.name.lstrip('/') for w in node.watched))
    say('      (a first start compiles the model\'s kernels: a minute or more)')


def _on_start(node: DemoCommander, ex: Any, opts: argparse.Namespace, say: Any, *,
              table: bool, ready_after: float) -> None:
    """Every node answered: ask their parameters, say what each shows, and (not on a
    terminal) the table's legend and header."""
    _ask_nodes(node, ex, opts)
    for w in node.shown:
        for line in node_lines(w.name, w.compensated):
            say(line)
    if opts.interface == 'stamped':
        say(f'      stream {(node.preview + node.lead) * 1e3:g} ms ahead (preview '
            f'{node.preview * 1e3:g} ms), ready after {ready_after:.1f} s')
    if table:
        for line in legend() + table_header([w.label for w in node.shown]):
            say(line)


def _print_rows(node: DemoCommander, out: TextIO, row: int) -> int:
    """The table's rows of the moves every node has completed from ``row`` on; the next."""
    while all(w.tracker.next_index > row for w in node.watched):
        done = [next((m for m in w.tracker.moves if m.index == row), None)
                for w in node.shown]
        if any(m is not None for m in done):
            print(format_row(done), file=out, flush=True)
        row += 1
    return row


def main(args: list[str] | None = None, out: TextIO | None = None) -> int:
    argv = sys.argv if args is None else args
    opts = _parse(remove_ros_args(args=argv)[1:])
    out = out or sys.stdout
    tty = out.isatty()
    width = min(LINE_WIDTH, shutil.get_terminal_size((LINE_WIDTH, 24)).columns) if tty \
        else LINE_WIDTH

    def say(line: str) -> None:
        print(fit(line), file=out, flush=True)
    from .run import make_executor
    cfg = load_config(opts.config) if opts.config else load_config()
    # rclpy.init() as a context manager exists only from Kilted (rclpy 9) on: on Jazzy
    # (rclpy 7.1) it returns None, so init, then try_shutdown in a finally.  Its signal
    # handlers stay out: a stop signal ends the demo through its own stop (StopRequest).
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    stop = StopRequest()
    node = ex = None
    rc = 0
    try:
        node = DemoCommander(opts.pattern, opts.rate, opts.nodes, opts.move_period,
                             opts.slew_rate, opts.slew_period, opts.interface,
                             opts.preview or 0.0, opts.lead, cfg)
        ex = make_executor('events')
        ex.add_node(node)
        never = Future()
        _introduce(node, opts, say)
        t_start = time.monotonic()
        last_print = 0.0
        asked = False
        row = 0                                   # the next move to print
        while not stop.requested:
            ex.spin_until_future_complete(never, timeout_sec=0.05)
            now = time.monotonic()
            if not node.started() and now - t_start > opts.startup_timeout:
                missing = [w.name.lstrip('/') for w in node.watched
                           if not (w.alive and w.answered)]
                say(f'no answer from {", ".join(missing)} within {opts.startup_timeout:g} s: '
                    'is the node running (same ROS_DOMAIN_ID)?')
                rc = 1
                break
            if node.started() and not asked:
                asked = True
                _on_start(node, ex, opts, say, table=not tty, ready_after=now - t_start)
            ending = node.started() and node.elapsed() >= opts.duration
            if tty and asked and now - last_print >= 0.1 and not ending:
                out.write('\r' + node.status_line(width) + '\x1b[K')
                out.flush()
                last_print = now
            elif not tty:   # before the end test: a move completed in the last spin is listed
                row = _print_rows(node, out, row)
            if ending:
                break
        # the end: the nodes stop first, while the stream goes on, then the stream; what
        # comes meanwhile is not counted (the figures are those of the duration)
        node.stop_measuring()
        stop_nodes(ex, opts.node_pid)
        if tty and node.started():
            out.write('\r' + node.status_line(width) + '\x1b[K\n')
        if node.started() and rc == 0:
            summary(node, opts, out)
        elif rc == 0:
            say('demo: stopped before the nodes answered')
    finally:
        with teardown_deadline(rc if sys.exc_info()[1] is None else None):
            if ex is not None:
                ex.shutdown(1.0)
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
    return rc


if __name__ == '__main__':
    sys.exit(main())
