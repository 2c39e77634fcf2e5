# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""records: CSV by header (units, epoch, every malformed case) and rosbag2 in/out on
small bags this test writes with ``rosbags`` itself (sqlite3 and mcap, Float64 and the
stamped JointState reference)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from worm_gear_sim.records import (
    Record,
    RecordError,
    align_by_stamp,
    read_bag,
    read_csv,
    read_record,
    read_series,
    write_bag,
)

TS = get_typestore(Stores.ROS2_KILTED)      # written with Kilted's store, read with Jazzy's
F64, JS = 'std_msgs/msg/Float64', 'sensor_msgs/msg/JointState'
JOINTS = ('worm_input_joint', 'worm_joint', 'worm_gear_joint', 'antenna_joint')
EPOCH = 1_763_890_855_123_456_789            # 2025-11-23T09:40:55.123456789Z


def write(tmp_path, text, name='rec.csv'):
    f = tmp_path / name
    f.write_text(text)
    return f


# ---- CSV: what is accepted ---------------------------------------------------------------
def test_csv_columns_by_name_units_converted(tmp_path):
    # swapped columns, degrees, milliseconds, an extra column, a comment, spaces
    f = write(tmp_path, '# drive 3, run 7\ntheta4 [mrad], temperature, t (ms), '
                        'theta1 [deg]\n0.0, 20, 0.0, 0\n0.5, 20, 1.0, 90\n1.0, 21, 2.5, 180\n')
    r = read_csv(f)
    assert isinstance(r, Record) and r.name == 'rec'
    np.testing.assert_allclose(r.t, [0.0, 1e-3, 2.5e-3], rtol=0, atol=1e-18)
    np.testing.assert_allclose(r.theta1, [0.0, math.pi / 2, math.pi], rtol=1e-15)
    np.testing.assert_allclose(r.measured['theta4'], [0.0, 5e-4, 1e-3], rtol=1e-15)
    assert list(r.measured) == ['theta4'] and r.t0_ns == 0 and not r.is_epoch
    assert r.source['units'] == {'t': 'ms', 'theta1': 'deg', 'theta4': 'mrad'}
    assert r.source['ignored_columns'] == ['temperature']
    assert r.command_stamps_ns is None
    ts, vs = r.command_stream()
    assert list(ts) == [0, 1_000_000, 2_500_000] and list(vs) == list(r.theta1)


def test_csv_epoch_seconds_keep_their_nanoseconds(tmp_path):
    # float64 epoch seconds would lose ~100 ns; the reader parses the decimals exactly
    rows = ''.join(f'{(EPOCH + k * 1_000_001) // 10**9}.{(EPOCH + k * 1_000_001) % 10**9:09d},'
                   f'{0.01 * k}\n' for k in range(5))
    r = read_csv(write(tmp_path, 't [s],theta1 [rad]\n' + rows))
    assert r.t0_ns == EPOCH and r.is_epoch
    np.testing.assert_array_equal(r.t, np.arange(5) * 1.000001e-3)
    assert '2025-11-23T09:40:55.123456789Z' in r.describe()


def test_csv_epoch_nanoseconds_and_plotjuggler_names(tmp_path):
    text = '__time [ns],/worm_angle_command/data,/joint_states/antenna_joint/position\n' + \
        ''.join(f'{EPOCH + k * 10**6},{k * 0.1},{k * 0.002}\n' for k in range(3))
    f = write(tmp_path, text)
    r = read_csv(f, columns={'theta1': '/worm_angle_command/data',
                             'theta4': '/joint_states/antenna_joint/position'})
    assert r.t0_ns == EPOCH and list(r.t) == [0.0, 1e-3, 2e-3]
    np.testing.assert_allclose(r.measured['theta4'], [0.0, 0.002, 0.004])
    with pytest.raises(RecordError, match='no column .theta1.'):
        read_csv(f)                               # without the mapping: named, not guessed


def test_csv_times_relative_to_first_sample(tmp_path):
    r = read_csv(write(tmp_path, 't,theta1\n2.5,0.1\n2.75,0.2\n'))
    assert list(r.t) == [0.0, 0.25] and r.t0_ns == 2_500_000_000 and not r.is_epoch
    assert 'shifted' in r.describe()


def test_csv_semicolon_tab_and_trailing_delimiter(tmp_path):
    for text in ('t;theta1\n0;0\n0.1;0.2\n', 't\ttheta1\n0\t0\n0.1\t0.2\n',
                 't,theta1,\n0,0,\n0.1,0.2,\n'):
        r = read_csv(write(tmp_path, text))
        assert list(r.theta1) == [0.0, 0.2]


# ---- CSV: every malformed case is a one-line error naming the cause ----------------------
@pytest.mark.parametrize('text, words', [
    ('time_s,theta1\n0,0\n1,1\n', ["no column 't'", "did you mean 'time_s'"]),
    ('t,theta_1\n0,0\n1,1\n', ["no column 'theta1'", "did you mean 'theta_1'"]),
    ('t,theta2\n0,0\n1,1\n', ["no column 'theta1'"]),
    ('0,0\n0.1,0.2\n', ['no header line']),
    ('', ['empty']),
    ('# only a comment\n', ['empty']),
    ('t,theta1\n', ['0 data row']),
    ('t,theta1\n0,0\n', ['1 data row', 'at least 2']),
    ('t,theta1\n0,0\n0.01,0.1\n0.01,0.2\n', ['line 4', 'repeats', 'duplicated']),
    ('t,theta1\n0,0\n0.02,0.1\n0.01,0.2\n', ['line 4', 'backwards']),
    ('t,theta1\n0,0\nnan,0.1\n', ['line 3', 'not a finite time']),
    ('t,theta1\n0,0\n0.01,nan\n', ['line 3', "column 'theta1'", 'nan']),
    ('t,theta1,theta4\n0,0,0\n0.01,0.1,\n', ['line 3', "column 'theta4'", 'empty']),
    ('t,theta1\n0,0\n0.01,inf\n', ['line 3', 'not a finite angle']),
    ('t,theta1\n0,0\n0.01,one\n', ['line 3', "'one' is not a number"]),
    ('t,theta1\n0,0\n0.01\n', ['line 3', '1 fields', 'header has 2']),
    ('t,theta1\n0,0\n0.01,0.1,7\n', ['line 3', '3 fields']),
    ('t,theta1 [grad]\n0,0\n1,1\n', ["unknown angle unit 'grad'", 'deg']),
    ('t [h],theta1\n0,0\n1,1\n', ["unknown time unit 'h'"]),
    ('t,theta1 [rad],theta1 [deg]\n0,0,0\n1,1,57\n', ['all give theta1', 'ambiguous']),
    ('t,time,theta1\n0,0,0\n1,1,1\n', ['all give t', 'ambiguous']),
    (f't,theta1\n{EPOCH},0\n{EPOCH + 10**6},0.1\n', ['not a plausible time in seconds',
                                                     't [ns]']),
])
def test_csv_malformed(tmp_path, text, words):
    f = write(tmp_path, text)
    with pytest.raises(RecordError) as exc:
        read_csv(f)
    msg = str(exc.value)
    assert '\n' not in msg and str(f) in msg
    for w in words:
        assert w in msg, (w, msg)


def test_csv_missing_file_directory_and_measured_required(tmp_path):
    with pytest.raises(RecordError, match='file not found'):
        read_csv(tmp_path / 'missing.csv')
    with pytest.raises(RecordError, match='is a directory'):
        read_csv(tmp_path)
    f = write(tmp_path, 't,theta1\n0,0\n1,1\n')
    with pytest.raises(RecordError, match='no measured column'):
        read_csv(f, require_measured=True)
    with pytest.raises(RecordError, match='unknown role'):
        read_csv(f, columns={'theta9': 'x'})
    with pytest.raises(RecordError, match="no column 'x' .mapped to theta1."):
        read_csv(f, columns={'theta1': 'x'})
    (tmp_path / 'bin.csv').write_bytes(b'\xff\xfe\x00\x81')
    with pytest.raises(RecordError, match='not a text CSV'):
        read_csv(tmp_path / 'bin.csv')


# ---- rosbag2 ----------------------------------------------------------------------------
def _time(ns):
    return TS.types['builtin_interfaces/msg/Time'](sec=ns // 10**9, nanosec=ns % 10**9)


def joint_state(ns, names, pos):
    return TS.types[JS](header=TS.types['std_msgs/msg/Header'](stamp=_time(ns), frame_id=''),
                        name=list(names), position=np.array(pos, float),
                        velocity=np.empty(0), effort=np.empty(0))


def make_bag(path, storage, messages):
    """messages: [(topic, msgtype, receive_ns, msg)]; written in receive order."""
    plugin = {'sqlite3': StoragePlugin.SQLITE3, 'mcap': StoragePlugin.MCAP}[storage]
    with Writer(path, version=9, storage_plugin=plugin) as w:
        conns = {}
        for topic, typ, _, _ in messages:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, typ, typestore=TS)
        for topic, typ, ns, msg in sorted(messages, key=lambda m: m[2]):
            w.write(conns[topic], ns, TS.serialize_cdr(msg, typ))
    return path


def drive_samples(n=40):
    """A command ramp at 1 kHz and a 'measured' drive at 2 kHz with a 94.5 Hz ring."""
    tc = np.arange(n) * 1e-3
    cmd = 0.05 * np.minimum(tc / 0.02, 1.0)
    tm = np.arange(2 * n) * 0.5e-3 - 1.5e-3          # starts before the first command
    th = np.column_stack([0.05 * np.minimum(np.clip(tm, 0, None) / 0.02, 1.0) + 1e-4 * k *
                          np.sin(2 * np.pi * 94.5 * tm) for k in (1, 2, 3)])
    return tc, cmd, tm, th


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
@pytest.mark.parametrize('stamped', [False, True])
def test_bag_command_and_measured(tmp_path, storage, stamped):
    tc, cmd, tm, th = drive_samples()
    jitter = np.random.default_rng(1).integers(50_000, 400_000, tc.size)   # receive delay
    msgs = []
    for k, (t, v) in enumerate(zip(tc, cmd)):
        stamp = EPOCH + int(round(t * 1e9))
        if stamped:
            msgs.append(('/worm_angle_reference', JS, stamp + int(jitter[k]),
                         joint_state(stamp, [JOINTS[0]], [v])))
        else:
            msgs.append(('/worm_angle_command', F64, stamp, TS.types[F64](data=v)))
    for t, row in zip(tm, th):
        stamp = EPOCH + int(round(t * 1e9))
        # a realistic driver: every joint, in another order, received later
        msgs.append(('/measured_joint_states', JS, stamp + 300_000,
                     joint_state(stamp, ['antenna_joint', 'worm_gear_joint', 'worm_joint',
                                         'worm_input_joint'], [row[2], row[1], row[0], 9.9])))
    msgs.append(('/rosout', 'rcl_interfaces/msg/Log', EPOCH, TS.types[
        'rcl_interfaces/msg/Log'](stamp=_time(EPOCH), level=20, name='n', msg='m', file='f',
                                  function='g', line=1)))
    bag = make_bag(tmp_path / 'bag', storage, msgs)
    r = read_bag(bag)
    assert r.source['command_topic'] == ('/worm_angle_reference' if stamped else
                                         '/worm_angle_command')
    assert r.source['command_stamp'] == ('header.stamp' if stamped else 'bag receive time')
    assert r.t0_ns == EPOCH and r.is_epoch
    keep = tm >= -1e-12
    assert r.source['measurements_before_first_command'] == int((~keep).sum()) == 3
    np.testing.assert_allclose(r.t, tm[keep], atol=1e-12)
    np.testing.assert_array_equal(r.measured['theta2'], th[keep, 0])
    np.testing.assert_array_equal(r.measured['theta4'], th[keep, 2])
    np.testing.assert_allclose(r.theta1, np.interp(tm[keep], tc, cmd), atol=1e-15)
    tcs, vcs = r.command_samples()
    np.testing.assert_allclose(tcs, tc, atol=1e-12)
    np.testing.assert_array_equal(vcs, cmd)
    stamps, vals = r.command_stream()
    assert stamps.dtype == np.int64 and stamps[0] == EPOCH and vals.size == tc.size
    # the same bag given as its storage file
    single = next(bag.glob('*.mcap' if storage == 'mcap' else '*.db3'))
    assert np.array_equal(read_record(single).t, r.t)
    # without the measured topic: the command samples themselves
    r2 = read_bag(bag, joint_states_topic=None, require_measured=False)
    assert r2.t.size == r.t.size        # defaults find measured_joint_states again
    hold = read_bag(bag, interpolation='hold')
    idx = np.searchsorted(tc, tm[keep] + 1e-12, side='right') - 1
    np.testing.assert_array_equal(hold.theta1, cmd[idx])


def test_bag_stamped_reference_raw_stream_and_rejections(tmp_path):
    # out-of-order arrival, a duplicate stamp, wrong joint names, an empty position, NaN
    m = [('/ns/worm_angle_reference', JS, EPOCH + 10, joint_state(EPOCH, [], [0.0])),
         ('/ns/worm_angle_reference', JS, EPOCH + 20, joint_state(EPOCH + 2000, [], [0.2])),
         ('/ns/worm_angle_reference', JS, EPOCH + 30, joint_state(EPOCH + 1000, [], [0.1])),
         ('/ns/worm_angle_reference', JS, EPOCH + 40, joint_state(EPOCH + 1000, [], [0.7])),
         ('/ns/worm_angle_reference', JS, EPOCH + 50, joint_state(EPOCH + 3000, ['x'], [5])),
         ('/ns/worm_angle_reference', JS, EPOCH + 60, joint_state(EPOCH + 3000, [], [])),
         ('/ns/worm_angle_reference', JS, EPOCH + 70,
          joint_state(EPOCH + 4000, [JOINTS[0]], [math.nan])),
         ('/ns/worm_angle_reference', JS, EPOCH + 80,
          joint_state(EPOCH + 5000, ['other', JOINTS[0]], [7.0, 0.3])),   # name[0] wrong
         ('/ns/worm_angle_reference', JS, EPOCH + 90,
          joint_state(EPOCH + 5000, [JOINTS[0], 'other'], [0.3, 7.0]))]
    r = read_bag(make_bag(tmp_path / 'b', 'mcap', m))      # namespaced topic found
    assert r.source['command_topic'] == '/ns/worm_angle_reference'
    assert r.source['rejected_commands'] == 3 and r.source['non_finite_commands'] == 1
    assert r.source['duplicate_command_stamps'] == 1 and r.measured == {}
    # raw stream in arrival order (what a node received), sorted valid samples in t/theta1
    assert list(r.command_stream()[0] - EPOCH) == [0, 2000, 1000, 1000, 4000, 5000]
    assert np.isnan(r.command_stream()[1][4])
    assert list(np.round(r.t * 1e9)) == [0, 1000, 2000, 5000]
    assert list(r.theta1) == [0.0, 0.1, 0.2, 0.3]           # first of a duplicate kept


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_bag_errors_name_the_cause(tmp_path, storage):
    m = [('/worm_angle_command', F64, EPOCH + k, TS.types[F64](data=0.1 * k))
         for k in range(3)]
    m.append(('/js', JS, EPOCH, joint_state(EPOCH, ['a', 'b'], [1.0, 2.0])))
    m.append(('/cmd_twist', 'std_msgs/msg/String', EPOCH, TS.types['std_msgs/msg/String'](
        data='x')))
    bag = make_bag(tmp_path / 'b', storage, m)
    with pytest.raises(RecordError, match=r'no command topic /servo_ref in the bag; it has: '
                       r'/cmd_twist \(std_msgs/msg/String\), /js'):
        read_bag(bag, command_topic='/servo_ref')
    with pytest.raises(RecordError, match='no measured JointState topic measured_joint_states '
                       'or joint_states'):
        read_bag(bag, require_measured=True)
    with pytest.raises(RecordError, match="/js has joints \\['a', 'b'\\]; none of worm_joint"):
        read_bag(bag, joint_states_topic='js')
    with pytest.raises(RecordError, match='is std_msgs/msg/String; expected'):
        read_bag(bag, command_topic='cmd_twist')
    with pytest.raises(RecordError, match='measured topic /worm_angle_command is'):
        read_bag(bag, joint_states_topic='worm_angle_command')
    r = read_bag(bag)
    assert r.measured == {} and list(r.theta1) == [0.0, 0.1, 0.2]
    with pytest.raises(RecordError, match='bag not found'):
        read_bag(tmp_path / 'nope')
    (tmp_path / 'junk').mkdir()
    with pytest.raises(RecordError, match='not a readable rosbag2 bag'):
        read_bag(tmp_path / 'junk')
    with pytest.raises(RecordError, match='need 4'):
        read_bag(bag, joint_names=['a'])


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
@pytest.mark.parametrize('float64', [False, True])
def test_write_bag_round_trip(tmp_path, storage, float64):
    n = 50
    stamps = EPOCH + np.arange(n, dtype=np.int64) * 1_000_000
    pos = np.random.default_rng(2).normal(size=(n, 4))
    vel, eff = pos * 2.0, pos * 3.0
    err, worm = pos[:, 3] - pos[:, 0] / 56, pos[:, 1] - pos[:, 0]
    ff = (stamps[::2], np.linspace(0, 1e-3, n // 2))
    out = write_bag(tmp_path / 'pred', stamps, pos, joint_names=JOINTS, velocity=vel,
                    effort=eff, positioning_error=err, worm_error=worm, feedforward=ff,
                    compensated_command=(ff[0], ff[1] + 1.0), float64_outputs=float64,
                    storage=storage)
    ts = get_typestore(Stores.ROS2_JAZZY)
    got: dict = {}
    with Reader(out) as reader:
        assert reader.message_count == n * 3 + n // 2 * 2
        for conn, log_ns, raw in reader.messages():
            msg = ts.deserialize_cdr(raw, conn.msgtype)
            got.setdefault(conn.topic, []).append((log_ns, msg))
    js = got['/joint_states']
    assert [log for log, _ in js] == list(stamps)
    assert all(m.header.stamp.sec * 10**9 + m.header.stamp.nanosec == s
               for (_, m), s in zip(js, stamps))
    np.testing.assert_array_equal(np.array([m.position for _, m in js]), pos)
    np.testing.assert_array_equal(np.array([m.effort for _, m in js]), eff)
    assert list(js[0][1].name) == list(JOINTS)
    pe = got['/worm_gear_sim/positioning_error']
    vals = [m.data for _, m in pe] if float64 else [m.position[0] for _, m in pe]
    np.testing.assert_array_equal(vals, err)
    if not float64:                      # the node's default: stamped, one named joint
        assert list(pe[0][1].name) == [JOINTS[3]]
        assert [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, m in pe] == \
            list(stamps)
        assert list(got['/worm_gear_sim/feedforward'][0][1].name) == [JOINTS[0]]
        assert list(got['/worm_gear_sim/worm_error'][0][1].name) == [JOINTS[1]]
    cc = got['/worm_gear_sim/compensated_command']
    np.testing.assert_array_equal([m.position[0] for _, m in cc], ff[1] + 1.0)
    # and back through the reader: the prediction as the measured topic
    rec = read_bag(out, command_topic='/worm_gear_sim/compensated_command',
                   joint_states_topic='joint_states')
    np.testing.assert_array_equal(rec.measured['theta4'][: n - 1], pos[: n - 1, 3])
    with pytest.raises(RecordError, match='exists already'):
        write_bag(out, stamps, pos, joint_names=JOINTS)
    write_bag(out, stamps[:2], pos[:2], joint_names=JOINTS, overwrite=True, namespace='replay')
    with Reader(out) as reader:
        assert [c.topic for c in reader.connections] == ['/replay/joint_states']
    (tmp_path / 'notabag').mkdir()
    with pytest.raises(RecordError, match='not a bag'):
        write_bag(tmp_path / 'notabag', stamps, pos, joint_names=JOINTS, overwrite=True)


def test_series_align_by_stamp(tmp_path):
    """read_series takes one value per message (a JointState's joint at its header.stamp, a
    Float64 at its receive time); align_by_stamp pairs the series at the stamps they all
    have, whatever order and gaps each has: known values in, the same values out."""
    n = 30
    stamps = EPOCH + np.arange(n, dtype=np.int64) * 1_000_000
    pos = np.column_stack([np.arange(n) * 1.0, np.zeros(n), np.zeros(n), np.arange(n) * 2.0])
    err = np.arange(n) * 3.0
    keep = np.arange(n) % 4 != 1                 # the corrections: every 4th stamp missing
    out = write_bag(tmp_path / 'b', stamps, pos, joint_names=JOINTS, positioning_error=err,
                    feedforward=(stamps[keep][::-1], np.arange(n)[keep][::-1] * 5.0))
    got = read_series(out, {'joint_states': JOINTS[3], 'worm_gear_sim/positioning_error': None,
                            '/worm_gear_sim/feedforward': JOINTS[0]})
    js = got['joint_states']
    assert js.stamped and js.topic == '/joint_states' and js.joint == JOINTS[3]
    np.testing.assert_array_equal(js.values, pos[:, 3])
    common, (theta4, pe, ff) = align_by_stamp(
        js, got['worm_gear_sim/positioning_error'], got['/worm_gear_sim/feedforward'])
    np.testing.assert_array_equal(common, stamps[keep])
    k = np.arange(n)[keep]
    np.testing.assert_array_equal(theta4, 2.0 * k)
    np.testing.assert_array_equal(pe, 3.0 * k)
    np.testing.assert_array_equal(ff, 5.0 * k)
    f64 = write_bag(tmp_path / 'f', stamps, pos, joint_names=JOINTS, positioning_error=err,
                    float64_outputs=True)
    s64 = read_series(f64, {'worm_gear_sim/positioning_error': None})
    assert not s64['worm_gear_sim/positioning_error'].stamped   # receive times: no stamp
    with pytest.raises(RecordError, match='no topic /nope in the bag'):
        read_series(out, {'/nope': None})
    none, values = align_by_stamp()
    assert none.size == 0 and values == []
