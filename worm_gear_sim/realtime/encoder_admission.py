# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""What an encoder sample (stamp, joint names, positions) must pass before it is used:
:class:`EncoderAdmission`, one rule for the live model check and the live adaptation, each
with its own instance.

The checks, cheap ones first, each with its reject reason (``non_finite``,
``out_of_order``, ``surplus``, ``malformed``, the consumer's ``missing``,
``outside_prediction``, ``implausible``): docs/node.md ("Bad input").
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
