# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Replay a recorded command stream through the node's real-time pipeline (no rclpy).

:func:`replay` feeds the command samples of a :class:`~worm_gear_sim.records.Record` read
from a bag to the same :class:`~worm_gear_sim.realtime.RealtimePredictor` the node uses,
in the order the recorder received them, and collects its predictions and corrections
stamped on the recording's clock.  Stamped references (``worm_angle_reference``) replay to
what the live node computed: the pipeline's result depends only on the accepted
(stamp, value) pairs.  Float64 commands (``worm_angle_command``) carry no time: the replay
makes them samples at the bag's receive time and runs the pipeline's ticks at
``node.publish_rate_hz`` on that clock, which resembles but cannot equal the live node's
wall-clock ticks.  See docs/data-formats.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..config.usable import Config
from ..records import (
    Record,
    RecordError,
    Series,
    align_by_stamp,
    bag_topics,
    read_bag,
    read_series,
    write_bag,
    write_csv_columns,
)
from ..records.topics import (
    FEEDFORWARD_TOPIC,
    FLOAT64,
    JOINT_STATE,
    POSITIONING_ERROR_TOPIC,
    WORM_ERROR_TOPIC,
    private_topic,
)

__all__ = ['Replay', 'replay', 'compare_with_recorded', 'REPLAY_CSV_COLUMNS']

#: receive time and stamp further apart than this (median): the stamps are on another
#: clock (sim time, a servo's clock), so the pipeline's stamp window is not applied
CLOCK_AGREEMENT_NS = 1_000_000_000
#: the order of a recorded held prediction and a sample where the stamps cannot tell it (a
#: sample after a gap, stamped before the held prediction: a resumed stream whose stamps lag
#: more than before): the hold came first if the node's clock at it was at most this much
#: after the recorder received the sample.  The recorder, a second subscriber, may get a
#: burst several ms before the node; after taking a sample, the node publishes no held
#: prediction for G + its stale margin (0.1 s).
RECEIVE_SKEW_NS = 50_000_000

REPLAY_CSV_COLUMNS = (
    ('t', 's'), ('theta1', 'rad'), ('theta2', 'rad'), ('theta3', 'rad'), ('theta4', 'rad'),
    ('theta1_dot', 'rad/s'), ('omega2', 'rad/s'), ('omega3', 'rad/s'), ('omega4', 'rad/s'),
    ('motor_torque', 'N m'), ('worm_mesh_torque', 'N m'), ('gear_mesh_torque', 'N m'),
    ('gear_shaft_torque', 'N m'), ('positioning_error', 'rad'), ('worm_error', 'rad'),
    ('held', '1'))


@dataclass
class Replay:
    """The pipeline's outputs for a record, stamps absolute [ns] on the recording's
    clock.  Predictions: ``stamps_ns`` (n,), ``position``/``velocity``/``effort`` (n, 4)
    as in ``joint_states``, ``positioning_error``, ``worm_error``, ``held`` (n,).
    Corrections (empty without a compensator): ``correction_stamps_ns``,
    ``theta1_ref``, ``delta`` (~/feedforward), ``compensated`` (~/compensated_command)."""

    record: Record
    t0_ns: int
    stamps_ns: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray
    positioning_error: np.ndarray
    worm_error: np.ndarray
    held: np.ndarray
    correction_stamps_ns: np.ndarray
    theta1_ref: np.ndarray
    delta: np.ndarray
    counters: dict[str, int] = field(default_factory=dict)
    events: list[str] = field(default_factory=list)
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def t(self) -> np.ndarray:
        """Prediction times [s] relative to ``t0_ns``."""
        return (self.stamps_ns - self.t0_ns) * 1e-9

    @property
    def compensated(self) -> np.ndarray:
        return self.theta1_ref + self.delta

    def write_bag(self, path: str | Path, *, joint_names: Sequence[str],
                  storage: str = 'sqlite3', float64_outputs: bool = False,
                  namespace: str = '', overwrite: bool = False) -> Path:
        """The node's output topics (``joint_states``, errors, feed-forward and, for a
        stamped input, ``compensated_command``) as a rosbag2 bag; the errors and the
        feed-forward stamped as the node publishes them (``float64_outputs``: Float64)."""
        corr = self.correction_stamps_ns.size > 0
        return write_bag(
            path, self.stamps_ns, self.position, joint_names=joint_names,
            velocity=self.velocity, effort=self.effort,
            positioning_error=self.positioning_error, worm_error=self.worm_error,
            feedforward=(self.correction_stamps_ns, self.delta) if corr else None,
            compensated_command=(self.correction_stamps_ns, self.compensated)
            if corr and self.info.get('input') == 'stamped' else None,
            float64_outputs=float64_outputs, namespace=namespace, storage=storage,
            overwrite=overwrite)

    def write_csv(self, path: str | Path, header_comment: str = '', digits: int = 12
                  ) -> list[Path]:
        """Predictions as CSV (t [s] relative to t0_ns with 9 decimals, others ``digits``
        significant digits) and, with corrections, ``<stem>_feedforward.csv`` (t,
        theta1_ref, delta, compensated)."""
        p = Path(path)
        comment = (f'worm_gear_sim replay of {self.record.source.get("path", "")}\n'
                   f't0_ns: {self.t0_ns} (t = 0 on the recording\'s clock)\n' + header_comment)
        data = np.column_stack([self.t, self.position, self.velocity, self.effort,
                                self.positioning_error, self.worm_error,
                                self.held.astype(float)])
        write_csv_columns(p, [f'{n} [{u}]' for n, u in REPLAY_CSV_COLUMNS], data,
                          ['%.9f'] + [f'%.{digits}g'] * 14 + ['%d'], comment)
        files = [p]
        if self.correction_stamps_ns.size:
            q = p.with_name(p.stem + '_feedforward' + p.suffix)
            tc = (self.correction_stamps_ns - self.t0_ns) * 1e-9
            write_csv_columns(q, ['t [s]', 'theta1_ref [rad]', 'delta [rad]',
                                  'compensated [rad]'],
                              np.column_stack([tc, self.theta1_ref, self.delta,
                                               self.compensated]),
                              ['%.9f'] + [f'%.{digits}g'] * 3, comment)
            files.append(q)
        return files



def replay(config: Config, record: Record, *, compensate: bool = True,
           end_time: float | None = None, use_receive_clock: bool | None = None,
           tick_stamps_ns: Sequence[int] | np.ndarray | None = None,
           hold_stamps_ns: Sequence[int] | np.ndarray | None = None) -> Replay:
    """Feed ``record``'s command stream to a :class:`RealtimePredictor` as the node would.

    Stamped references: ``push(stamp, value, now_ns=receive time)`` in arrival order (the
    stamp window is skipped when the receive times are on another clock, or with
    ``use_receive_clock=False``), ``hold`` (the node's timer; it acts only when the stream
    pauses) at ``hold_stamps_ns`` (the stamps of the node's recorded held predictions:
    when its timer fired) or else every 1 / ``node.publish_rate_hz`` on the receive clock,
    ``finish`` at the end.  Float64 commands: ``push_command(receive time, value)`` and
    ``tick`` every 1 / ``node.publish_rate_hz`` from the first command, or at
    ``tick_stamps_ns`` (the stamps of the live node's recorded joint_states: its ticks on
    the recording's clock).  ``end_time`` [s
    after the first command]: stop feeding samples stamped later, or keep the held
    prediction going up to it after the last one (the stream paused)."""
    from . import RealtimePredictor
    kind = _command_kind(record)
    stream = _Stream.of(config, record, end_time)
    feed = _Feed(RealtimePredictor(config, compensate=compensate))
    info: dict[str, Any] = {'period_ns': stream.period}
    if kind == JOINT_STATE:
        _feed_stamped(feed, stream, info, use_receive_clock, hold_stamps_ns)
    else:
        _feed_float64(feed, stream, info, tick_stamps_ns)
    if not feed.preds:
        raise RecordError(f'{record.name}: the pipeline accepted no command sample '
                          f'({_rejections(feed.pred.counters)})')
    return _collected(record, feed, info)


def _command_kind(record: Record) -> Any:
    """The record's command type, or a :class:`RecordError` when there is none to replay."""
    if record.command_stamps_ns is None:
        raise RecordError(f'{record.name}: no command stream to replay (a bag is needed)')
    kind = record.source.get('command_type')
    if kind not in (FLOAT64, JOINT_STATE):
        raise RecordError(f'{record.name}: unknown command type {kind!r}')
    return kind


@dataclass
class _Stream:
    """A record's command samples as arrays, the node's timer period and the stop [ns]."""

    stamps: np.ndarray
    values: np.ndarray
    receive: np.ndarray
    period: int
    stop_ns: int | None

    @classmethod
    def of(cls, config: Config, record: Record, end_time: float | None) -> _Stream:
        stamps = np.asarray(record.command_stamps_ns, dtype=np.int64)
        receive = stamps if record.command_receive_ns is None else \
            np.asarray(record.command_receive_ns, dtype=np.int64)
        stop_ns = None if end_time is None else record.t0_ns + int(round(end_time * 1e9))
        return cls(stamps, np.asarray(record.command_values, dtype=float), receive,
                   int(round(1e9 / config.node.publish_rate_hz)), stop_ns)


@dataclass
class _Feed:
    """The pipeline being fed and what it has put out so far."""

    pred: Any
    preds: list[Any] = field(default_factory=list)
    corrs: list[Any] = field(default_factory=list)
    events: list[str] = field(default_factory=list)

    def collect(self, out: Any) -> None:
        self.preds.extend(out.predictions)
        self.corrs.extend(out.corrections)
        self.events.extend(f'{e.kind}: {e.message}' for e in out.events
                           if e.level != 'info')


def _feed_stamped(feed: _Feed, stream: _Stream, info: dict[str, Any],
                  use_receive_clock: bool | None,
                  hold_stamps_ns: Sequence[int] | np.ndarray | None) -> None:
    """Stamped references: push in arrival order, the node's holds between, finish."""
    pred, collect = feed.pred, feed.collect
    stamps, values, receive = stream.stamps, stream.values, stream.receive
    period, stop_ns = stream.period, stream.stop_ns
    info['input'] = 'stamped'
    ok = np.isfinite(values)
    same = bool(np.median(np.abs(receive[ok] - stamps[ok])) < CLOCK_AGREEMENT_NS) \
        if ok.any() else False
    use_now = same if use_receive_clock is None else bool(use_receive_clock)
    info['stamp_window'] = use_now
    given = hold_stamps_ns is not None
    holds = _hold_instants(stream, info, hold_stamps_ns, use_now)

    def fire_at(h: int) -> int:
        # a given hold is a held prediction's stamp, the stream's time: the node's
        # clock then was later by the stream's lag (the stamps lagged their arrival)
        return h + pred.stream_lag_ns if given else h

    def hold_first(h: int, s: int, rx: int) -> bool:
        """Did the node fire the hold at ``h`` before it took the sample stamped ``s``,
        received at ``rx``?  A recorded held prediction proves the stream was stale in
        the node; the recorder (a second subscriber) may have received ``s`` earlier."""
        if not given:
            return h <= rx
        if s > h:       # taken first, it would have left no stream stale at h
            return True
        if s < pred.last_stamp_ns + pred.stale_after_ns:
            return False    # no gap: after the hold it would have been a late sample
        # a resumed stream whose stamps lag more than before: the receive clock decides
        return not use_now or fire_at(h) <= rx + RECEIVE_SKEW_NS

    k = 0
    last_rx = int(receive[0])
    fired = None
    for s, x, rx in zip(stamps.tolist(), values.tolist(), receive.tolist()):
        if stop_ns is not None and s > stop_ns:
            continue
        while k < len(holds) and hold_first(holds[k], s, rx):
            fired = fire_at(holds[k])
            collect(pred.hold(fired))
            k += 1
        # (the node took the sample after the held prediction it published before it)
        now = rx if fired is None else max(rx, fired)
        collect(pred.push(s, x, now_ns=now if use_now else None))
        last_rx = max(last_rx, rx)
    # after the last sample: the node's timer keeps publishing the held prediction,
    # stamped with its clock (the receive clock when it agrees with the stamps)
    offset = last_rx - pred.last_stamp_ns if use_now else 0
    until = None if stop_ns is None else stop_ns + offset
    for h in holds[k:]:
        if until is None or h <= until:
            collect(pred.hold(fire_at(h)))
    if until is not None and pred.started:
        h = max(pred.last_stamp_ns + offset, holds[-1] if holds else 0) + period
        while h <= until:
            collect(pred.hold(h))
            h += period
    collect(pred.finish())


def _hold_instants(stream: _Stream, info: dict[str, Any],
                   hold_stamps_ns: Sequence[int] | np.ndarray | None,
                   use_now: bool) -> list[int]:
    """When the node's timer holds: the given instants, or every period on the receive
    clock when it agrees with the stamps, or never."""
    period, receive = stream.period, stream.receive
    holds: list[int] = []
    if hold_stamps_ns is not None:
        holds = np.unique(np.asarray(hold_stamps_ns, dtype=np.int64)).tolist()
        info['holds'] = f'{len(holds)} given instants'
    elif use_now:
        holds = list(range(int(receive[0]) + period, int(receive.max()) + 1, period))
        info['holds'] = f'every {period} ns on the receive clock'
    else:
        info['holds'] = 'none (stamps and receive times on different clocks)'
    return holds


def _feed_float64(feed: _Feed, stream: _Stream, info: dict[str, Any],
                  tick_stamps_ns: Sequence[int] | np.ndarray | None) -> None:
    """Float64 commands: push each at its receive time, the node's ticks between."""
    pred, collect = feed.pred, feed.collect
    values, receive = stream.values, stream.receive
    period, stop_ns = stream.period, stream.stop_ns
    info['input'] = 'float64'
    end = int(receive.max()) + period if stop_ns is None else stop_ns
    if tick_stamps_ns is not None and len(tick_stamps_ns):
        ticks = np.unique(np.asarray(tick_stamps_ns, dtype=np.int64)).tolist()
        info['ticks'] = 'recorded joint_states stamps'
        end = max(end, ticks[-1]) if stop_ns is None else end
    else:
        ticks = []
        info['ticks'] = f'every {period} ns from the first command'
    k = 0

    def next_tick(after: int) -> int:
        return ticks[k] if k < len(ticks) else (
            max(after, ticks[-1] if ticks else int(receive[0])) + period)

    tick = next_tick(int(receive[0]))
    for x, rx in zip(values.tolist(), receive.tolist()):
        if stop_ns is not None and rx > stop_ns:
            break
        while tick <= rx:
            collect(pred.tick(tick))
            k += 1
            tick = next_tick(tick)
        collect(pred.push_command(rx, x))
    while tick <= end:
        collect(pred.tick(tick))
        k += 1
        tick = next_tick(tick)


def _collected(record: Record, feed: _Feed, info: dict[str, Any]) -> Replay:
    """The pipeline's outputs gathered into a :class:`Replay`."""
    preds, corrs, pred = feed.preds, feed.corrs, feed.pred
    pos = np.array([p.position for p in preds], dtype=float)
    return Replay(
        record=record, t0_ns=record.t0_ns,
        stamps_ns=np.array([p.stamp_ns for p in preds], dtype=np.int64),
        position=pos, velocity=np.array([p.velocity for p in preds], dtype=float),
        effort=np.array([p.effort for p in preds], dtype=float),
        positioning_error=np.array([p.positioning_error for p in preds], dtype=float),
        worm_error=np.array([p.worm_error for p in preds], dtype=float),
        held=np.array([p.held for p in preds], dtype=bool),
        correction_stamps_ns=np.array([c.stamp_ns for c in corrs], dtype=np.int64),
        theta1_ref=np.array([c.theta1_ref for c in corrs], dtype=float),
        delta=np.array([c.delta for c in corrs], dtype=float),
        counters=dict(pred.counters), events=feed.events,
        info=info | {'compensation_error': pred.compensation_error})


def _rejections(counters: dict[str, int]) -> str:
    rej = {k[9:]: v for k, v in counters.items() if k.startswith('rejected_') and v
           and k != 'rejected_samples'}
    return 'rejected: ' + ', '.join(f'{k} {v}' for k, v in rej.items()) if rej else \
        'nothing rejected'


def compare_with_recorded(rep: Replay, bag: str | Path, topic: str = 'joint_states',
                          joint_names: Sequence[str] | None = None) -> dict[str, Any] | None:
    """If ``bag`` holds the live node's predicted ``joint_states``, the largest difference
    [rad] between them and the replay at equal stamps, per theta2..theta4 and overall,
    with the number of stamps compared, of replayed stamps inside the recorded span that
    were not recorded (``replay_only``: samples the node did not take, or recorder losses)
    and of recorded stamps the replay did not produce (``recorded_only``); ``answers``: the
    recorded stamped answers against the replay's, stamp by stamp
    (:func:`_compare_answers`).  None if the bag has no such topic."""
    try:
        live = read_bag(bag, command_topic=rep.record.source.get('command_topic'),
                        joint_states_topic=topic, joint_names=joint_names,
                        require_measured=True, min_samples=1)
    except RecordError:
        return None
    ns = live.t0_ns + np.round(live.t * 1e9).astype(np.int64)
    common, i_live, i_rep = np.intersect1d(ns, rep.stamps_ns, return_indices=True)
    out: dict[str, Any] = {'topic': live.source['joint_states_topic'],
                           'stamps_compared': int(common.size),
                           'live_stamps': int(ns.size), 'replay_stamps': int(rep.stamps_ns.size)}
    inside = rep.stamps_ns[(rep.stamps_ns >= ns.min()) & (rep.stamps_ns <= ns.max())]
    out['replay_only'] = int(np.setdiff1d(inside, ns).size)
    out['recorded_only'] = int(np.setdiff1d(ns, rep.stamps_ns).size)
    if not common.size:
        return out
    worst = 0.0
    for k, name in enumerate(('theta2', 'theta3', 'theta4'), start=1):
        if name in live.measured:
            d = float(np.max(np.abs(live.measured[name][i_live] - rep.position[i_rep, k])))
            out[name] = d
            worst = max(worst, d)
    out['max_abs_diff'] = worst
    out['answers'] = _compare_answers(rep, bag)
    return out


def _compare_answers(rep: Replay, bag: str | Path) -> dict[str, dict[str, Any]]:
    """The node's stamped answers the bag recorded (``~/positioning_error``,
    ``~/worm_error`` at the predictions' stamps, ``~/feedforward`` at the corrections'),
    each against the replay's value of the same stamp: {name: {'stamps_compared',
    'max_abs_diff'}}.  Float64 answers (no stamp) cannot be aligned: left out."""
    mine = {POSITIONING_ERROR_TOPIC: (rep.stamps_ns, rep.positioning_error),
            WORM_ERROR_TOPIC: (rep.stamps_ns, rep.worm_error),
            FEEDFORWARD_TOPIC: (rep.correction_stamps_ns, rep.delta)}
    have = bag_topics(bag)
    names = {private_topic(t): t for t in mine
             if have.get('/' + private_topic(t)) == JOINT_STATE}
    out: dict[str, dict[str, Any]] = {}
    if not names:
        return out
    for name, series in read_series(bag, dict.fromkeys(names)).items():
        stamps, values = mine[names[name]]
        common, (live, again) = align_by_stamp(series, Series('', stamps, values, True))
        out[names[name].removeprefix('~/')] = {
            'stamps_compared': int(common.size),
            'max_abs_diff': float(np.max(np.abs(live - again))) if common.size else 0.0}
    return out
