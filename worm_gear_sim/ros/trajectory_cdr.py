# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A dense ``trajectory_msgs/JointTrajectory`` serialized with numpy, ready for
``Publisher.publish(bytes)``: the CDR (little-endian, XCDR1) bytes the middleware would
write for the message object, built column by column in a few milliseconds for 100 000
points, where building the message object point by point and converting it held the
interpreter lock for 120-680 ms.  Every point has the same fields, so
a point's layout depends only on its start modulo 8 (a cycle of one or two points);
deserialized, :func:`serialize_trajectory`'s bytes are the message object
(test/ros/test_hostile_node.py).
"""

from __future__ import annotations

import struct
from typing import Any

import numpy as np

from ..joint_trajectory.compensate import JointTrajectoryData

__all__ = ['serialize_trajectory', 'parse_trajectory']

_ENCAPSULATION = b'\x00\x01\x00\x00'          # CDR, little endian
_NS = 1_000_000_000


def _align(offset: int, n: int) -> int:
    return (offset + n - 1) // n * n


class _Writer:
    def __init__(self) -> None:
        self.buf = bytearray()

    def pad(self, n: int) -> None:
        self.buf.extend(b'\x00' * (_align(len(self.buf), n) - len(self.buf)))

    def u32(self, fmt: str, value: int) -> None:
        self.pad(4)
        self.buf.extend(struct.pack('<' + fmt, value))

    def string(self, text: str) -> None:
        data = text.encode() + b'\x00'
        self.u32('I', len(data))
        self.buf.extend(data)


def _point_layout(start: int, counts: tuple[int, ...]) -> tuple[list[tuple[int, int]], int]:
    """Per sequence field of a point (positions, velocities, accelerations, effort):
    (offset of its length, offset of its data) from the point's start, then the offset of
    time_from_start and the point's size, for a point at body offset ``start``."""
    o = start
    fields = []
    for c in counts:
        o = _align(o, 4)
        length = o
        o += 4
        if c:
            o = _align(o, 8)
        fields.append((length - start, o - start))
        o += 8 * c
    o = _align(o, 4)
    fields.append((o - start, o - start))
    o += 8
    return fields, o - start


def _rows(layouts: list, cols: list, counts: tuple[int, ...], dur: np.ndarray, a: int,
          b: int) -> bytes:
    """Points a..b-1 laid out by the cycle ``layouts`` (point a takes the first)."""
    n, period = b - a, len(layouts)
    groups = -(-n // period)
    width = sum(size for _, size in layouts)
    rows = np.zeros((groups, width), np.uint8)
    base = 0
    for k, (fields, size) in enumerate(layouts):
        sel = slice(a + k, b, period)
        m = len(range(a + k, b, period))
        for (length, data), c, arr in zip(fields[:4], counts, cols + [None]):
            rows[:m, base + length:base + length + 4] = np.frombuffer(
                struct.pack('<I', c), np.uint8)
            if c:
                rows[:m, base + data:base + data + 8 * c] = np.ascontiguousarray(
                    arr[sel], '<f8').view(np.uint8).reshape(m, 8 * c)
        off = base + fields[4][0]
        rows[:m, off:off + 8] = dur[sel].view(np.uint8).reshape(m, 8)
        base += size
    used = sum(size for _, size in layouts[:n % period]) if n % period else width
    return rows.tobytes()[:groups * width - width + used]


def serialize_trajectory(traj: JointTrajectoryData, header: Any) -> bytes:
    """CDR bytes of the message :func:`~.trajectory_bridge.to_message` would build:
    ``header`` (stamp, frame_id), the joint names, and per point positions, velocities and
    accelerations (when the trajectory has them), no effort, time_from_start."""
    n, nj = traj.positions.shape
    cols = [traj.positions, traj.velocities, traj.accelerations]
    counts = tuple(0 if c is None else nj for c in cols) + (0,)
    w = _Writer()
    w.u32('i', int(header.stamp.sec))
    w.u32('I', int(header.stamp.nanosec))
    w.string(header.frame_id)
    w.u32('I', len(traj.joint_names))
    for name in traj.joint_names:
        w.string(name)
    w.u32('I', n)
    head = bytes(w.buf)
    ns = np.round(traj.time_from_start * 1e9).astype(np.int64)
    dur = np.empty((n, 2), '<u4')
    dur[:, 0] = (ns // _NS).astype('<i4').view('<u4')
    dur[:, 1] = ns % _NS
    # a point's layout depends on its start modulo 8 (0 or 4): at most one point of
    # transient, then a cycle of one or two points
    layouts, phases, o = [], [], len(head)
    while o % 8 not in phases:
        phases.append(o % 8)
        layouts.append(_point_layout(o, counts))
        o += layouts[-1][1]
    first = phases.index(o % 8)
    parts = [_rows(layouts[:first], cols, counts, dur, 0, min(first, n))] if first else []
    if n > first:
        parts.append(_rows(layouts[first:], cols, counts, dur, first, n))
    return b''.join([_ENCAPSULATION, head, *parts])


class _Reader:
    def __init__(self, body: memoryview) -> None:
        self.body = body
        self.o = 0

    def u32(self, fmt: str = 'I') -> int:
        self.o = _align(self.o, 4)
        (v,) = struct.unpack_from('<' + fmt, self.body, self.o)
        self.o += 4
        return int(v)

    def string(self) -> str:
        n = self.u32()
        text = bytes(self.body[self.o:self.o + max(0, n - 1)]).decode()
        self.o += n
        return text


def parse_trajectory(data: bytes) -> tuple[JointTrajectoryData, tuple[int, int, str]] | None:
    """The trajectory and (stamp sec, nanosec, frame_id) of a serialized
    ``JointTrajectory`` whose points all carry the same numbers of values (read with numpy,
    milliseconds for 100 000 points); None for anything else (ragged points, efforts, a
    big-endian or short buffer): the caller deserializes those the usual way."""
    if len(data) < 8 or data[:2] != _ENCAPSULATION[:2]:
        return None
    body = memoryview(data)[4:]
    try:
        r = _Reader(body)
        sec, nanosec = r.u32('i'), r.u32()
        frame = r.string()
        names = tuple(r.string() for _ in range(r.u32()))
        n = r.u32()
        start = r.o
        if n == 0 or not names:
            return None
        counts = []
        for _ in range(4):
            c = r.u32()
            counts.append(c)
            r.o = _align(r.o, 8) + 8 * c if c else r.o
        nj = len(names)
        if counts[0] != nj or counts[1] not in (0, nj) or counts[2] not in (0, nj) or \
                counts[3] or (counts[2] and not counts[1]):
            return None
    except (struct.error, UnicodeDecodeError, ValueError):
        return None
    cnt = tuple(counts)
    layouts, phases, o = [], [], start
    while o % 8 not in phases:
        phases.append(o % 8)
        layouts.append(_point_layout(o, cnt))
        o += layouts[-1][1]
    first = phases.index(o % 8)
    total = sum(size for _, size in layouts[:first]) + sum(
        size for _, size in (layouts[first:] * n)[:n - first]) if n > first else \
        sum(size for _, size in layouts[:n])
    if len(body) < start + total:
        return None
    cols = [np.empty((n, c)) if c else None for c in cnt[:3]]
    ns = np.empty((n, 2))                      # (sec, nanosec) of time_from_start
    pos = start
    for i in range(min(first, n)):            # the transient point, if any
        if not _read_rows(body, pos, [layouts[i]], cnt, cols, ns, i, i + 1):
            return None
        pos += layouts[i][1]
    if n > first and not _read_rows(body, pos, layouts[first:], cnt, cols, ns, first, n):
        return None
    traj = JointTrajectoryData(names, ns[:, 0] + ns[:, 1] * 1e-9, cols[0], cols[1], cols[2],
                               sec * _NS + nanosec)
    return traj, (sec, nanosec, frame)


def _read_rows(body: memoryview, pos: int, layouts: list, counts: tuple[int, ...],
               cols: list, ns: np.ndarray, a: int, b: int) -> bool:
    """Points a..b-1 from ``pos`` laid out by the cycle ``layouts`` into ``cols`` / ``ns``;
    False when a point's counts differ from the first point's."""
    n, period = b - a, len(layouts)
    width = sum(size for _, size in layouts)
    groups = n // period
    full = np.frombuffer(body, np.uint8, count=groups * width, offset=pos).reshape(
        groups, width) if groups else np.zeros((0, width), np.uint8)
    rest = n - groups * period
    tail = np.zeros((1, width), np.uint8)
    if rest:
        used = sum(size for _, size in layouts[:rest])
        tail[0, :used] = np.frombuffer(body, np.uint8, count=used, offset=pos + groups * width)
    rows = np.concatenate((full, tail)) if rest else full
    base = 0
    for k, (fields, size) in enumerate(layouts):
        m = len(range(a + k, b, period))
        sel = slice(a + k, b, period)
        block = rows[:m]
        for (length, data), c, col in zip(fields[:4], counts, cols + [None]):
            got = block[:, base + length:base + length + 4].copy().view('<u4')[:, 0]
            if np.any(got != c):
                return False
            if c:
                col[sel] = block[:, base + data:base + data + 8 * c].copy().view('<f8')
        off = base + fields[4][0]
        d = block[:, off:off + 8].copy().view('<u4')
        ns[sel, 0] = d[:, 0].view('<i4')
        ns[sel, 1] = d[:, 1]
        base += size
    return True
