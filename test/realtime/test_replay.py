# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``simulate --bag``: a recorded command stream replays through the node's pipeline to
the prediction the node computed live.  The 'live' run here feeds the pipeline exactly as
the node's callbacks do (arrival order, jittered arrivals, bursts, its receive clock),
independently of worm_gear_sim.realtime.replay; the bag is written with rosbags directly."""

from __future__ import annotations

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from worm_gear_sim import load_config
from worm_gear_sim.cli import main
from worm_gear_sim.dynamics.profiles import TrapezoidalProfile
from worm_gear_sim.realtime import RealtimePredictor
from worm_gear_sim.realtime.replay import compare_with_recorded, replay
from worm_gear_sim.records import prediction_streams as streams_of
from worm_gear_sim.records import read_bag, read_csv, write_streams

TS = get_typestore(Stores.ROS2_KILTED)
JS, F64 = 'sensor_msgs/msg/JointState', 'std_msgs/msg/Float64'
EPOCH = 1_763_890_855_000_000_123
JOINTS = ('worm_input_joint', 'worm_joint', 'worm_gear_joint', 'antenna_joint')


def servo_stream(seed=3, n=80):
    """The paper's move and a reversal, 1 kHz stamps on an epoch clock; arrivals 0.05-0.9
    ms late, in bursts of up to 3 (a stamp never arrives before an earlier one)."""
    rng = np.random.default_rng(seed)
    move = TrapezoidalProfile(0.1130973, 0.02, 0.004, 0.005)
    t = np.arange(n) * 1e-3
    x = move.theta1(t) - 0.5 * move.theta1(t - 0.04)
    stamps = EPOCH + np.round(t * 1e9).astype(np.int64)
    rx = stamps + rng.integers(50_000, 900_000, n)
    burst = rng.random(n) < 0.2
    for i in np.flatnonzero(burst)[:-1]:
        rx[i] = rx[i + 1]                       # held back, arrives with the next one
    rx = np.maximum.accumulate(rx)
    return stamps, x, rx


def live_node(cfg, stamps, x, rx, stale_margin=0.02, hold_until=None):
    """What the node's callbacks do: push each sample at reception, a 1 kHz hold timer
    (firing on up to ``hold_until`` after the last sample, if given)."""
    p = RealtimePredictor(cfg, stale_margin=stale_margin)
    preds = []
    timer = int(rx[0])
    for s, v, r in zip(stamps.tolist(), x.tolist(), rx.tolist()):
        while timer <= r:
            preds += p.hold(timer).predictions
            timer += 1_000_000
        preds += p.push(s, v, now_ns=r).predictions
    while hold_until is not None and timer <= hold_until:
        preds += p.hold(timer).predictions
        timer += 1_000_000
    return preds


def record_bag(path, storage, stamps, x, rx, preds, stamped=True, answers=()):
    """A recording: the commands (stamped references or Float64), the node's joint_states
    and ``answers``, (topic, joint, stamps, values) of the node's stamped answers."""
    plugin = {'sqlite3': StoragePlugin.SQLITE3, 'mcap': StoragePlugin.MCAP}[storage]
    Header, Time = TS.types['std_msgs/msg/Header'], TS.types['builtin_interfaces/msg/Time']
    with Writer(path, version=9, storage_plugin=plugin) as w:
        if stamped:
            c = w.add_connection('/worm_angle_reference', JS, typestore=TS)
            for s, v, r in zip(stamps.tolist(), x.tolist(), rx.tolist()):
                msg = TS.types[JS](header=Header(stamp=Time(sec=s // 10**9,
                                                            nanosec=s % 10**9), frame_id=''),
                                   name=[JOINTS[0]], position=np.array([v]),
                                   velocity=np.empty(0), effort=np.empty(0))
                w.write(c, r, TS.serialize_cdr(msg, JS))
        else:
            c = w.add_connection('/worm_angle_command', F64, typestore=TS)
            for v, r in zip(x.tolist(), rx.tolist()):
                w.write(c, r, TS.serialize_cdr(TS.types[F64](data=v), F64))
        # the node's live joint_states, as a recorder received them
        js = TS.types[JS]
        c2 = w.add_connection('/joint_states', JS, typestore=TS)
        for p in preds:
            s = p.stamp_ns
            msg = js(header=Header(stamp=Time(sec=s // 10**9, nanosec=s % 10**9),
                                   frame_id=''), name=list(JOINTS),
                     position=np.array(p.position), velocity=np.array(p.velocity),
                     effort=np.array(p.effort))
            w.write(c2, s + 200_000, TS.serialize_cdr(msg, JS))
        for topic, joint, st, values in answers:
            c3 = w.add_connection(topic, JS, typestore=TS)
            for s, v in zip(st, values):
                msg = js(header=Header(stamp=Time(sec=s // 10**9, nanosec=s % 10**9),
                                       frame_id=''), name=[joint], position=np.array([v]),
                         velocity=np.empty(0), effort=np.empty(0))
                w.write(c3, s + 300_000, TS.serialize_cdr(msg, JS))
    return path


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_bag_replays_to_the_live_prediction(tmp_path, capsys, storage):
    cfg = load_config()
    stamps, x, rx = servo_stream()
    live = live_node(cfg, stamps, x, rx)
    assert len(live) == stamps.size and not any(p.held for p in live)
    bag = record_bag(tmp_path / 'rec', storage, stamps, x, rx, live)
    out = tmp_path / 'replay.csv'
    status = main(['simulate', '--bag', str(bag), '-o', str(out), '--no-plot'])
    stdout = capsys.readouterr().out
    assert status == 0, stdout
    line = next(ln for ln in stdout.splitlines() if 'max |replay - recorded /joint_states|' in ln)
    assert float(line.split('= ')[1].split()[0]) <= 1e-9 and 'over 80 equal stamps' in line
    # the prediction bag: stamped on the recording's clock, equal to the live node
    pred = read_bag(tmp_path / 'replay_bag', command_topic='/worm_gear_sim/feedforward',
                    joint_states_topic='joint_states', require_measured=True)
    got_ns = pred.t0_ns + np.round(pred.t * 1e9).astype(np.int64)
    live_ns = np.array([p.stamp_ns for p in live])
    np.testing.assert_array_equal(got_ns, live_ns)
    live_pos = np.array([p.position for p in live])
    for k, name in enumerate(('theta2', 'theta3', 'theta4'), start=1):
        assert np.max(np.abs(pred.measured[name] - live_pos[:, k])) <= 1e-9
    # the antenna really moved and rang: the comparison is not between zeros
    assert np.ptp(live_pos[:, 3]) > 1e-3
    # the CSV beside it: same prediction, t relative to the first stamp
    csv = read_csv(out)                       # the reader takes the writer's header
    np.testing.assert_allclose(csv.t, (live_ns - EPOCH) * 1e-9, rtol=0, atol=1e-12)
    assert np.max(np.abs(csv.measured['theta4'] - live_pos[:, 3])) <= 1e-9
    assert f't0_ns: {EPOCH}' in out.read_text()
    assert (tmp_path / 'replay_feedforward.csv').is_file()


def test_recorded_answers_align_with_the_replay_by_stamp(tmp_path, capsys):
    """The node's stamped answers in the bag (~/positioning_error at its predictions'
    stamps, ~/feedforward at its corrections') are compared with the replay stamp by stamp:
    0 rad for the node's own values, the offset for values shifted by a known amount."""
    cfg = load_config()
    stamps, x, rx = servo_stream(seed=9)
    p = RealtimePredictor(cfg, stale_margin=0.02)
    preds, corrs = [], []
    for s, v, r in zip(stamps.tolist(), x.tolist(), rx.tolist()):
        out = p.push(s, v, now_ns=r)
        preds += out.predictions
        corrs += out.corrections
    assert len(corrs) > 40 and np.ptp([c.delta for c in corrs]) > 1e-4
    pe = ('/worm_gear_sim/positioning_error', JOINTS[3], [q.stamp_ns for q in preds],
          [q.positioning_error for q in preds])
    ff = ('/worm_gear_sim/feedforward', JOINTS[0], [c.stamp_ns for c in corrs],
          [c.delta + 1e-6 for c in corrs])          # 1 urad off: the comparison sees it
    bag = record_bag(tmp_path / 'rec', 'mcap', stamps, x, rx, preds, answers=(pe, ff))
    cmp = compare_with_recorded(replay(cfg, read_bag(bag)), bag)
    assert cmp['answers']['positioning_error'] == {'stamps_compared': len(preds),
                                                   'max_abs_diff': 0.0}
    assert cmp['answers']['feedforward']['stamps_compared'] == len(corrs)
    assert cmp['answers']['feedforward']['max_abs_diff'] == pytest.approx(1e-6, abs=1e-12)
    assert 'worm_error' not in cmp['answers']             # not recorded
    assert main(['simulate', '--bag', str(bag), '-o', str(tmp_path / 'r.csv'),
                 '--no-plot']) == 0
    out = capsys.readouterr().out
    assert f'max |replay - recorded ~/positioning_error| = 0.000e+00 rad over {len(preds)} ' \
        'equal stamps' in out, out
    assert 'max |replay - recorded ~/feedforward| = 1.000e-06 rad' in out, out


def test_replay_api_reports_agreement_and_float64_path(tmp_path):
    cfg = load_config()
    stamps, x, rx = servo_stream(seed=5)
    live = live_node(cfg, stamps, x, rx)
    bag = record_bag(tmp_path / 'rec', 'sqlite3', stamps, x, rx, live)
    rep = replay(cfg, read_bag(bag))
    assert rep.info['input'] == 'stamped' and rep.info['stamp_window']
    cmp = compare_with_recorded(rep, bag)
    assert cmp['stamps_compared'] == stamps.size and cmp['max_abs_diff'] <= 1e-9
    # Float64: samples at the receive time, ticks at node.publish_rate_hz on that clock
    bag2 = record_bag(tmp_path / 'rec64', 'mcap', stamps, x, rx, live, stamped=False)
    rep2 = replay(cfg, read_bag(bag2))
    assert rep2.info['input'] == 'float64'
    p = RealtimePredictor(cfg)
    ticks = []
    tick = int(rx[0]) + 1_000_000
    for v, r in zip(x.tolist(), rx.tolist()):
        while tick <= r:
            ticks += p.tick(tick).predictions
            tick += 1_000_000
        p.push_command(r, v)
    while tick <= int(rx.max()) + 1_000_000:
        ticks += p.tick(tick).predictions
        tick += 1_000_000
    assert [q.stamp_ns for q in ticks] == rep2.stamps_ns.tolist()
    np.testing.assert_array_equal(np.array([q.position for q in ticks]), rep2.position)


def test_simulate_bag_errors(tmp_path, capsys):
    st = EPOCH + np.arange(5, dtype=np.int64) * 1_000_000
    write_streams(tmp_path / 'only_js', streams_of(st, np.zeros((5, 4)), joint_names=JOINTS))
    status = main(['simulate', '--bag', str(tmp_path / 'only_js'), '-o',
                   str(tmp_path / 'o.csv'), '--no-plot'])
    err = capsys.readouterr().err
    assert status == 2 and 'no command topic' in err and '/joint_states' in err
    assert 'Traceback' not in err
    status = main(['simulate', '--bag', str(tmp_path / 'nope'), '-o', str(tmp_path / 'o.csv')])
    assert status == 2 and 'bag not found' in capsys.readouterr().err
    status = main(['simulate', '--bag', str(tmp_path / 'only_js'), '--csv', 'x.csv'])
    assert status == 2


def test_float64_replay_on_recorded_ticks(tmp_path, capsys):
    """The live node's Float64 path ticks on its wall clock (jittered, a missed tick): the
    replay ticks at the stamps of its recorded joint_states."""
    cfg = load_config()
    stamps, x, rx = servo_stream(seed=7)
    rng = np.random.default_rng(8)
    ticks = rx[0] + 1_000_000 * np.arange(1, 90) + rng.integers(-300_000, 300_000, 89)
    ticks = np.delete(ticks, 30)                      # a missed tick
    p = RealtimePredictor(cfg)
    live = []
    k = 0
    for v, r in zip(x.tolist(), rx.tolist()):
        while k < ticks.size and ticks[k] <= r:
            live += p.tick(int(ticks[k])).predictions
            k += 1
        p.push_command(r, v)
    for tk in ticks[k:].tolist():
        live += p.tick(int(tk)).predictions
    bag = record_bag(tmp_path / 'rec64', 'sqlite3', stamps, x, rx, live, stamped=False)
    rep = replay(cfg, read_bag(bag), tick_stamps_ns=ticks)
    assert rep.info['ticks'] == 'recorded joint_states stamps'
    cmp = compare_with_recorded(rep, bag)
    assert cmp['stamps_compared'] == len(live) and cmp['max_abs_diff'] == 0.0
    grid = replay(cfg, read_bag(bag))                 # a regular grid instead: not the same
    assert compare_with_recorded(grid, bag)['stamps_compared'] < len(live)
    # the command line finds the recorded ticks itself
    assert main(['simulate', '--bag', str(bag), '-o', str(tmp_path / 'r.csv'), '--no-plot']) == 0
    out = capsys.readouterr().out
    assert 'ticks at the recorded joint_states stamps' in out
    assert '= 0.000e+00 rad' in out


@pytest.mark.parametrize('take_us', [20, 8000])
@pytest.mark.parametrize('early_ms', [0, 4, 20])
def test_a_pause_replays_when_the_recorder_got_the_samples_before_the_node(
        tmp_path, capsys, early_ms, take_us):
    """Two bursts of stamped samples with a pause between them; the node (its hold timer
    every 1 ms, the node's stale margin of 0.1 s) publishes held predictions in the pause.
    The recorder, a second subscriber on the node's executor, may receive the second burst
    before the node takes it, while the node's timer still publishes held predictions: the
    replay must put those held predictions before the burst (a held prediction proves the
    node had not taken the burst yet).  Seen live under load as 222 of 592 equal stamps.

    ``take_us`` 8000: a loaded node takes a sample every 8 ms, so the first burst's last
    sample arrives 16 ms after its stamp; the node then stamps its held predictions with
    the stream's time (its clock less that lag), and the replay must fire its hold at the
    clock that gave each stamp (the recorder got the samples earlier: its lag is smaller).
    Seen live on Jazzy under CI load as 139 of 254 equal stamps."""
    cfg = load_config()
    move = TrapezoidalProfile(0.1130973, 0.02, 0.004, 0.005)
    x = move.theta1(np.arange(120) * 1e-3)
    t_node = EPOCH
    stamps, rx_node = [], []
    for arrive in (0, 1_000_000_000):                         # bursts at 0 and 1 s
        base = t_node + arrive + 400_000_000                    # stamped 0.4 s ahead
        stamps += [base + k * 1_000_000 for k in range(60)]
        rx_node += [t_node + arrive + 3_000_000 + k * take_us * 1000 for k in range(60)]
    stamps, rx_node = np.array(stamps), np.array(rx_node)
    # (the node's stale margin, ros/node.py STALE_MARGIN; the second pause held too)
    preds = live_node(cfg, stamps, x, rx_node, stale_margin=0.1,
                      hold_until=int(rx_node[-1]) + 600_000_000)
    held = [q.stamp_ns for q in preds if q.stamp_ns not in set(stamps.tolist())]
    second = int(rx_node[60])
    lag = max(0, int(rx_node[59] - stamps[59]))
    assert lag == (16_000_000 if take_us == 8000 else 0)
    # held stamps: the node's timer instants (every 1 ms from the first sample) less the lag
    assert all((h + lag - int(rx_node[0])) % 1_000_000 == 0 for h in held)
    assert sum(second - 3_000_000 <= h + lag < second for h in held) == 3   # in the last 3 ms
    rx_rec = rx_node.copy()
    rx_rec[60 if take_us == 20 else 0:] -= early_ms * 1_000_000    # the recorder got it early
    bag = record_bag(tmp_path / 'pause', 'sqlite3', stamps, x, rx_rec, preds)
    assert main(['simulate', '--bag', str(bag), '-o', str(tmp_path / 'r.csv'),
                 '--no-plot']) == 0
    line = next(ln for ln in capsys.readouterr().out.splitlines()
                if 'max |replay - recorded /joint_states|' in ln)
    assert float(line.split('= ')[1].split()[0]) <= 1e-9
    assert f'over {len(preds)} equal stamps' in line, line


def test_a_pause_replays_when_the_recorder_stalled_inside_a_burst(tmp_path, capsys):
    """Stamps 50 ms behind the node's clock (a servo's transport delay); the recorder's
    process stalls 150 ms in the middle of the first burst, which the node took evenly.
    The recorder's receive times then show a gap longer than the stale margin inside the
    burst, where the node published no held prediction: the replay must not fire the
    node's first held prediction there (the samples' stamps prove the node took them
    before it; after it they would have been late).  Seen live beside three busy loops as
    a difference of 5.9e-4 rad at 469 of 529 stamps."""
    cfg = load_config()
    move = TrapezoidalProfile(0.1130973, 0.02, 0.004, 0.005)
    x = move.theta1(np.arange(120) * 1e-3)
    stamps, rx_node = [], []
    for arrive in (0, 1_000_000_000):
        stamps += [EPOCH + arrive - 50_000_000 + k * 1_000_000 for k in range(60)]
        rx_node += [EPOCH + arrive + 3_000_000 + k * 2_000_000 for k in range(60)]
    stamps, rx_node = np.array(stamps), np.array(rx_node)
    preds = live_node(cfg, stamps, x, rx_node, stale_margin=0.1,
                      hold_until=int(rx_node[-1]) + 600_000_000)
    held = [q.stamp_ns for q in preds if q.stamp_ns not in set(stamps.tolist())]
    assert held and min(held) > stamps[59] + 100_000_000     # held only after the burst
    rx_rec = rx_node.copy()
    rx_rec[40:60] += 150_000_000                             # the recorder stalled
    bag = record_bag(tmp_path / 'stall', 'sqlite3', stamps, x, rx_rec, preds)
    assert main(['simulate', '--bag', str(bag), '-o', str(tmp_path / 'r.csv'),
                 '--no-plot']) == 0
    line = next(ln for ln in capsys.readouterr().out.splitlines()
                if 'max |replay - recorded /joint_states|' in ln)
    assert float(line.split('= ')[1].split()[0]) <= 1e-9, line
    assert f'over {len(preds)} equal stamps' in line, line
