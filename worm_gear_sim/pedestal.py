# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A pedestal: N worm drives (a radar's azimuth and elevation), each with its own parameter
set, joint names and ROS namespace, described by one YAML file (``config/pedestal.yaml``)::

    pedestal:
      drives:
        azimuth:                          # the drive's name = its ROS namespace
          params_file: worm_gear_sim.yaml # relative to this file; a fitted YAML works too
          parameters:                     # dotted overrides on top of it (optional)
            node.joint_names: [azimuth_worm_input_joint, ...]
        elevation: ...

:func:`load_pedestal` reads and validates it (the drives' worm input joints, i.e.
``node.joint_names[0]``, must differ: they are how a two-joint trajectory is split).  The
node process (:mod:`worm_gear_sim.ros.pedestal`) and the offline tools (the tracking pass,
:mod:`worm_gear_sim.studies.tracking_pass`) read the same file.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .config_io import default_config_path, load_config, read_config_text, safe_yaml_load
from .params import Config
from .validation import ConfigError

__all__ = ['Drive', 'load_pedestal', 'default_pedestal_path', 'MAX_DRIVES']

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
        except ConfigError as exc:
            raise ConfigError(exc.key, f'{p}: drive {name!r}: {exc.reason}') from None
        out.append(Drive(name, cfg))
    joints = [d.joint for d in out]
    for d in out:
        if joints.count(d.joint) > 1:
            raise ConfigError(f'pedestal.drives.{d.name}', f'{p}: worm input joint '
                              f'{d.joint!r} is used by more than one drive')
    return out
