# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Configuration in and out: parameter files, ``--set`` overrides, the resolved-parameters
document.

In: :func:`load_config` (YAML, ROS layout or plain sections), :func:`default_config_path`,
:func:`load_params_json`, :func:`load_any_config`, :func:`typed_value`.  Out:
:func:`params_document`, :func:`params_json_dump`, :func:`params_yaml_text`,
:func:`write_params_yaml`.  Errors are ``ConfigError`` naming the parameter.
"""

from __future__ import annotations

import dataclasses
import json
import math
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml

from .._support.guarded_io import (
    MAX_CONFIG_BYTES,
    GuardedFileError,
    guarded_yaml_load,
    read_text_file,
)
from ..schema.sections import NODE_NAME, SECTIONS
from ..schema.validation import (
    ConfigError,
    ForeignParameterWarning,
    suggest,
    unknown_name,
    value_kind,
)
from .usable import Config, config_from_mapping

__all__ = ['load_config', 'default_config_path', 'PARAMS_FORMAT', 'typed_value', 'parse_set',
           'check_key', 'params_document', 'load_params_json', 'load_any_config',
           'resolve_config', 'params_json_dump', 'params_yaml_text', 'write_params_yaml',
           'read_config_text',
           'safe_yaml_load', 'ROS_RESERVED']

PARAMS_FORMAT = 'worm_gear_sim.config.usable/1'
_RESERVED_JSON_KEYS = ('format', 'derived')

_TRUE = ('true', 'yes', 'on', '1')
_FALSE = ('false', 'no', 'off', '0')


def _matches(key: str, node_name: str) -> bool:
    """Whether a params file's top-level key addresses the node ``node_name`` (in any
    namespace): ``node_name``, ``/node_name``, ``/ns/node_name``, ``/**`` and
    ``/**/node_name`` (the wildcards of rcl's params files)."""
    return key in (node_name, f'/{node_name}', '/**') or key.endswith('/' + node_name)


def _ros_parameters(doc: Any, path: str, node_name: str) -> dict[str, Any]:
    """The parameters (dotted names) a params file gives the node ``node_name``: every block
    addressed to it (:func:`_matches`), merged in file order as rcl does (a later block's
    value wins); plain sections at top level (no ``ros__parameters``) for offline use."""
    if not isinstance(doc, Mapping):
        raise ConfigError('', f'{path}: expected a mapping with "/**: ros__parameters:" (or '
                          f'"{node_name}: ros__parameters:")')
    blocks = [(k, v) for k, v in doc.items() if isinstance(k, str) and _matches(k, node_name)]
    if blocks:
        merged: dict[str, Any] = {}
        for key, block in blocks:
            if not isinstance(block, Mapping) or 'ros__parameters' not in block:
                raise ConfigError(key, f'{path}: "{key}" must hold a "ros__parameters" mapping')
            merged.update(_dotted(block['ros__parameters'] or {}, f'{path}: {key}'))
        return merged
    if 'ros__parameters' in doc:
        raise ConfigError('', f'{path}: put ros__parameters under "/**:" (or "{node_name}:")')
    # Plain sections at top level are accepted for offline use.
    return dict(_dotted(doc, path))


def _dotted(params: Any, where: str) -> list[tuple[str, Any]]:
    """(dotted name, value) of a ``ros__parameters`` mapping: a section's mapping gives
    ``section.key`` names, a plain name stays plain (as rcl flattens a section)."""
    if not isinstance(params, Mapping):
        raise ConfigError('', f'{where}: parameters must be a mapping, got '
                          f'{type(params).__name__}')
    out = []
    for name, value in params.items():
        if not isinstance(name, str):
            raise ConfigError(str(name), 'parameter names must be strings')
        if isinstance(value, Mapping) and name not in ROS_RESERVED:
            out += [(f'{name}.{sub}', v) for sub, v in value.items()]
        else:
            out.append((name, value))
    return out


def load_config(path: str | Path | None = None, overrides: Mapping[str, Any] | None = None,
                node_name: str = NODE_NAME) -> Config:
    """Load a YAML parameter file (ROS layout or plain sections) and validate it as the node
    does: each value of its parameter's type (``5.0``, not ``5``, for a float: strict
    :func:`~worm_gear_sim.schema.validation.coerce`), an unknown dotted name an error, a plain name
    unlike ours ignored with a :class:`~worm_gear_sim.schema.validation.ForeignParameterWarning`
    (:func:`~worm_gear_sim.schema.validation.unknown_name`: the node's rule).  ``overrides``
    (dotted, e.g. ``--set`` values) are applied after, leniently."""
    if path is None:
        path = default_config_path()
    p = Path(path)
    doc = safe_yaml_load(read_config_text(p), str(p))
    if doc is None:
        doc = {}
    params = {}
    for name, value in _ros_parameters(doc, str(p), node_name).items():
        if name.split('.', 1)[0] in ROS_RESERVED:
            continue
        if name not in _MODEL_NAMES:
            err = unknown_name(name, _MODEL_NAMES, SECTIONS)
            if err is not None:
                raise ConfigError(err.key, f'{err.reason} (in {p})')
            warnings.warn(f'{p}: ignoring parameter {name!r}: not a parameter of '
                          f'{node_name} (another node\'s, in a shared block?)',
                          ForeignParameterWarning, stacklevel=2)
            continue
        params[name] = value
    cfg = config_from_mapping(params, source=str(p), strict=True)
    return cfg.replace(overrides) if overrides else cfg


#: Parameters of ROS itself a params file may hold (a name or a section); not the model's:
#: skipped by the loader, never an unknown name for the node.
ROS_RESERVED = frozenset({'use_sim_time', 'qos_overrides', 'diagnostic_updater',
                           'start_type_description_service'})
#: The model's parameters (dotted names).
_MODEL_NAMES = frozenset(Config().to_flat_dict())


def default_config_path() -> Path:
    """The package's default YAML: source tree, or installed share/worm_gear_sim/config."""
    here = Path(__file__).resolve().parent
    candidates = [here.parents[1] / 'config' / 'worm_gear_sim.yaml',   # this is <package>/config
                  here / 'worm_gear_sim.yaml']
    import sys
    candidates.append(Path(sys.prefix) / 'share' / 'worm_gear_sim' / 'config'
                      / 'worm_gear_sim.yaml')
    for c in candidates:
        if c.is_file():
            return c
    return candidates[0]


def check_key(key: str) -> Any:
    """The default of the dotted parameter ``key``; ConfigError for an unknown key."""
    defaults = Config().to_flat_dict()
    if key not in defaults:
        raise ConfigError(key, 'unknown parameter' + suggest(key, list(defaults)))
    return defaults[key]


def typed_value(key: str, raw: str, default: Any) -> Any:
    """Parse a command-line string for the parameter ``key`` by its kind (the type of its
    default, :func:`~worm_gear_sim.config.usable.value_kind`)."""
    text = raw.strip()
    kind = value_kind(default)
    if kind == 'bool':
        if text.lower() in _TRUE:
            return True
        if text.lower() in _FALSE:
            return False
        raise ConfigError(key, f'must be true or false, got {raw!r}')
    if kind == 'int':
        try:
            return int(text)
        except ValueError:
            try:
                f = float(text)
            except ValueError:
                raise ConfigError(key, f'must be an integer, got {raw!r}') from None
            if not f.is_integer():
                raise ConfigError(key, f'must be an integer, got {raw!r}') from None
            return int(f)
    if kind == 'float':
        try:
            return float(text)
        except ValueError:
            raise ConfigError(key, f'must be a number, got {raw!r}') from None
    if kind in ('str_list', 'float_list'):
        inner = text[1:-1] if text.startswith('[') and text.endswith(']') else text
        items = [s.strip().strip('\'"') for s in inner.split(',')] if inner.strip() else []
        if kind == 'str_list':
            return items
        out = []
        for i, s in enumerate(items):
            try:
                out.append(float(s))
            except ValueError:
                raise ConfigError(f'{key}[{i}]', f'must be a number, got {s!r}') from None
        return out
    return raw


def parse_set(items: Sequence[str] | None) -> dict[str, Any]:
    """``['mesh.stiffness_model=linear', ...]`` -> typed dotted overrides (unknown keys and
    malformed items raise ConfigError)."""
    out: dict[str, Any] = {}
    for item in items or ():
        key, sep, raw = item.partition('=')
        key = key.strip()
        if not sep or not key:
            raise ConfigError('', f'--set {item!r}: expected KEY=VALUE, e.g. '
                              'mesh.stiffness_model=linear')
        out[key] = typed_value(key, raw, check_key(key))
    return out


def params_document(cfg: Config) -> dict[str, Any]:
    """The fully resolved parameters: every config section plus a ``derived`` block
    (inertias, stiffnesses, lead per radian, ratio, mesh calibration, back-drive margin at
    rest, linear modes)."""
    from ..dynamics.modal import modes
    from ..dynamics.model import DriveModel
    doc: dict[str, Any] = {'format': PARAMS_FORMAT}
    doc.update(cfg.to_nested_dict())
    model = DriveModel(cfg)
    d = dataclasses.asdict(model.derived)
    d['worm_contact_origin_deg'], d['gear_contact_origin_deg'] = model.contact_origins_deg
    d['backdrive_margin'] = model.backdrive_margin()     # at rest: > 1 self-locking
    try:
        d['natural_frequencies_hz'] = [float(f) for f in modes(model).undamped_hz]
    except Exception:  # noqa: BLE001 - informative only
        d['natural_frequencies_hz'] = None
    doc['derived'] = d
    return doc


def _close(a: Any, b: Any) -> bool:
    if isinstance(a, bool) or isinstance(b, bool) or a is None or b is None:
        return a == b
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return math.isclose(float(a), float(b), rel_tol=1e-9, abs_tol=1e-300)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_close(x, y) for x, y in zip(a, b))
    return a == b


def read_config_text(path: str | Path) -> str:
    """The text of a parameter file (:func:`~worm_gear_sim._support.guarded_io.read_text_file`:
    size limit, UTF-8, no NUL); a ConfigError naming the file."""
    p = Path(path)
    if not p.exists():
        raise ConfigError('', f'config file not found: {p}')
    if p.is_dir():
        raise ConfigError('', f'config path is a directory: {p}')
    try:
        return read_text_file(p, MAX_CONFIG_BYTES, 'a parameter file')
    except GuardedFileError as exc:
        raise ConfigError('', str(exc)) from None


def safe_yaml_load(text: str, where: str) -> Any:
    """YAML the guarded way (:func:`~worm_gear_sim._support.guarded_io.guarded_yaml_load`: no
    aliases, limited nesting); a ConfigError naming ``where``."""
    try:
        return guarded_yaml_load(text, where)
    except GuardedFileError as exc:
        raise ConfigError('', str(exc)) from None


def load_params_json(path: str | Path, doc: Mapping[str, Any] | None = None) -> Config:
    """Config from a ``params`` JSON: sections are the parameters; the ``derived`` block is
    checked against the values derived again (a mismatch is an error: derived quantities are
    outputs, edit the sections instead)."""
    p = Path(path)
    if doc is None:
        try:
            doc = json.loads(read_config_text(p))
        except json.JSONDecodeError as exc:
            raise ConfigError('', f'{p}: broken JSON at line {exc.lineno}, column '
                              f'{exc.colno}: {exc.msg}') from None
        except RecursionError:
            raise ConfigError('', f'{p}: JSON nested too deep') from None
    if not isinstance(doc, Mapping):
        raise ConfigError('', f'{p}: expected a JSON object of parameter sections')
    fmt = doc.get('format', PARAMS_FORMAT)
    if fmt != PARAMS_FORMAT:
        raise ConfigError('format', f'{p}: unsupported format {fmt!r} (expected '
                          f'{PARAMS_FORMAT!r})')
    sections = {k: v for k, v in doc.items() if k not in _RESERVED_JSON_KEYS}
    cfg = config_from_mapping(sections, source=str(p))
    derived = doc.get('derived')
    if derived is not None:
        if not isinstance(derived, Mapping):
            raise ConfigError('derived', f'{p}: must be an object')
        fresh = params_document(cfg)['derived']
        for key, value in derived.items():
            if key not in fresh:
                raise ConfigError(f'derived.{key}', 'unknown derived quantity'
                                  + suggest(key, list(fresh)))
            if not _close(value, fresh[key]):
                raise ConfigError(f'derived.{key}', f'{value!r} does not match the value '
                                  f'derived from the parameters ({fresh[key]!r}); derived '
                                  'quantities are outputs: edit the sections and delete the '
                                  'derived block')
    return cfg


def load_any_config(path: str | Path | None) -> Config:
    """YAML (ROS layout or plain sections) or a ``params`` JSON; None = package default."""
    if path is None:
        return load_config()
    p = Path(path)
    text = read_config_text(p)
    if p.suffix.lower() == '.json':
        return load_params_json(p)
    if text.lstrip().startswith('{'):
        try:
            doc = json.loads(text)
        except (json.JSONDecodeError, RecursionError):
            doc = None
        if isinstance(doc, Mapping) and ('derived' in doc or 'format' in doc):
            return load_params_json(p, doc)
    return load_config(p)


def resolve_config(config_path: str | Path | None, sets: Sequence[str] | None = None,
                   extra: Mapping[str, Any] | None = None) -> Config:
    """The run's config: file (or default) + ``--set`` items + command-specific overrides."""
    cfg = load_any_config(config_path)
    overrides = parse_set(sets)
    if extra:
        overrides.update(extra)
    return cfg.replace(overrides) if overrides else cfg


def params_json_dump(doc: Mapping[str, Any], path: str | Path | None) -> str:
    """JSON text with exact float round trip (repr); written to ``path`` unless None."""
    text = json.dumps(doc, indent=2, allow_nan=False) + '\n'
    if path is not None:
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)
    return text


def params_yaml_text(doc: Mapping[str, Any]) -> str:
    """A :func:`params_document` as a ROS params YAML (the derived block as a comment)."""
    body = {k: v for k, v in doc.items() if k not in _RESERVED_JSON_KEYS}
    derived = json.dumps(doc['derived'])
    return ('# worm_gear_sim resolved parameters (ROS params file; /**: whatever the node is '
            'named)\n'
            f'# derived: {derived}\n'
            + yaml.safe_dump({'/**': {'ros__parameters': body}},
                             sort_keys=False, default_flow_style=None))


def write_params_yaml(cfg: Config, path: str | Path, header: Sequence[str]) -> None:
    """The node's params file (every parameter, as ``params --format yaml``) with ``header``
    as comments on top."""
    Path(path).write_text(''.join(f'# {h}\n' for h in header)
                          + params_yaml_text(params_document(cfg)))
