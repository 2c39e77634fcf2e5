# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The whole parameter set of the worm-gear drive, typed, immutable and checked.

This module contains :class:`Parameters` (one section of :mod:`.sections` each), its
checks per field and across fields (:func:`validate`, :func:`cross_checks`), the sections
built from a mapping (:func:`sections_from_mapping`) and a checked copy with changes
(:func:`replaced`).  Users build its subclass :class:`worm_gear_sim.config.usable.Config`.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any, TypeVar

from .sections import (
    ADAPTABLE_KEYS,
    ERROR_SLOPE_LIMIT,
    MAX_ERROR_ORDERS,
    SECTIONS,
    AdaptationSettings,
    CompensationSettings,
    Damping,
    Friction,
    Geometry,
    InputProfile,
    Integrator,
    Load,
    Materials,
    Mesh,
    NodeSettings,
    Shafts,
)
from .validation import ConfigError, coerce, field_default, suggest

__all__ = ['Parameters', 'sections_from_mapping', 'validate', 'replaced', 'cross_checks']

P = TypeVar('P', bound='Parameters')


@dataclass(frozen=True)
class Parameters:
    """The whole parameter set; immutable; checked per field and across fields.  Users build
    :class:`worm_gear_sim.config.usable.Config` (this plus the usable check of its builders)."""

    geometry: Geometry = field(default_factory=Geometry)
    materials: Materials = field(default_factory=Materials)
    shafts: Shafts = field(default_factory=Shafts)
    mesh: Mesh = field(default_factory=Mesh)
    friction: Friction = field(default_factory=Friction)
    damping: Damping = field(default_factory=Damping)
    load: Load = field(default_factory=Load)
    integrator: Integrator = field(default_factory=Integrator)
    input: InputProfile = field(default_factory=InputProfile)
    node: NodeSettings = field(default_factory=NodeSettings)
    compensation: CompensationSettings = field(default_factory=CompensationSettings)
    adaptation: AdaptationSettings = field(default_factory=AdaptationSettings)

    def __post_init__(self) -> None:
        validate(self)

    def to_flat_dict(self) -> dict[str, Any]:
        """Dotted names (``'mesh.stiffness_model'``) to values, in declaration order."""
        out: dict[str, Any] = {}
        for sec in SECTIONS:
            obj = getattr(self, sec)
            for f in fields(obj):
                v = getattr(obj, f.name)
                out[f'{sec}.{f.name}'] = list(v) if isinstance(v, tuple) else v
        return out

    def to_nested_dict(self) -> dict[str, dict[str, Any]]:
        """Sections to plain dicts (for JSON/YAML)."""
        nested: dict[str, dict[str, Any]] = {}
        for key, v in self.to_flat_dict().items():
            sec, name = key.split('.', 1)
            nested.setdefault(sec, {})[name] = v
        return nested

    @staticmethod
    def metadata() -> dict[str, dict[str, Any]]:
        """Dotted name -> field metadata (description, unit, lo, hi, choices, ...)."""
        out = {}
        for sec, cls in SECTIONS.items():
            for f in fields(cls):
                out[f'{sec}.{f.name}'] = dict(f.metadata)
        return out


def sections_from_mapping(data: Mapping[str, Any], source: str = '<mapping>',
                          strict: bool = False) -> dict[str, Any]:
    """The section objects (``{'mesh': Mesh(...), ...}``) of nested sections (the
    ``ros__parameters`` content) or dotted keys, each value checked and coerced per field
    (``strict``: as a params file, :func:`~worm_gear_sim.schema.validation.coerce`);
    :class:`ConfigError` names an unknown section or key (with the closest valid name)."""
    if not isinstance(data, Mapping):
        raise ConfigError('', f'{source}: parameters must be a mapping, got {type(data).__name__}')
    nested: dict[str, dict[str, Any]] = {}
    for key, value in data.items():
        if not isinstance(key, str):
            raise ConfigError(str(key), 'parameter names must be strings')
        if '.' in key:  # dotted form, as ROS would flatten it
            sec, _, name = key.partition('.')
            nested.setdefault(sec, {})[name] = value
        elif isinstance(value, Mapping):
            nested.setdefault(key, {}).update(value)
        else:
            raise ConfigError(key, 'unknown parameter' + suggest(key, SECTIONS)
                              + f' (top level holds the sections {", ".join(SECTIONS)})')
    known = Parameters.metadata()
    kwargs: dict[str, Any] = {}
    for sec, values in nested.items():
        if sec not in SECTIONS:
            raise ConfigError(sec, 'unknown section' + suggest(sec, SECTIONS))
        cls = SECTIONS[sec]
        names = {f.name: f for f in fields(cls)}
        sec_kwargs = {}
        for name, value in values.items():
            key = f'{sec}.{name}'
            if name not in names:
                raise ConfigError(key, 'unknown parameter' + suggest(key, known))
            f = names[name]
            default = field_default(f)
            sec_kwargs[name] = coerce(key, value, default, f.metadata, strict)
        kwargs[sec] = cls(**sec_kwargs)
    return kwargs


def validate(cfg: Parameters) -> None:
    """Per-field checks (types, finiteness, ranges, choices) of every section of ``cfg`` and
    the cross-field checks; raises :class:`ConfigError` naming the key."""
    for section in fields(cfg):
        sec = section.name
        obj = getattr(cfg, sec)
        for f in fields(obj):
            key = f'{sec}.{f.name}'
            default = field_default(f)
            coerce(key, getattr(obj, f.name), default, f.metadata)
    cross_checks(cfg)


def replaced(cfg: P, changes: Mapping[str, Any]) -> P:
    """A copy of the validated ``cfg`` with the dotted-key ``changes``: each changed value
    checked and coerced by its field's rule (:func:`coerce`, as :func:`sections_from_mapping`
    does, in declaration order: the same error), then the cross-field checks; the unchanged
    fields, checked when ``cfg`` was built, are not checked again.  An unknown key raises
    :class:`ConfigError` (the first in ``changes`` order)."""
    table = _field_table()
    for key in changes:
        if key not in table:
            raise ConfigError(key, 'unknown parameter' + suggest(key, table))
    per_section: dict[str, dict[str, Any]] = {}
    for key in sorted(changes, key=lambda k: table[k][0]):
        _, sec, f = table[key]
        per_section.setdefault(sec, {})[f.name] = coerce(key, changes[key], field_default(f),
                                                         f.metadata)
    new = copy.copy(cfg)                 # no __post_init__: the sections are set below
    for sec, values in per_section.items():
        object.__setattr__(new, sec, dataclasses.replace(getattr(cfg, sec), **values))
    cross_checks(new)
    return new


_FIELD_TABLE: dict[str, tuple[int, str, Any]] = {}


def _field_table() -> dict[str, tuple[int, str, Any]]:
    """Dotted name -> (declaration rank, section, dataclass field)."""
    if not _FIELD_TABLE:
        for sec, cls in SECTIONS.items():
            for f in fields(cls):
                _FIELD_TABLE[f'{sec}.{f.name}'] = (len(_FIELD_TABLE), sec, f)
    return _FIELD_TABLE


def cross_checks(cfg: Parameters) -> None:
    """The checks across fields of a set whose every field is valid; raises
    :class:`ConfigError` naming the key."""
    integ = cfg.integrator
    if not (2.0 * integ.newmark_beta >= integ.newmark_gamma - 1e-15):
        raise ConfigError('integrator.newmark_beta', f'{integ.newmark_beta:g} with gamma '
                          f'{integ.newmark_gamma:g} is only conditionally stable: need '
                          '2*beta >= gamma >= 1/2')
    inp = cfg.input
    if inp.profile in ('trapezoidal', 's_curve') and 2.0 * inp.accel_time > inp.move_time:
        raise ConfigError('input.accel_time', f'2*accel_time ({2 * inp.accel_time:g} s) must '
                          f'not exceed move_time ({inp.move_time:g} s)')
    if inp.profile == 'csv' and not inp.csv_path:
        raise ConfigError('input.csv_path', 'is required when input.profile is csv')
    g = cfg.geometry
    if g.lead_angle == 0.0 and g.lead / (2 * math.pi) >= g.worm_pitch_radius:
        raise ConfigError('geometry.lead', 'lead/2pi must be smaller than the worm pitch radius')
    if g.gear_pitch_radius <= 0 or g.lead <= 0:  # pragma: no cover - range checks catch it
        raise ConfigError('geometry.lead', 'must be > 0')
    half_pitch = 0.5 * g.lead / g.gear_pitch_radius     # pi / z_g, z_g = 2 pi r_g / lead
    if cfg.mesh.backlash >= half_pitch:
        raise ConfigError('mesh.backlash', f'{float(cfg.mesh.backlash)!r} rad is more play '
                          f'than a tooth pitch allows: it must be less than half the gear '
                          f'pitch, 0.5 geometry.lead / geometry.gear_pitch_radius = 0.5 * '
                          f'{g.lead!r} / {g.gear_pitch_radius!r} = {half_pitch!r} rad')
    for key in ('worm_error_harmonics', 'gear_error_harmonics'):
        coeffs = getattr(cfg.mesh, key)
        if len(coeffs) % 2:
            raise ConfigError(f'mesh.{key}', f'needs pairs [s1, c1, s2, c2, ...]: got an odd '
                              f'number of entries ({len(coeffs)})')
        if len(coeffs) > 2 * MAX_ERROR_ORDERS:
            raise ConfigError(f'mesh.{key}', f'at most {MAX_ERROR_ORDERS} orders '
                              f'({2 * MAX_ERROR_ORDERS} entries), got {len(coeffs)} entries')
        # bound of |de/dtheta|: sum_k k sqrt(s_k^2 + c_k^2)
        slope = sum((k + 1) * math.hypot(coeffs[2 * k], coeffs[2 * k + 1])
                    for k in range(len(coeffs) // 2))
        if key == 'worm_error_harmonics' and slope > 0.0:
            l_w = g.lead / (2.0 * math.pi) if g.lead_convention == 'kinematic' else g.lead
            slope = slope * g.gear_pitch_radius / l_w if l_w > 0.0 else math.inf
        if slope > ERROR_SLOPE_LIMIT:
            raise ConfigError(f'mesh.{key}', f'too steep: its slope bound sum_k k |a_k| '
                              f'{"r_g / l_w " if key[0] == "w" else ""}is {slope:.3g}, at most '
                              f'{ERROR_SLOPE_LIMIT:g} (the error must stay a small '
                              'correction of the ratio)')
    bad = [k for k in cfg.adaptation.keys if k not in ADAPTABLE_KEYS]
    if bad:
        raise ConfigError('adaptation.keys', f'{", ".join(bad)} cannot be adapted: choose from '
                          f'{", ".join(ADAPTABLE_KEYS)}')
    if cfg.adaptation.enabled and not cfg.adaptation.keys:
        raise ConfigError('adaptation.keys', 'is empty while adaptation.enabled is true: '
                          f'name at least one of {", ".join(ADAPTABLE_KEYS)}')
    if cfg.integrator.time_step * cfg.node.publish_rate_hz > 1.0 + 1e-9:
        raise ConfigError('integrator.time_step', 'must not exceed the node tick period '
                          f'1/publish_rate_hz = {1.0 / cfg.node.publish_rate_hz:g} s')
    if cfg.node.max_catch_up * cfg.node.publish_rate_hz < 1.0 - 1e-9:
        # below one tick period the physics falls behind every tick and never catches up
        raise ConfigError('node.max_catch_up', f'{cfg.node.max_catch_up:g} s must be at least '
                          f'the tick period 1/publish_rate_hz = '
                          f'{1.0 / cfg.node.publish_rate_hz:g} s')
