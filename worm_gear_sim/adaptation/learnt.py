# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""What live adaptation has learnt, kept through what an operator does (pure core).

The rules ``LiveAdaptation`` applies when a parameter set comes in: which sets leave the
adapter as it is (:data:`NEUTRAL_PREFIXES`, :data:`NEUTRAL_KEYS`), what the old and new
estimator share (:func:`carried_values`, :func:`carried_adapter`) and what is lost
(:func:`carry_notes`).  docs/adaptation.md ("In the node").
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from typing import Any

import numpy as np

from ..config.usable import Config
from ..dynamics.model import DriveModel
from ..schema.parameters import Parameters
from ..schema.sections import ADAPTABLE_KEYS
from .estimator import Adapter
from .layout import Layout, shared_indices

__all__ = ['NEUTRAL_PREFIXES', 'NEUTRAL_KEYS', 'touches_estimator', 'carried_values',
           'carried_adapter', 'carry_notes', 'format_value']

#: Sections whose parameters the estimator does not read (the node's wiring, the
#: feed-forward's design: the residual compares measurement and prediction of one command).
NEUTRAL_PREFIXES = ('node.', 'compensation.')
#: Adaptation settings the estimator does not read (:class:`~.live.LiveAdaptation` reads
#: ``sample_delay``).
NEUTRAL_KEYS = frozenset({'adaptation.enabled', 'adaptation.params_file',
                          'adaptation.sample_delay'})


def _same(a: Any, b: Any) -> bool:
    """Equal values (harmonic lists: equal after padding the shorter with zeros)."""
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        n = max(len(a), len(b))
        return list(a) + [0.0] * (n - len(a)) == list(b) + [0.0] * (n - len(b))
    return bool(a == b)


def touches_estimator(old: Parameters, new: Parameters, names: Collection[str]) -> bool:
    """Whether the parameter set of ``names`` (from the operator's set ``old`` to ``new``)
    changes what the estimator reads: an adaptable key set explicitly, or another key
    outside the neutral ones set to a new value."""
    a, b = old.to_flat_dict(), new.to_flat_dict()
    return any(not (k.startswith(NEUTRAL_PREFIXES) or k in NEUTRAL_KEYS)
               and (k in ADAPTABLE_KEYS or not _same(a.get(k), b.get(k)))
               for k in names)


def carried_values(adapter: Adapter, new: Config, names: Collection[str]) -> dict[str, Any]:
    """The values in use of ``adapter`` that the operator's new set ``new`` keeps (a set of
    the parameters ``names``): those of each key estimated before and after (of a harmonic
    key, the orders both estimate) that the set does not name, where they differ from
    ``new``'s.  The model in use is ``new.replace(carried_values(...))``."""
    lay = Layout.for_set(new, new.adaptation)
    i_old, i_new = shared_indices(adapter.layout, lay, skip=names)
    if not i_old.size:
        return {}
    x = lay.pack(new)
    x[i_new] = adapter.applied_x[i_old]
    flat = new.to_flat_dict()
    return {k: v for k, v in lay.overrides(x).items() if not _same(v, flat[k])}


def carried_adapter(old: Adapter, model: DriveModel, declared: Config,
                    names: Collection[str]) -> Adapter:
    """A new adapter for the pipeline's ``model`` (the operator's set ``declared`` with
    :func:`carried_values` on top; ``names``: the parameters the set named) with what
    ``old`` learnt of the keys both estimate but those named: the estimate, its covariance
    (those entries and between them; a restarted key's prior, uncorrelated) and the target;
    the nominal set is ``declared``'s; the counts of steps and refusals go on."""
    new = Adapter(model, declared.adaptation)
    new.nominal_x = new.layout.pack(declared)
    i_old, i_new = shared_indices(old.layout, new.layout, skip=names)
    if i_old.size:
        new.theta[i_new] = old.theta[i_old]
        new.P[np.ix_(i_new, i_new)] = old.P[np.ix_(i_old, i_old)]
        if old.target is not None:
            target = new.applied_x.copy()
            target[i_new] = old.target[i_old]
            new.target = None if np.array_equal(target, new.applied_x) else target
    new.switches, new.refusals, new.last_refusal = old.switches, old.refusals, old.last_refusal
    return new


def carry_notes(old: Adapter, old_values: Mapping[str, Any], new: Adapter,
                names: Collection[str]) -> list[str]:
    """What a parameter set took from what was learnt, one line per key: restarted from the
    operator's value (set explicitly), or no longer estimated (its learnt value in use
    ``old_values[key]`` dropped for the operator's)."""
    notes = []
    values = new.applied_values()
    for key in old.layout.keys:
        a, b = old.layout.span(key), new.layout.span(key)
        if key in names and key in new.layout.keys:
            notes.append(f'{key} set to {format_value(values[key])}: its estimate restarts '
                         'there (its nominal value, the prior)')
        elif key in names or b[1] - b[0] < a[1] - a[0]:
            what = 'no longer estimated' if key not in new.layout.keys else \
                'fewer orders estimated'
            notes.append(f'{key} {what}: the learnt {format_value(old_values[key])} '
                         'dropped for the declared value')
    return notes


def format_value(v: Any) -> str:
    """A value in use or estimated, for a log line or a status."""
    if isinstance(v, list):
        return '[' + ', '.join(f'{x:.4g}' for x in v) + ']'
    return f'{v:.6g}'
