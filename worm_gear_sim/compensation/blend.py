# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A new compensator blended in over a short time instead of switched at once (pure core):
:class:`BlendedCompensator`.

The correction goes from the old compensator's to the new one's along a cosine ramp,
w = (1 - cos(pi s)) / 2 with s = elapsed / ``duration``, both fed meanwhile, so that a
model swapped in while the stream runs does not ring the antenna mode
(docs/adaptation.md, "When the model in use changes").
"""

from __future__ import annotations

import copy
import math

from .streaming import Compensator

__all__ = ['BlendedCompensator', 'unwrap', 'settled']


def unwrap(comp: Compensator | BlendedCompensator | None) -> Compensator | None:
    """The compensator in charge (a blend's new one)."""
    return comp.new if isinstance(comp, BlendedCompensator) else comp


def settled(comp: Compensator | BlendedCompensator | None
            ) -> Compensator | BlendedCompensator | None:
    """``comp``, or the new compensator of a blend that has ended (it alone runs from then
    on: the same corrections, no wrapper left)."""
    if isinstance(comp, BlendedCompensator) and comp.old is None:
        return comp.new
    return comp


class BlendedCompensator:
    """``old`` handing over to ``new`` over ``duration`` [s] (module docstring); it takes the
    samples of both and evaluates the blended correction.  :func:`copy.copy` gives a copy
    that runs on its own (of both compensators); it copies, deep-copies and pickles."""

    def __init__(self, old: Compensator | BlendedCompensator | None, new: Compensator,
                 duration: float) -> None:
        if not (math.isfinite(duration) and duration > 0.0):
            raise ValueError(f'blend duration {duration!r}: must be > 0 s')
        self.old = old
        self.new = new
        self.duration = float(duration)
        self._t0: float | None = None

    def __copy__(self) -> BlendedCompensator:
        new = object.__new__(BlendedCompensator)
        new.__dict__.update(self.__dict__)
        new.old, new.new = copy.copy(self.old), copy.copy(self.new)
        return new

    @property
    def blending(self) -> bool:
        return self.old is not None

    def add_sample(self, t: float, theta1_ref: float) -> None:
        self.new.add_sample(t, theta1_ref)
        if self.old is not None:
            self.old.add_sample(t, theta1_ref)

    def trim(self, te_min: float) -> None:
        self.new.trim(te_min)
        if self.old is not None:
            self.old.trim(te_min)

    def reset(self, theta1_ref: float, t: float) -> None:
        self.old = None                       # a restart: nothing to hand over
        self.new.reset(theta1_ref, t)

    def copy_history(self, other: Compensator) -> None:
        self.new.copy_history(other)

    def evaluate(self, te: float) -> float:
        d = self.new.evaluate(te)
        old = self.old
        if old is None:
            return d
        if self._t0 is None:
            self._t0 = float(te)
        s = (float(te) - self._t0) / self.duration
        if s >= 1.0:
            self.old = None
            return d
        d_old = old.evaluate(te)
        w = 0.5 - 0.5 * math.cos(math.pi * max(s, 0.0))
        return d_old + w * (d - d_old)
