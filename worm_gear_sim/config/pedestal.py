# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A pedestal file (``config/pedestal.yaml``): N worm drives, each with its parameter set,
joint names and ROS namespace.

:func:`load_pedestal` reads and validates it (the drives' worm input joints must differ);
:func:`drive_params_file` and :func:`shared_params_files` give each drive its own file for
what it learns.  Read by the pedestal node and the offline tracking pass; the file's
format: docs/pedestal.md.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .._support.guarded_io import resolved_target
from ..schema.sections import AdaptationSettings
from ..schema.validation import ConfigError
from .files import default_config_path, load_config, read_config_text, safe_yaml_load
from .usable import Config

__all__ = ['Drive', 'load_pedestal', 'default_pedestal_path', 'MAX_DRIVES',
           'drive_params_file', 'shared_params_files', 'PARAMS_FILE_KEY']

#: The parameter naming the file a drive's ~/write_adapted_parameters writes.
PARAMS_FILE_KEY = 'adaptation.params_file'

MAX_DRIVES = 8
_NAME = re.compile(r'^[A-Za-z][A-Za-z0-9_]*$')     # a ROS name token


@dataclass(frozen=True)
class Drive:
    """One drive of a pedestal: ``name`` (= its namespace) and its validated ``config``."""

    name: str
    config: Config

    @property
    def joint(self) -> str:
        """The worm input joint: the joint a trajectory names for this drive."""
        return self.config.node.joint_names[0]


def default_pedestal_path() -> Path:
    """config/pedestal.yaml beside the package's default parameters."""
    return default_config_path().with_name('pedestal.yaml')


def load_pedestal(path: str | Path | None = None) -> list[Drive]:
    """The drives of a pedestal file, in file order (ConfigError naming the problem)."""
    p = Path(path) if path is not None else default_pedestal_path()
    doc = safe_yaml_load(read_config_text(p), str(p))
    drives = doc.get('pedestal', {}).get('drives') if isinstance(doc, Mapping) else None
    if not isinstance(drives, Mapping) or not drives:
        raise ConfigError('pedestal.drives', f'{p}: expected "pedestal: drives:" with one '
                                             'mapping per drive')
    if len(drives) > MAX_DRIVES:
        raise ConfigError('pedestal.drives', f'{p}: {len(drives)} drives, more than '
                                             f'{MAX_DRIVES}')
    out: list[Drive] = []
    for name, spec in drives.items():
        key = f'pedestal.drives.{name}'
        if not isinstance(name, str) or not _NAME.match(name):
            raise ConfigError(key, f'{p}: drive name {name!r} is not a ROS name token')
        spec = {} if spec is None else spec
        if not isinstance(spec, Mapping) or set(spec) - {'params_file', 'parameters'}:
            raise ConfigError(key, f'{p}: a drive takes "params_file" and "parameters"')
        params_file = spec.get('params_file')
        overrides: Any = spec.get('parameters') or {}
        if not isinstance(overrides, Mapping):
            raise ConfigError(f'{key}.parameters', f'{p}: expected a mapping of dotted keys')
        source = (p.parent / params_file) if params_file else None
        try:
            cfg = load_config(source, overrides=dict(overrides))
            own = drive_params_file(name, cfg.adaptation.params_file)
            if PARAMS_FILE_KEY not in overrides and own != cfg.adaptation.params_file:
                cfg = cfg.replace({PARAMS_FILE_KEY: own})
        except ConfigError as exc:
            raise ConfigError(exc.key, f'{p}: drive {name!r}: {exc.reason}') from None
        out.append(Drive(name, cfg))
    joints = [d.joint for d in out]
    for d in out:
        if joints.count(d.joint) > 1:
            raise ConfigError(f'pedestal.drives.{d.name}', f'{p}: worm input joint '
                              f'{d.joint!r} is used by more than one drive')
    shared = shared_params_files({d.name: d.config.adaptation.params_file for d in out})
    if shared is not None:
        raise ConfigError(f'pedestal.drives.{shared[0]}.{PARAMS_FILE_KEY}', f'{p}: {shared[1]}')
    return out


def drive_params_file(name: str, params_file: str) -> str:
    """The file drive ``name`` writes what it learnt to: ``params_file`` itself, unless
    it is the single drive's default (``worm_gear_sim_adapted.yaml``), which becomes
    ``worm_gear_sim_adapted_<name>.yaml`` (module docstring)."""
    default = AdaptationSettings().params_file
    if params_file != default:
        return params_file
    stem, dot, suffix = default.rpartition('.')
    return f'{stem}_{name}{dot}{suffix}'


def shared_params_files(files: Mapping[str, str]) -> tuple[str, str] | None:
    """None if the drives' ``adaptation.params_file`` (drive name -> path) name different
    files, else (the second of the first two drives that share one, a line naming both and
    the file)."""
    seen: dict[Path, str] = {}
    for name, path in files.items():
        target = resolved_target(path)
        if target in seen:
            return name, (f'drives {seen[target]!r} and {name!r} both write what they '
                          f'learnt to {target} ({PARAMS_FILE_KEY}): name a file per drive')
        seen[target] = name
    return None
