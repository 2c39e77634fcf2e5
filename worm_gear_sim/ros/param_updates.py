# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A parameter set's way into the running node.

Checked on the parameter service (rclpy's pre-set and on-set callbacks): model parameters
only, read-only and type checks here, everything else by the core (:meth:`Config.replace`,
which proves the set usable).  Accepted sets are prepared in a worker thread
(:meth:`RealtimePredictor.prepare`: compensator design, the simulator's trial) and swapped
in on the executor thread between two samples (:meth:`RealtimePredictor.reconfigure`),
polled by a steady-clock timer and at the start of every sample callback.  The set the
pipeline runs may differ from the declared one (``pipeline``: the adaptation's values in
use on top, :class:`~.adaptation.NodeAdaptation`); ``swapped`` hears of each set swapped in.
"""

from __future__ import annotations

import concurrent.futures
from collections.abc import Callable, Collection
from typing import Any

from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter

from ..adaptation.live import swap_back
from ..config.usable import Config
from ..dynamics.load import elastic_load_warning
from ..realtime import RealtimePredictor
from ..schema.validation import ConfigError
from .params_bridge import coerce_parameter, is_model_parameter, to_core_value

__all__ = ['ParameterUpdates', 'SWAP_POLL_PERIOD']

SWAP_POLL_PERIOD = 0.002  # s: polls a parameter set being built in the worker thread


class ParameterUpdates:
    """Registers the parameter callbacks on ``node`` and owns the node's current
    :class:`Config` (``config``).  ``types``: declared ROS type of each model parameter;
    ``counters``: the node's counters (``rejected_parameter_sets``,
    ``accepted_parameter_sets``, ``parameter_build_errors`` are counted here); ``warn(cause,
    text)``: the node's throttled warning; ``guard``: wraps a timer callback;
    ``pipeline(declared, names)``: the set the pipeline is to run for the declared set of a
    set of ``names`` (ConfigError: the set is refused); ``swapped(declared, names)``: called
    on the executor thread once that set runs."""

    def __init__(self, node: Node, rt: RealtimePredictor, config: Config,
                 types: dict[str, int], counters: dict[str, Any],
                 warn: Callable[[str, str], None],
                 guard: Callable[[Callable[[], None]], Any],
                 pipeline: Callable[[Config, Collection[str]], Config] | None = None,
                 swapped: Callable[[Config, Collection[str]], None] | None = None) -> None:
        self.node, self.rt, self.config = node, rt, config
        self._types, self._counters, self._warn = types, counters, warn
        self._pipeline = pipeline or (lambda cfg, names: cfg)
        self._swapped = swapped or (lambda cfg, names: None)
        self._evaluated: tuple[tuple, str, tuple[Config, Config, tuple] | None] | None = None
        self._accepted: tuple[Config, Config, tuple] | None = None
        self._builder = concurrent.futures.ThreadPoolExecutor(
            max_workers=1, thread_name_prefix='worm_gear_sim_params')
        self._building: concurrent.futures.Future | None = None
        self._running: tuple[Config, tuple] | None = None     # (pipeline's set, names)
        self._returning: Config | None = None   # the set a reset returns to (swap_back)
        #: the names of the sets accepted since the last swap (a set superseded before it
        #: was swapped in still counts as set)
        self._unswapped: tuple[str, ...] = ()
        node.add_pre_set_parameters_callback(self._pre_set)
        node.add_on_set_parameters_callback(self._on_set)
        node.add_post_set_parameters_callback(self._post_set)
        # polls a parameter build on the steady clock (also under use_sim_time); the
        # EventsExecutor of the wheels supports no guard conditions
        self._swap_timer = node.create_timer(SWAP_POLL_PERIOD, guard(self.swap_prepared),
                                             clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._swap_timer.cancel()

    @property
    def pending(self) -> bool:
        """An accepted parameter set is still being built (not swapped in yet)."""
        return self._building is not None

    def _evaluate(self, params: list[Parameter]
                  ) -> tuple[str, tuple[Config, Config, tuple] | None]:
        """('', (candidate, the pipeline's set, names)) if the model parameters in
        ``params`` form a usable set, else (reason, None).  Non-model parameters
        (qos_overrides, use_sim_time) are left to rclpy.  The result of the last call is
        remembered (pre-set and on-set callbacks see the same list)."""
        key = tuple((p.name, p.type_, repr(p.value)) for p in params)
        if self._evaluated is not None and self._evaluated[0] == key:
            return self._evaluated[1], self._evaluated[2]
        overrides = {}
        reason = ''
        for p in params:
            if not is_model_parameter(p.name):
                continue
            if self.node.describe_parameter(p.name).read_only:
                reason = f'{p.name} is read-only (structural); restart the node to change it'
                break
            if p.type_.value != self._types[p.name]:
                reason = (f'{p.name}: wrong type {p.type_.name}, expected '
                          f'{Parameter.Type(self._types[p.name]).name}')
                break
            overrides[p.name] = to_core_value(p.value)
        candidate = None
        if not reason and overrides:
            try:    # the core's validation: types, ranges, cross-field, usable (check_usable)
                declared = self.config.replace(overrides)
                names = tuple(dict.fromkeys(self._unswapped + tuple(overrides)))
                candidate = (declared, self._pipeline(declared, names), names)
            except (ConfigError, ValueError) as exc:
                reason = str(exc)
        self._evaluated = (key, reason, candidate)
        return reason, candidate

    def _pre_set(self, params: list[Parameter]) -> list[Parameter]:
        """Accept integers for doubles, and count/log every rejected set (descriptor checks
        of rclpy run after this callback and do not report back)."""
        params = [coerce_parameter(p, self._types[p.name]) if p.name in self._types else p
                  for p in params]
        reason, _ = self._evaluate(params)
        if reason:
            self._counters['rejected_parameter_sets'] += 1
            self._warn('parameters', f'rejected parameter set: {reason}')
        return params

    def _on_set(self, params: list[Parameter]) -> SetParametersResult:
        reason, candidate = self._evaluate(params)
        self._evaluated = None
        if reason:
            return SetParametersResult(successful=False, reason=reason)
        self._accepted = candidate
        return SetParametersResult(successful=True)

    def _post_set(self, params: list[Parameter]) -> None:
        """Accepted: the new pipeline configuration is prepared in the worker thread;
        :meth:`swap_prepared` swaps it in on the executor thread, between two samples."""
        accepted, self._accepted = self._accepted, None
        if accepted is None:
            return
        self.config, run, names = accepted
        self._counters['accepted_parameter_sets'] += 1
        self._build(run, names)
        self.node.get_logger().info('parameters accepted: ' + ', '.join(
            p.name for p in params if is_model_parameter(p.name)))

    def rebuild(self) -> None:
        """Prepare the declared set again (its pipeline's set may have changed: the
        adaptation's reset) and swap it in as a parameter set, no parameter changed."""
        try:
            run = self._pipeline(self.config, self._unswapped)
        except (ConfigError, ValueError) as exc:
            self._warn('parameters', f'could not rebuild the parameter set: {exc}')
            return
        self._build(run, self._unswapped)
        self._returning = run

    def _build(self, run: Config, names: tuple) -> None:
        self._running = (run, names)
        self._unswapped = names
        self._building = self._builder.submit(self.rt.prepare, run)
        self._swap_timer.reset()

    def swap_prepared(self) -> None:
        """Swap a prepared set in, if one is ready (cheap when none is pending)."""
        fut = self._building
        if fut is None or not fut.done():
            return
        self._building = None
        self._swap_timer.cancel()
        try:
            prepared = fut.result()
            assert self._running is not None
            run, names = self._running
            if prepared.config is run:           # else a newer set superseded it
                if run is self._returning:       # a reset: reseated and blended
                    swap_back(self.rt, prepared)
                else:
                    self.rt.reconfigure(prepared)
                self._returning = None
                self._unswapped = ()
                self._swapped(self.config, names)
                note = elastic_load_warning(self.rt.model)   # allowed, not plausible
                if note:
                    self._warn('load_elastic_parameter', note)
        except (ConfigError, ValueError) as exc:
            self._counters['parameter_build_errors'] += 1
            self._warn('parameters', f'could not apply parameters: {exc}')

    def shutdown(self) -> None:
        self._builder.shutdown(wait=False, cancel_futures=True)
