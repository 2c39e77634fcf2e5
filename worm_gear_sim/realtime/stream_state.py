# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""This module holds the declared state of the real-time pipeline's input stream
(:class:`StreamState`), what a stale hold saves for its retraction (:class:`SavedStream`)
and the constants of the stream's rules (the package's docstring,
:mod:`worm_gear_sim.realtime`, says what they mean)."""

from __future__ import annotations

import collections
import copy
from dataclasses import dataclass, field

from ..compensation.blend import BlendedCompensator
from ..compensation.streaming import Compensator
from .drive import SimulatedDrive

__all__ = ['StreamState', 'SavedStream', 'STALE_PERIODS', 'STALE_MAX_INTERVAL',
           'LOAD_PENDING', 'RETRACTED_COUNTS']

STALE_PERIODS = 3.5          # tick periods without a sample: the reference rests
STALE_MAX_INTERVAL = 0.05    # s: sample intervals longer than this are pauses, not a rate
LOAD_PENDING = 1000     # load samples kept from before the first reference (10 s at 100 Hz)
#: the counts a retracted stale hold takes back with the state
RETRACTED_COUNTS = ('overruns', 'dropped_time_ns', 'rest_samples')


def _load_queue() -> collections.deque:
    return collections.deque(maxlen=LOAD_PENDING)


@dataclass
class StreamState:
    """The state of the stream being served (stamped references or Float64 commands):
    everything the next sample's fate and the corrections depend on besides the
    compensator and the simulated drive.  A new stream (a start, a resync, a restart)
    begins with a fresh one; :func:`copy.copy` gives a copy with its own queues (what a
    stale hold saves)."""

    base_ns: int | None               # the time origin [ns] (None: the first sample's stamp)
    gap_ns: int                       # G at the last accepted sample [ns]
    started: bool = False             # a first sample started the simulation
    mode: str = ''                    # 'stamped' | 'command' once started
    last_ns: int = 0                  # last sample fed, real or rest [ns]
    last_real_ns: int = 0             # last accepted sample [ns]
    last_real_ref: float = 0.0        # its theta1_ref [rad]
    last_arrival_ns: int = 0          # the caller's clock at that sample [ns]
    rest_k: int = 0                   # rest samples inserted after it
    #: samples whose correction waits for the preview: (ns, theta1_ref, real)
    pending: collections.deque = field(default_factory=collections.deque)
    stale: bool = False               # no sample for G (+ the margin): the reference rests
    delta: float = 0.0                # last correction [rad]
    last_load_ns: int | None = None   # last accepted load sample [ns]
    #: load samples before the start: (stamp [ns], N m), the newest LOAD_PENDING
    load_pending: collections.deque = field(default_factory=_load_queue)

    def __copy__(self) -> StreamState:
        new = object.__new__(StreamState)
        new.__dict__.update(self.__dict__)
        new.pending = collections.deque(self.pending)
        new.load_pending = collections.deque(self.load_pending, LOAD_PENDING)
        return new


@dataclass(frozen=True)
class SavedStream:
    """What a stale hold saves and a late sample's retraction restores: the stream's state,
    the compensator in charge and the simulated drive (copies that run on their own) and
    the counts of :data:`RETRACTED_COUNTS`."""

    state: StreamState
    compensator: Compensator | BlendedCompensator | None
    drive: SimulatedDrive
    counts: dict[str, int]

    @classmethod
    def of(cls, state: StreamState, compensator: Compensator | BlendedCompensator | None,
           drive: SimulatedDrive, counters: dict[str, int]) -> SavedStream:
        """Copies of the pieces as they are now."""
        return cls(copy.copy(state), copy.copy(compensator), copy.copy(drive),
                   {k: counters[k] for k in RETRACTED_COUNTS})
