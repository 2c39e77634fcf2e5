# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Where each adapted key sits in the estimator's state vector (:class:`Layout`), the prior
of each key, and what two layouts share (:func:`shared_indices`: what a parameter set that
changes the keys or orders estimated carries over, :mod:`.learnt`)."""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..schema.parameters import Parameters
from ..schema.sections import ADAPTABLE_KEYS, MAX_ERROR_ORDERS

__all__ = ['PRIOR_STD', 'Layout', 'shared_indices', 'LOAD_KEY', 'DRAG_KEY', 'PLAY_KEY',
           'WORM_KEY', 'GEAR_KEY']

LOAD_KEY, DRAG_KEY, PLAY_KEY, WORM_KEY, GEAR_KEY = ADAPTABLE_KEYS
#: Prior standard deviation of each key's estimate about its start value (per coefficient
#: for the harmonics): rad at the gear, N m, N m s/rad, rad.
PRIOR_STD: dict[str, float] = {WORM_KEY: 1e-4, GEAR_KEY: 3e-5, LOAD_KEY: 5.0,
                               DRAG_KEY: 50.0, PLAY_KEY: 1e-3}


@dataclass(frozen=True)
class Layout:
    """Where each adapted key sits in the state vector (-1: not adapted)."""

    keys: tuple[str, ...]
    worm_orders: int
    gear_orders: int
    i_load: int
    i_drag: int
    i_play: int
    worm0: int
    gear0: int
    n: int

    @classmethod
    def of(cls, keys: Sequence[str], worm_orders: int, gear_orders: int) -> Layout:
        bad = [k for k in keys if k not in ADAPTABLE_KEYS]
        if bad:
            raise ValueError(f'adaptation.keys: {", ".join(bad)} cannot be adapted (choose '
                             f'from {", ".join(ADAPTABLE_KEYS)})')
        chosen = tuple(k for k in ADAPTABLE_KEYS if k in keys)
        if not chosen:
            raise ValueError('adaptation.keys: empty (nothing to adapt)')
        idx: dict[str, int] = {}
        n = 0
        for k in chosen:
            idx[k] = n
            n += {WORM_KEY: 2 * worm_orders, GEAR_KEY: 2 * gear_orders}.get(k, 1)
        return cls(chosen, int(worm_orders) if WORM_KEY in idx else 0,
                   int(gear_orders) if GEAR_KEY in idx else 0, idx.get(LOAD_KEY, -1),
                   idx.get(DRAG_KEY, -1), idx.get(PLAY_KEY, -1), idx.get(WORM_KEY, -1),
                   idx.get(GEAR_KEY, -1), n)

    @classmethod
    def for_set(cls, cfg: Parameters, settings: Any) -> Layout:
        """The layout of an :class:`~.estimator.Adapter` of ``cfg`` with ``settings`` (the
        ``adaptation`` section): the orders estimated are at least those of the set's
        harmonics."""
        worm = max(int(settings.worm_error_orders), len(cfg.mesh.worm_error_harmonics) // 2)
        gear = max(int(settings.gear_error_orders), len(cfg.mesh.gear_error_harmonics) // 2)
        return cls.of(settings.keys, min(worm, MAX_ERROR_ORDERS), min(gear, MAX_ERROR_ORDERS))

    def span(self, key: str) -> tuple[int, int]:
        """Where ``key`` sits: (first index, past the last); (0, 0) when not estimated."""
        i = {LOAD_KEY: self.i_load, DRAG_KEY: self.i_drag, PLAY_KEY: self.i_play,
             WORM_KEY: self.worm0, GEAR_KEY: self.gear0}[key]
        n = {WORM_KEY: 2 * self.worm_orders, GEAR_KEY: 2 * self.gear_orders}.get(key, 1)
        return (i, i + n) if i >= 0 else (0, 0)

    def pack(self, cfg: Parameters) -> np.ndarray:
        """The state vector of ``cfg``'s values (harmonics padded with zeros)."""
        x = np.zeros(self.n)
        for i, key in ((self.i_load, LOAD_KEY), (self.i_drag, DRAG_KEY),
                       (self.i_play, PLAY_KEY)):
            if i >= 0:
                x[i] = float(cfg.to_flat_dict()[key])
        for i0, orders, key in ((self.worm0, self.worm_orders, WORM_KEY),
                                (self.gear0, self.gear_orders, GEAR_KEY)):
            if i0 >= 0:
                v = list(getattr(cfg.mesh, key.split('.')[1]))[:2 * orders]
                x[i0:i0 + len(v)] = v
        return x

    def overrides(self, x: np.ndarray) -> dict[str, Any]:
        """The parameter overrides (dotted keys) of a state vector."""
        out: dict[str, Any] = {}
        for i, key in ((self.i_load, LOAD_KEY), (self.i_drag, DRAG_KEY),
                       (self.i_play, PLAY_KEY)):
            if i >= 0:
                out[key] = float(x[i])
        for i0, orders, key in ((self.worm0, self.worm_orders, WORM_KEY),
                                (self.gear0, self.gear_orders, GEAR_KEY)):
            if i0 >= 0:
                out[key] = [float(v) for v in x[i0:i0 + 2 * orders]]
        return out

    def prior_std(self) -> np.ndarray:
        s = np.zeros(self.n)
        for i, key in ((self.i_load, LOAD_KEY), (self.i_drag, DRAG_KEY),
                       (self.i_play, PLAY_KEY)):
            if i >= 0:
                s[i] = PRIOR_STD[key]
        for i0, orders, key in ((self.worm0, self.worm_orders, WORM_KEY),
                                (self.gear0, self.gear_orders, GEAR_KEY)):
            if i0 >= 0:
                s[i0:i0 + 2 * orders] = PRIOR_STD[key]
        return s


def shared_indices(old: Layout, new: Layout, skip: Collection[str] = ()
                   ) -> tuple[np.ndarray, np.ndarray]:
    """(indices in ``old``, the same entries' indices in ``new``) of what both layouts
    estimate: each key in both (but those in ``skip``), and of a harmonic key the orders
    both have."""
    i_old: list[int] = []
    i_new: list[int] = []
    for key in old.keys:
        if key in skip or key not in new.keys:
            continue
        a, b = old.span(key), new.span(key)
        n = min(a[1] - a[0], b[1] - b[0])
        i_old += range(a[0], a[0] + n)
        i_new += range(b[0], b[0] + n)
    return np.array(i_old, np.int64), np.array(i_new, np.int64)
