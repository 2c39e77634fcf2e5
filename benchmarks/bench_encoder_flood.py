# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""An encoder flood against the sample path, the node in-process (its callbacks called as
the executor calls them, no DDS timing).

The node (adaptation on by default; ``--adaptation off``) is fed in real time, events in the
order of their instants, each handled once its instant has come (or at once when the feed
is behind):

* a stamped reference every 1 ms (``_on_reference``; the 2 rad/s slew of bench_node.py);
* ``measured_joint_states`` (``_on_measured``): the encoder, stamped with the predictions'
  stamps one period back, at 1 kHz (``quiet``) or ``--flood`` samples per ms (``flood``,
  20: a 20 kHz stream; values the prediction of their stamp plus 1 urad).

Runs ``--seconds`` s quiet, then as long flooded, then quiet again, after a warm-up of 1 s
(compilation and the adaptation's first sample off the figures).  Printed for each: the
lateness of the reference samples (the end of its callback minus its instant) p50 / p99 /
max, the references answered (corrections published) of those sent, how far the feed fell
behind, the thread time per encoder message and per ms of stream (encoder and reference
callbacks: what the flood costs, nearly independent of the machine's load, unlike the
lateness), and what the model check and the adaptation counted (samples used, surplus);
then flood / quiet of the p99.  Target: under the flood
every stamped sample answered and p99 <= 5 ms.

    python benchmarks/bench_encoder_flood.py [--seconds 2] [--flood 20] [--adaptation on]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from node_probe import slew  # noqa: E402

MS = 1_000_000


def run(seconds: float, flood: int, adaptation: bool) -> list[dict]:
    import rclpy
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import JointState

    from worm_gear_sim.ros.node import WormGearSimNode

    rclpy.init()
    node = WormGearSimNode(parameter_overrides=[
        Parameter('adaptation.enabled', value=adaptation),
        Parameter('node.compensation_applied', value=True)])
    names = node.config.node.joint_names
    ref = JointState(name=[names[0]], position=[0.0])
    enc = JointState(name=[names[3]], position=[0.0])
    preds: dict[int, float] = {}            # stamp -> predicted theta4
    push = node.rt.push

    def recording_push(*a, **k):
        out = push(*a, **k)
        for p in out.predictions:
            preds[p.stamp_ns] = p.theta[2]
        return out
    node.rt.push = recording_push
    state = {'base': 0}

    def rebase(k: int) -> None:
        """Reference k is due 20 ms from now."""
        state['base'] = node.get_clock().now().nanoseconds + 20 * MS - k * MS

    def phase(k0: int, n_ms: int, per_ms: int) -> dict:
        """References k0 .. k0 + n_ms - 1, ``per_ms`` encoder messages per ms."""
        late, enc_cpu, ref_cpu, behind = [], 0, 0, 0
        rc, check = node.rt.counters, node._check
        live = node.adaptation.live
        c0 = rc['corrections']
        r0 = dict(check.rejections)
        a0 = dict(live.counters) if live is not None else {}
        s0 = check.monitor.samples
        n_enc = 0
        for k in range(k0, k0 + n_ms):
            due = state['base'] + k * MS
            events = [(due + j * MS // per_ms, j) for j in range(per_ms)]
            events.insert(0, (due, -1))            # the reference first, then the encoder
            for at, j in events:
                now = time.time_ns()
                while now < at:
                    now = time.time_ns()
                behind = max(behind, now - at)
                if j < 0:
                    ref.header.stamp.sec, ref.header.stamp.nanosec = divmod(due, 10**9)
                    ref.position[0] = slew(k * 1e-3, 2.0)
                    c = time.thread_time_ns()
                    node._on_reference(ref)
                    ref_cpu += time.thread_time_ns() - c
                    late.append(time.time_ns() - due)
                    continue
                stamp = due - MS + j * MS // per_ms      # one period back: predicted
                lo = due - MS
                th = preds.get(lo)
                hi = preds.get(due)
                if th is None or hi is None:
                    continue
                value = th + (hi - th) * (stamp - lo) / MS + 1e-6
                enc.header.stamp.sec, enc.header.stamp.nanosec = divmod(stamp, 10**9)
                enc.position[0] = value
                c = time.thread_time_ns()
                node._on_measured(enc)
                enc_cpu += time.thread_time_ns() - c
                n_enc += 1
            for old in [s for s in preds if s < due - 3 * MS]:
                del preds[old]
        lat = np.array(late) / 1e6
        rej = {r: v - r0.get(r, 0) for r, v in check.rejections.items() if v != r0.get(r, 0)}
        out = dict(lat=lat, answered=rc['corrections'] - c0, sent=n_ms,
                   behind_ms=behind / 1e6, enc=n_enc,
                   enc_us=enc_cpu / max(n_enc, 1) / 1e3, enc_per_ms=enc_cpu / n_ms / 1e3,
                   ref_us=ref_cpu / n_ms / 1e3,
                   check_used=check.monitor.samples - s0, check_rejected=rej)
        if live is not None:
            out['adapt'] = {k: live.counters[k] - a0.get(k, 0) for k in live.counters
                            if live.counters[k] != a0.get(k, 0)}
        return out

    n = int(round(seconds * 1000))
    rebase(0)
    phase(0, 100, 1)                     # compiles (late: the stream restarts after it)
    rebase(100)
    phase(100, 900, 1)                   # warm-up: the adaptation's first samples
    results = [dict(name='quiet', **phase(1000, n, 1)),
               dict(name=f'flood {flood}/ms', **phase(1000 + n, n, flood)),
               dict(name='quiet again', **phase(1000 + 2 * n, n, 1))]
    node.destroy_node()
    rclpy.try_shutdown()
    return results


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seconds', type=float, default=2.0)
    ap.add_argument('--flood', type=int, default=20, help='encoder messages per ms [20]')
    ap.add_argument('--adaptation', choices=('on', 'off'), default='on')
    args = ap.parse_args()
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    load0 = os.getloadavg()
    res = run(args.seconds, args.flood, args.adaptation == 'on')
    load1 = os.getloadavg()
    print(f'load average {load0[0]:.2f} before, {load1[0]:.2f} after (1 min); adaptation '
          f'{args.adaptation}; {args.seconds:g} s per phase, references at 1 kHz')
    for r in res:
        lat = r['lat']
        print(f"  {r['name']}: lateness p50 {np.percentile(lat, 50):.2f} ms, p99 "
              f"{np.percentile(lat, 99):.2f} ms, max {lat.max():.2f} ms; answered "
              f"{r['answered']}/{r['sent']}; fell behind {r['behind_ms']:.1f} ms at most; "
              f"{r['enc']} encoder messages, {r['enc_us']:.1f} us thread time each")
        print(f"    thread time per ms of stream: encoder {r['enc_per_ms']:.0f} us, reference "
              f"callbacks {r['ref_us']:.0f} us")
        print(f"    model check: {r['check_used']} used, rejected {r['check_rejected']}")
        if 'adapt' in r:
            print(f"    adaptation: {r['adapt']}")
    q, f = (np.percentile(res[i]['lat'], 99) for i in (0, 1))
    print(f'p99 flood / quiet: {f / q:.2f} ({f:.2f} ms / {q:.2f} ms; target: flood p99 '
          f'<= 5 ms, every sample answered: {res[1]["answered"]}/{res[1]["sent"]})')
    return 0


if __name__ == '__main__':
    sys.exit(main())
