# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Validation of parameter values: the one "type from the default" rule (:func:`value_kind`),
the per-field checks (type, finiteness, range, choices, length) against a field's metadata,
and the one rule for a name that is not a parameter of the model (:func:`unknown_name`).
The cross-field checks of a whole set are the schema's (:mod:`~worm_gear_sim.schema.sections`,
``validate``), which calls these per field.

Whether a valid set can also be *simulated* is a separate question, answered by the model
itself: :mod:`worm_gear_sim.dynamics.usability`.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
from collections.abc import Iterable, Mapping
from typing import Any

__all__ = ['ConfigError', 'suggest', 'VALUE_KINDS', 'value_kind', 'field_default', 'coerce',
           'unknown_name', 'ForeignParameterWarning']


class ConfigError(ValueError):
    """An invalid parameter value or configuration file; ``key`` names the bad parameter,
    ``keys`` every parameter blamed (a whole-set rule of
    :mod:`~worm_gear_sim.dynamics.usability` may name several)."""

    def __init__(self, key: str, message: str, keys: Iterable[str] = ()) -> None:
        self.key = key
        self.keys: tuple[str, ...] = tuple(keys) or ((key,) if key else ())
        self.reason = message
        super().__init__(f'{key}: {message}' if key else message)



class ForeignParameterWarning(UserWarning):
    """A parameter name unlike every one of the model's, ignored: another node's key in a
    ``/**`` block shared by several nodes (:func:`unknown_name`)."""


def unknown_name(name: str, known: Iterable[str], sections: Iterable[str]
                 ) -> ConfigError | None:
    """The one rule for a name that is not a parameter of the model, in a params file the
    command line reads (:func:`~worm_gear_sim.config.files.load_config`) and in the parameters
    the node is given (a params file, ``-p``).  A dotted name (every parameter of the package
    is ``section.key``) is an error: a key unknown in one of the sections, or an unknown
    section (``adaptaton.enabled``: ignored, the user would believe a setting applied that
    is not); so is a plain name close to one of ours.  A plain name unlike any of ours is
    another node's key in a ``/**`` block shared by several nodes (``use_sim_time``-like):
    None, the caller ignores it with a warning (:class:`ForeignParameterWarning`)."""
    known, sections = list(known), list(sections)
    head, dot, _ = name.partition('.')
    if dot:
        if head in sections:
            return ConfigError(name, 'unknown parameter' + suggest(name, known))
        return ConfigError(name, f'unknown section {head!r}'
                           + (suggest(name, known) or suggest(head, sections))
                           + f' (the sections: {", ".join(sections)})')
    if name in sections:
        return ConfigError(name, 'is a section: give it a mapping of its parameters')
    close = suggest(name, known) or suggest(name, sections)
    if close:
        return ConfigError(name, 'unknown parameter' + close)
    return None


def suggest(key: str, known: Iterable[str]) -> str:
    """`` (did you mean x?)`` for a mistyped name among ``known``, or ''."""
    close = difflib.get_close_matches(key, list(known), n=1, cutoff=0.6)
    return f' (did you mean {close[0]}?)' if close else ''


#: The parameter kinds; a parameter's kind is the type of its default (:func:`value_kind`).
VALUE_KINDS = ('bool', 'int', 'float', 'str', 'str_list', 'float_list')


def value_kind(default: Any) -> str:
    """The kind of a parameter, from its default: the one typing rule of the YAML loader,
    ``--set`` parsing (:mod:`worm_gear_sim.config.files`) and the node's ROS parameters."""
    if isinstance(default, bool):
        return 'bool'
    if isinstance(default, int):
        return 'int'
    if isinstance(default, float):
        return 'float'
    if isinstance(default, str):
        return 'str'
    if isinstance(default, (tuple, list)):
        return 'str_list' if default and isinstance(default[0], str) else 'float_list'
    raise TypeError(f'unsupported parameter default {default!r}')


def field_default(f: dataclasses.Field) -> Any:
    """The default of a dataclass field (given, or made by its factory)."""
    if f.default is not dataclasses.MISSING:
        return f.default
    factory = f.default_factory
    if not callable(factory):
        raise TypeError(f'field {f.name} has no default')
    return factory()


#: Why a params file must write a value as its parameter's type (strict coercion).
_AS_THE_NODE = 'a params file types a value as written; the node refuses another type'


def coerce(key: str, value: Any, default: Any, meta: Mapping[str, Any],
           strict: bool = False) -> Any:
    """Type-check one value against its field's kind (:func:`value_kind`) and metadata.
    Lenient (``strict`` False: Python values, ``--set`` literals): an integer for a float,
    an integral float for an integer.  ``strict`` (a YAML params file, the node's rule):
    neither, with the value to write instead."""
    kind = value_kind(default)
    if kind == 'bool':
        if not isinstance(value, bool):
            raise ConfigError(key, f'must be true or false, got {value!r}')
        return value
    if kind == 'int':
        if isinstance(value, bool) or not isinstance(value, int):
            if isinstance(value, float) and value.is_integer() and not strict:
                value = int(value)
            elif isinstance(value, float) and value.is_integer():
                raise ConfigError(key, f'must be an integer, got the float {value!r}: write '
                                  f'{int(value)} ({_AS_THE_NODE})')
            else:
                raise ConfigError(key, f'must be an integer, got {value!r}')
        _check_range(key, float(value), meta)
        return value
    if kind == 'float':
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(key, f'must be a number, got {value!r}')
        if strict and isinstance(value, int):
            raise ConfigError(key, f'must be a floating-point number, got the integer '
                              f'{value!r}: write {value}.0 ({_AS_THE_NODE})')
        value = float(value)
        _check_range(key, value, meta)
        return value
    if kind == 'str':
        if not isinstance(value, str):
            raise ConfigError(key, f'must be a string, got {value!r}')
        if meta.get('choices') and value not in meta['choices']:
            raise ConfigError(key, f'must be one of {", ".join(meta["choices"])}; got {value!r}')
        return value
    if kind in ('str_list', 'float_list'):
        if isinstance(value, (str, bytes)) or not hasattr(value, '__iter__'):
            raise ConfigError(key, f'must be a list, got {value!r}')
        value = tuple(value)
        if meta.get('length') is not None and len(value) != meta['length']:
            raise ConfigError(key, f'must have {meta["length"]} entries, got {len(value)}')
        if kind == 'str_list':
            if not all(isinstance(v, str) and v for v in value):
                raise ConfigError(key, 'entries must be non-empty strings')
            if len(set(value)) != len(value):
                raise ConfigError(key, 'entries must be unique')
            return value
        out = []
        for i, v in enumerate(value):
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise ConfigError(key, f'entry {i} must be a number, got {v!r}')
            if strict and isinstance(v, int):
                raise ConfigError(key, f'entry {i} must be a floating-point number, got the '
                                  f'integer {v!r}: write {v}.0 ({_AS_THE_NODE})')
            _check_range(f'{key}[{i}]', float(v), meta)
            out.append(float(v))
        return tuple(out)
    raise ConfigError(key, f'unsupported type {type(default).__name__}')  # pragma: no cover


def _check_range(key: str, value: float, meta: Mapping[str, Any]) -> None:
    if not math.isfinite(value):
        raise ConfigError(key, f'must be finite, got {value!r}')
    lo, hi = meta.get('lo'), meta.get('hi')
    if lo is not None:
        if meta.get('lo_open') and value <= lo:
            raise ConfigError(key, f'must be > {lo:g}, got {value!r}')
        if value < lo:
            raise ConfigError(key, f'must be >= {lo:g}, got {value!r}')
    if hi is not None and value > hi:
        raise ConfigError(key, f'must be <= {hi:g}, got {value!r}')
