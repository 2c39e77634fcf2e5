# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A guard on the node's /clock subscription: rclpy's ``TimeSource.clock_callback`` turns a
``rosgraph_msgs/Clock`` into ``rclpy.time.Time`` and raises ``ValueError`` inside the
executor for a negative ``sec`` (or a ``nanosec`` past 1e9), which would end the process.
Any node on the domain can send such a message; the guard rejects it (the callback
``on_reject`` names it: the node logs and counts it) and keeps the clock where it was."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ['guard_clock_source', 'clock_message_problem']

_NS = 1_000_000_000


def clock_message_problem(msg: Any) -> str:
    """Why a /clock message cannot be a time ('' if it can)."""
    st = msg.clock
    if st.sec < 0:
        return f'negative sec {st.sec}'
    if not 0 <= st.nanosec < _NS:
        return f'nanosec {st.nanosec} outside [0, 1e9)'
    return ''


def guard_clock_source(node: Any, on_reject: Callable[[str], None]) -> bool:
    """Replace the node's time source's clock callback with one that validates first
    (now, and for every later /clock subscription: ``use_sim_time`` switched on at run
    time).  Returns False when this rclpy has no such time source (nothing changed)."""
    ts = getattr(node, '_time_source', None)
    original = getattr(ts, 'clock_callback', None)
    if ts is None or original is None or not hasattr(ts, '_subscribe_to_clock_topic'):
        return False

    def clock_callback(msg: Any) -> None:
        problem = clock_message_problem(msg)
        if problem:
            on_reject(problem)
            return
        original(msg)

    ts.clock_callback = clock_callback          # used by every later subscription
    sub = getattr(ts, '_clock_sub', None)
    if sub is not None:                         # subscribed already (use_sim_time at start)
        node.destroy_subscription(sub)
        ts._clock_sub = None
        ts._subscribe_to_clock_topic()
    return True
