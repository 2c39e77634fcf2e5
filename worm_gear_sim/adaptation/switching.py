# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The arithmetic of the rule that lets an adapted set replace the model in use.

This module contains the pieces of :meth:`~.estimator.Adapter.poll`'s rule that depend on
their arguments alone: the candidate set of an estimate, bounded at zero
(:func:`bounded_candidate`), the change of the static correction a parameter change makes
(:func:`correction_bound`) and the next bounded step towards the target
(:func:`step_towards`).  The rule itself: the module docstring of :mod:`.estimator`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from .layout import DRAG_KEY, PLAY_KEY, Layout

__all__ = ['BOUND_SIGMAS', 'bounded_candidate', 'correction_bound', 'step_towards']

#: A play or drag estimate below zero by more than this many standard deviations is refused.
BOUND_SIGMAS = 3.0


def bounded_candidate(x: np.ndarray, P: np.ndarray, layout: Layout) -> tuple[np.ndarray, str]:
    """The candidate of estimate ``x`` (covariance ``P``): a play or drag below zero by less
    than ``BOUND_SIGMAS`` standard deviations is set to zero (zero is within its
    uncertainty), the other values conditioned on it (x - P[:, i] x_i / P_ii: those it
    is correlated with take what it gave, e.g. the load the play's share of one offset
    on a drive that keeps one flank); one further below is refused (the reason)."""
    cand = x.copy()
    P = P.copy()
    for i, key in ((layout.i_play, PLAY_KEY), (layout.i_drag, DRAG_KEY)):
        if i >= 0 and cand[i] < 0.0:
            sd = math.sqrt(max(P[i, i], 0.0))
            if cand[i] < -BOUND_SIGMAS * sd:
                return cand, (f'{key} estimate {cand[i]:.3g} is negative (beyond '
                              f'{BOUND_SIGMAS:g} standard deviations, {sd:.2g}): not '
                              'applied')
            if P[i, i] > 0.0:
                gain = P[:, i] / P[i, i]
                cand -= gain * cand[i]
                P -= np.outer(gain, P[i, :])
            cand[i] = 0.0
    return cand, ''


def correction_bound(delta: np.ndarray, layout: Layout, compliance: tuple[float, float],
                     w_max: float) -> float:
    """Bound of the change of the static antenna correction a parameter change ``delta``
    makes [rad] (the sensitivities of the estimator's module docstring: the wind-up
    ``compliance`` per N m, sliding forwards and backwards, the largest antenna rate
    ``w_max`` seen)."""
    c = max(abs(compliance[0]), abs(compliance[1]))
    out = 0.0
    if layout.i_load >= 0:
        out += c * abs(delta[layout.i_load])
    if layout.i_drag >= 0:
        out += c * w_max * abs(delta[layout.i_drag])
    if layout.i_play >= 0:
        out += 0.5 * abs(delta[layout.i_play])
    for i0, k in ((layout.worm0, layout.worm_orders), (layout.gear0, layout.gear_orders)):
        if i0 >= 0:
            out += float(np.sum(np.abs(delta[i0:i0 + 2 * k])))
    return out


def step_towards(target: np.ndarray, applied: np.ndarray, budget: float,
                 order: Sequence[np.ndarray], bound: Callable[[np.ndarray], float]
                 ) -> np.ndarray:
    """The next step from ``applied`` towards ``target``: the parts of ``order`` one after
    the other, each whole while the ``budget`` [rad] of the change of the correction
    (``bound`` of a change) lasts, the part it runs out in moved by what is left."""
    delta = target - applied
    step = applied.copy()
    for part in order:
        d = np.zeros_like(delta)
        d[part] = delta[part]
        b = bound(d)
        if b <= budget:
            step[part] = target[part]
            budget -= b
        else:
            step[part] += budget / b * d[part]
            break
    return step
