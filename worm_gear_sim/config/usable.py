# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The parameter set users build: :class:`Config`, whose builders prove it usable.

:class:`Config` is the schema's ``Parameters`` plus the usable check of every way a set is
built from outside (:func:`config_from_mapping`, :meth:`Config.replace`, ``load_config``):
they raise ``ConfigError`` naming the keys unless the whole set can be simulated
(:func:`check_usable`, the rules of :mod:`~worm_gear_sim.dynamics.usability`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from .._support.stepwise import Steps, run_steps
from ..schema.parameters import Parameters, replaced, sections_from_mapping

__all__ = [
    'Config', 'config_from_mapping', 'default_config', 'check_usable',
]


@dataclass(frozen=True)
class Config(Parameters):
    """The whole parameter set; immutable. Build variants with :meth:`replace`."""

    def replace(self, overrides: Mapping[str, Any] | None = None, **kw: Any) -> Config:
        """Return a validated copy with dotted-name overrides applied (all or nothing): per
        field, cross-field, and usable (:func:`check_usable`, naming the keys changed)."""
        changes = dict(overrides or {})
        changes.update({k.replace('__', '.'): v for k, v in kw.items()})
        return run_steps(self.replace_steps(changes))

    def replace_steps(self, overrides: Mapping[str, Any]) -> Steps[Config]:
        """:meth:`replace` in steps (:mod:`worm_gear_sim._support.stepwise`)."""
        changes = dict(overrides)
        cfg = replaced(self, changes)     # the changed fields checked, then across fields
        yield
        from ..dynamics.usability import check_usable_steps
        yield from check_usable_steps(cfg, changed=[k for k in changes])
        return cfg


def config_from_mapping(data: Mapping[str, Any], source: str = '<mapping>',
                        usable: bool = True, strict: bool = False) -> Config:
    """Build a Config from nested sections (the ``ros__parameters`` content) or dotted keys,
    validated per field (``strict``: each value of its parameter's type, as in a params
    file), across fields and (``usable``) by :func:`check_usable`."""
    cfg = Config(**sections_from_mapping(data, source, strict))
    if usable:
        check_usable(cfg)
    return cfg


def check_usable(cfg: Parameters, changed: Iterable[str] | None = None) -> None:
    """Raise :class:`ConfigError` unless the parameter set can be simulated: tooth
    stiffness finite and > 0 over the mesh cycle, no spring of the chain lost next to its
    neighbour (singular stiffness), every mode resolved by the time step, and a trial
    (equilibrium, modes, a 2 ms move) computable and finite.  The error names the keys that
    set the failing quantity, the ``changed`` keys first (default: the keys that differ from
    the defaults).  Called by :func:`config_from_mapping`, :meth:`Config.replace`,
    :func:`~worm_gear_sim.config.files.load_config` and the Simulator; cached per Config; pure
    (no shared state besides the cache), so it can run off the node's real-time path.  The
    rules: :mod:`worm_gear_sim.dynamics.usability` (imported here on first use: the model and numba
    load only when a set is checked)."""
    from ..dynamics.usability import check_usable as _check
    _check(cfg, changed)


def default_config() -> Config:
    """The code defaults (equal to config/worm_gear_sim.yaml, checked by a test)."""
    return Config()


#: Names that moved out of this module, and where they live now.  Their aliases here (one
#: release with a DeprecationWarning) are gone, and with them the import of config_io from
#: params that closed a loop; the error still says where to import them from.
_MOVED = {'load_config': 'config_io', 'default_config_path': 'config_io',
          'derive': 'derived', 'Derived': 'derived'}


def __getattr__(name: str) -> Any:
    home = _MOVED.get(name)
    if home is not None:
        raise AttributeError(f'worm_gear_sim.config.usable.{name} moved to '
                             f'worm_gear_sim.{home}.{name}: import it from there')
    raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
