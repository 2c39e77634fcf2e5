# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The integrator's two methods for the tests that check an integration against an
independent reference: the fixed step (``integrator.method: fixed``) and the variable step
(``adaptive``).  A test that runs the fixed step finer than its default (a small
``integrator.time_step``) runs the variable step with tolerances tighter than its defaults:
:func:`method_overrides`.  The checks themselves are the same for both."""

from __future__ import annotations

from typing import Any

METHODS = ('fixed', 'adaptive')


def method_overrides(method: str, tol_worm: float | None = None,
                     tol_gear: float | None = None) -> dict[str, Any]:
    """Config overrides for ``method``: none for the fixed step; the variable step with the
    given tolerances [rad per step] (None: the defaults)."""
    if method == 'fixed':
        return {}
    over: dict[str, Any] = {'integrator.method': 'adaptive'}
    if tol_worm is not None:
        over['integrator.adaptive_tolerance_worm'] = tol_worm
    if tol_gear is not None:
        over['integrator.adaptive_tolerance_gear'] = tol_gear
    return over
