# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A package's public names imported on first use (PEP 562): the package's ``__getattr__``
and ``__dir__`` from a table of name -> relative module."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ['lazy_exports']


def lazy_exports(package: str, namespace: dict[str, Any], exports: Mapping[str, str]
                 ) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` for ``package`` whose globals are ``namespace``: a name of
    ``exports`` is imported from its module (relative to the package) when first asked for,
    then kept in the namespace."""

    def get(name: str) -> Any:
        module = exports.get(name)
        if module is None:
            raise AttributeError(f'module {package!r} has no attribute {name!r}')
        value = getattr(importlib.import_module(module, package), name)
        namespace[name] = value
        return value

    def names() -> list[str]:
        return sorted(set(namespace) | set(exports))

    return get, names
