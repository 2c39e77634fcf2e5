# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""CSV records: reading a record by its header (names and units), and the numeric CSV
writer every table of the package uses (``# `` comment lines, then ``name[unit]`` columns).

Columns and units: docs/data-formats.md.
"""

from __future__ import annotations

import csv
import difflib
import math
import re
from array import array
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from pathlib import Path
from typing import Any

import numpy as np

from ..schema.sections import LOAD_LIMIT
from .record import ANGLE_NAMES, MEASURED_NAMES, Record, RecordError

__all__ = ['read_csv', 'write_csv_header', 'write_csv_columns', 'ANGLE_UNITS', 'TIME_UNITS',
           'TORQUE_UNITS', 'LOAD_NAME',
           'TIME_NAMES', 'MAX_CSV_LINE_CHARS', 'MAX_CSV_ROWS']

#: angle units accepted in a CSV header, factor to rad
ANGLE_UNITS: dict[str, float] = {'rad': 1.0, 'mrad': 1e-3, 'urad': 1e-6, 'µrad': 1e-6,
                                 'deg': math.pi / 180.0}
#: torque units accepted in a CSV header (the ``load_torque`` column), factor to N m
TORQUE_UNITS: dict[str, float] = {'N*m': 1.0, 'N.m': 1.0, 'N m': 1.0, 'Nm': 1.0, 'N·m': 1.0,
                                  'mN*m': 1e-3, 'mNm': 1e-3, 'kN*m': 1e3, 'kNm': 1e3}
#: the CSV column of a load torque signal on the antenna
LOAD_NAME = 'load_torque'
#: time units accepted in a CSV header, factor to s (exact decimals)
TIME_UNITS: dict[str, Decimal] = {'s': Decimal(1), 'ms': Decimal('1e-3'),
                                  'us': Decimal('1e-6'), 'µs': Decimal('1e-6'),
                                  'ns': Decimal('1e-9')}
TIME_NAMES = ('t', 'time', '__time')            # __time: PlotJuggler's CSV export
#: a unitless time column starting above this many "seconds" (year 5138) is refused:
#: it is a stamp in ms/us/ns whose unit the header must name
PLAUSIBLE_SECONDS = 1e11
#: Limits of a CSV record: a longer line (a header of many thousand columns, a binary
#: file) or more rows is a RecordError naming the limit.  Memory while reading: 8 bytes per
#: value read (t and the columns used) plus one line: a 10-million-row record of 5
#: columns takes 400 MB, the size of its file.
MAX_CSV_LINE_CHARS = 65_536
MAX_CSV_ROWS = 50_000_000


def write_csv_header(fh: Any, names: Sequence[str], comment: str = '') -> None:
    """The head of a numeric CSV: each line of ``comment`` as a ``# `` line, then the column
    names (with their units, e.g. ``theta4[rad]``) on one line."""
    fh.write(''.join(f'# {line}\n' for line in comment.splitlines()))
    fh.write(','.join(names) + '\n')


def write_csv_columns(path: str | Path, names: Sequence[str], data: np.ndarray,
                      fmt: str | Sequence[str] = '%.12g', comment: str = '') -> Path:
    """Numeric columns as CSV (``data``: one row per sample), with the head of
    :func:`write_csv_header`; the parent directory is created."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    with open(p, 'w') as fh:
        write_csv_header(fh, names, comment)
        np.savetxt(fh, data, delimiter=',', fmt=fmt)
    return p



# ---- CSV ---------------------------------------------------------------------------------
_HEADER_RE = re.compile(r'^\s*(?P<name>[^\[\(]*?)\s*(?:[\[\(](?P<unit>[^\]\)]*)[\]\)])?\s*$')


def _split_header(field_text: str) -> tuple[str, str]:
    """'theta1 [deg]' -> ('theta1', 'deg'); 't(s)' -> ('t', 's'); 'theta2' -> ('theta2', '')."""
    text = field_text.strip().strip('"\'')
    m = _HEADER_RE.match(text)
    if not m:
        return text, ''
    return m.group('name').strip(), (m.group('unit') or '').strip()


def read_csv(path: str | Path, *, columns: Mapping[str, str] | None = None,
             name: str | None = None, min_samples: int = 2,
             require_measured: bool = False) -> Record:
    """Read a CSV record whose header names its columns.

    Required: a time column ``t`` (also ``time`` or PlotJuggler's ``__time``) and
    ``theta1``; optional ``theta2``, ``theta3``, ``theta4`` and ``load_torque`` (the load
    on the antenna, positive turning it back).  A unit in brackets or parentheses after the
    name is converted (time: s, ms, us, ns; angles: rad, mrad, urad, deg; torque: N*m,
    mN*m, kN*m); without one, SI (s, rad, N m) is assumed; a load beyond +-1e5 N m is an
    error.  ``columns`` maps a role to a header name
    (``{'theta1': '/worm_angle_command/data'}``).  Other columns are ignored and listed in
    ``source['ignored_columns']``.  Lines starting with '#' are comments.  Times become
    relative to the first sample, read as exact decimals (epoch stamps keep their
    nanoseconds); ``t0_ns`` is the first time.  Every problem raises :class:`RecordError`
    naming the line and column.
    """
    p = Path(path)
    where = str(p)
    if not p.exists():
        raise RecordError(f'{where}: file not found')
    if p.is_dir():
        raise RecordError(f'{where}: is a directory (a rosbag2 bag? use --bag)')
    try:
        with open(p, encoding='utf-8-sig', newline='') as fh:
            return _read_csv_stream(fh, p, columns or {}, name, min_samples,
                                    require_measured)
    except UnicodeDecodeError:
        raise RecordError(f'{where}: not a text CSV file') from None
    except OSError as exc:
        raise RecordError(f'{where}: cannot read ({exc.strerror or exc})') from None


def _read_csv_stream(fh: Any, p: Path, columns: Mapping[str, str], name: str | None,
                     min_samples: int, require_measured: bool) -> Record:
    """read_csv on an open file, one line at a time: the memory is the columns' arrays
    (8 bytes per value) plus one line, whatever the file's size."""
    lines = _Lines(fh, str(p))
    head = _read_header(lines, columns)
    body = _read_body(lines, head)
    return _as_record(p, head, body, name, min_samples, require_measured)


class _Lines:
    """The file's data lines (not blank, not ``#`` comments), each read bounded, and the
    number of the line last read."""

    def __init__(self, fh: Any, where: str) -> None:
        self.fh, self.where, self.line_no = fh, where, 0
        self._rows = self._read()

    def _read(self) -> Iterator[str]:
        while ln := self.fh.readline(MAX_CSV_LINE_CHARS + 1):  # bounded: never a whole
            self.line_no += 1                                    # huge line in memory
            if len(ln) > MAX_CSV_LINE_CHARS:
                raise RecordError(f'{self.where}: line {self.line_no}: over '
                                  f'{MAX_CSV_LINE_CHARS} characters; a CSV line is at most '
                                  f'{MAX_CSV_LINE_CHARS}')
            if ln.strip() and not ln.lstrip().startswith('#'):
                yield ln

    def __iter__(self) -> Iterator[str]:
        return self._rows

    def first(self) -> str | None:
        return next(self._rows, None)


@dataclass
class _Header:
    """The header line read: delimiter, column texts, each role's column, unit and scale."""

    where: str
    delim: str
    header: list[str]
    fields: list[tuple[str, str]]
    roles: dict[str, int]
    units: dict[str, str]
    scale: dict[str, float]

    def column(self, col: int) -> str:
        return repr(self.header[col].strip())


def _read_header(lines: _Lines, columns: Mapping[str, str]) -> _Header:
    """The first data line as the header: the columns' roles and units."""
    where = lines.where
    head = lines.first()
    if head is None:
        raise RecordError(f'{where}: empty (no header, no data)')
    if '\x00' in head:
        raise RecordError(f'{where}: not a text CSV file')
    head_no = lines.line_no
    delim = next((d for d in (',', ';', '\t') if d in head), ',')
    header = _csv_row(head, delim, where, head_no)
    if all(_is_number(h) for h in header):
        raise RecordError(f'{where}: line {head_no}: no header line; the first line must '
                          "name the columns, e.g. 't [s],theta1 [rad]'")
    fields = [_split_header(h) for h in header]
    roles = _assign_roles(fields, header, columns, where)
    units, scale = _column_units(fields, header, roles, where)
    return _Header(where, delim, header, fields, roles, units, scale)


def _column_units(fields: list[tuple[str, str]], header: list[str], roles: dict[str, int],
                  where: str) -> tuple[dict[str, str], dict[str, float]]:
    """Each role's unit (named in the header or the default) and its scale to SI."""
    units, scale = {}, {}
    for role, col in roles.items():
        unit = fields[col][1]
        if role == 't':
            unit = unit or 's'
            if unit not in TIME_UNITS:
                raise RecordError(f'{where}: column {header[col].strip()!r}: unknown time unit '
                                  f'{unit!r} (use one of {", ".join(TIME_UNITS)})')
        elif role == LOAD_NAME:
            unit = unit or 'N*m'
            if unit not in TORQUE_UNITS:
                raise RecordError(f'{where}: column {header[col].strip()!r}: unknown torque '
                                  f'unit {unit!r} (use one of {", ".join(TORQUE_UNITS)})')
            scale[role] = TORQUE_UNITS[unit]
        else:
            unit = unit or 'rad'
            if unit not in ANGLE_UNITS:
                raise RecordError(f'{where}: column {header[col].strip()!r}: unknown angle '
                                  f'unit {unit!r} (use one of {", ".join(ANGLE_UNITS)})')
            scale[role] = ANGLE_UNITS[unit]
        units[role] = unit
    return units, scale


@dataclass
class _Body:
    """The data rows read: times after the first [s], each role's values, the first time."""

    t_rel: array
    values: dict[str, array]
    first: Decimal | None = None            # seconds, exact
    first_raw: Decimal | None = None        # in the column's unit
    n: int = 0


def _read_body(lines: _Lines, head: _Header) -> _Body:
    """Every data row after the header, checked: field count, increasing times, values."""
    where, n_fields, t_col = head.where, len(head.header), head.roles['t']
    sc = TIME_UNITS[head.units['t']]
    body = _Body(array('d'), {r: array('d') for r in head.roles if r != 't'})
    value_cols = [(head.roles[r], head.scale[r], vals, r) for r, vals in body.values.items()]
    prev: Decimal | None = None
    for ln in lines:
        line_no = lines.line_no
        row = _csv_row(ln, head.delim, where, line_no)
        if len(row) == n_fields + 1 and not row[-1].strip():
            row = row[:-1]                        # trailing delimiter
        if len(row) != n_fields:
            raise RecordError(f'{where}: line {line_no}: {len(row)} fields, the header has '
                              f'{n_fields}')
        tv = _row_time(row[t_col].strip(), prev, head, line_no)
        if body.first is None:
            body.first, body.first_raw = tv * sc, tv
        prev = tv
        body.n += 1
        if body.n > MAX_CSV_ROWS:
            raise RecordError(f'{where}: more than {MAX_CSV_ROWS} data rows; a record is at '
                              f'most {MAX_CSV_ROWS} rows: decimate it first')
        body.t_rel.append(float(tv * sc - body.first))
        for col, k, vals, role in value_cols:
            vals.append(_row_value(row[col].strip(), k, role, head, col, line_no))
    return body


def _row_time(cell: str, prev: Decimal | None, head: _Header, line_no: int) -> Decimal:
    """A row's time as an exact decimal, finite and after the previous one."""
    where, column = head.where, head.column(head.roles['t'])
    try:
        tv = Decimal(cell)
    except InvalidOperation:
        tv = Decimal('NaN')
    if not tv.is_finite():
        raise RecordError(f'{where}: line {line_no}, column {column}: '
                          f'{cell!r} is not a finite time')
    if prev is not None and tv <= prev:
        what = 'repeats the previous time (duplicated sample)' if tv == prev else \
            f'goes backwards (after {prev})'
        raise RecordError(f'{where}: line {line_no}, column {column}: '
                          f'time {cell} {what}; times must increase strictly')
    return tv


def _row_value(cell: str, k: float, role: str, head: _Header, col: int,
               line_no: int) -> float:
    """A row's angle or load torque in SI units, finite (a load within its limit)."""
    where, column = head.where, head.column(col)
    try:
        v = float(cell)
    except ValueError:
        what = 'empty' if not cell else f'{cell!r} is not a number'
        raise RecordError(f'{where}: line {line_no}, column {column}: '
                          f'{what}') from None
    if not math.isfinite(v):
        what = 'load torque' if role == LOAD_NAME else 'angle'
        raise RecordError(f'{where}: line {line_no}, column {column}: '
                          f'{cell} is not a finite {what}')
    if role == LOAD_NAME and abs(v * k) > LOAD_LIMIT:
        raise RecordError(f'{where}: line {line_no}, column {column}: '
                          f'load torque {cell} is beyond +-{LOAD_LIMIT:g} N m')
    return v * k


def _as_record(p: Path, head: _Header, body: _Body, name: str | None, min_samples: int,
               require_measured: bool) -> Record:
    """The rows read as a :class:`Record`, checked for length, time unit and measurement."""
    where, header, roles = head.where, head.header, head.roles
    t_col = roles['t']
    if body.n < min_samples:
        raise RecordError(f'{where}: {body.n} data row(s); a record needs at least '
                          f'{min_samples} samples')
    first, first_raw = body.first, body.first_raw
    assert first is not None and first_raw is not None
    if not head.fields[t_col][1] and abs(first) > PLAUSIBLE_SECONDS:
        raise RecordError(f'{where}: column {header[t_col].strip()!r}: first time {first_raw} '
                          'is not a plausible time in seconds; name its unit in the header, '
                          "e.g. 't [ns]' or 't [ms]'")
    t = np.frombuffer(body.t_rel, dtype=float)
    t0_ns = int((first * 10 ** 9).to_integral_value())
    cols = {r: np.frombuffer(v, dtype=float) for r, v in body.values.items()}
    measured = {r: cols[r] for r in MEASURED_NAMES if r in cols}
    if require_measured and not measured:
        raise RecordError(f'{where}: no measured column (theta2, theta3 or theta4) in the '
                          f'header {", ".join(h.strip() for h in header)}')
    used = set(roles.values())
    src = {'kind': 'csv', 'path': str(p), 'units': head.units,
           'columns': {r: header[c].strip() for r, c in roles.items()},
           'ignored_columns': [header[i].strip() for i in range(len(header))
                               if i not in used]}
    return Record(name=name or p.stem, t=t, theta1=cols['theta1'],
                  measured=measured, t0_ns=t0_ns, source=src, load_torque=cols.get(LOAD_NAME))


def _csv_row(line: str, delim: str, where: str, line_no: int) -> list[str]:
    try:
        return next(csv.reader([line], delimiter=delim))
    except (csv.Error, StopIteration) as exc:
        raise RecordError(f'{where}: line {line_no}: not a CSV row ({exc})') from None


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _assign_roles(fields: list[tuple[str, str]], header: list[str],
                  columns: Mapping[str, str], where: str) -> dict[str, int]:
    """Column index of each role (t, theta1..theta4) by header name."""
    known = ('t',) + ANGLE_NAMES + (LOAD_NAME,)
    for role in columns:
        if role not in known:
            raise RecordError(f'column mapping {role!r}: unknown role (one of '
                              f'{", ".join(known)})')
    names = [f[0] for f in fields]
    roles: dict[str, int] = {}
    for role in known:
        if role in columns:
            want = columns[role].strip()
            hits = [i for i, h in enumerate(header) if h.strip() == want or names[i] == want]
            if not hits:
                raise RecordError(f'{where}: no column {want!r} (mapped to {role}) in the '
                                  f'header {", ".join(h.strip() for h in header)}'
                                  + _did_you_mean(want, names))
        else:
            aliases = TIME_NAMES if role == 't' else (role,)
            hits = [i for i, n in enumerate(names) if n in aliases
                    and not any(names[i] == columns[r] for r in columns)]
        if len(hits) > 1:
            cols = ', '.join(repr(header[i].strip()) for i in hits)
            raise RecordError(f'{where}: columns {cols} all give {role}: ambiguous, keep one')
        if hits:
            roles[role] = hits[0]
    for role in ('t', 'theta1'):
        if role not in roles:
            what = 'time' if role == 't' else 'commanded worm angle'
            raise RecordError(f'{where}: no column {role!r} ({what}) in the header '
                              f'{", ".join(h.strip() for h in header)}'
                              + _did_you_mean(role, names, TIME_NAMES if role == 't' else ())
                              + '; name it in the header or map it (--column ROLE=NAME)')
    return roles


def _did_you_mean(name: str, candidates: Sequence[str], aliases: Sequence[str] = ()) -> str:
    for n in (name, *aliases):
        close = difflib.get_close_matches(n, list(candidates), n=1, cutoff=0.5)
        if close:
            return f' (did you mean {close[0]!r}?)'
    return ''
