# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A simulated drive as a ROS node: the live stand-in for the real one when the node adapts
(the wiring only; the plant is the core's ``EncoderPlant``, the one the offline twin steps).

    python -m worm_gear_sim.ros.plant --plant PLANT.yaml [--noise RAD] [--record OUT.npz]

It takes ``worm_angle_reference`` (start and restarts) and the node's
``~/compensated_command``, and publishes the encoder on ``measured_joint_states`` stamped
with the command's stamp; start-up errors end it with one line and exit code 2.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.utilities import remove_ros_args
from sensor_msgs.msg import JointState

from .._support.guarded_io import GuardedFileError, check_write_target
from ..adaptation.plant import EncoderPlant
from ..config.files import load_config
from ..config.usable import Config
from ..records.topics import (
    COMPENSATED_COMMAND_TOPIC,
    MEASURED_TOPIC,
    REFERENCE_TOPIC,
    private_topic,
)
from ..schema.validation import ConfigError
from .callbacks import stamp_ns
from .config_errors import clean_rcl_message, config_error
from .interface import REFERENCE_DEPTH
from .teardown import teardown_deadline

__all__ = ['PlantNode', 'main', 'PLANT_NODE_NAME']

PLANT_NODE_NAME = 'worm_gear_plant'
PROGRAM = 'worm_gear_sim.ros.plant'
#: Commands kept while the first reference has not come (the plant does not know its t = 0).
MAX_EARLY = 1000
#: References seen connected in a row before the plant starts (module docstring).
READY_SAMPLES = 3
#: A reference this far [ns] before the newest one seen restarts the plant (the node's
#: pipeline restarts on its clock going back by more than 1 ms).
RESTART_BACK_NS = 1_000_000


class PlantNode(Node):
    """The plant node (module docstring)."""

    def __init__(self, plant: Config, *, noise: float = 1e-6, encoder_bits: int = 20,
                 seed: int = 0, node_under_test: str = 'worm_gear_sim', subscribers: int = 1,
                 **kwargs: Any) -> None:
        super().__init__(PLANT_NODE_NAME, **kwargs)
        self.config = plant
        self._plant_args = {'noise': noise, 'encoder_bits': encoder_bits, 'seed': seed}
        self.plant: EncoderPlant | None = None
        self.base_ns: int | None = None
        self.theta1_start = float('nan')
        self.counters = {'commands': 0, 'published': 0, 'before_start': 0,
                         'out_of_order': 0, 'malformed': 0, 'before_ready': 0, 'restarts': 0}
        self._newest_ref_ns = 0
        self._first_ref_ns = 0                # the first reference of the stream
        self._subscribers = int(subscribers)
        self._ready = 0
        self._early: list[tuple[int, float]] = []
        self._last_ns = 0
        self.record: list[tuple[int, float, float, float]] = []
        reliable = QoSProfile(depth=REFERENCE_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
        self._out = JointState(name=[plant.node.joint_names[3]], position=[0.0])
        self._pub = self.create_publisher(JointState, MEASURED_TOPIC, reliable)
        self.create_subscription(JointState, REFERENCE_TOPIC, self._on_reference, reliable)
        self._commands = self.create_subscription(
            JointState, private_topic(COMPENSATED_COMMAND_TOPIC, node_under_test),
            self._on_command, reliable)

    def _on_reference(self, msg: JointState) -> None:
        if not msg.position:
            return
        ns = stamp_ns(msg.header.stamp)
        if ns <= 0:
            return
        newest, self._newest_ref_ns = self._newest_ref_ns, max(self._newest_ref_ns, ns)
        if not newest:
            self._first_ref_ns = ns
        if self.plant is not None:
            if ns < newest - RESTART_BACK_NS:         # the clock went back: start again
                self.counters['restarts'] += 1
                self._newest_ref_ns = ns
                # commands waiting from the old stream's span are its stragglers; those
                # before it came from the new stream ahead of this reference
                old = self._first_ref_ns
                self._first_ref_ns = ns
                self.counters['before_start'] += sum(1 for c in self._early if c[0] >= old)
                self._early = [c for c in self._early if c[0] < old]
                self.record.clear()
                self._last_ns = 0
                self._start(ns, float(msg.position[0]))
            return
        connected = self._pub.get_subscription_count() >= self._subscribers and \
            self._commands.get_publisher_count() >= 1
        self._ready = self._ready + 1 if connected else 0
        if self._ready < READY_SAMPLES:
            self.counters['before_ready'] += 1
            return
        self._start(ns, float(msg.position[0]))

    def _start(self, ns: int, theta1: float) -> None:
        """The plant starts (again) at rest at the reference stamped ``ns``; the commands
        waiting for it are stepped."""
        self.base_ns, self.theta1_start = ns, theta1
        self.plant = EncoderPlant(self.config, self.theta1_start, **self._plant_args)
        self.get_logger().info(f'plant started at theta1 = {self.theta1_start:.6g} rad '
                               f'(stamp {ns} ns)')
        early, self._early = self._early, []
        for ns_c, value in sorted(early):
            self._command(ns_c, value)

    def _on_command(self, msg: JointState) -> None:
        ns = stamp_ns(msg.header.stamp)
        if not msg.position or ns <= 0:
            self.counters['malformed'] += 1
            return
        if self.plant is None or (self.base_ns is not None and ns < self.base_ns):
            if len(self._early) < MAX_EARLY:       # before the start: it may be a restart's
                self._early.append((ns, float(msg.position[0])))
            else:
                self.counters['before_start'] += 1
            return
        self._command(ns, float(msg.position[0]))

    def _command(self, ns: int, value: float) -> None:
        assert self.plant is not None and self.base_ns is not None
        self.counters['commands'] += 1
        if ns < self.base_ns:
            self.counters['before_start'] += 1
            return
        if ns <= self._last_ns:
            self.counters['out_of_order'] += 1
            return
        self._last_ns = ns
        theta4, meas = self.plant.command((ns - self.base_ns) * 1e-9, value)
        m = self._out
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(ns, 1_000_000_000)
        m.position[0] = meas
        self._pub.publish(m)
        self.counters['published'] += 1
        self.record.append((ns, value, theta4, meas))

    def write_record(self, path: Path) -> None:
        """The record (module docstring) as an .npz file."""
        self.counters['before_start'] += len(self._early)     # no start took them
        self._early = []
        rec = np.array(self.record, dtype=float).reshape(-1, 4)
        stamps = np.array([r[0] for r in self.record], dtype=np.int64)
        np.savez(path, stamp_ns=stamps, command=rec[:, 1], theta4=rec[:, 2],
                 measured=rec[:, 3], base_ns=np.int64(self.base_ns or 0),
                 theta1_start=self.theta1_start,
                 **{f'counter_{k}': v for k, v in self.counters.items()})


class _Parser(argparse.ArgumentParser):
    """Usage errors as one line (:func:`main`), not argparse's usage block."""

    def error(self, message: str) -> NoReturn:
        raise _StartupError(message)


class _StartupError(Exception):
    """A start-up error: one line, exit code 2 (:mod:`.config_errors`)."""


def _parse(argv: list[str]) -> argparse.Namespace:
    ap = _Parser(prog=PROGRAM, description=__doc__.split('\n\n')[0])
    ap.add_argument('--plant', required=True, metavar='PLANT.yaml',
                    help='the simulated drive (a params file)')
    ap.add_argument('--noise', type=float, default=1e-6, help='encoder noise RMS [1e-6 rad]')
    ap.add_argument('--encoder-bits', type=int, default=20, help='resolution 2 pi / 2^N [20]')
    ap.add_argument('--seed', type=int, default=0, help='noise seed [0]')
    ap.add_argument('--record', metavar='OUT.npz', help='write the record here on exit')
    ap.add_argument('--node-name', default='worm_gear_sim',
                    help='the node whose ~/compensated_command drives the plant')
    ap.add_argument('--subscribers', type=int, default=1,
                    help='encoder readers to wait for before starting [1: the node]')
    return ap.parse_args(argv)


def _checked(argv: list[str]) -> tuple[argparse.Namespace, Config]:
    """The options and the plant, checked before anything starts: the plant file (the
    core's loader), the encoder's noise, resolution and seed (a trial of the core's
    :class:`EncoderPlant`, which the first reference would otherwise build) and that
    ``--record`` can be written; _StartupError naming the option otherwise."""
    opts = _parse(argv)
    try:
        plant = load_config(opts.plant)
    except (ConfigError, OSError) as exc:
        raise _StartupError(f'--plant {opts.plant}: {exc}') from None
    if opts.subscribers < 0:
        raise _StartupError(f'--subscribers {opts.subscribers}: must be >= 0')
    try:
        EncoderPlant(plant, 0.0, noise=opts.noise, encoder_bits=opts.encoder_bits,
                     seed=opts.seed)
    except (ConfigError, ValueError, ArithmeticError) as exc:
        raise _StartupError(f'the encoder (--noise, --encoder-bits, --seed): {exc}') from None
    if opts.record:
        try:
            check_write_target(opts.record)
        except GuardedFileError as exc:
            raise _StartupError(f'--record {opts.record}: cannot write the record ({exc})'
                                ) from None
    return opts, plant


def main(args: list[str] | None = None) -> int:
    argv = list(sys.argv if args is None else args)
    from .run import RCLError, after_shutdown, leave, make_executor, spin_until_shutdown
    try:
        opts, plant = _checked(remove_ros_args(args=argv)[1:])
    except _StartupError as exc:
        return config_error(str(exc), PROGRAM)
    except RCLError as exc:
        return config_error(clean_rcl_message(exc), PROGRAM)
    try:
        rclpy.init(args=argv)
    except RCLError as exc:
        return config_error(clean_rcl_message(exc), PROGRAM)
    node = ex = None
    try:
        node = PlantNode(plant, noise=opts.noise, encoder_bits=opts.encoder_bits,
                         seed=opts.seed, node_under_test=opts.node_name,
                         subscribers=opts.subscribers)
        ex = make_executor('events')
        ex.add_node(node)
        node.get_logger().info(f'ready: {opts.plant} -> {MEASURED_TOPIC}')
        spin_until_shutdown(ex, slice_s=0.2)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if not after_shutdown(ex):      # e.g. the executor's registration cut short
            raise
    finally:
        if node is not None:
            if opts.record:
                node.write_record(Path(opts.record))
            print(f'plant: {node.counters}', flush=True)
        with teardown_deadline():       # Fast DDS can hang in it (.teardown)
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
    return leave(0)


if __name__ == '__main__':
    sys.exit(main())
