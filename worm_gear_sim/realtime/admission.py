# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""What a sample must pass before the pipeline takes it: the input checks and the
confirmation of a jump, written once for every input of :class:`~.predictor.RealtimePredictor`
(stamped references, Float64 commands, load torques).  The rules are those of the package's
docstring (:mod:`worm_gear_sim.realtime`): a value that is NaN, inf or beyond its limit; a
stamp that is zero, negative, outside the window around the caller's clock, equal to or older
than the last accepted one; a change of more than ``node.max_command_jump``.  A rejected jump
(or a restart of the stamps) is a candidate: :class:`JumpConfirmation` says when
``confirm_samples`` candidates in a row agree, so that the new level is real."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from .outputs import Reject

__all__ = ['Admission', 'Candidate', 'JumpConfirmation', 'CHAIN_MAX_GAP_NS']

CHAIN_MAX_GAP_NS = 50_000_000  # candidates further apart do not confirm each other


@dataclass
class Admission:
    """The input checks with the limits in force (the pipeline updates them when its
    configuration changes).  ``max_abs`` / ``max_jump`` [rad]: ``node.max_command_abs`` and
    ``node.max_command_jump``; ``max_age_ns`` / ``lead_ns``: the accepted stamp window
    around the caller's clock (the lead includes the preview)."""

    max_abs: float
    max_jump: float
    max_age_ns: int
    lead_ns: int

    def value_reason(self, value: float, limit: float | None = None) -> Reject | None:
        """NaN, inf or ``|value|`` beyond ``limit`` (None: ``max_abs``)."""
        if math.isnan(value):
            return Reject.NAN
        if math.isinf(value):
            return Reject.INF
        if abs(value) > (self.max_abs if limit is None else limit):
            return Reject.OUT_OF_RANGE
        return None

    def stamp_reason(self, stamp_ns: int, now_ns: int | None) -> Reject | None:
        """A zero or negative stamp; one outside the window around ``now_ns`` (None:
        offline, no window)."""
        if stamp_ns < 0:
            return Reject.NEGATIVE_STAMP
        if stamp_ns == 0:
            return Reject.ZERO_STAMP
        if now_ns is not None and stamp_ns < now_ns - self.max_age_ns:
            return Reject.TOO_OLD
        if now_ns is not None and stamp_ns > now_ns + self.lead_ns:
            return Reject.TOO_NEW
        return None

    @staticmethod
    def order_reason(stamp_ns: int, last_ns: int | None) -> Reject | None:
        """A stamp equal to or before the last accepted one (None: nothing accepted yet)."""
        if last_ns is None:
            return None
        if stamp_ns == last_ns:
            return Reject.DUPLICATE
        if stamp_ns < last_ns:
            return Reject.OUT_OF_ORDER
        return None

    def jump_reason(self, value: float, last: float | None) -> Reject | None:
        """A change of more than ``max_jump`` from the last accepted value (None: none)."""
        if last is not None and abs(value - last) > self.max_jump:
            return Reject.JUMP
        return None


@dataclass(frozen=True, slots=True)
class Candidate:
    """A rejected sample kept until its fate is known: ``stamp_ns`` (None on an unstamped
    input), the value and the reason it was rejected for."""

    stamp_ns: int | None
    value: float
    reason: Reject


@dataclass
class JumpConfirmation:
    """The candidates of a resync: samples rejected as a jump (or a restart of the stamps)
    that agree with each other (values within ``max_jump``; stamps, where there are any,
    increasing by at most :data:`CHAIN_MAX_GAP_NS`).  ``needed`` candidates in a row confirm
    that the new level or timeline is real."""

    needed: int
    max_jump: float
    candidates: list[Candidate] = field(default_factory=list)

    def offer(self, value: float, reason: Reject, stamp_ns: int | None = None
              ) -> tuple[bool, list[Candidate]]:
        """Add a candidate.  Returns (confirmed, broken): ``broken`` holds the candidates of
        the chain this one did not agree with (dropped: the caller counts them rejected)."""
        broken: list[Candidate] = []
        if self.candidates:
            last = self.candidates[-1]
            agrees = abs(value - last.value) <= self.max_jump
            if stamp_ns is not None and last.stamp_ns is not None:
                agrees = agrees and 0 < stamp_ns - last.stamp_ns <= CHAIN_MAX_GAP_NS
            if not agrees:
                broken = self.clear()
        self.candidates.append(Candidate(stamp_ns, value, reason))
        return len(self.candidates) >= self.needed, broken

    def clear(self) -> list[Candidate]:
        """Drop the candidates; returns them."""
        dropped, self.candidates = self.candidates, []
        return dropped

    def __len__(self) -> int:
        return len(self.candidates)
