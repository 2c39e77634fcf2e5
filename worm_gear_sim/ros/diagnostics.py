# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""DiagnosticArray built by hand with the diagnostic_updater conventions.

``diagnostic_updater`` has no PyPI wheel, so the node publishes on the absolute topic
``/diagnostics`` itself: one ``DiagnosticStatus`` per task, named ``"<node>: <task>"``, with
``hardware_id``, a ``level`` byte (``DiagnosticStatus.OK/WARN/ERROR/STALE``) and values as
``KeyValue`` strings.  ``<node>`` is the node's fully qualified name without the leading
slash (:func:`identity`): ``worm_gear_sim`` in the root namespace,
``azimuth/worm_gear_sim`` in a pedestal, so an aggregator tells the drives apart.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

__all__ = ['OK', 'WARN', 'ERROR', 'STALE', 'status', 'array', 'level_name', 'identity']

OK = DiagnosticStatus.OK
WARN = DiagnosticStatus.WARN
ERROR = DiagnosticStatus.ERROR
STALE = DiagnosticStatus.STALE

_LEVEL_NAMES = {OK: 'OK', WARN: 'WARN', ERROR: 'ERROR', STALE: 'STALE'}


def level_name(level: bytes) -> str:
    """'OK', 'WARN', 'ERROR' or 'STALE'."""
    return _LEVEL_NAMES.get(level, repr(level))


def identity(node: Any, hardware: str = 'worm_gear_sim') -> tuple[str, str]:
    """(status name prefix, hardware_id) of ``node``: its fully qualified name without the
    leading slash, and ``hardware`` followed by ``:<namespace>`` outside the root."""
    ns = node.get_namespace().strip('/')
    return node.get_fully_qualified_name().lstrip('/'), f'{hardware}:{ns}' if ns else hardware


def _text(v: Any) -> str:
    if isinstance(v, float):
        return f'{v:.6g}'
    return str(v)


def status(node_name: str, task: str, level: bytes, message: str,
           values: Mapping[str, Any], hardware_id: str = '') -> DiagnosticStatus:
    """One status named ``"<node_name>: <task>"``; values become KeyValue strings."""
    return DiagnosticStatus(
        level=level, name=f'{node_name}: {task}', message=message, hardware_id=hardware_id,
        values=[KeyValue(key=str(k), value=_text(v)) for k, v in values.items()])


def array(stamp: Time, statuses: Iterable[DiagnosticStatus]) -> DiagnosticArray:
    """DiagnosticArray with the given header stamp."""
    msg = DiagnosticArray()
    msg.header.stamp = stamp
    msg.status = list(statuses)
    return msg
