# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""What a joint was commanded, instant by instant, given the trajectories sent for it (pure
core): the start position and hand-over history of ``TrajectoryCompensator``.

The rule is a splice at the stamp: a trajectory takes over at its start instant; what was
sent before goes on until then, and whatever was sent to start at or after it is dropped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ['CommandTimeline']


@dataclass(frozen=True)
class _Piece:
    """From ``start_ns`` on (until the next piece): ``ref`` at ``t`` [s after
    ``start_ns``], its last value held after its end."""

    start_ns: int
    t: np.ndarray
    ref: np.ndarray


class CommandTimeline:
    """The commanded reference of one joint over time (module docstring).  ``keep_s``:
    seconds kept before the newest start (older pieces are forgotten; an instant before
    the oldest piece kept reads its first value)."""

    def __init__(self, keep_s: float = 3600.0) -> None:
        self.keep_ns = int(keep_s * 1e9)
        self._pieces: list[_Piece] = []

    def __len__(self) -> int:
        return len(self._pieces)

    @property
    def first_ns(self) -> int | None:
        """The start of the oldest piece kept (None: nothing sent)."""
        return self._pieces[0].start_ns if self._pieces else None

    def at(self, ns: np.ndarray | int) -> np.ndarray:
        """The commanded position at the instants ``ns`` [int ns]; ValueError when
        nothing was sent."""
        if not self._pieces:
            raise ValueError('CommandTimeline.at: nothing sent yet')
        x = np.atleast_1d(np.asarray(ns, dtype=np.int64))
        out = np.empty(x.shape)
        starts = np.array([p.start_ns for p in self._pieces], dtype=np.int64)
        k = np.clip(np.searchsorted(starts, x, side='right') - 1, 0, len(starts) - 1)
        for i in np.unique(k):
            sel = k == i
            p = self._pieces[int(i)]
            out[sel] = np.interp((x[sel] - p.start_ns) / 1e9, p.t, p.ref)
        return out

    def position(self, ns: int) -> float | None:
        """The commanded position at ``ns`` (None: nothing sent)."""
        return float(self.at(ns)[0]) if self._pieces else None

    def splice(self, start_ns: int, t: np.ndarray, ref: np.ndarray) -> None:
        """A trajectory starting at ``start_ns`` (``ref`` at ``t`` s after it) was sent:
        it replaces what was sent from ``start_ns`` on."""
        kept = [p for p in self._pieces if p.start_ns < start_ns]
        kept.append(_Piece(int(start_ns), np.asarray(t, float), np.asarray(ref, float)))
        horizon = kept[-1].start_ns - self.keep_ns
        while len(kept) > 1 and kept[1].start_ns <= horizon:
            kept.pop(0)
        self._pieces = kept
