# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A minimal rosbag2 recorder for this package's topics, for installs without ``ros2 bag``
(the PyPI ROS wheels have no rosbag2).

    python -m worm_gear_sim.ros.bag_recorder -o run_bag [--storage sqlite3] [--duration 20]

Writes the messages serialized, with their receive time, with the ``rosbags`` writer; the
bag feeds ``simulate --bag`` and ``identify`` (docs/data-formats.md).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from ..records import BAG_VERSION
from ..records.topics import (
    ANSWER_TOPICS,
    COMMAND_TOPIC,
    COMPENSATED_COMMAND_TOPIC,
    FLOAT64,
    JOINT_STATE,
    JOINT_STATES_TOPIC,
    MEASURED_TOPIC,
    REFERENCE_TOPIC,
    private_topic,
)
from .teardown import teardown_deadline

__all__ = ['BagRecorder', 'DEFAULT_TOPICS', 'ALL_TOPICS', 'all_topics', 'main']

#: topic -> message type recorded by default: the node's inputs and its prediction (what
#: ``simulate --bag`` and ``identify`` read); ``--all`` adds ALL_TOPICS' answers
DEFAULT_TOPICS = {
    '/' + REFERENCE_TOPIC: JOINT_STATE,
    '/' + COMMAND_TOPIC: FLOAT64,
    '/' + JOINT_STATES_TOPIC: JOINT_STATE,
    '/' + MEASURED_TOPIC: JOINT_STATE,
}


def all_topics(float64_outputs: bool = False) -> dict[str, str]:
    """DEFAULT_TOPICS and the node's answers: ``~/compensated_command`` and the scalar
    answers (stamped JointStates; Float64 for a node with ``node.float64_outputs``)."""
    answers = {'/' + private_topic(t): FLOAT64 if float64_outputs else JOINT_STATE
               for t in ANSWER_TOPICS}
    return {**DEFAULT_TOPICS, **answers,
            '/' + private_topic(COMPENSATED_COMMAND_TOPIC): JOINT_STATE}


ALL_TOPICS = all_topics()
_CLASSES = {FLOAT64: Float64, JOINT_STATE: JointState}


class BagRecorder(Node):
    """Records ``topics`` ({name: 'std_msgs/msg/Float64' | 'sensor_msgs/msg/JointState'})
    into the rosbag2 bag ``path`` (storage sqlite3 or mcap).  ``best_effort``: subscribe
    best effort (matches best-effort publishers too, may lose messages under load);
    default reliable, depth ``depth``."""

    def __init__(self, path: str | Path, topics: dict[str, str] | None = None, *,
                 storage: str = 'sqlite3', best_effort: bool = False, depth: int = 1000,
                 **kwargs: Any) -> None:
        super().__init__('worm_gear_sim_bag_recorder', **kwargs)
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore
        plugins = {'sqlite3': StoragePlugin.SQLITE3, 'mcap': StoragePlugin.MCAP}
        if storage not in plugins:
            raise ValueError(f'storage must be sqlite3 or mcap, got {storage!r}')
        topics = dict(DEFAULT_TOPICS if topics is None else topics)
        for name, typ in topics.items():
            if typ not in _CLASSES:
                raise ValueError(f'{name}: can record {FLOAT64} or {JOINT_STATE}, not {typ}')
        self.counts: dict[str, int] = {}
        ts = get_typestore(Stores.ROS2_JAZZY)
        self._writer = Writer(Path(path), version=BAG_VERSION, storage_plugin=plugins[storage])
        self._writer.open()
        self._conns: dict[str, Any] = {}
        self._types = {}
        qos = QoSProfile(depth=depth, reliability=ReliabilityPolicy.BEST_EFFORT
                         if best_effort else ReliabilityPolicy.RELIABLE)
        clock = self.get_clock()
        for name, typ in topics.items():
            resolved = self.resolve_topic_name(name)
            self._types[resolved] = typ
            self.counts[resolved] = 0

            def store(raw: bytes, topic: str = resolved) -> None:
                if self._writer is None:
                    return
                conn = self._conns.get(topic)
                if conn is None:          # a connection once a message has come
                    conn = self._conns[topic] = self._writer.add_connection(
                        topic, self._types[topic], typestore=ts)
                self._writer.write(conn, clock.now().nanoseconds, raw)
                self.counts[topic] += 1

            self.create_subscription(_CLASSES[typ], name, store, qos, raw=True)

    def close(self) -> None:
        """Finish the bag (metadata.yaml); further messages are ignored."""
        w, self._writer = self._writer, None
        if w is not None:
            w.close()


def _parse(argv: list[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog='python -m worm_gear_sim.ros.bag_recorder',
                                description=__doc__.split('\n\n')[0])
    p.add_argument('-o', '--output', required=True, help='bag directory to create')
    p.add_argument('--storage', choices=('sqlite3', 'mcap'), default='mcap',
                   help='default: %(default)s')
    p.add_argument('--all', action='store_true', help='also the node\'s answers: the '
                   'errors, the feed-forward, the back-drive margin and the compensated '
                   'command')
    p.add_argument('--float64-outputs', action='store_true', help='with --all: the node '
                   'publishes its scalar answers as Float64 (node.float64_outputs)')
    p.add_argument('--topic', action='append', default=[], metavar='NAME:TYPE',
                   help='record NAME (TYPE Float64 or JointState) instead of the defaults '
                   '(repeatable)')
    p.add_argument('--duration', type=float, default=0.0, help='stop after S seconds of '
                   'wall time (default: until Ctrl-C)')
    p.add_argument('--best-effort', action='store_true', help='best-effort subscriptions')
    return p.parse_args(argv)


def main(args: list[str] | None = None) -> int:
    from rclpy.executors import ExternalShutdownException
    from rclpy.utilities import remove_ros_args
    argv = sys.argv if args is None else args
    opts = _parse(remove_ros_args(args=argv)[1:])
    topics = all_topics(opts.float64_outputs) if opts.all else None
    if opts.topic:
        kinds = {'float64': FLOAT64, 'jointstate': JOINT_STATE, FLOAT64.lower(): FLOAT64,
                 JOINT_STATE.lower(): JOINT_STATE}
        topics = {}
        for item in opts.topic:
            name, _, kind = item.partition(':')
            if kind.lower() not in kinds:
                print(f'bag_recorder: error: --topic {item!r}: expected NAME:Float64 or '
                      'NAME:JointState', file=sys.stderr)
                return 2
            topics[name] = kinds[kind.lower()]
    if Path(opts.output).exists():
        print(f'bag_recorder: error: {opts.output} exists already', file=sys.stderr)
        return 2
    rclpy.init(args=argv)          # not the context manager: Jazzy's rclpy returns None
    node = None
    try:
        node = BagRecorder(opts.output, topics, storage=opts.storage,
                           best_effort=opts.best_effort)
        print(f'bag_recorder: recording {len(node.counts)} topics to {opts.output}',
              flush=True)
        end = time.monotonic() + opts.duration if opts.duration > 0 else None
        while rclpy.ok() and (end is None or time.monotonic() < end):
            rclpy.spin_once(node, timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.close()
            counts = ', '.join(f'{k} {v}' for k, v in node.counts.items() if v) or 'nothing'
            print(f'bag_recorder: wrote {opts.output}: {counts}', flush=True)
        with teardown_deadline():       # Fast DDS can hang in it (.teardown)
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
    return 0


if __name__ == '__main__':  # pragma: no cover
    sys.exit(main())
