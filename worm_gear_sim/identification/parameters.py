# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The fitted quantities: ``--fit`` keys resolved against the base config, their bounds and
the normalised coordinate x the search works in (``log(value / base)`` for positive
quantities, ``(value - base) / scale`` otherwise)."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..config.usable import Config
from ..schema.validation import suggest
from .data import IdentificationError

__all__ = ['FITTABLE_SECTIONS', 'FitParameter', 'fit_parameters', 'apply_values']

#: Sections that describe the drive itself (integrator, input, node, compensation do not).
FITTABLE_SECTIONS: tuple[str, ...] = ('geometry', 'materials', 'shafts', 'mesh', 'friction',
                                      'damping', 'load')
_KEY_RE = re.compile(r'^([a-z_]+\.[a-z0-9_]+)(?:\[(\d+)\])?$')


@dataclass(frozen=True)
class FitParameter:
    """One fitted quantity: a numeric parameter key (``damping.modal_damping_ratios[0]`` for an
    entry of a list), its base value, physical bounds and normalised coordinate x."""

    key: str
    path: str
    index: int | None
    base: float
    lo: float
    hi: float
    log: bool
    scale: float        # linear keys: x = (value - base) / scale
    unit: str
    box: tuple[float, float]   # multi-start box in x

    def to_x(self, value: float) -> float:
        if self.log:
            return math.log(value / self.base)
        return (value - self.base) / self.scale

    def from_x(self, x: float) -> float:
        if self.log:
            return self.base * math.exp(min(x, 700.0))   # an interval may be unbounded
        return self.base + x * self.scale

    @property
    def x_bounds(self) -> tuple[float, float]:
        if self.log:
            lo = math.log(self.lo / self.base) if self.lo > 0 else -np.inf
            hi = math.log(self.hi / self.base) if math.isfinite(self.hi) else np.inf
            return lo, hi
        return (self.to_x(self.lo) if math.isfinite(self.lo) else -np.inf,
                self.to_x(self.hi) if math.isfinite(self.hi) else np.inf)


def fit_parameters(base: Config, keys: Sequence[str],
                   bounds: Mapping[str, tuple[float, float]] | None = None,
                   start_factor: float = 2.0) -> list[FitParameter]:
    """Resolve the ``--fit`` keys against the base config.  Bounds: the parameter metadata,
    narrowed by ``bounds`` (key -> (lo, hi)).  Positive quantities (lower bound >= 0, base > 0)
    are fitted in log scale; their multi-start box is base / start_factor ... base *
    start_factor (or the given bounds).  Unknown, non-numeric, integer or non-drive keys raise
    IdentificationError."""
    flat = base.to_flat_dict()
    meta = Config.metadata()
    out: list[FitParameter] = []
    bounds = dict(bounds or {})
    if not keys:
        raise IdentificationError('--fit: give at least one parameter key')
    for key in keys:
        key = key.strip()
        m = _KEY_RE.match(key)
        path, idx = (m.group(1), m.group(2)) if m else (key, None)
        if path not in flat:
            raise IdentificationError(f'--fit {key}: unknown parameter' + suggest(path, flat))
        sec = path.split('.', 1)[0]
        if sec not in FITTABLE_SECTIONS:
            raise IdentificationError(f'--fit {key}: not a parameter of the drive (section '
                                      f'{sec}); fittable sections: {", ".join(FITTABLE_SECTIONS)}')
        v, i = _base_value(key, path, idx, flat[path])
        md = meta[path]
        user = bounds.pop(key, None)
        lo, hi, v = _fit_range(key, md, user, v)
        use_log, scale, box = _start_box(lo, hi, v, user is not None, start_factor)
        out.append(FitParameter(key=key, path=path, index=i, base=v, lo=lo, hi=hi,
                                log=use_log, scale=scale, unit=str(md.get('unit', '')),
                                box=(float(box[0]), float(box[1]))))
    if bounds:
        raise IdentificationError(f'--bounds {next(iter(bounds))}: not among the --fit keys')
    if len({p.key for p in out}) != len(out):
        raise IdentificationError('--fit: a key is given twice')
    return out


def _base_value(key: str, path: str, idx: str | None, value: Any
                ) -> tuple[float, int | None]:
    """The base value of a ``--fit`` key and its list index (None for a scalar)."""
    if isinstance(value, list):
        if not value or not all(isinstance(v, float) for v in value):
            raise IdentificationError(f'--fit {key}: not a numeric parameter')
        if idx is None:
            raise IdentificationError(f'--fit {key}: a list of {len(value)} numbers; fit '
                                      f'one entry, e.g. {path}[0]')
        i = int(idx)
        if i >= len(value):
            raise IdentificationError(f'--fit {key}: index out of range (0..'
                                      f'{len(value) - 1})')
        return float(value[i]), i
    if idx is not None:
        raise IdentificationError(f'--fit {key}: {path} is not a list')
    if isinstance(value, bool) or not isinstance(value, float):
        kind = 'an integer setting' if isinstance(value, int) and not \
            isinstance(value, bool) else f'not numeric ({type(value).__name__})'
        raise IdentificationError(f'--fit {key}: {kind}, cannot be fitted')
    return float(value), None


def _fit_range(key: str, md: Mapping[str, Any], user: tuple[float, float] | None,
               v: float) -> tuple[float, float, float]:
    """(lo, hi, base): the parameter's range, narrowed by the user's ``--bounds``; a base
    outside them moves to their middle (geometric when positive)."""
    lo = -np.inf if md.get('lo') is None else float(md['lo'])
    hi = np.inf if md.get('hi') is None else float(md['hi'])
    if md.get('lo_open') and lo == 0.0:
        lo = 0.0
    if user is not None:
        ulo, uhi = float(user[0]), float(user[1])
        if not (ulo < uhi):
            raise IdentificationError(f'--bounds {key}: need LO < HI, got {ulo:g}:{uhi:g}')
        if ulo < lo or uhi > hi:
            raise IdentificationError(f'--bounds {key}: {ulo:g}:{uhi:g} leaves the '
                                      f'parameter range {lo:g}..{hi:g}')
        lo, hi = ulo, uhi
        if not (lo <= v <= hi):
            v = math.sqrt(lo * hi) if lo > 0 else 0.5 * (lo + hi)
    return lo, hi, v


def _start_box(lo: float, hi: float, v: float, given: bool, start_factor: float
               ) -> tuple[bool, float, tuple[float, float]]:
    """(log scale?, scale, multi-start box in x): the fit's coordinate for the parameter."""
    use_log = lo >= 0.0 and v > 0.0
    if use_log:
        scale = 1.0
        if given and lo > 0:
            box = (math.log(lo / v), math.log(hi / v))
        else:
            box = (max(-math.log(start_factor), math.log(lo / v) if lo > 0 else -np.inf),
                   min(math.log(start_factor), math.log(hi / v)))
    else:
        if v != 0.0:
            scale = abs(v)
        elif math.isfinite(hi - lo):
            scale = 0.1 * min(hi - lo, 1.0)
        else:
            scale = 0.1
        if given:
            box = ((lo - v) / scale, (hi - v) / scale)
        else:
            box = (max(-1.0, (lo - v) / scale), min(1.0, (hi - v) / scale))
    return use_log, scale, box


def apply_values(base: Config, params: Sequence[FitParameter],
                 values: Sequence[float]) -> Config:
    """The base config with the fitted values (validated, all or nothing)."""
    flat = base.to_flat_dict()
    changes: dict[str, Any] = {}
    for p, v in zip(params, values):
        if p.index is None:
            changes[p.path] = float(v)
        else:
            lst = list(changes.get(p.path, flat[p.path]))
            lst[p.index] = float(v)
            changes[p.path] = lst
    return base.replace(changes)
