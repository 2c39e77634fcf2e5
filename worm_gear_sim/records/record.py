# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The record type: command and measurements of one run on one time base (CSV and bag
readers in :mod:`.csv_io` and :mod:`.bag_io` both return it)."""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

import numpy as np

__all__ = ['Record', 'RecordError', 'ANGLE_NAMES', 'MEASURED_NAMES', 'EPOCH_MIN_NS', 'iso_time',
           'valid_sorted']

#: the record's angles: the command theta1 and the measured outputs theta2..theta4 [rad]
ANGLE_NAMES = ('theta1', 'theta2', 'theta3', 'theta4')
MEASURED_NAMES = ('theta2', 'theta3', 'theta4')

#: a start later than this (1973-03-03) is an absolute epoch stamp
EPOCH_MIN_NS = 10 ** 17


class RecordError(ValueError):
    """A record that cannot be read as asked: one line naming the cause, the file and the
    row/column or topic (the CLI reports it with exit status 2)."""


@dataclass
class Record:
    """Command and measurements of one run on one time base.

    ``t`` [s] is relative to ``t0_ns`` (the source clock at t = 0; 0 when the source times
    started at 0) and strictly increasing; ``theta1`` [rad] is the command at ``t``;
    ``measured`` maps a subset of ``theta2``, ``theta3``, ``theta4`` to angles [rad] at
    ``t``; ``load_torque`` [N m] the load on the antenna at ``t`` when it was recorded or
    designed (None: the model's constant).  When the command came as a separate stream
    (a bag), ``command_stamps_ns``
    (absolute, int64) and ``command_values`` [rad] hold its raw samples in arrival order,
    invalid ones included, as a live node would have received them; ``t``/``theta1`` then
    hold the valid samples sorted by stamp (or the command interpolated at the measurement
    stamps when a measured topic was read), and ``command_receive_ns`` the bag's receive
    times of the raw samples.  ``source`` says where everything came from.
    """

    name: str
    t: np.ndarray
    theta1: np.ndarray
    measured: dict[str, np.ndarray] = field(default_factory=dict)
    t0_ns: int = 0
    command_stamps_ns: np.ndarray | None = None
    command_values: np.ndarray | None = None
    source: dict[str, Any] = field(default_factory=dict)
    command_receive_ns: np.ndarray | None = None
    #: load torque on the antenna [N m] at ``t`` (a CSV's ``load_torque`` column), or None:
    #: the model's constant ``load.output_torque``
    load_torque: np.ndarray | None = None

    @property
    def is_epoch(self) -> bool:
        """True if ``t0_ns`` is an absolute (Unix epoch) time."""
        return self.t0_ns >= EPOCH_MIN_NS

    @property
    def duration(self) -> float:
        return float(self.t[-1]) if self.t.size else 0.0

    def command_samples(self) -> tuple[np.ndarray, np.ndarray]:
        """The valid command samples sorted by time: (t [s] relative to t0_ns, theta1)."""
        if self.command_stamps_ns is None or self.command_values is None:
            return self.t, self.theta1
        t, v, _ = valid_sorted(self.command_stamps_ns, self.command_values, self.t0_ns)
        return t, v

    def command_stream(self) -> tuple[np.ndarray, np.ndarray]:
        """The command as received: (absolute stamps [ns] int64, values [rad]) in arrival
        order (a CSV's rows when the command did not come separately)."""
        if self.command_stamps_ns is not None and self.command_values is not None:
            return self.command_stamps_ns, self.command_values
        return self.t0_ns + np.round(self.t * 1e9).astype(np.int64), self.theta1

    def describe(self) -> str:
        """One line: samples, span, measured outputs, epoch."""
        meas = ', '.join(self.measured) or 'none'
        start = (f'; t = 0 at {iso_time(self.t0_ns)}' if self.is_epoch else
                 f'; times shifted by -{self.t0_ns * 1e-9:.9g} s' if self.t0_ns else '')
        return (f'{self.name}: {self.t.size} samples over {self.duration:.6g} s, measured: '
                f'{meas}{start}')


def iso_time(ns: int) -> str:
    """An epoch stamp [ns] as ISO 8601 UTC with nanoseconds."""
    sec, frac = divmod(int(ns), 10 ** 9)
    return datetime.fromtimestamp(sec, UTC).strftime('%Y-%m-%dT%H:%M:%S') + \
        f'.{frac:09d}Z'



def valid_sorted(stamps: np.ndarray, vals: np.ndarray, t0_ns: int
                  ) -> tuple[np.ndarray, np.ndarray, int]:
    """Finite samples sorted by stamp (stable: of equal stamps the first received is kept),
    as (t [s] relative to t0_ns, values, number of duplicates dropped)."""
    ok = np.isfinite(vals)
    s, v = stamps[ok], vals[ok]
    order = np.argsort(s, kind='stable')
    s, v = s[order], v[order]
    first = np.concatenate(([True], np.diff(s) > 0))
    return (s[first] - t0_ns) * 1e-9, v[first], int((~first).sum())

