# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``worm_gear_sim_calibrate``: calibrate a running node against its drive in one command.

It reads the node's parameters, streams the core's excitation to the servo, records the
encoders, fits and validates with the core's ``calibrate``, writes FITTED.json, FITTED.png
and (accepted) FITTED.yaml, and, accepted, sets the fitted keys on the node in one atomic
parameter set.  Usage and exit statuses: docs/identification.md.  Only the standard library
is imported at the top, so the SIGINT handler is in place before numpy and rclpy load.
"""

from __future__ import annotations

import argparse
import math
import os
import signal
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .teardown import teardown_deadline

if TYPE_CHECKING:
    import numpy as np

__all__ = ['main', 'RosDrive']

PROG = 'worm_gear_sim_calibrate'
INTERRUPTED = f'{PROG}: interrupted; nothing applied'
EXIT_INTERRUPTED = 130    # 128 + SIGINT, as a shell reports it

LEAD_S = 0.05             # references are sent this far ahead of their instant
SETTLE_WINDOW_S = 0.05    # at rest: the measured antenna angle moves less than
SETTLE_TOL_RAD = 1e-6     # this over that window
MEASURED_DEPTH = 2000     # encoder samples queued (2 s at 1 kHz)
OUTPUTS = {'theta2': 1, 'theta3': 2, 'theta4': 3}     # index in node.joint_names


class CalibrationAborted(Exception):
    """The drive or the node did not cooperate: one line, exit status 2."""


def _args(argv: list[str]) -> argparse.Namespace:
    from ..identification.calibration_options import add_limit_options
    ap = argparse.ArgumentParser(prog=PROG,
                                 description=__doc__.split('\n\n')[0])
    ap.add_argument('--fit', action='append', required=True, metavar='KEY[,KEY...]',
                    help='parameters to fit (repeatable)')
    ap.add_argument('-o', '--output', required=True, metavar='FITTED.yaml')
    ap.add_argument('--node', default='/worm_gear_sim', help='the node to calibrate')
    ap.add_argument('--servo-topic', required=True,
                    help="the servo's stamped reference input (JointState)")
    ap.add_argument('--measured-topic', default='measured_joint_states',
                    help="the drive's encoders (JointState; default: %(default)s)")
    ap.add_argument('--measure', default='theta4', help='measured outputs (default theta4)')
    ap.add_argument('--outputs', default=None, help='outputs to fit (as for identify)')
    ap.add_argument('--accept', type=float, default=0.05, metavar='SHARE')
    ap.add_argument('--settle-timeout', type=float, default=10.0, metavar='S',
                    help='longest wait for the drive to come to rest (default: %(default)s)')
    ap.add_argument('--dry-run', action='store_true', help='do not set the fitted values')
    ap.add_argument('--yes', '-y', action='store_true',
                    help='do not ask before moving the axis (needed when stdin is not a '
                    'terminal)')
    ap.add_argument('--serial', action='store_true', help='fit in this process (no Dask)')
    ap.add_argument('--no-plot', action='store_true')
    ap.add_argument('--no-progress', action='store_true', help='no progress bar')
    add_limit_options(ap)
    return ap.parse_args(argv)


class RosDrive:
    """The drive behind a servo, as the core's ``run(move) -> Record``: streams each move to
    the servo (continuing from where the last one ended), records the encoders."""

    def __init__(self, node: Any, executor: Any, servo_topic: str, measured_topic: str,
                 joint_names: list[str], measure: list[str], rate: float,
                 settle_timeout: float) -> None:
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import JointState
        self.node, self.ex = node, executor
        self.rate, self.settle_timeout = rate, settle_timeout
        self.joints = joint_names
        self.measure = measure
        self.pub = node.create_publisher(JointState, servo_topic, QoSProfile(
            depth=1000, reliability=ReliabilityPolicy.RELIABLE))
        self.samples: list[tuple[int, dict[str, float]]] = []
        # best effort (takes a reliable or a best-effort encoder topic), and deep: while this
        # process streams a move it takes one sample per spin, and a queue of 5 (the sensor
        # QoS) lost up to a fifth of a move's samples on a loaded machine
        node.create_subscription(JointState, measured_topic, self._on_measured, QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=MEASURED_DEPTH,
            reliability=ReliabilityPolicy.BEST_EFFORT))
        self.msg = JointState(name=[joint_names[0]], position=[0.0])
        self.position = 0.0        # the last commanded worm angle
        self.next_ns = 0           # the next sample's stamp
        self.servo_topic, self.measured_topic = servo_topic, measured_topic

    def _on_measured(self, msg: Any) -> None:
        st = msg.header.stamp
        names = list(msg.name)
        vals = {}
        for o in self.measure:
            j = self.joints[OUTPUTS[o]]
            if j in names and names.index(j) < len(msg.position):
                vals[o] = float(msg.position[names.index(j)])
        if vals:
            self.samples.append((st.sec * 10**9 + st.nanosec, vals))

    def _now(self) -> int:
        return self.node.get_clock().now().nanoseconds

    def _stream(self, values: np.ndarray) -> tuple[int, int]:
        """Send ``values`` at the rate, LEAD_S ahead of their instants; (first, last)
        stamps."""
        period = int(round(1e9 / self.rate))
        if self.next_ns < self._now() + int(LEAD_S * 1e9):
            self.next_ns = self._now() + int(LEAD_S * 1e9)
        first = self.next_ns
        k = 0
        while k < values.size:
            horizon = self._now() + int(LEAD_S * 1e9)
            while k < values.size and self.next_ns <= horizon:
                m = self.msg
                m.header.stamp.sec, m.header.stamp.nanosec = divmod(self.next_ns, 10**9)
                m.position[0] = float(values[k])
                self.pub.publish(m)
                self.next_ns += period
                k += 1
            self.ex.spin_once(timeout_sec=0.001)
        self.position = float(values[-1])
        return first, self.next_ns - period

    def _wait_for(self, stamp_ns: int, timeout: float) -> None:
        """Spin until a measurement stamped at or after ``stamp_ns`` came in, holding the
        last position meanwhile (a servo keeps streaming its reference: a drive that fell
        behind and dropped the last samples answers the next ones)."""
        import numpy as np
        t0 = time.monotonic()
        hold = np.full(max(1, int(self.rate * 0.005)), self.position)
        while not (self.samples and self.samples[-1][0] >= stamp_ns):
            if time.monotonic() - t0 > timeout:
                raise CalibrationAborted(
                    f'no measured joint states on {self.measured_topic} after the command '
                    f'(is the encoder topic right, does the servo take {self.servo_topic}?)')
            self._stream(hold)

    def settle(self) -> None:
        """Hold the position until the measured antenna is at rest (or the timeout)."""
        import numpy as np
        t0 = time.monotonic()
        hold = np.full(int(self.rate * SETTLE_WINDOW_S), self.position)
        while True:
            first, last = self._stream(hold)
            self._wait_for(last, max(2.0, self.settle_timeout))
            window = [v for s, v in self.samples if first <= s <= last]
            o = self.measure[-1]
            ys = [v[o] for v in window if o in v]
            if len(ys) >= 3 and max(ys) - min(ys) <= SETTLE_TOL_RAD:
                return
            if time.monotonic() - t0 > self.settle_timeout:
                raise CalibrationAborted(
                    f'the drive did not come to rest within {self.settle_timeout:g} s '
                    f'({o} moved {max(ys) - min(ys) if ys else math.nan:.3g} rad over '
                    f'{SETTLE_WINDOW_S:g} s): raise --settle-timeout or check the servo')

    def __call__(self, move: Any) -> Any:
        import numpy as np

        from ..records import Record
        self.settle()
        n = int(math.floor(move.t_end * self.rate + 1e-9)) + 1
        x = move.profile.theta1(np.arange(n) / self.rate)
        x = x - x[0] + self.position             # from where the drive is
        self.samples.clear()
        first, last = self._stream(x)
        try:
            self._wait_for(last, 5.0)
        except CalibrationAborted:
            pass                                 # the core names a record that stops
        window = [(s, v) for s, v in self.samples if first <= s <= last]
        got = _increasing(window)
        if len(got) < len(window):
            self.node.get_logger().warning(
                f'{move.name}: measured samples out of order or repeated dropped')
        stamps = np.array([s for s, _ in got], dtype=np.int64)
        cmd_t = first + np.arange(n, dtype=np.int64) * int(round(1e9 / self.rate))
        measured = {o: np.array([v.get(o, np.nan) for _, v in got]) for o in self.measure}
        t = (stamps - first) / 1e9
        theta1 = np.interp(t, (cmd_t - first) / 1e9, x) if stamps.size else np.empty(0)
        return Record(move.name, t, theta1, measured, t0_ns=int(first),
                      source={'servo_topic': self.servo_topic,
                              'measured_topic': self.measured_topic})


def _increasing(samples: list[tuple[int, dict[str, float]]]
                ) -> list[tuple[int, dict[str, float]]]:
    """The samples whose stamps increase strictly, in arrival order (a sample stamped at or
    before the last one kept is dropped: delivered late, or sent twice)."""
    out: list[tuple[int, dict[str, float]]] = []
    for s, v in samples:
        if not out or s > out[-1][0]:
            out.append((s, v))
    return out


def _node_config(node: Any, executor: Any, target: str) -> Any:
    """The target node's parameter set (its parameter service), as a core Config."""
    from rclpy.parameter import parameter_value_to_python
    from rclpy.parameter_client import AsyncParameterClient

    from ..config.usable import Config, config_from_mapping
    client = AsyncParameterClient(node, target)
    if not client.wait_for_services(timeout_sec=30.0):
        raise CalibrationAborted(f'no node {target} (its parameter services did not answer '
                                 'within 30 s)')
    names = list(Config().to_flat_dict())
    fut = client.get_parameters(names)
    executor.spin_until_future_complete(fut, timeout_sec=30.0)
    if not fut.done() or fut.result() is None:
        raise CalibrationAborted(f'{target} did not return its parameters')
    values = {n: parameter_value_to_python(v) for n, v in zip(names, fut.result().values)}
    return config_from_mapping(values, source=f'{target} parameters'), client


def _exit_interrupted(signum: int, frame: Any) -> None:
    """SIGINT while starting (imports, arguments, ``rclpy.init``): the line, exit 130 at
    once; unwinding could interrupt a C extension's initialisation (see
    :mod:`.signals`)."""
    try:
        print(INTERRUPTED, file=sys.stderr, flush=True)
    finally:
        os._exit(EXIT_INTERRUPTED)


def bad_arguments(opts: argparse.Namespace) -> str | None:
    """The first option out of its range, as one line (None: all valid)."""
    from ..identification.calibration_options import angle_list
    from ..identification.data import IdentificationError
    try:
        angle_list(opts.measure, '--measure')
        angle_list(opts.outputs, '--outputs')
    except IdentificationError as exc:
        return str(exc)
    if Path(opts.output).suffix.lower() not in ('.yaml', '.yml'):
        return f'-o {opts.output}: the fitted parameter file must end in .yaml'
    if not (math.isfinite(opts.accept) and 0 < opts.accept < 1):
        return f'--accept {opts.accept!r}: a share between 0 and 1'
    if not (math.isfinite(opts.settle_timeout) and opts.settle_timeout > 0):
        return (f'--settle-timeout {opts.settle_timeout!r}: a finite number of seconds > 0 '
                '(the longest wait for the drive to come to rest)')
    return None


def consent(opts: argparse.Namespace, stdin: Any = None, stdout: Any = None
            ) -> tuple[int, str] | None:
    """Ask before the axis moves: None to go on, else (exit status, the one line why not).
    ``--yes`` skips the question; a stdin that is not a terminal cannot answer it: refused
    (2, as a bad argument); an answer other than y: 1."""
    if opts.yes:
        return None
    stdin = sys.stdin if stdin is None else stdin
    stdout = sys.stdout if stdout is None else stdout
    if not (hasattr(stdin, 'isatty') and stdin.isatty()):
        return 2, ('stdin is not a terminal, so nobody can confirm that the axis may move: '
                   'give --yes to let the calibration move it; nothing moved')
    stdout.write(f'This streams an excitation to {opts.servo_topic}: the worm axis of '
                 f'{opts.node} moves up to {opts.max_angle:g} rad each way from where it is, '
                 f'at up to {opts.max_rate:g} rad/s and {opts.max_accel:g} rad/s^2, '
                 f'{opts.duration:g} s of moves. Clear the axis. Move it? [y/N] ')
    stdout.flush()
    answer = stdin.readline().strip().lower()
    return None if answer in ('y', 'yes') else (1, 'not confirmed; nothing moved')


def main(argv: list[str] | None = None) -> int:
    """The command (module docstring); Ctrl-C at any point before the fitted set is sent:
    one line, exit 130, nothing applied."""
    previous = signal.signal(signal.SIGINT, _exit_interrupted)
    try:
        opts = _args(sys.argv[1:] if argv is None else argv)
        why = bad_arguments(opts)
        if why is not None:
            print(f'{PROG}: {why}', file=sys.stderr)
            return 2
        refused = consent(opts)
        if refused is not None:
            print(f'{PROG}: {refused[1]}', file=sys.stderr)
            return refused[0]
        # the heavy imports while a Ctrl-C still ends the process at once
        import rclpy
        from rclpy.signals import SignalHandlerOptions

        from ..identification import calibrate as _fit  # noqa: F401
        from ..identification import calibration_report as _report  # noqa: F401
        rclpy.init(args=[], signal_handler_options=SignalHandlerOptions.NO)
        try:
            # from here a Ctrl-C unwinds (KeyboardInterrupt): the node is destroyed cleanly
            signal.signal(signal.SIGINT, signal.default_int_handler)
            return _run(opts, argv)
        except KeyboardInterrupt:
            print(INTERRUPTED, file=sys.stderr)
            return EXIT_INTERRUPTED
        finally:
            signal.signal(signal.SIGINT, signal.SIG_IGN)   # a second Ctrl-C: no traceback
            with teardown_deadline():   # Fast DDS can hang in it (.teardown)
                rclpy.try_shutdown()
    finally:
        signal.signal(signal.SIGINT, previous)


def _run(opts: argparse.Namespace, argv: list[str] | None) -> int:
    from ..identification import FitOptions
    from ..identification.calibrate import calibrate
    from ..identification.calibration_options import limits_of
    from ..identification.calibration_report import StageBar, report_calibration
    from ..identification.data import IdentificationError
    from ..identification.excitation import design_excitation
    from ..schema.validation import ConfigError
    from ..studies.recommendation import calibration_recommendation
    keys = [k.strip() for item in opts.fit for k in item.split(',') if k.strip()]
    measure = [o.strip() for o in opts.measure.split(',') if o.strip()]
    out = Path(opts.output)
    limits = limits_of(opts)
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    node = rclpy.create_node('worm_gear_sim_calibrator')
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    try:
        base, client = _node_config(node, ex, opts.node)
        unknown = [k for k in keys if k not in base.to_flat_dict()]
        if unknown:
            raise CalibrationAborted(f'unknown parameter(s) {", ".join(unknown)}')
        drive = RosDrive(node, ex, opts.servo_topic, opts.measured_topic,
                         list(base.node.joint_names), measure,
                         base.node.publish_rate_hz, opts.settle_timeout)
        t0 = time.perf_counter()
        stages = None
        try:
            stages = StageBar(len(design_excitation(limits, keys, base)),
                              not opts.no_progress)
            res = calibrate(base, keys, limits, drive,
                            options=FitOptions(strategy='robust', serial=opts.serial),
                            outputs=opts.outputs.split(',') if opts.outputs else None,
                            accept_rel=opts.accept, progress=stages)
            advice = calibration_recommendation(res, stages)
        except (IdentificationError, ConfigError) as exc:
            raise CalibrationAborted(str(exc)) from None
        finally:
            if stages is not None:
                stages.close()
        wall = time.perf_counter() - t0
        json_path, _ = report_calibration(
            res, base, keys, limits, out, f'node {opts.node} on {opts.measured_topic}',
            ' '.join(sys.argv if argv is None else ['worm_gear_sim_calibrate', *argv]),
            wall, not opts.no_plot, print, advice, node=opts.node,
            servo_topic=opts.servo_topic, measured_topic=opts.measured_topic)
        if not res.accepted:
            print(f'calibration not accepted: {res.reasons[0]}; nothing applied to '
                  f'{opts.node}, its parameters stay in use (report: {json_path})',
                  file=sys.stderr)
            return 1
        if opts.dry_run:
            print(f'accepted; --dry-run: {opts.node} left unchanged')
            return 0
        fitted = res.config.to_flat_dict()
        params = [Parameter(k, value=float(fitted[k])) for k in keys]
        signal.signal(signal.SIGINT, signal.SIG_IGN)   # the answer is always reported
        fut = client.set_parameters_atomically(params)
        ex.spin_until_future_complete(fut, timeout_sec=30.0)
        result = fut.result().result if fut.done() and fut.result() is not None else None
        if result is None or not result.successful:
            why = result.reason if result is not None else 'no answer within 30 s'
            print(f'{opts.node} refused the fitted set ({why}); nothing applied',
                  file=sys.stderr)
            return 1
        print(f'applied to {opts.node} in one atomic set: ' + ', '.join(
            f'{k} = {fitted[k]:.6g}' for k in keys))
        return 0
    except CalibrationAborted as exc:
        print(f'{PROG}: {exc}; nothing applied', file=sys.stderr)
        return 2
    finally:
        with teardown_deadline():       # Fast DDS can hang in it (.teardown)
            ex.shutdown()
            node.destroy_node()


if __name__ == '__main__':   # pragma: no cover
    sys.exit(main())
