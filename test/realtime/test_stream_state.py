# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The real-time pipeline's stream state (worm_gear_sim.realtime, no ROS): what a stale hold
saves and a late sample restores, across a blended reconfigure; every piece the pipeline
holds through copy, deepcopy and pickle; a blend that leaves no wrapper; load samples
across a start and a restart."""

from __future__ import annotations

import copy
import dataclasses
import pickle

import numpy as np
import pytest

from worm_gear_sim import Config
from worm_gear_sim.compensation.blend import BlendedCompensator
from worm_gear_sim.compensation.streaming import Compensator
from worm_gear_sim.realtime import RealtimePredictor, feedforward_series
from worm_gear_sim.realtime.model_check import ModelCheck
from worm_gear_sim.realtime.outputs import Output, Reject

EPOCH = 1_700_000_000_123_456_789          # ns: a ROS time stamp of 2023
MS = 1_000_000
LOADED = {'load.output_torque': 5.0, 'load.output_viscous_coefficient': 2.0}
ADAPTED = {'load.output_torque': 6.0}      # a step as the adaptation makes one


def ref(k: int) -> float:
    """The worm reference of sample k (1 kHz): a slow sine."""
    return 0.2 * float(np.sin(k * 2e-2))


def stamp(k: int) -> int:
    return EPOCH + k * MS


def push_range(p: RealtimePredictor, ks, now_lag: int = 0) -> list[Output]:
    out = []
    for k in ks:
        o = p.push(stamp(k), ref(k), now_ns=stamp(k) + now_lag)
        assert o.accepted, (k, o.rejected)
        out.append(o)
    return out


def test_a_stale_hold_after_a_blended_reconfigure():
    """200 samples, a blended reconfigure (the adaptation's step), 200 samples, then the
    servo pauses: the hold declares the stream stale (it saves the stream for a
    retraction) and holds the prediction; the stream resumes after the pause."""
    cfg = Config().replace(LOADED)
    p = RealtimePredictor(cfg)
    push_range(p, range(200))
    p.reconfigure(cfg.replace(ADAPTED), blend=0.05)
    push_range(p, range(200, 400))
    now = stamp(399) + 120 * MS                   # a pause longer than ~0.11 s
    o = p.hold(now)
    assert p.stale and 'stream_stale' in [e.kind for e in o.events]    # (and an overrun)
    assert o.predictions and o.predictions[-1].held
    o = p.push(stamp(400) + 500 * MS, ref(399), now_ns=now + 400 * MS)
    assert o.accepted and not p.stale and p.counters['stale_retractions'] == 0


@pytest.mark.parametrize('preview', [0.0, 0.005])
def test_a_retraction_during_a_blend_is_the_stall_free_stream(preview):
    """A blended reconfigure at sample 150 (the blend runs 0.2 s); at sample 200 the
    samples stop arriving for 0.4 s (a transport stall) and the watch holds the stream as
    stale; then the late samples come and retract the hold.  Every correction and
    prediction after it is the stall-free pipeline's (same reconfigure), bit for bit;
    once the blend has ended the corrections are those of the offline twin of the new
    set."""
    cfg = Config().replace({**LOADED, 'compensation.preview_time': preview})
    new = cfg.replace(ADAPTED)
    p = RealtimePredictor(cfg, stale_margin=0.1)
    twin = RealtimePredictor(cfg, stale_margin=0.1)       # no stall
    live: dict[int, float] = {}
    for k in range(600):
        s = stamp(k)
        if k == 150:
            for q in (p, twin):
                q.reconfigure(new, blend=0.2)
        now = s
        if k == 200:                            # arrivals stop; the watch every 20 ms
            for h in range(s + 20 * MS, s + 400 * MS, 20 * MS):
                live.update({c.stamp_ns: c.delta for c in p.hold(h).corrections})
            assert p.stale and p.counters['stale_events'] == 1
        if k >= 200:                            # the late samples, in a burst
            now = max(s, stamp(200) + 400 * MS)
        o = p.push(s, ref(k), now_ns=now)
        r = twin.push(s, ref(k), now_ns=s)
        assert o.accepted and r.accepted
        if k == 200:
            assert [e.kind for e in o.events] == ['stale_retracted'] and not p.stale
        live.update({c.stamp_ns: c.delta for c in o.corrections})
        if k >= 200:
            assert [(c.stamp_ns, c.delta) for c in o.corrections] == \
                [(c.stamp_ns, c.delta) for c in r.corrections if c.stamp_ns > s - 60 * MS]
            assert [(q.stamp_ns, q.theta, q.effort) for q in o.predictions] == \
                [(q.stamp_ns, q.theta, q.effort) for q in r.predictions]
    for k in ('overruns', 'dropped_time_ns', 'rest_samples', 'samples_accepted'):
        assert p.counters[k] == twin.counters[k], k
    live.update({c.stamp_ns: c.delta for c in p.finish().corrections})
    st = np.array([stamp(k) for k in range(600)], dtype=np.int64)
    x = np.array([ref(k) for k in range(600)])
    want = feedforward_series(new, st, x)
    got = np.array([live[s] for s in st.tolist()])
    assert np.array_equal(got[400:], want[400:])     # the blend ended at sample ~350


def test_a_blend_leaves_no_wrapper_and_keeps_the_twin_equality():
    """The corrections before a blended reconfigure are the offline twin's of the old
    set; once the blend has ended the pipeline holds the new compensator alone (no
    wrapper left) and its corrections are the offline twin's of the new set, bit for
    bit (the twin knows no reconfigure: the handover leaves no trace)."""
    cfg = Config().replace(LOADED)
    new = cfg.replace(ADAPTED)
    st = np.array([stamp(k) for k in range(600)], dtype=np.int64)
    x = np.array([ref(k) for k in range(600)])
    p = RealtimePredictor(cfg, simulate=False)
    got: dict[int, float] = {}
    for k in range(600):
        if k == 200:
            p.reconfigure(new, blend=0.05)
            assert isinstance(p._samples.comp, BlendedCompensator)
        got.update({c.stamp_ns: c.delta for c in p.push(int(st[k]), float(x[k])).corrections})
        if k == 220:
            assert isinstance(p._samples.comp, BlendedCompensator)     # still blending
    got.update({c.stamp_ns: c.delta for c in p.finish().corrections})
    assert type(p._samples.comp) is Compensator and p.compensator is p._samples.comp
    d = np.array([got[s] for s in st.tolist()])
    assert np.array_equal(d[:200], feedforward_series(cfg, st, x)[:200])
    assert np.array_equal(d[260:], feedforward_series(new, st, x)[260:])
    assert not np.array_equal(d[200:250], feedforward_series(new, st, x)[200:250])


# ---- copy, deepcopy and pickle of every piece -------------------------------------------------
def blending_pipeline() -> RealtimePredictor:
    """A pipeline in the middle of a blended reconfigure, with a command queued and a
    resync candidate kept."""
    cfg = Config().replace(LOADED)
    p = RealtimePredictor(cfg)
    push_range(p, range(200))
    p.reconfigure(cfg.replace(ADAPTED), blend=0.1)
    push_range(p, range(200, 230))
    p.push_command(5_000 * MS, 0.01)
    o = p.push(stamp(230), ref(229) + 3.0, now_ns=stamp(230))
    assert o.rejected is Reject.JUMP and p.resync_candidates == 1
    assert isinstance(p._samples.comp, BlendedCompensator)
    return p


def pieces(p: RealtimePredictor) -> dict:
    samples = p._samples
    blend = samples.comp
    assert isinstance(blend, BlendedCompensator)
    return {'predictor': p, 'blend': blend, 'compensator': blend.new, 'simulator': p.sim,
            'drive': samples.drive, 'state': samples.state, 'queue': p._commands.queue,
            'stream_clock': p._commands.stream, 'admission': p._admission,
            'chain': p._stamped.chain, 'model_check': model_check()}


def model_check() -> ModelCheck:
    mc = ModelCheck(('worm_joint', 'gear_joint', 'antenna_joint'), 0.05, 1e-4)
    for k in range(100):
        mc.predicted_ns(stamp(k), [1e-3 * k, 2e-3 * k, 3e-3 * k])
        if k % 3 == 0:
            mc.measured_ns(stamp(k), {'antenna_joint': 3e-3 * k + 1e-5})
    return mc


def further(name: str, obj) -> list:
    """What ``obj`` yields on the same further input (plain values)."""
    ks = range(231, 281)
    if name == 'predictor':
        out = [obj.push(stamp(k), ref(k), now_ns=stamp(k)) for k in ks]
        return [([(c.stamp_ns, c.delta) for c in o.corrections],
                 [(q.stamp_ns, q.theta, q.effort) for q in o.predictions], o.rejected)
                for o in out] + [sorted(obj.counters.items())]
    t = [(stamp(k) - EPOCH) * 1e-9 for k in ks]
    if name in ('blend', 'compensator'):
        res = []
        for tk, k in zip(t, ks):
            obj.add_sample(tk, ref(k))
            res.append(obj.evaluate(tk))
            obj.trim(tk)
        return res
    if name == 'simulator':
        return [(obj.advance_to(tk, ref(k)), obj.joint_state()) for tk, k in zip(t, ks)]
    if name == 'drive':
        out = Output()
        for tk, k in zip(t, ks):
            obj.drive(stamp(k), tk, ref(k), ref(k), out, True)
        return [(q.stamp_ns, q.theta, q.effort) for q in out.predictions]
    if name == 'state':
        before = dataclasses.astuple(obj)
        obj.pending.append((stamp(300), 0.1, True))
        obj.load_pending.append((stamp(300), 1.0))
        obj.last_ns = stamp(300)
        return [before, dataclasses.astuple(obj)]
    if name == 'queue':
        for k in ks:
            obj.push('wall', stamp(k), ref(k))
        return [obj.take('wall', stamp(230), stamp(260)), obj.take('wall', stamp(260),
                                                                  stamp(290)), len(obj)]
    if name == 'stream_clock':
        return [obj(stamp(k) + (k % 7) * 50_000) for k in ks] + [obj.relocks, obj.outliers]
    if name == 'admission':
        return [(obj.value_reason(ref(k) * 1e3), obj.stamp_reason(stamp(k), stamp(k) - MS),
                 obj.jump_reason(ref(k) + 1.0, ref(k))) for k in ks]
    if name == 'chain':
        return [obj.offer(ref(229) + 3.0 + 1e-3 * i, Reject.JUMP, stamp(231 + i))[0]
                for i in range(3)] + [len(obj)]
    assert name == 'model_check'
    res = []
    for k in range(100, 150):
        obj.predicted_ns(stamp(k), [1e-3 * k, 2e-3 * k, 3e-3 * k])
        res.append(obj.measured_message_ns(stamp(k) - MS // 2, ['antenna_joint'],
                                           [3e-3 * k - 2e-5]))
    return [(names, r.tolist()) for names, r in res] + [obj.status_ns(stamp(150)).values]


#: pieces whose copy.copy runs on its own (the rest: a shallow copy that shares what it
#: holds, working in place of the original)
OWN_STATE = {'blend', 'compensator', 'simulator', 'drive', 'state'}
ROUND_TRIPS = {'copy': copy.copy, 'deepcopy': copy.deepcopy,
               'pickle': lambda x: pickle.loads(pickle.dumps(x))}


def test_every_piece_survives_copy_deepcopy_and_pickle():
    """After a blended reconfigure (the blend still running), each piece of the pipeline,
    the pipeline itself and the live model check go through copy.copy, copy.deepcopy and
    pickle; the copy yields what the original yields on the same further input, and
    the copies that run on their own leave the original as it was."""
    names = list(pieces(blending_pipeline()))
    want = {n: further(n, pieces(blending_pipeline())[n]) for n in names}
    for how, trip in ROUND_TRIPS.items():
        for n in names:
            original = pieces(blending_pipeline())[n]
            twin = trip(original)
            assert type(twin) is type(original), (how, n)
            assert further(n, twin) == want[n], (how, n)
            if how != 'copy' or n in OWN_STATE:
                assert further(n, original) == want[n], (how, n)      # untouched


def test_a_retraction_takes_back_the_stamped_stream_only():
    """While the stream is held as stale: a sample far back in time (a resync candidate,
    not yet counted) and a Float64 command (queued) arrive; then a late sample retracts
    the hold.  The candidate is still counted once (rejected when its chain breaks: every
    received sample is accepted or counted) and the command stays queued."""
    p = RealtimePredictor(Config(), stale_margin=0.0)
    push_range(p, range(300))
    now = stamp(299) + 30 * MS
    p.hold(now)
    assert p.stale
    o = p.push(stamp(100), ref(100), now_ns=now)          # 200 ms back: a restart?
    assert o.rejected is Reject.OUT_OF_ORDER and p.resync_candidates == 1
    assert p.push_command(7_000 * MS, 0.0).accepted and p.queued_commands == 1
    o = p.push(stamp(300), ref(300), now_ns=now)          # late: the hold retracted
    assert o.accepted and [e.kind for e in o.events] == ['stale_retracted']
    c = p.counters
    assert p.resync_candidates == 0 and c['rejected_samples'] == 1
    assert c['rejected_out_of_order'] == 1
    assert c['samples_received'] == c['samples_accepted'] + c['rejected_samples']
    assert p.queued_commands == 1


# ---- load samples across a start and a restart --------------------------------------------
def test_a_load_sample_stamped_before_the_start_comes_late():
    """A load sample kept before the first reference, the reference starts, then a load
    sample stamped between the two arrives: it applies from the simulator's time on
    (counted late), as any late load sample; nothing raises."""
    p = RealtimePredictor(Config())
    assert p.push_load(stamp(0) - 10 * MS, 1.0, now_ns=stamp(0)) is None
    push_range(p, range(1))
    assert p.load_torque == 1.0
    assert p.push_load(stamp(0) - 5 * MS, 2.0, now_ns=stamp(0)) is None
    assert p.counters['late_load_samples'] == 1 and p.load_torque == 2.0
    push_range(p, range(1, 50))
    assert p.load_torque == 2.0 and p.counters['simulation_errors'] == 0


def test_load_samples_after_a_restart_follow_the_new_time_origin():
    """A stream with a load sample, a reset, a new stream 2 s later: the load held is the
    last one (nothing of the former time origin left in the simulator) and the next load
    sample applies at its stamp."""
    p = RealtimePredictor(Config())
    push_range(p, range(5))
    assert p.push_load(stamp(5), 3.0, now_ns=stamp(5)) is None
    push_range(p, range(5, 300))
    p.reset()
    push_range(p, range(2000, 2050))
    assert p.load_torque == 3.0
    assert p.push_load(stamp(2060), 4.0, now_ns=stamp(2050)) is None
    push_range(p, range(2050, 2059))
    assert p.load_torque == 3.0
    push_range(p, range(2059, 2070))
    assert p.load_torque == 4.0 and p.counters['late_load_samples'] == 0
