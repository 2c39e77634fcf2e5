# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Study cases: the paper's Sec. 4 parametric studies (Figs. 12-18), sweeps of any parameter,
and the worst case over a ``--compare`` family.  Pure logic: no running, no plotting."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..config.usable import Config

__all__ = ['Case', 'Study', 'PAPER_STUDIES', 'paper_study', 'param_study', 'module_overrides',
           'parse_values', 'envelope_rows', 'ENVELOPE_COLUMNS', 'COMPARE_SEP']


# ---- cases and studies -------------------------------------------------------------------
@dataclass(frozen=True)
class Case:
    """One run of a study: the base config plus dotted ``overrides``."""

    study: str
    series: str            # one line/bar group of the figure
    x: float               # abscissa (numeric; categorical studies use the index)
    label: str             # human-readable value, e.g. 'G x 10'
    overrides: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Study:
    """A named list of cases plus what the figure needs."""

    name: str
    title: str
    x_label: str
    cases: tuple[Case, ...]
    x_log: bool = False
    categorical: bool = False
    note: str = ''
    paper_figure: str = ''


# Table 1 geometry at module M2 (what the module study scales).
_M_REF = 2.0
_MODULE_SCALED = ('geometry.worm_pitch_radius', 'geometry.gear_pitch_radius', 'geometry.lead',
                  'geometry.worm_length', 'geometry.gear_width')


def module_overrides(base: Config, module: float, scaling: str = 'geometry') -> dict[str, Any]:
    """Overrides that turn the base (M2) drive into module ``module``.

    ``scaling='geometry'``: a geometrically similar worm set.  The worm and gear pitch radii,
    the lead (pi M per revolution) and the worm/gear body lengths scale with M/2, so the
    ratio (1:56), the lead angle and the pressure angle are unchanged; the tooth stiffnesses
    scale with M (``geometry.module``, the M factor of Eqs. 16-17);
    inertias J_w, J_g grow as M^5 (solid cylinders).  Shafts, bearings and flywheel are
    unchanged (they are the radar's, not the gear set's).

    ``scaling='stiffness'``: only the tooth stiffnesses scale with M (the reading of the
    paper's Sec. 4.2: "when the modulus of gear is larger ... the rigidity of the teeth is
    larger"); geometry and inertias stay at M2.
    """
    if scaling not in ('geometry', 'stiffness'):
        raise ValueError(f'module scaling must be geometry or stiffness, got {scaling!r}')
    if not module > 0:
        raise ValueError(f'module must be > 0, got {module!r}')
    f = module / _M_REF
    flat = base.to_flat_dict()
    # tooth stiffness scales with geometry.module itself (the M of Eqs. 16-17)
    out: dict[str, Any] = {'geometry.module': float(module)}
    if scaling == 'geometry':
        for key in _MODULE_SCALED:
            out[key] = flat[key] * f
    return out


def _g_cases(study: str, series: str, keys: Sequence[str], base: Config,
             factors: Sequence[float]) -> list[Case]:
    flat = base.to_flat_dict()
    out = []
    for fac in factors:
        ov = {k: flat[k] * fac for k in keys}
        out.append(Case(study, series, float(fac), f'x{fac:g}', ov))
    return out


SHEAR_FACTORS = (0.25, 0.5, 1.0, 2.0, 5.0, 10.0, 100.0, 1000.0, 10000.0)
TOOTH_FACTORS = (0.25, 0.5, 1.0, 2.0, 4.0, 10.0, 100.0)
FLYWHEEL_RADII = tuple(round(0.01 * k, 2) for k in range(2, 17))   # 0.02 ... 0.16 m
MODULES = (1.0, 2.0, 3.0, 4.0, 5.0)
FRICTION_FACTORS = (0.0, 0.5, 1.0, 1.5, 2.0, 3.0)
CONSTANT_MU = (0.0, 0.05, 0.1, 0.145, 0.2, 0.3, 0.45)


def paper_study(name: str, base: Config) -> Study:
    """The paper's Sec. 4 studies, by name (see :data:`PAPER_STUDIES`)."""
    cases: Sequence[Case]
    if name == 'flywheel':
        cases = (Case(name, 'flywheel', 0.0, 'without', {'geometry.flywheel_enabled': False}),
                 Case(name, 'flywheel', 1.0, 'with', {'geometry.flywheel_enabled': True}))
        return Study(name, 'Flywheel off / on (paper Figs. 12-13)', 'flywheel', cases,
                     categorical=True, paper_figure='Figs. 12-13',
                     note='without the flywheel the massless gear shaft ends free: theta4 is its '
                          'end, J_4 = 0 unless geometry.shaft_end_inertia or '
                          'shafts.gear_shaft_inertia_fraction is set (derived.derive)')
    if name == 'flywheel_diameter':
        cases = tuple(Case(name, 'flywheel diameter', 2 * r, f'D={2 * r:g} m',
                           {'geometry.flywheel_enabled': True, 'geometry.flywheel_radius': r})
                      for r in FLYWHEEL_RADII)
        return Study(name, 'Flywheel diameter (paper Fig. 14; Table 1: D = 0.24 m)',
                     'flywheel diameter 2 R5 [m]', cases, paper_figure='Fig. 14',
                     note='flywheel length L5 = 0.03 m kept; J_4 grows as D^4')
    if name == 'module':
        module_cases: list[Case] = []
        for scaling, series in (('geometry', 'similar gear set (r_w r_g lead L2 L3 k ~ M)'),
                                ('stiffness', 'tooth stiffness only (k ~ M)')):
            for m in MODULES:
                module_cases.append(Case(name, series, m, f'M{m:g}',
                                         module_overrides(base, m, scaling)))
        return Study(name, 'Module M1-M5 (paper Fig. 15)', 'module M [mm]', tuple(module_cases),
                     paper_figure='Fig. 15',
                     note='see module_overrides(): shafts, bearings and flywheel unchanged')
    if name == 'shear_modulus':
        w, g = 'materials.worm_shaft_shear_modulus', 'materials.gear_shaft_shear_modulus'
        cases = (_g_cases(name, 'both shafts (paper)', (w, g), base, SHEAR_FACTORS)
                 + _g_cases(name, 'worm shaft only', (w,), base, SHEAR_FACTORS)
                 + _g_cases(name, 'gear shaft only', (g,), base, SHEAR_FACTORS))
        return Study(name, 'Shaft shear modulus up to rigid (paper Fig. 16)',
                     'G / 77 GPa', tuple(cases), x_log=True, paper_figure='Fig. 16',
                     note='x 10000 is rigid for this drive (shaft modes above 800 kHz)')
    if name == 'tooth_stiffness':
        w, g = 'mesh.worm_tooth_stiffness_multiplier', 'mesh.gear_tooth_stiffness_multiplier'
        cases = (_g_cases(name, 'both teeth (paper)', (w, g), base, TOOTH_FACTORS)
                 + _g_cases(name, 'worm tooth only', (w,), base, TOOTH_FACTORS)
                 + _g_cases(name, 'gear tooth only', (g,), base, TOOTH_FACTORS))
        return Study(name, 'Tooth stiffness multiplier (paper Fig. 17)',
                     'tooth stiffness multiplier', tuple(cases), x_log=True,
                     paper_figure='Fig. 17')
    if name == 'friction':
        flat = base.to_flat_dict()
        mk, md = flat['friction.mu_kinetic'], flat['friction.mu_stribeck_drop']
        friction_cases: list[Case] = []
        for f in FRICTION_FACTORS:
            friction_cases.append(Case(name, 'Eq. 18 scaled', (mk + md) * f, f'Eq.18 x{f:g}',
                                       {'friction.model': 'stribeck',
                                        'friction.mu_kinetic': mk * f,
                                        'friction.mu_stribeck_drop': md * f}))
        for mu in CONSTANT_MU:
            friction_cases.append(Case(name, 'constant mu', mu, f'mu={mu:g}',
                                       {'friction.model': 'constant',
                                        'friction.constant_coefficient': mu}))
        return Study(name, 'Friction coefficient (paper Fig. 18)',
                     'friction coefficient at rest mu(0)', tuple(friction_cases),
                     paper_figure='Fig. 18',
                     note='Eq. 18 scaled: mu_kinetic and mu_stribeck_drop times a factor; '
                          'x = mu(0) = factor x 0.1527')
    raise ValueError(f'unknown study {name!r}; known: {", ".join(PAPER_STUDIES)}')


PAPER_STUDIES: tuple[str, ...] = ('flywheel', 'flywheel_diameter', 'module', 'shear_modulus',
                                  'tooth_stiffness', 'friction')


def parse_values(text: str | None = None, range_spec: str | None = None,
                 log: bool = False) -> list[str]:
    """Values of a user sweep: 'a,b,c' or a range 'start:stop:num' (linear or log spaced);
    returned as strings (typed per parameter by the caller)."""
    if (text is None) == (range_spec is None):
        raise ValueError('give exactly one of --values and --range')
    if text is not None:
        vals = [v.strip() for v in text.split(',')]
        if not vals or any(v == '' for v in vals):
            raise ValueError(f'--values: empty entry in {text!r}')
        return vals
    assert range_spec is not None
    parts = range_spec.split(':')
    if len(parts) != 3:
        raise ValueError(f'--range must be start:stop:num, got {range_spec!r}')
    try:
        a, b, n = float(parts[0]), float(parts[1]), int(parts[2])
    except ValueError:
        raise ValueError(f'--range must be start:stop:num with numbers, got {range_spec!r}') \
            from None
    if n < 1 or n > 100000:
        raise ValueError(f'--range: num must be 1..100000, got {n}')
    if not (math.isfinite(a) and math.isfinite(b)):
        raise ValueError('--range: start and stop must be finite')
    if log:
        if a <= 0 or b <= 0:
            raise ValueError('--log range needs start and stop > 0')
        xs = np.geomspace(a, b, n)
    else:
        xs = np.linspace(a, b, n)
    return [repr(float(x)) for x in xs]


def param_study(paths: Sequence[str], values: Sequence[Any], labels: Sequence[str] | None = None,
                name: str = 'custom') -> Study:
    """A user sweep: every path in ``paths`` set to each value in turn (typed values)."""
    if not paths:
        raise ValueError('no parameter path given')
    labels = list(labels) if labels is not None else [str(v) for v in values]
    numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)
    cases = []
    for i, (v, lab) in enumerate(zip(values, labels)):
        x = float(v) if numeric else float(i)
        cases.append(Case(name, ' = '.join(paths) if len(paths) > 1 else paths[0], x, lab,
                          {p: v for p in paths}))
    positive = numeric and all(float(v) > 0 for v in values)
    spread = numeric and positive and max(values) / min(values) >= 100
    return Study(name, f'Sweep of {", ".join(paths)}', ', '.join(paths), tuple(cases),
                 x_log=bool(spread), categorical=not numeric)


COMPARE_SEP = ' | '
ENVELOPE_COLUMNS: tuple[str, ...] = ('study', 'series', 'label', 'x', 'amp2', 'amp4',
                                     'amp2_at', 'amp4_at', 'cases')


def envelope_rows(rows: Sequence[Mapping[str, Any]], sep: str = COMPARE_SEP) -> list[dict]:
    """Worst case over a ``--compare`` family: rows whose series read ``'<base> | k=v'`` are
    grouped by (base series, label) and reduced to the maximum amplitudes, with the compared
    value that produced each maximum (``amp2_at``, ``amp4_at``).  Rows of failed cases
    (an ``error``) are left out."""
    groups: dict[tuple[str, str], list[Mapping[str, Any]]] = {}
    for r in rows:
        if r.get('error'):
            continue
        base, _, tag = str(r['series']).partition(sep)
        groups.setdefault((base, str(r['label'])), []).append({**r, '_tag': tag})
    out = []
    for (base, label), rs in groups.items():
        i2 = max(range(len(rs)), key=lambda i: rs[i]['amp2'])
        i4 = max(range(len(rs)), key=lambda i: rs[i]['amp4'])
        out.append({'study': rs[0]['study'], 'series': base, 'label': label, 'x': rs[0]['x'],
                    'amp2': rs[i2]['amp2'], 'amp4': rs[i4]['amp4'],
                    'amp2_at': rs[i2]['_tag'], 'amp4_at': rs[i4]['_tag'], 'cases': len(rs)})
    return out
