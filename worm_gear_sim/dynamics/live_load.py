# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A load torque that arrives in real time, for the stepping integration.

This module contains :class:`LiveLoad`: the load torque samples pushed to a
:class:`~worm_gear_sim.dynamics.stepping.Stepper` (``push_load``, ``hold_load``), each held
until the next one (zero-order hold: causal, no look-ahead), and their values on the
integration grid.  The offline load signals are in :mod:`~worm_gear_sim.dynamics.load`.
"""

from __future__ import annotations

import numpy as np

__all__ = ['LiveLoad', 'NO_LOAD']

#: The kernel's "the model's constant load" (no samples).
NO_LOAD = np.empty(0)


class LiveLoad:
    """Load torque samples ``v`` [N m] at increasing times ``t`` [s], each held until the
    next one; none: the model's constant load.  The arrays are replaced, never written
    into, so a copy may share them."""

    __slots__ = ('t', 'v')

    def __init__(self) -> None:
        self.t, self.v = np.empty(0), np.empty(0)

    def __copy__(self) -> LiveLoad:
        new = LiveLoad()
        new.t, new.v = self.t, self.v
        return new

    @property
    def live(self) -> bool:
        """Samples were pushed (they, not the model's constant, give the load)."""
        return self.t.size > 0

    def push(self, t: float, torque: float, now: float, constant: float) -> bool:
        """A sample at ``t`` (after the last one, ValueError otherwise); one at or before
        ``now`` applies from ``now`` on (returns False: it came late); before the first
        sample the load is ``constant``."""
        lt, lv = self.t, self.v
        if lt.size and t <= lt[-1]:
            raise ValueError(f'push_load: t = {t!r} s is not after the last load sample '
                             f'({lt[-1]!r} s)')
        if t <= now:           # late: from now on
            self.t, self.v = np.array([now]), np.array([torque])
            return False
        if not lt.size:        # the constant until the first sample
            lt, lv = np.array([now]), np.array([constant])
        self.t, self.v = np.append(lt, t), np.append(lv, torque)
        return True

    def hold(self, torque: float, now: float) -> None:
        """``torque`` from ``now`` on, held (replaces every sample)."""
        self.t, self.v = np.array([now]), np.array([torque])

    def at(self, t: np.ndarray) -> np.ndarray:
        """The held load at times ``t`` (live only)."""
        i = np.searchsorted(self.t, t, side='right') - 1
        return self.v[np.clip(i, 0, None)]

    def on_grid(self, t0: float, k: int, m: int, dt: float) -> np.ndarray:
        """The load at the grid points t0 + (k + i) dt, i = 0..m (NO_LOAD when not live)."""
        if not self.live:
            return NO_LOAD
        return self.at(t0 + (k + np.arange(m + 1)) * dt)

    def restart(self, t0: float, torque: float) -> None:
        """A restart at ``t0`` under ``torque``: the samples before are done with, the
        later ones stay."""
        later = self.t > t0
        self.t = np.concatenate(([t0], self.t[later]))
        self.v = np.concatenate(([torque], self.v[later]))

    def trim(self, now: float) -> None:
        """Drop the samples passed at ``now`` (keep the one before it)."""
        lt = self.t
        if lt.size < 2:
            return
        i = int(np.searchsorted(lt, now, side='right')) - 1
        if i > 0:
            self.t, self.v = lt[i:], self.v[i:]
