# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Demo command stream for the worm_gear_sim node, with a live terminal display.

Publishes ``worm_angle_command`` (std_msgs/Float64, rad) at ``--rate`` Hz like a servo
would, following one of two patterns built from the core's profiles (no physics here):

* ``paper``: the paper's 18-step move (0.1131 rad of worm in 20 ms, trapezoidal), forward
  then back, every ``--move-period`` seconds;
* ``slew``: a radar slew: constant worm rate (``--slew-rate``) with a sharp reversal every
  ``--slew-period`` seconds (triangle).

and shows what the node predicts, refreshed ~10 times a second: the command, the antenna
angle theta4, the antenna positioning error theta4 - theta1 l_w/r_g (urad, with a bar),
its peak since the last move, the feed-forward correction and the node's real-time figures
from /diagnostics.  Stops after ``--duration`` seconds of streaming (exit code 0), or on
Ctrl-C.

    python -m worm_gear_sim.demo_commander --duration 20 --pattern paper
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from typing import Any, TextIO

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.task import Future
from rclpy.utilities import remove_ros_args
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from ..params import Config, derive
from ..profiles import TrapezoidalProfile

__all__ = ['DemoCommander', 'command_pattern', 'main']


def command_pattern(name: str, cfg: Config, move_period: float = 0.5,
                    slew_rate: float = 2.0, slew_period: float = 2.0):
    """theta1(t) [rad] of the demo stream, vectorised over t [s]."""
    if name == 'paper':
        inp = cfg.input
        move = TrapezoidalProfile(inp.target_angle, inp.move_time, inp.accel_time, 0.0)
        lead = 0.05   # rest before the first move [s]

        def theta1(t):
            t = np.asarray(t, float) - lead
            k = np.floor(np.maximum(t, 0.0) / move_period)
            tau = np.where(t < 0.0, -1.0, t - k * move_period)
            x = move.theta1(tau)
            return np.where(k % 2 == 0, x, inp.target_angle - x)   # forward, back, ...
        return theta1
    if name == 'slew':
        amp = slew_rate * slew_period      # one leg: slew_period at slew_rate

        def theta1(t):
            x = (np.asarray(t, float) / (2.0 * slew_period)) % 1.0
            return np.where(x < 0.5, 2.0 * amp * x, 2.0 * amp * (1.0 - x))
        return theta1
    raise ValueError(f'unknown pattern {name!r} (paper | slew)')


class DemoCommander(Node):
    """Streams the pattern and keeps the latest predictions for the display."""

    def __init__(self, pattern: str = 'paper', rate: float = 1000.0,
                 node_under_test: str = 'worm_gear_sim', move_period: float = 0.5,
                 slew_rate: float = 2.0, slew_period: float = 2.0, **kwargs: Any):
        super().__init__('demo_commander', **kwargs)
        self.cfg = Config()
        self.ratio = derive(self.cfg).output_per_input
        self.theta1 = command_pattern(pattern, self.cfg, move_period, slew_rate, slew_period)
        self.pattern = pattern
        self.segment_period = move_period if pattern == 'paper' else slew_period
        self.segment = -1
        self.pub = self.create_publisher(Float64, 'worm_angle_command', QoSProfile(depth=10))
        ns = node_under_test
        self.js: JointState | None = None
        self.js_at_error: JointState | None = None
        self.error = math.nan
        self.feedforward = math.nan
        self.diag: dict[str, str] = {}
        self.n_js = 0
        self.peak_error = 0.0       # since the last move started
        self.peak_all = 0.0
        self.t0: float | None = None   # streaming starts when the node answers
        self.sent = 0
        self.last_cmd = float(self.theta1(0.0))
        self.create_subscription(JointState, 'joint_states', self._on_js, 10)
        self.create_subscription(Float64, f'/{ns}/positioning_error', self._on_err, 10)
        self.create_subscription(Float64, f'/{ns}/feedforward',
                                 lambda m: setattr(self, 'feedforward', m.data), 10)
        self.create_subscription(DiagnosticArray, '/diagnostics', self._on_diag, 10)
        self.create_timer(1.0 / rate, self._on_timer)

    def elapsed(self) -> float:
        return 0.0 if self.t0 is None else time.monotonic() - self.t0

    def _on_timer(self) -> None:
        # Before the node answers, hold the first sample (it starts the simulation there).
        t = self.elapsed()
        v = float(self.theta1(t))
        segment = int(t // self.segment_period)
        if segment != self.segment:     # a new move / slew leg: restart the peak
            self.segment, self.peak_error = segment, 0.0
        self.pub.publish(Float64(data=v))
        self.last_cmd = v
        self.sent += 1

    def _on_js(self, msg: JointState) -> None:
        self.js = msg
        self.n_js += 1
        if self.t0 is None:
            self.t0 = time.monotonic()

    def _on_err(self, msg: Float64) -> None:
        self.error = msg.data
        self.js_at_error = self.js      # published just before it, in the same tick
        if self.t0 is not None:
            self.peak_error = max(self.peak_error, abs(msg.data))
            self.peak_all = max(self.peak_all, abs(msg.data))

    def _on_diag(self, msg: DiagnosticArray) -> None:
        for s in msg.status:
            if s.name.endswith(': simulation'):
                self.diag = {kv.key: kv.value for kv in s.values}

    def status_line(self, width: int = 24) -> str:
        js = self.js_at_error or self.js
        if js is None:
            return 'waiting for joint_states from the worm_gear_sim node ...'
        e_urad = self.error * 1e6
        scale = max(50.0, self.peak_all * 1e6)
        n = int(round(min(1.0, abs(e_urad) / scale) * width))
        bar = (' ' * (width - n) + '#' * n + '|' + ' ' * width) if e_urad < 0 else \
            (' ' * width + '|' + '#' * n + ' ' * (width - n))
        d = self.diag
        rt = f'rtf {float(d["real_time_factor"]):.3f} load {float(d["compute_load"]):.2f}' \
            if d else 'rtf -'
        return (f't {self.elapsed():6.2f} s  theta1 {js.position[0]:+.5f}  theta4 '
                f'{js.position[3]:+.6f} rad  error {e_urad:+8.2f} urad [{bar}] '
                f'peak {self.peak_error * 1e6:7.2f}  ff {self.feedforward * 1e6:+8.2f} urad'
                f'  {rt}')


def _parse(argv: list[str]) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog='demo_commander', description=__doc__.split('\n\n')[0])
    ap.add_argument('--pattern', choices=('paper', 'slew'), default='paper')
    ap.add_argument('--duration', type=float, default=20.0,
                    help='seconds of streaming after the node answers [20]')
    ap.add_argument('--rate', type=float, default=1000.0, help='command rate [Hz] (1000)')
    ap.add_argument('--move-period', type=float, default=0.5,
                    help='paper: seconds between moves [0.5]')
    ap.add_argument('--slew-rate', type=float, default=2.0,
                    help='slew: worm rate [rad/s] (2.0: antenna ~2 deg/s)')
    ap.add_argument('--slew-period', type=float, default=2.0,
                    help='slew: seconds between reversals [2.0]')
    ap.add_argument('--startup-timeout', type=float, default=120.0,
                    help='seconds to wait for the node (first start compiles numba) [120]')
    ap.add_argument('--node-name', default='worm_gear_sim')
    return ap.parse_args(argv)


def main(args: list[str] | None = None, out: TextIO | None = None) -> int:
    argv = sys.argv if args is None else args
    opts = _parse(remove_ros_args(args=argv)[1:])
    out = out or sys.stdout
    tty = out.isatty()
    from .node import make_executor
    # rclpy.init() as a context manager exists only from Kilted (rclpy 9) on: on Jazzy
    # (rclpy 7.1) it returns None, so init, then try_shutdown in a finally.
    rclpy.init(args=argv)
    try:
        node = DemoCommander(opts.pattern, opts.rate, opts.node_name, opts.move_period,
                             opts.slew_rate, opts.slew_period)
        ex = make_executor('events')
        ex.add_node(node)
        never = Future()
        t_start = time.monotonic()
        last_print = 0.0
        print(f'demo: {opts.pattern} pattern at {opts.rate:g} Hz on '
              f'{node.resolve_topic_name("worm_angle_command")}; antenna error = theta4 - '
              f'theta1 l_w/r_g (ratio 1:{1 / node.ratio:.4g})', file=out, flush=True)
        while True:
            ex.spin_until_future_complete(never, timeout_sec=0.1)
            now = time.monotonic()
            if node.t0 is None and now - t_start > opts.startup_timeout:
                print(f'\nno joint_states within {opts.startup_timeout:g} s: is the node '
                      'running (same ROS_DOMAIN_ID)?', file=out, flush=True)
                return 1
            if node.t0 is not None and node.elapsed() >= opts.duration:
                break
            if tty and now - last_print >= 0.1:
                out.write('\r' + node.status_line() + '\x1b[K')
                out.flush()
                last_print = now
            elif not tty and now - last_print >= 1.0:
                print(node.status_line(), file=out, flush=True)
                last_print = now
        if tty:
            out.write('\n')
        print(f'demo done: {node.sent} commands sent, {node.n_js} joint_states received, '
              f'largest antenna error {node.peak_all * 1e6:.2f} urad', file=out,
              flush=True)
        ex.shutdown(1.0)
        node.destroy_node()
    except (KeyboardInterrupt, ExternalShutdownException):
        print('', file=out)
    finally:
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
