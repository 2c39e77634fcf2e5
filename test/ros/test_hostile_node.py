# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The trajectory interface of a drive node process under hostile input (cases 1, 3, 4,
5 of the hostile review), one process for every check: a far-future trajectory does not
move the next start; 3000 replacements at 1 kHz, the last one out within 1 s of its
sending, every one counted (compensated, superseded or rejected: none dropped
silently); the stamped path answers every sample, none too_old, no overrun, while a
100 000-point, 100 s trajectory is compensated and published; the counters on
/diagnostics under the node's name.  The serialization of the dense output (numpy)
equals the message object."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from trajectory_probe import big_trajectory, node_and_probe, trajectory

pytest.importorskip('rclpy')
pytest.importorskip('trajectory_msgs')

pytestmark = pytest.mark.ros


def children(pid: int) -> list[int]:
    """The child processes of ``pid`` (every thread's)."""
    kids: list[int] = []
    for task in Path(f'/proc/{pid}/task').iterdir():
        kids += [int(k) for k in (task / 'children').read_text().split()]
    return kids


@pytest.fixture(scope='module')
def node_process(tmp_path_factory):
    """One drive node process (statuses every 0.1 s) and a probe talking to it over DDS."""
    import os
    domain = int(os.environ.get('ROS_DOMAIN_ID', '42') or 42) + 1
    with node_and_probe(tmp_path_factory.mktemp('hostile') / 'node.log', domain,
                        ['-p', 'node.diagnostic_period:=0.1']) as probe:
        yield probe


def send(probe, msg, timeout=30.0):
    n = len(probe.out)
    probe.pub.publish(msg)
    return probe.spin_until(lambda: len(probe.out) > n, timeout)


def test_a_far_future_trajectory_does_not_move_the_next_start(node_process):
    p = node_process
    now = p.node.get_clock().now().nanoseconds
    assert send(p, trajectory([0.05, 0.1], [0.5, 0.5]))
    assert send(p, trajectory([0.0, 0.1], [-0.5, -0.5], now + 3000 * 10**9))
    p.spin_until(lambda: False, 0.3)                 # T1 has ended
    assert send(p, trajectory([0.05, 0.1], [0.6, 0.6]))
    got = p.last().positions[:, 0]
    assert abs(got[0] - 0.5) < 1e-3 and np.abs(np.diff(got)).max() < 0.05
    # beyond the limit: refused and counted
    p.pub.publish(trajectory([0.1], [0.1], (2**31 - 1) * 10**9))
    vals = p.fresh_status('trajectories', lambda v: v['rejected_trajectory_future_stamp']
                          == '1')
    assert vals.get('rejected_trajectory_future_stamp') == '1', vals


def test_3000_replacements_at_1khz_the_last_out_within_1s_and_all_counted(node_process):
    p = node_process
    n0 = int(p.fresh_status('trajectories')['trajectories_received'])
    t0 = time.monotonic()
    k = 0
    while k < 3000:                                  # 1 kHz, spinning in between
        if time.monotonic() >= t0 + k * 1e-3:
            p.pub.publish(trajectory([0.05, 0.1], [1e-4 * (k + 1)] * 2))
            k += 1
        p.ex.spin_once(timeout_sec=0.0)
    sent_last = time.monotonic()
    last_value = 1e-4 * 3000
    assert p.spin_until(lambda: p.out and abs(p.last().positions[-1, 0] - last_value)
                        < 1e-9, 10.0)
    arrival = p.out[-1][0]
    def accounted(v: dict[str, str]) -> int:
        return sum(int(v[k]) for k in ('trajectories_compensated', 'trajectories_superseded',
                                       'rejected_trajectories'))

    # every one received and accounted for: one can be in the worker, not queued, when a
    # status is published (seen once in CI: received 3004, accounted 3003), so the wait is
    # for the counts to meet, within the 10 s of fresh_status, not for the queue alone
    vals = p.fresh_status('trajectories', lambda v: int(v['trajectories_received']) >=
                          n0 + 3000 and v['queued'] == '0'
                          and accounted(v) == int(v['trajectories_received']))
    done = accounted(vals)
    assert int(vals['trajectories_received']) == n0 + 3000, vals
    assert done == int(vals['trajectories_received']), vals
    assert vals['trajectory_messages_lost'] == '0'
    assert int(vals['trajectories_superseded']) > 1000
    assert arrival - sent_last < 1.0, arrival - sent_last


def test_the_stamped_path_is_answered_while_a_100s_trajectory_is_compensated(node_process):
    """1 kHz stamped samples, never paused, from before a 100 000-point, 100 s trajectory
    is sent until 0.3 s after its compensated trajectory arrives (worker process, started
    by this first long trajectory; numpy serialization): every sample answered, none
    too_old or out of order; no overrun unless the probe itself paused for longer than the
    node's stale margin (a loaded machine).  benchmarks/bench_trajectory_node.py measures
    the same over several trajectories."""
    p = node_process
    assert children(p.proc.pid) == [], 'the worker process started before it was needed'
    big = big_trajectory(p.node.get_clock().now().nanoseconds + 2 * 10**9)
    p.stream(lambda: False, 0.3)                     # the stream runs
    names = ('samples_received', 'samples_accepted', 'rejected_too_old',
             'rejected_out_of_order', 'overruns', 'stale_events', 'stale_retractions')
    base = p.counters(names)
    # (answers are matched by stamp: the node may still owe answers to the samples sent
    # before, on a loaded machine; counting them would pass a lost answer)
    sent0, n_out = p.sent, len(p.out)
    run = p.stream(lambda: len(p.out) > n_out, 30.0, extra=big)
    assert len(p.out) > n_out, 'no compensated trajectory'
    assert children(p.proc.pid), 'no worker process'   # it (and its resource tracker)
    tail = p.stream(lambda: False, 0.3)
    got = p.counters(names)
    missing, repeated = p.wait_answered(sent0, 5.0)
    diff = {k: got[k] - base[k] for k in names}
    assert (missing, repeated) == (0, 0), (p.sent - sent0, missing, repeated, diff, run, tail)
    assert got['rejected_too_old'] == base['rejected_too_old']
    assert got['rejected_out_of_order'] == base['rejected_out_of_order']
    if max(run['widest_gap_ms'], tail['widest_gap_ms']) < 100.0:
        assert got['overruns'] == base['overruns'], (run, got, base)
    assert p.last().positions.shape == (100_000 + 101, 1)


def test_serialized_output_equals_the_message_object():
    from rclpy.serialization import deserialize_message, serialize_message
    from std_msgs.msg import Header
    from trajectory_msgs.msg import JointTrajectory

    from worm_gear_sim.joint_trajectory.compensate import JointTrajectoryData
    from worm_gear_sim.ros.trajectory_bridge import from_message, to_message
    from worm_gear_sim.ros.trajectory_cdr import parse_trajectory, serialize_trajectory
    rng = np.random.default_rng(3)
    for nj, kinds, n in ((1, 3, 5), (2, 1, 4), (3, 2, 3), (2, 3, 1)):
        h = Header(frame_id='ab' * nj)
        h.stamp.sec, h.stamp.nanosec = 12, 345
        d = JointTrajectoryData(tuple(f'j{k}' * (k + 1) for k in range(nj)),
                                np.cumsum(rng.random(n)), rng.standard_normal((n, nj)),
                                rng.standard_normal((n, nj)) if kinds > 1 else None,
                                rng.standard_normal((n, nj)) if kinds > 2 else None)
        msg = to_message(d, h)
        assert deserialize_message(serialize_trajectory(d, h), JointTrajectory) == msg
        got, head = parse_trajectory(serialize_message(msg))
        want = from_message(msg)
        assert head == (12, 345, h.frame_id)
        for a, b in ((got.time_from_start, want.time_from_start),
                     (got.positions, want.positions), (got.velocities, want.velocities)):
            assert (a is None and b is None) or np.array_equal(a, b)
    msg.points[0].effort = [1.0]                      # not uniform: read the usual way
    assert parse_trajectory(serialize_message(msg)) is None
