# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The tracking pass through the ROS nodes (``scripts/run_pass.sh``): a planner's stand-in
that streams a satellite pass (:mod:`worm_gear_sim.studies.tracking_pass`) to a running
``worm_gear_sim_pedestal`` as two-joint trajectories on ``/pedestal/reference_trajectory``, stamped
on the ROS clock a moment ahead, collects ``/pedestal/compensated_trajectory``, checks
each against the offline twin, and reports the per-axis pointing error with and without
compensation (the drives simulated on the stitched commands) with a CSV and a figure.

    python -m worm_gear_sim.ros.pass_demo --duration 60 -o pass/

Exit status: 0 when every trajectory came back equal to its twin (<= 1e-9 rad), 1 if not,
2 for bad arguments.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from .teardown import teardown_deadline

__all__ = ['main']

TWIN_TOLERANCE = 1e-9       # rad
LEAD = 2.0                  # s between sending and the first trajectory's start


def _args(argv: list[str]) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog='pass_demo', description=__doc__.split('\n\n')[0])
    ap.add_argument('--duration', type=float, default=60.0, help='seconds of the pass')
    ap.add_argument('--max-elevation', type=float, default=85.0, help='deg at culmination')
    ap.add_argument('--pedestal', default=None, help='the pedestal file the nodes run')
    ap.add_argument('-o', '--output', default='pass', help='directory for CSV and PNG')
    ap.add_argument('--timeout', type=float, default=120.0,
                    help='seconds to wait for the pedestal and its answers')
    return ap.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    opts = _args(sys.argv[1:] if argv is None else argv)
    if not (0 < opts.duration <= 1200 and 0 < opts.max_elevation < 90):
        print('pass_demo: --duration in (0, 1200] s, --max-elevation in (0, 90) deg',
              file=sys.stderr)
        return 2
    models, sent = _planned_pass(opts)
    exchanged = _exchange(opts, sent)
    if exchanged is None:
        return 1
    sent, got, answered = exchanged
    if len(got) < len(sent):
        print(f'pass_demo: {len(got)} of {len(sent)} trajectories came back', file=sys.stderr)
        return 1
    return _report(opts, models, sent, got, answered)


def _planned_pass(opts: argparse.Namespace) -> tuple[dict[str, Any], list[Any]]:
    """The pedestal's drive models and the pass as trajectories to send."""
    from ..config.pedestal import load_pedestal
    from ..studies.tracking_pass import pass_window, stream_pass
    drives = load_pedestal(opts.pedestal)
    models = {d.joint: d.config for d in drives}
    az_joint, el_joint = (d.joint for d in drives[:2])
    t, az, el = pass_window(opts.duration, max_elevation=math.radians(opts.max_elevation))
    sent, _ = stream_pass(models, {az_joint: az - az[0], el_joint: el}, t)
    return models, sent


def _exchange(opts: argparse.Namespace, sent: list[Any]
              ) -> tuple[list[Any], list[Any], float] | None:
    """Send the pass to the pedestal node, re-stamped a moment ahead on the ROS clock, and
    collect its answers: (sent, answers, seconds until the last came), or None when no
    pedestal answers."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from trajectory_msgs.msg import JointTrajectory

    from ..records.topics import PEDESTAL_TRAJECTORY_TOPIC, private_topic
    from .pedestal import PEDESTAL_NODE_NAME
    from .trajectory_bridge import to_message

    rclpy.init(args=[])
    node = rclpy.create_node('pass_planner')
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    qos = QoSProfile(depth=len(sent) + 10, reliability=ReliabilityPolicy.RELIABLE)
    pub = node.create_publisher(
        JointTrajectory, '/' + private_topic(PEDESTAL_TRAJECTORY_TOPIC, PEDESTAL_NODE_NAME), qos)
    got: list = []
    node.create_subscription(JointTrajectory, '/pedestal/compensated_trajectory',
                             got.append, qos)

    def spin_until(pred, timeout: float) -> bool:
        t0 = time.monotonic()
        while not pred():
            if time.monotonic() - t0 > timeout:
                return False
            ex.spin_once(timeout_sec=0.05)
        return True

    try:
        if not spin_until(lambda: pub.get_subscription_count() > 0 and
                          node.count_publishers('/pedestal/compensated_trajectory') > 0,
                          opts.timeout):
            print('pass_demo: no pedestal answers (is worm_gear_sim_pedestal running on '
                  'this ROS_DOMAIN_ID?)', file=sys.stderr)
            return None
        shift = node.get_clock().now().nanoseconds + int(LEAD * 1e9) - sent[0].stamp_ns
        sent = [dataclasses.replace(s, stamp_ns=s.stamp_ns + shift) for s in sent]
        t0 = time.perf_counter()
        for s in sent:                     # a planner sends each ahead of its start
            msg = to_message(s, JointTrajectory().header)
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(s.stamp_ns, 10**9)
            msg.header.frame_id = 'pedestal'
            pub.publish(msg)
        spin_until(lambda: len(got) >= len(sent), opts.timeout)
        answered = time.perf_counter() - t0
    finally:
        with teardown_deadline():       # Fast DDS can hang in it (.teardown)
            ex.shutdown()
            node.destroy_node()
            rclpy.try_shutdown()
    return sent, got, answered


def _report(opts: argparse.Namespace, models: dict[str, Any], sent: list[Any],
            got: list[Any], answered: float) -> int:
    """Each answer against its offline twin, the pass's pointing error (table, CSV,
    figure); the exit status."""
    from ..joint_trajectory.compensate import TrajectoryCompensator
    from ..studies.pass_report import pass_table, write_pass
    from ..studies.tracking_pass import evaluate_pass
    from .trajectory_bridge import from_message
    received = [from_message(m) for m in got]
    twin = TrajectoryCompensator(models)
    worst = 0.0
    for s, r in zip(sent, received):
        w = twin.compensate(s).trajectory
        worst = max(worst, float(np.max(np.abs(r.positions - w.positions))),
                    float(np.max(np.abs(r.time_from_start - w.time_from_start))))
    result = evaluate_pass(models, sent, received)
    title = (f'pass through the pedestal node: {opts.duration:g} s around a '
             f'{opts.max_elevation:g} deg culmination, {len(sent)} trajectories')
    csv, png = write_pass(result, Path(opts.output), title)
    print(title)
    print(f'{len(received)}/{len(sent)} compensated trajectories received in '
          f'{answered:.2f} s; node output - offline twin: {worst:.2e} rad (max)')
    print(pass_table(result))
    print(f'wrote {csv} and {png}')
    return 0 if worst <= TWIN_TOLERANCE else 1


if __name__ == '__main__':   # pragma: no cover
    sys.exit(main())
