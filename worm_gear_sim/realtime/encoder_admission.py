# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""What an encoder sample (a ``measured_joint_states`` message: stamp, joint names, positions)
must pass before it is used: one rule for the live model check
(:class:`~.model_check.ModelCheck`) and the live adaptation
(:class:`~worm_gear_sim.adaptation.live.LiveAdaptation`), each with its own instance (its own
prediction history, its own last sample).

The checks, in this order (the cheap ones first: a flood of messages costs a few comparisons
per message), each with the reason a sample is rejected for:

* ``non_finite``: a stamp that is NaN or infinite;
* ``out_of_order``: a stamp not after the last sample used;
* ``surplus``: the sample would be more than one per command period (``period``).  A sample
  is used only when its stamp has reached the *due* stamp; each sample used moves the due
  stamp one period on from the later of the old due stamp and half a period before its own
  stamp.  So an encoder at the command rate has every sample used even when its stamps
  jitter by up to half a period, and a faster stream has one sample used per period (at most
  k + 1 in any k periods); the rest cost two comparisons each;
* ``malformed``: names and positions of unequal length, or a joint name given twice (which
  of the two values would be the joint's?);
* the consumer's reason for a message without any of the joints it uses (``missing``: the
  model check's ``no_monitored_joint``, the adaptation's ``other_joint``);
* ``non_finite``: the position of a joint used is NaN, infinite or no number;
* ``outside_prediction``: no prediction covers the stamp (``predict`` returns None);
* ``implausible``: a joint used is farther than ``max_residual`` [rad]
  (``node.residual_plausible_max``) from the prediction of its stamp.  No model error of a
  drive the model describes comes near the default bound (docs/node.md): such a sample is an
  encoder of another drive, a wrapped or corrupted reading, and one of them would otherwise
  poison every windowed figure computed from the residuals.

The stamps are the consumer's (integer nanoseconds or float seconds, ``period`` in the same
unit); the admission keeps only the last stamp used and the due stamp (:meth:`reset` forgets
them: a restart of the consumer's timeline).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

__all__ = ['EncoderAdmission', 'ENCODER_REASONS', 'Predict', 'Admitted']

#: The reasons of the rule besides the consumer's missing-joint reason.
ENCODER_REASONS = ('non_finite', 'out_of_order', 'surplus', 'malformed', 'outside_prediction',
                   'implausible')
#: The prediction (theta2, theta3, theta4) at a stamp, or None outside the stored ones.
Predict = Callable[[Any], Sequence[float] | None]
#: An admitted sample: (the indices of the joints used that it holds, their positions, the
#: prediction of its stamp).
Admitted = tuple[list[int], list[float], Sequence[float]]

_INF = math.inf


class EncoderAdmission:
    """The rule of the module docstring for the joints ``joint_names`` (theta2, theta3,
    theta4's names) of which the consumer uses those at ``used`` (indices; a sample must hold
    at least one, else it is rejected for ``missing``).  ``max_residual`` [rad]: the
    plausibility bound (inf: none); ``period``: the command period in the stamps' unit (0:
    no rate bound)."""

    __slots__ = ('joint_names', 'used', 'missing', 'max_residual', 'period', '_half',
                 'last', 'due')

    def __init__(self, joint_names: Sequence[str], used: Sequence[int], missing: str, *,
                 max_residual: float = _INF, period: float = 0) -> None:
        if len(joint_names) != 3:
            raise ValueError('joint_names: the names of theta2, theta3 and theta4')
        if not used or any(j not in (0, 1, 2) for j in used):
            raise ValueError(f'used: indices of theta2..theta4 (0, 1, 2), got {used!r}')
        if not max_residual > 0.0:
            raise ValueError(f'max_residual must be > 0 rad, got {max_residual!r}')
        if not (period >= 0 and math.isfinite(period)):
            raise ValueError(f'period must be >= 0, got {period!r}')
        self.joint_names = tuple(joint_names)
        self.used = tuple(int(j) for j in used)
        self.missing = missing
        self.max_residual = float(max_residual)
        self.period = period
        self._half = period // 2 if isinstance(period, int) else 0.5 * period
        self.last: Any = None         # the stamp of the last sample used
        self.due: Any = None          # the first stamp the next sample may be used at

    def reset(self) -> None:
        """Forget the last sample used (the consumer's timeline restarts)."""
        self.last = self.due = None

    def admit(self, stamp: Any, names: Sequence[str], positions: Sequence[float],
              predict: Predict) -> str | Admitted:
        """The reason ``(stamp, names, positions)`` is rejected for, or the admitted sample
        (:data:`Admitted`; the sample then counts as used for the order and the rate)."""
        if stamp != stamp or stamp == _INF or stamp == -_INF:
            return 'non_finite'
        last = self.last
        if last is not None:
            if stamp <= last:
                return 'out_of_order'
            if stamp < self.due:
                return 'surplus'
        n = len(names)
        if n != len(positions):
            return 'malformed'
        if not isinstance(names, (list, tuple)):
            names = list(names)
        if n > 1 and len(set(names)) != n:
            return 'malformed'
        present: list[int] = []
        values: list[float] = []
        for j in self.used:
            name = self.joint_names[j]
            if name in names:
                try:
                    v = float(positions[names.index(name)])
                except (TypeError, ValueError, OverflowError):
                    return 'non_finite'
                if v != v or v == _INF or v == -_INF:
                    return 'non_finite'
                present.append(j)
                values.append(v)
        if not present:
            return self.missing
        pred = predict(stamp)
        if pred is None:
            return 'outside_prediction'
        bound = self.max_residual
        for j, v in zip(present, values):
            if not abs(v - pred[j]) <= bound:
                return 'implausible'
        self.last = stamp
        due = self.due
        start = stamp - self._half
        self.due = (start if due is None or start > due else due) + self.period
        return present, values, pred
