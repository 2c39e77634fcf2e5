# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""rosbag2 bags in and out with the ``rosbags`` library (no ROS installation, never rclpy):
a record read from the node's command and JointState topics, a prediction written with
the node's output topics and message types, and one-value topics (references, the node's
stamped answers) read as series that align sample by sample by their stamps
(:func:`read_series`, :func:`align_by_stamp`).

Topics and types: docs/data-formats.md.
"""

from __future__ import annotations

import shutil
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from .._support.guarded_io import (
    MAX_CONFIG_BYTES,
    GuardedFileError,
    guarded_yaml_load,
    read_text_file,
)
from .record import MEASURED_NAMES, Record, RecordError, valid_sorted
from .topics import (
    ANSWER_TOPICS,
    COMMAND_TOPIC,
    COMPENSATED_COMMAND_TOPIC,
    FEEDFORWARD_TOPIC,
    FLOAT64,
    JOINT_STATE,
    JOINT_STATES_TOPIC,
    MEASURED_TOPIC,
    POSITIONING_ERROR_TOPIC,
    REFERENCE_TOPIC,
    WORM_ERROR_TOPIC,
    private_topic,
)

__all__ = ['read_bag', 'bag_topics', 'BagStream', 'write_streams', 'prediction_streams',
           'write_bag', 'Series', 'read_series', 'align_by_stamp', 'DEFAULT_COMMAND_TOPICS',
           'DEFAULT_MEASURED_TOPICS', 'BAG_VERSION']

DEFAULT_COMMAND_TOPICS = (REFERENCE_TOPIC, COMMAND_TOPIC)
DEFAULT_MEASURED_TOPICS = (MEASURED_TOPIC, JOINT_STATES_TOPIC)
BAG_VERSION: Literal[8, 9] = 8          # rosbag2 metadata version (rosbags writes 8 or 9)


def _typestore() -> Any:
    from rosbags.typesys import Stores, get_typestore
    return get_typestore(Stores.ROS2_JAZZY)   # Float64/JointState are the same in Kilted


def _open_reader(path: Path) -> Any:
    from rosbags.rosbag2 import Reader, ReaderError
    if not path.exists():
        raise RecordError(f'{path}: bag not found')
    meta = path / 'metadata.yaml'
    if path.is_dir() and meta.is_file():
        # rosbags' own parser has no limits and fails on an empty file with a TypeError:
        # read it with the package's guarded loader first
        try:
            doc = guarded_yaml_load(read_text_file(meta, MAX_CONFIG_BYTES, 'a metadata.yaml'),
                                    str(meta))
        except GuardedFileError as exc:
            raise RecordError(f'{path}: not a readable rosbag2 bag: {exc}') from None
        if not isinstance(doc, dict) or not isinstance(
                doc.get('rosbag2_bagfile_information'), dict):
            raise RecordError(f'{path}: not a readable rosbag2 bag: {meta} is empty or has '
                              'no rosbag2_bagfile_information')
    try:
        reader = Reader(path)
        reader.open()
    except (ReaderError, OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        raise RecordError(f'{path}: not a readable rosbag2 bag (sqlite3 or mcap): '
                          f'{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}'
                          ) from None
    return reader


def bag_topics(path: str | Path) -> dict[str, str]:
    """{topic: message type} of a bag."""
    reader = _open_reader(Path(path))
    try:
        return {c.topic: c.msgtype for c in reader.connections}
    finally:
        reader.close()


def _topic_list(topics: Mapping[str, str]) -> str:
    return ', '.join(f'{k} ({v})' for k, v in sorted(topics.items())) or 'no topics'


def _find_topic(topics: Mapping[str, str], wanted: str) -> str | None:
    """The bag topic named ``wanted`` (relative names match absolute ones and, if unique,
    a namespaced one: 'joint_states' finds '/arm1/joint_states')."""
    w = '/' + wanted.strip().lstrip('/')
    if w in topics:
        return w
    if wanted.strip().startswith('/'):
        return None
    hits = [t for t in topics if t.endswith(w)]
    return hits[0] if len(hits) == 1 else None


def _resolve_topic(topics: Mapping[str, str], given: str | None, defaults: Sequence[str],
                   what: str, option: str, where: str, required: bool) -> str | None:
    names = [given] if given else list(defaults)
    for n in names:
        hit = _find_topic(topics, n)
        if hit:
            return hit
    if given or required:
        said = given or ' or '.join(defaults)
        raise RecordError(f'{where}: no {what} topic {said} in the bag; it has: '
                          f'{_topic_list(topics)} (choose one with {option})')
    return None


def _stamp_ns(header: Any) -> int:
    return int(header.stamp.sec) * 10 ** 9 + int(header.stamp.nanosec)


def read_bag(path: str | Path, *, command_topic: str | None = None,
             joint_states_topic: str | None = None,
             joint_names: Sequence[str] | None = None, name: str | None = None,
             require_measured: bool = False, interpolation: str = 'linear',
             min_samples: int = 2) -> Record:
    """Read a rosbag2 bag (a directory with metadata.yaml, or a single .db3/.mcap file).

    Command: ``command_topic`` (default: ``worm_angle_reference``, else
    ``worm_angle_command``), of type std_msgs/Float64 (stamp = the bag's receive time) or
    sensor_msgs/JointState (the stamped reference: stamp = header.stamp, theta1 =
    position[0]; ``name[0]``, when given, must be ``joint_names[0]``, else the message is
    rejected and counted, as the node does).  Measured:
    ``joint_states_topic`` (default: ``measured_joint_states``, else ``joint_states``; ''
    reads none),
    sensor_msgs/JointState; theta2..theta4 by ``joint_names[1:4]`` (default
    ``node.joint_names``), stamps from header.stamp (the receive time if every stamp is 0).
    With measurements, ``t`` is their stamps and ``theta1`` the command interpolated there
    (``interpolation`` linear or hold); measurements before the first command are dropped
    (counted in ``source``).  Without, ``t``/``theta1`` are the valid command samples.
    ``t0_ns`` is the first command stamp.
    """
    p = Path(path)
    where = str(p)
    joint_names = _checked_joint_names(joint_names, interpolation)
    reader = _open_reader(p)
    try:
        topics, cmd_topic, meas_topic = _chosen_topics(
            reader, where, command_topic, joint_states_topic, require_measured)
        cmd = _read_commands(reader, cmd_topic, topics[cmd_topic], joint_names[0], where)
        meas = (_read_joint_states(reader, meas_topic, joint_names[1:], where)
                if meas_topic else None)
    finally:
        reader.close()
    stamps, vals, n_rejected, received = cmd
    src: dict[str, Any] = {'kind': 'bag', 'path': str(p), 'command_topic': cmd_topic,
                           'command_type': topics[cmd_topic],
                           'command_stamp': 'header.stamp' if topics[cmd_topic] == JOINT_STATE
                           else 'bag receive time', 'rejected_commands': n_rejected,
                           'topics': topics}
    t0_ns, tc, yc = _valid_commands(stamps, vals, where, cmd_topic, src)
    rec_name = name or p.stem
    if meas is None:
        if tc.size < min_samples:
            raise RecordError(f'{where}: {tc.size} valid command sample(s) on {cmd_topic}; '
                              f'a record needs at least {min_samples}')
        return Record(rec_name, tc, yc, {}, t0_ns, stamps, vals, src, received)
    m_stamps, m_vals, m_info = meas
    src.update({'joint_states_topic': meas_topic, **m_info})
    keep = m_stamps >= t0_ns
    src['measurements_before_first_command'] = int((~keep).sum())
    t = (m_stamps[keep] - t0_ns) * 1e-9
    if t.size < min_samples:
        raise RecordError(f'{where}: {t.size} measurement(s) on {meas_topic} at or after the '
                          f'first command; a record needs at least {min_samples}')
    if interpolation == 'linear':
        th1 = np.interp(t, tc, yc)
    else:
        th1 = yc[np.clip(np.searchsorted(tc, t, side='right') - 1, 0, None)]
    measured = {k: v[keep] for k, v in m_vals.items()}
    return Record(rec_name, t, th1, measured, t0_ns, stamps, vals, src, received)


def _checked_joint_names(joint_names: Sequence[str] | None, interpolation: str
                         ) -> tuple[str, ...]:
    """The four joint names (default ``node.joint_names``), the interpolation checked."""
    if joint_names is None:
        from ..schema.parameters import Parameters
        joint_names = tuple(Parameters().node.joint_names)
    joint_names = tuple(joint_names)
    if len(joint_names) != 4:
        raise RecordError(f'joint names: need 4 (theta1..theta4), got {list(joint_names)}')
    if interpolation not in ('linear', 'hold'):
        raise RecordError(f'interpolation must be linear or hold, got {interpolation!r}')
    return joint_names


def _chosen_topics(reader: Any, where: str, command_topic: str | None,
                   joint_states_topic: str | None, require_measured: bool
                   ) -> tuple[dict[str, str], str, str | None]:
    """The bag's topics (name -> type), the command topic and the measured one (or None),
    each checked for its type."""
    topics = {c.topic: c.msgtype for c in reader.connections}
    cmd_topic = _resolve_topic(topics, command_topic, DEFAULT_COMMAND_TOPICS, 'command',
                               '--command-topic', where, True)
    assert cmd_topic is not None
    if topics[cmd_topic] not in (FLOAT64, JOINT_STATE):
        raise RecordError(f'{where}: command topic {cmd_topic} is {topics[cmd_topic]}; '
                          f'expected {FLOAT64} or {JOINT_STATE} (the stamped reference)')
    meas_topic = None if joint_states_topic == '' and not require_measured else \
        _resolve_topic(topics, joint_states_topic, DEFAULT_MEASURED_TOPICS,
                       'measured JointState', '--joint-states-topic', where,
                       require_measured)
    if meas_topic is not None and topics[meas_topic] != JOINT_STATE:
        raise RecordError(f'{where}: measured topic {meas_topic} is {topics[meas_topic]}; '
                          f'expected {JOINT_STATE}')
    return topics, cmd_topic, meas_topic


def _valid_commands(stamps: np.ndarray, vals: np.ndarray, where: str, cmd_topic: str,
                    src: dict[str, Any]) -> tuple[int, np.ndarray, np.ndarray]:
    """(t0_ns, t, theta1): the first finite command's stamp and the valid samples sorted;
    the non-finite and duplicated ones counted in ``src``."""
    if stamps.size == 0:
        raise RecordError(f'{where}: no command samples on {cmd_topic}')
    ok = np.isfinite(vals)
    if not ok.any():
        raise RecordError(f'{where}: no finite command sample on {cmd_topic}')
    t0_ns = int(stamps[ok].min())
    tc, yc, n_dup = valid_sorted(stamps, vals, t0_ns)
    src['non_finite_commands'] = int((~ok).sum())
    src['duplicate_command_stamps'] = n_dup
    return t0_ns, tc, yc


def _read_commands(reader: Any, topic: str, msgtype: str, worm_joint: str, where: str
                   ) -> tuple[np.ndarray, np.ndarray, int, np.ndarray]:
    """Raw command samples in bag order: (stamps [ns], values, messages without a value,
    receive times [ns])."""
    ts = _typestore()
    conns = [c for c in reader.connections if c.topic == topic]
    stamps: list[int] = []
    vals: list[float] = []
    received: list[int] = []
    rejected = 0
    for conn, log_ns, raw in reader.messages(connections=conns):
        msg = ts.deserialize_cdr(raw, conn.msgtype)
        if msgtype == FLOAT64:
            stamps.append(int(log_ns))
            vals.append(float(msg.data))
            received.append(int(log_ns))
            continue
        names = list(msg.name)
        if len(msg.position) == 0 or (names and names[0] != worm_joint):
            rejected += 1           # empty position or another joint: the node rejects it
            continue
        stamps.append(_stamp_ns(msg.header))
        vals.append(float(msg.position[0]))
        received.append(int(log_ns))
    return (np.array(stamps, dtype=np.int64), np.array(vals, dtype=float), rejected,
            np.array(received, dtype=np.int64))


def _read_joint_states(reader: Any, topic: str, joints: Sequence[str], where: str
                       ) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, Any]]:
    """Measured theta2..theta4 from a JointState topic, sorted by stamp."""
    ts = _typestore()
    conns = [c for c in reader.connections if c.topic == topic]
    per: dict[str, tuple[list[int], list[float]]] = {j: ([], []) for j in joints}
    header_ns: list[int] = []
    log: list[int] = []
    seen: set[str] = set()
    malformed = 0
    for conn, log_ns, raw in reader.messages(connections=conns):
        msg = ts.deserialize_cdr(raw, conn.msgtype)
        names = list(msg.name)
        seen.update(names)
        if len(msg.position) != len(names):
            malformed += 1
            continue
        stamp = _stamp_ns(msg.header)
        for j in joints:
            if j in names:
                v = float(msg.position[names.index(j)])
                per[j][0].append(len(header_ns))
                per[j][1].append(v)
        header_ns.append(stamp)
        log.append(int(log_ns))
    found = [j for j in joints if per[j][0]]
    if not found:
        raise RecordError(f'{where}: {topic} has joints {sorted(seen) or "none"}; none of '
                          f'{", ".join(joints)} (node.joint_names for theta2..theta4; choose '
                          'them with --joint-names)')
    h = np.array(header_ns, dtype=np.int64)
    stamp_kind = 'header.stamp'
    if np.all(h == 0):
        h, stamp_kind = np.array(log, dtype=np.int64), 'bag receive time (header stamps 0)'
    elif np.any(h == 0):
        raise RecordError(f'{where}: {topic}: {int((h == 0).sum())} of {h.size} messages have '
                          'a zero header.stamp; cannot place them in time')
    roles = dict(zip(joints, MEASURED_NAMES))
    series: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for j in found:
        idx = np.array(per[j][0])
        pos = np.array(per[j][1])
        bad = ~np.isfinite(pos)
        if bad.any():
            raise RecordError(f'{where}: {topic}: joint {j} has {int(bad.sum())} non-finite '
                              'position(s)')
        series[j] = (h[idx], pos)
    # one grid: the stamps carrying every found joint in the common span (exact in the usual
    # case of one message per stamp with all joints), sorted; duplicates: first kept
    grid = np.unique(np.concatenate([s for s, _ in series.values()]))
    lo = max(s.min() for s, _ in series.values())
    hi = min(s.max() for s, _ in series.values())
    grid = grid[(grid >= lo) & (grid <= hi)]
    out: dict[str, np.ndarray] = {}
    n_dup = 0
    for j, (sj, pj) in series.items():
        order = np.argsort(sj, kind='stable')
        sj, pj = sj[order], pj[order]
        first = np.concatenate(([True], np.diff(sj) > 0))
        n_dup = max(n_dup, int((~first).sum()))
        sj, pj = sj[first], pj[first]
        out[roles[j]] = np.interp(grid.astype(float), sj.astype(float), pj) \
            if sj.size != grid.size or np.any(sj != grid) else pj
    info = {'measured_stamp': stamp_kind, 'measured_joints': {roles[j]: j for j in found},
            'malformed_joint_states': malformed, 'duplicate_measurement_stamps': n_dup}
    return grid, out, info


# ---- one-value series, aligned by stamp -------------------------------------------------------
@dataclass
class Series:
    """One value per message of a bag topic: ``stamps_ns`` the ``header.stamp`` of a
    JointState (``stamped``), else the bag's receive time (a Float64 has no stamp: it can
    be aligned with nothing but its arrival); ``values`` the position of ``joint`` (the
    first entry when no joint is asked for) or the Float64's data."""

    topic: str
    stamps_ns: np.ndarray
    values: np.ndarray
    stamped: bool
    joint: str = ''


def read_series(path: str | Path, topics: Mapping[str, str | None]) -> dict[str, Series]:
    """The series of ``topics`` ({topic: joint or None}, names as :func:`read_bag` finds
    them: '/ns/joint_states' for 'joint_states' when unique), keyed by the names given, in
    bag order.  A JointState without the joint (or without a position) is skipped; a topic
    the bag lacks, or of another type, is an error listing what the bag has."""
    p = Path(path)
    where = str(p)
    reader = _open_reader(p)
    try:
        have = {c.topic: c.msgtype for c in reader.connections}
        found: dict[str, str] = {}
        for name in topics:
            hit = _find_topic(have, name)
            if hit is None:
                raise RecordError(f'{where}: no topic {name} in the bag; it has: '
                                  f'{_topic_list(have)}')
            if have[hit] not in (FLOAT64, JOINT_STATE):
                raise RecordError(f'{where}: {hit} is {have[hit]}; expected {FLOAT64} or '
                                  f'{JOINT_STATE}')
            found[hit] = name
        ts = _typestore()
        rows: dict[str, tuple[list[int], list[float]]] = {n: ([], []) for n in topics}
        conns = [c for c in reader.connections if c.topic in found]
        for conn, log_ns, raw in reader.messages(connections=conns):
            name = found[conn.topic]
            msg = ts.deserialize_cdr(raw, conn.msgtype)
            if conn.msgtype == FLOAT64:
                rows[name][0].append(int(log_ns))
                rows[name][1].append(float(msg.data))
                continue
            names = list(msg.name)
            joint = topics[name]
            i = names.index(joint) if joint and joint in names else (0 if not joint else -1)
            if i < 0 or i >= len(msg.position):
                continue
            rows[name][0].append(_stamp_ns(msg.header))
            rows[name][1].append(float(msg.position[i]))
    finally:
        reader.close()
    return {name: Series(hit, np.array(rows[name][0], dtype=np.int64),
                         np.array(rows[name][1], dtype=float), have[hit] == JOINT_STATE,
                         topics[name] or '')
            for hit, name in found.items()}


def align_by_stamp(*series: Series) -> tuple[np.ndarray, list[np.ndarray]]:
    """The stamps every series has (sorted) and each series' values at them: the outputs
    that answer a sample side by side with that sample.  A stamp repeated within a series
    (a resynchronised stream) keeps its last value."""
    if not series:
        return np.empty(0, dtype=np.int64), []
    common = np.unique(series[0].stamps_ns)
    for s in series[1:]:
        common = np.intersect1d(common, s.stamps_ns)
    out = []
    for s in series:
        last = {int(k): v for k, v in zip(s.stamps_ns.tolist(), s.values.tolist())}
        out.append(np.array([last[int(k)] for k in common.tolist()], dtype=float))
    return common, out


# ---- writing -----------------------------------------------------------------------------
@dataclass
class BagStream:
    """One output topic: ``kind`` 'float64' (std_msgs/Float64, the bag time = the stamp) or
    'joint_state' (sensor_msgs/JointState with header.stamp; ``position`` (n, k) for the
    ``names``, optional ``velocity``/``effort`` of the same shape)."""

    topic: str
    stamps_ns: np.ndarray
    position: np.ndarray
    kind: str = 'float64'
    names: tuple[str, ...] = ()
    velocity: np.ndarray | None = None
    effort: np.ndarray | None = None


def write_streams(path: str | Path, streams: Sequence[BagStream], *,
                  storage: str = 'sqlite3', overwrite: bool = False) -> Path:
    """Write the streams as a rosbag2 bag (directory ``path``), messages in time order."""
    from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
    p = Path(path)
    plugins = {'sqlite3': StoragePlugin.SQLITE3, 'mcap': StoragePlugin.MCAP}
    if storage not in plugins:
        raise RecordError(f'bag storage must be sqlite3 or mcap, got {storage!r}')
    if p.exists():
        if not overwrite:
            raise RecordError(f'{p}: exists already; choose another output bag or remove it')
        if not (p / 'metadata.yaml').is_file():
            raise RecordError(f'{p}: exists and is not a bag; not overwriting it')
        shutil.rmtree(p)
    p.parent.mkdir(parents=True, exist_ok=True)
    ts = _typestore()
    Float64 = ts.types[FLOAT64]
    JointState = ts.types[JOINT_STATE]
    Header = ts.types['std_msgs/msg/Header']
    Time = ts.types['builtin_interfaces/msg/Time']
    empty = np.empty(0)
    events: list[tuple[int, int, int]] = []         # (stamp, stream, row)
    for k, s in enumerate(streams):
        st = np.asarray(s.stamps_ns, dtype=np.int64)
        if st.size and np.any(st < 0):
            raise RecordError(f'{s.topic}: negative stamps cannot be written to a bag')
        events.extend((int(x), k, i) for i, x in enumerate(st))
    events.sort()
    try:
        with Writer(p, version=BAG_VERSION, storage_plugin=plugins[storage]) as writer:
            conns = [writer.add_connection('/' + s.topic.lstrip('/'),
                                           FLOAT64 if s.kind == 'float64' else JOINT_STATE,
                                           typestore=ts) for s in streams]
            for stamp, k, i in events:
                s = streams[k]
                if s.kind == 'float64':
                    msg = Float64(data=float(np.ravel(s.position)[i]))
                    writer.write(conns[k], stamp, ts.serialize_cdr(msg, FLOAT64))
                    continue
                pos = np.atleast_2d(s.position)
                if pos.shape[0] == 1 and len(s.stamps_ns) != 1:
                    pos = pos.T
                sec, nsec = divmod(stamp, 10 ** 9)
                msg = JointState(
                    header=Header(stamp=Time(sec=sec, nanosec=nsec), frame_id=''),
                    name=list(s.names), position=np.ascontiguousarray(pos[i], dtype=float),
                    velocity=empty if s.velocity is None else
                    np.ascontiguousarray(np.atleast_2d(s.velocity)[i], dtype=float),
                    effort=empty if s.effort is None else
                    np.ascontiguousarray(np.atleast_2d(s.effort)[i], dtype=float))
                writer.write(conns[k], stamp, ts.serialize_cdr(msg, JOINT_STATE))
    except WriterError as exc:
        raise RecordError(f'{p}: cannot write the bag: {exc}') from None
    return p


def prediction_streams(stamps_ns: np.ndarray, position: np.ndarray, *,
                       joint_names: Sequence[str], velocity: np.ndarray | None = None,
                       effort: np.ndarray | None = None,
                       positioning_error: np.ndarray | None = None,
                       worm_error: np.ndarray | None = None,
                       feedforward: tuple[np.ndarray, np.ndarray] | None = None,
                       compensated_command: tuple[np.ndarray, np.ndarray] | None = None,
                       float64_outputs: bool = False, namespace: str = '') -> list[BagStream]:
    """The node's output topics for a prediction: ``joint_states`` (theta1..theta4, rates,
    torques), ``worm_gear_sim/positioning_error``, ``worm_gear_sim/worm_error`` and, when
    given as (stamps_ns, values), ``worm_gear_sim/feedforward`` and
    ``worm_gear_sim/compensated_command`` (JointState of the worm input joint).  The errors
    and the feed-forward are, as the node publishes them, JointStates of one joint (antenna,
    worm, worm input: ``topics.ANSWER_TOPICS``) with the stamp of the sample they answer;
    ``float64_outputs`` writes them as std_msgs/Float64 (``node.float64_outputs``).
    ``namespace`` prefixes every topic (e.g. 'replay' -> /replay/joint_states)."""
    names = tuple(joint_names)
    ns = '/' + namespace.strip('/') if namespace.strip('/') else ''
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    out = [BagStream(f'{ns}/{JOINT_STATES_TOPIC}', stamps, np.asarray(position), 'joint_state',
                     names, velocity, effort)]

    def scalar(topic: str, st: np.ndarray, v: np.ndarray) -> BagStream:
        name = f'{ns}/{private_topic(topic)}'
        if float64_outputs:
            return BagStream(name, st, np.asarray(v), 'float64')
        return BagStream(name, st, np.asarray(v).reshape(-1, 1), 'joint_state',
                         (names[ANSWER_TOPICS[topic]],))

    if positioning_error is not None:
        out.append(scalar(POSITIONING_ERROR_TOPIC, stamps, positioning_error))
    if worm_error is not None:
        out.append(scalar(WORM_ERROR_TOPIC, stamps, worm_error))
    if feedforward is not None:
        out.append(scalar(FEEDFORWARD_TOPIC, feedforward[0], feedforward[1]))
    if compensated_command is not None:
        out.append(BagStream(f'{ns}/{private_topic(COMPENSATED_COMMAND_TOPIC)}',
                             compensated_command[0],
                             np.asarray(compensated_command[1]).reshape(-1, 1), 'joint_state',
                             (names[0],)))
    return out


def write_bag(path: str | Path, stamps_ns: np.ndarray, position: np.ndarray, *,
              joint_names: Sequence[str], storage: str = 'sqlite3', overwrite: bool = False,
              **topics: Any) -> Path:
    """Write a prediction (``position`` (n, 4) theta1..theta4 at ``stamps_ns``, absolute on
    the recording's clock) with the node's topics as a rosbag2 bag: see
    :func:`prediction_streams` for the optional topics (velocity, effort, errors,
    feed-forward, float64_outputs, namespace).  Storage sqlite3 (default) or mcap."""
    streams = prediction_streams(stamps_ns, position, joint_names=joint_names, **topics)
    return write_streams(path, streams, storage=storage, overwrite=overwrite)
