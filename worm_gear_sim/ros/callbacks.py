# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""What every callback of the node wraps itself in: a guard that ends quietly when Ctrl-C /
SIGTERM shut the context down while it runs, throttled log lines (one per cause), the
one-joint JointState samples of the node's inputs, and the look for other nodes of the same
name.  No physics, no pipeline: the node (:mod:`.node`) composes these."""

from __future__ import annotations

import inspect
import time
from collections.abc import Callable
from typing import Any

__all__ = ['LogThrottle', 'guard_timer', 'guard_message', 'one_joint_sample', 'stamp_ns',
           'same_name_nodes', 'SameNameWatch', 'NS']

NS = 1_000_000_000


class LogThrottle:
    """One log line per cause every ``period`` seconds (monotonic clock); the lines held
    back are counted and reported with the next line of that cause."""

    def __init__(self, period: float) -> None:
        self.period_ns = int(period * 1e9)
        self._last: dict[str, int] = {}
        self._held: dict[str, int] = {}

    def __call__(self, cause: str, text: str | Callable[[], str]) -> str:
        """The line to log now for ``cause`` ('' while throttled); ``text`` may be a
        callable that makes the line, called only when it is logged (a flood of bad input
        costs no formatting)."""
        now = time.monotonic_ns()
        last = self._last.get(cause)
        if last is not None and now - last < self.period_ns:
            self._held[cause] = self._held.get(cause, 0) + 1
            return ''
        self._last[cause] = now
        held = self._held.pop(cause, 0)
        if not isinstance(text, str):
            text = text()
        return f'{text} [{held} more like this held back]' if held else text


def guard_timer(context: Any, callback: Callable[[], Any]) -> Callable[[], None]:
    """Timer callback that ends quietly when Ctrl-C / SIGTERM shut ``context`` down while it
    runs (a publish on a dying context raises); other errors propagate."""

    def guarded() -> None:
        try:
            callback()
        except Exception:
            if context.ok():
                raise
    # The EventsExecutor calls inspect.signature() on every timer callback (to decide on
    # passing TimerInfo); a ready-made signature makes that O(1) (~20 us a call less).
    fn: Any = guarded
    fn.__signature__ = inspect.Signature()
    return fn


def guard_message(context: Any, callback: Callable[[Any], Any]) -> Callable[[Any], None]:
    """Subscription callback that ends quietly when Ctrl-C / SIGTERM shut ``context`` down
    while it runs; other errors propagate."""

    def guarded(msg: Any) -> None:
        try:
            callback(msg)
        except Exception:
            if context.ok():
                raise
    return guarded


def stamp_ns(stamp: Any) -> int:
    """A ``builtin_interfaces/Time`` in nanoseconds."""
    return stamp.sec * NS + stamp.nanosec


def one_joint_sample(msg: Any, values: Any, field: str, joint: str, prefix: str,
                     reject: Callable[[str, str], None]) -> tuple[int, float] | None:
    """(stamp [ns], values[0]) of a one-joint JointState sample, or None after
    ``reject(prefix + reason, text)``: no ``field[0]`` (``empty_<field>``) or a
    ``name[0]`` other than ``joint`` (``wrong_joint``)."""
    if len(values) == 0:
        reject(f'{prefix}empty_{field}', f'no {field}[0]')
        return None
    names = msg.name
    if len(names) and names[0] != joint:
        reject(f'{prefix}wrong_joint', f'joint {names[0]!r}; this input takes {joint!r}')
        return None
    return stamp_ns(msg.header.stamp), values[0]


def same_name_nodes(node: Any) -> int:
    """How many other nodes on the domain have ``node``'s name and namespace."""
    me = (node.get_name(), node.get_namespace())
    return sum(1 for nn in node.get_node_names_and_namespaces() if nn == me) - 1


class SameNameWatch:
    """Warns (and counts in ``counters['same_name_nodes']``, which /diagnostics reports)
    when other nodes on the domain have ``node``'s fully qualified name: their topics,
    parameters and services would mix with the node's, silently.  Looks ``checks`` times,
    every ``period`` s after the start (discovery takes a moment); ``guard`` wraps the
    timer's callback."""

    def __init__(self, node: Any, counters: dict[str, Any], guard: Any,
                 period: float = 1.0, checks: int = 5) -> None:
        self._node, self._counters, self._checks = node, counters, checks
        self._timer = node.create_timer(period, guard(self.check))

    def check(self) -> None:
        node = self._node
        n = same_name_nodes(node)
        if n > self._counters['same_name_nodes']:
            self._counters['same_name_nodes'] = n
            node.get_logger().warning(
                f'{n} other node(s) named {node.get_fully_qualified_name()} on this domain: '
                'their topics, parameters and services mix with this one\'s; give each '
                'drive its own name or namespace (ROS_DOMAIN_ID apart for separate setups)')
        self._checks -= 1
        if self._checks <= 0:
            self._timer.cancel()
