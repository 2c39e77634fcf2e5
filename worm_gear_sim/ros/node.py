# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""ROS 2 node ``worm_gear_sim``: the worm-gear model running in real time beside a servo.

An I/O shell around the core's real-time pipeline
:class:`~worm_gear_sim.realtime.RealtimePredictor`: this module holds only topics, QoS,
parameters, timers and diagnostics; every number it publishes comes from the core (the
pipeline drives :class:`~worm_gear_sim.simulation.Simulator` and the feed-forward
:class:`~worm_gear_sim.compensation.Compensator`).

Interface (SI units, rad; relative, remappable names; docs/node.md):

* ``worm_angle_reference`` (in, sensor_msgs/JointState, reliable, keep last 1000): stamped
  reference samples, ``header.stamp`` = the instant the sample applies (may be in the
  future: a preview), ``position[0]`` = theta1_ref; ``name[0]``, when given, must be the
  worm input joint (``node.joint_names[0]``).  Event-driven: each sample is processed in
  its callback (``RealtimePredictor.push``); a slow timer only watches for a paused stream.
* ``~/compensated_command`` (out, JointState, same stamp, theta1_ref + delta) and
  ``~/feedforward`` (std_msgs/Float64, delta), one per accepted stamped sample;
* ``worm_angle_command`` (in, std_msgs/Float64): unstamped commands, sampled as
  ``node.command_timing`` says by a tick timer at ``node.publish_rate_hz``, which runs only
  while this path is in use (``RealtimePredictor.push_command`` / ``tick``);
* ``joint_states`` (out, JointState theta1..theta4, rates, shaft torques), stamped with the
  instant it predicts, plus ``~/positioning_error`` and ``~/worm_error``;
* ``measured_joint_states`` (in, optional, JointState from the drive's encoders, names of
  ``node.joint_names``, sensor data QoS): the live model check
  (:class:`~worm_gear_sim.model_check.ModelCheck`) publishes ``~/prediction_residual``
  (JointState, the measurement's stamp, measured - predicted per measured joint) and a
  ``model check`` status on /diagnostics that turns WARN when a joint's residual RMS over
  ``node.residual_window`` exceeds its ``node.residual_warn_rms``;
* ``/diagnostics``: counters of the pipeline and of this node, stale-stream status;
* every model parameter is a declared ROS parameter (dotted names of
  :meth:`Config.to_flat_dict`), validated by the core (:meth:`Config.replace`, which proves
  the set usable); the new pipeline is prepared in a worker thread and swapped in on the
  executor thread.

Run ``worm_gear_sim_node --ros-args --params-file config/worm_gear_sim.yaml`` (or
``python -m worm_gear_sim.node ...``); ``--executor single_threaded`` overrides the
``node.executor`` parameter.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import gc
import inspect
import sys
import time
from typing import Any

import rclpy
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy_impl
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.qos_overriding_options import QoSOverridingOptions
from rclpy.task import Future
from rclpy.utilities import remove_ros_args
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from ..command_timing import COMMAND_QUEUE_LENGTH, CommandQueue, StreamClock
from ..config_io import load_config
from ..model_check import ModelCheck
from ..params import NODE_NAME, SECTIONS, Config, ConfigError, config_from_mapping
from ..params import suggest as suggest_name
from ..realtime import STALE_PERIODS, Output, Prediction, RealtimePredictor, Reject
from . import diagnostics as diag
from . import startup
from .params_bridge import (
    MODEL_PARAMETER_NAMES,
    coerce_parameter,
    declare_config,
    is_model_parameter,
    parameter_type,
    to_core_value,
)

RCLError = _rclpy_impl.RCLError          # RCLInvalidROSArgsError derives from it

__all__ = ['WormGearSimNode', 'LogThrottle', 'main', 'file_defaults', 'make_executor',
           'spin_until_shutdown', 'COMMAND_TOPIC', 'REFERENCE_TOPIC', 'REFERENCE_DEPTH',
           'JOINT_STATES_TOPIC', 'REJECT_REASONS', 'NODE_REJECT_REASONS', 'WATCH_PERIOD',
           'CommandQueue', 'StreamClock', 'COMMAND_QUEUE_LENGTH', 'STALE_PERIODS']

COMMAND_TOPIC = 'worm_angle_command'
REFERENCE_TOPIC = 'worm_angle_reference'
REFERENCE_DEPTH = 1000   # every sample matters to the filter: reliable, keep last 1000 (1 s
#                          at 1 kHz: a stalled executor loses none)
JOINT_STATES_TOPIC = 'joint_states'
MEASURED_TOPIC = 'measured_joint_states'
REJECT_REASONS = tuple(r.value for r in Reject)          # the pipeline's (core) reasons
NODE_REJECT_REASONS = ('empty_position', 'wrong_joint')  # message-level, checked here
LOG_THROTTLE_S = 2.0   # at most one log line per cause every 2 s (bursts of bad input)
WATCH_PERIOD = 0.02    # s: the slow timer that notices a paused stamped stream
# s: lateness allowed to a stamped sample before the stream is declared stale (held output,
# rest samples): scheduling stalls of a loaded sender shorter than this change nothing
STALE_MARGIN = 0.1
SWAP_POLL_PERIOD = 0.002  # s: polls a parameter set being built in the worker thread
_NS = 1_000_000_000


class LogThrottle:
    """One log line per cause every ``period`` seconds (monotonic clock); the lines held
    back are counted and reported with the next line of that cause."""

    def __init__(self, period: float) -> None:
        self.period_ns = int(period * 1e9)
        self._last: dict[str, int] = {}
        self._held: dict[str, int] = {}

    def __call__(self, cause: str, text: str) -> str:
        """The line to log now for ``cause`` ('' while throttled)."""
        now = time.monotonic_ns()
        last = self._last.get(cause)
        if last is not None and now - last < self.period_ns:
            self._held[cause] = self._held.get(cause, 0) + 1
            return ''
        self._last[cause] = now
        held = self._held.pop(cause, 0)
        return f'{text} [{held} more like this held back]' if held else text




def file_defaults() -> Config:
    """Declaration defaults: the package's YAML (source tree or installed share/), falling
    back to the code defaults, which equal it (a test checks this)."""
    try:
        return load_config()
    except ConfigError:
        return Config()


def _timer_signature(fn: Any) -> Any:
    # The EventsExecutor calls inspect.signature() on every timer callback (to decide on
    # passing TimerInfo); a ready-made signature makes that O(1) (~20 us a call less).
    fn.__signature__ = inspect.Signature()
    return fn


class WormGearSimNode(Node):
    """Real-time worm-gear prediction; see the module docstring for the interface.

    ``defaults`` sets the declaration defaults (``--params-file`` and ``parameter_overrides``
    still win); other keyword arguments (``context``, ``parameter_overrides``, ``cli_args``,
    ``namespace``) go to :class:`rclpy.node.Node`.  Raises :class:`ConfigError` when the
    declared values do not form a usable configuration or name an unknown parameter.
    """

    def __init__(self, node_name: str = NODE_NAME, *, defaults: Config | None = None,
                 **kwargs: Any):
        super().__init__(node_name, **kwargs)
        self._clock = self.get_clock()
        self._monotonic_ns = time.monotonic_ns    # the wall time base (tests replace it)
        values = declare_config(self, defaults if defaults is not None else file_defaults())
        self._types = {name: parameter_type(v) for name, v in values.items()}
        cfg = config_from_mapping(values, source='ROS parameters')
        self.config: Config = cfg
        self.rt = RealtimePredictor(cfg, sim_time=self._clock.ros_time_is_active,
                                    stale_margin=STALE_MARGIN)
        self._worm_input_joint = cfg.node.joint_names[0]

        self.counters: dict[str, Any] = dict(
            **{f'rejected_{r}': 0 for r in NODE_REJECT_REASONS},
            ticks=0, missed_ticks=0, held_predictions=0, rejected_parameter_sets=0,
            accepted_parameter_sets=0, parameter_build_errors=0)
        self.last_error = ''
        self._throttle = LogThrottle(LOG_THROTTLE_S)
        self._window: dict[str, Any] = {}
        self._mode = ''                          # 'stamped' | 'command' once input came
        self._last_mono_ns = 0
        self._last_watch_ns = 0
        self._period_ns = int(round(1e9 / cfg.node.publish_rate_hz))
        self._window = self._window_start()

        # --- parameter sets: validated on the parameter service, built in a worker ------
        self._evaluated: tuple[tuple, str, Config | None] | None = None
        self._accepted: Config | None = None
        self._builder = concurrent.futures.ThreadPoolExecutor(
            max_workers=1, thread_name_prefix='worm_gear_sim_params')
        self._building: concurrent.futures.Future | None = None

        # --- ROS interfaces --------------------------------------------------------------
        qos_state = QoSProfile(depth=10)
        overrides = QoSOverridingOptions.with_default_policies
        self._pub_js = self.create_publisher(JointState, JOINT_STATES_TOPIC, qos_state,
                                             qos_overriding_options=overrides())
        self._pub_err = self.create_publisher(Float64, '~/positioning_error', qos_state)
        self._pub_worm = self.create_publisher(Float64, '~/worm_error', qos_state)
        self._pub_ff = self.create_publisher(Float64, '~/feedforward',
                                             QoSProfile(depth=REFERENCE_DEPTH))
        self._pub_cc = self.create_publisher(JointState, '~/compensated_command',
                                             QoSProfile(depth=REFERENCE_DEPTH),
                                             qos_overriding_options=overrides())
        self._pub_diag = self.create_publisher(diag.DiagnosticArray, '/diagnostics', 1)
        self._sub_cmd = self.create_subscription(
            Float64, COMMAND_TOPIC, self._on_command, qos_profile_sensor_data,
            qos_overriding_options=overrides())
        self._check = ModelCheck(cfg.node.joint_names[1:], cfg.node.residual_window,
                                 cfg.node.residual_warn_rms)
        self._pub_res = self.create_publisher(JointState, '~/prediction_residual', qos_state)
        self._sub_meas = self.create_subscription(
            JointState, MEASURED_TOPIC, self._on_measured, qos_profile_sensor_data,
            qos_overriding_options=overrides())
        self._res = JointState()
        self._sub_ref = self.create_subscription(
            JointState, REFERENCE_TOPIC, self._on_reference,
            QoSProfile(depth=REFERENCE_DEPTH, reliability=ReliabilityPolicy.RELIABLE),
            qos_overriding_options=overrides())

        # pre-built messages: a sample only rewrites their fields
        self._js = JointState()
        self._js.name = list(cfg.node.joint_names)
        self._cc = JointState()
        self._cc.name = [self._worm_input_joint]
        self._cc.position = [0.0]
        self._f_err, self._f_worm, self._f_ff = Float64(), Float64(), Float64()

        self._check_overrides()

        self.add_pre_set_parameters_callback(self._pre_set)
        self.add_on_set_parameters_callback(self._on_set)
        self.add_post_set_parameters_callback(self._post_set)

        # Timers: the tick runs only on the Float64 path, the held output only while the
        # stamped stream is stale; the watch is slow.  They start cancelled.
        period = 1.0 / cfg.node.publish_rate_hz
        self._tick_timer = self.create_timer(period, self._guard(self._on_tick))
        self._hold_timer = self.create_timer(period, self._guard(self._on_hold))
        self._watch_timer = self.create_timer(WATCH_PERIOD, self._guard(self._on_watch))
        # polls a parameter build on the steady clock (also under use_sim_time); the
        # EventsExecutor of the wheels supports no guard conditions
        self._swap_timer = self.create_timer(SWAP_POLL_PERIOD, self._guard(self._swap_prepared),
                                             clock=Clock(clock_type=ClockType.STEADY_TIME))
        for t in (self._tick_timer, self._hold_timer, self._watch_timer, self._swap_timer):
            t.cancel()
        self._diag_timer = self.create_timer(cfg.node.diagnostic_period,
                                             self._guard(self.publish_diagnostics))
        self.get_logger().info(
            f'ready: dt = {self.sim.dt:g} s, {cfg.node.publish_rate_hz:g} Hz, ratio '
            f'1:{self.rt.model.derived.ratio:.6g}; waiting for '
            f'{self.resolve_topic_name(REFERENCE_TOPIC)} (stamped) or '
            f'{self.resolve_topic_name(COMMAND_TOPIC)}')
        if self.rt.compensator is None:
            self.get_logger().error(
                f'feed-forward unavailable ({self.rt.compensation_error}); no corrections')

    # ---- read-only views (tests, diagnostics) --------------------------------------------
    @property
    def sim(self) -> Any:
        """The pipeline's Simulator."""
        return self.rt.sim

    @property
    def compensator(self) -> Any:
        return self.rt.compensator

    @property
    def parameters_pending(self) -> bool:
        """An accepted parameter set is still being built (not swapped in yet)."""
        return self._building is not None

    # ---- helpers -------------------------------------------------------------------------
    def _check_overrides(self) -> None:
        """Parameters given to this node (params file, ``-p``, ``parameter_overrides``) that
        it does not declare: a misspelt model or QoS key raises :class:`ConfigError` naming
        it, with the closest declared name; any other unknown name is logged and ignored
        (a ``/**`` block shared by several nodes may hold theirs)."""
        declared = {name: None for name in MODEL_PARAMETER_NAMES}
        unknown = sorted(n for n in self._parameter_overrides if not self.has_parameter(n))
        for name in unknown:
            head = name.split('.', 1)[0]
            hint = suggest_name(name, declared)
            if head in SECTIONS or head == 'qos_overrides' or hint:
                if head == 'qos_overrides':
                    hint = suggest_name(name, {n: None for n in self._qos_parameter_names()})
                raise ConfigError(name, 'unknown parameter of this node' + hint)
            self.get_logger().warning(f'ignoring parameter {name!r}: not a parameter of '
                                      f'{self.get_name()}')

    def _qos_parameter_names(self) -> list[str]:
        return ['qos_overrides.' + n for n in self.get_parameters_by_prefix('qos_overrides')]

    def _guard(self, callback: Any) -> Any:
        """Timer callback that ends quietly when Ctrl-C / SIGTERM shut the context down
        while it runs (a publish on a dying context raises); other errors propagate."""
        context = self.context

        def guarded() -> None:
            try:
                callback()
            except Exception:
                if context.ok():
                    raise
        return _timer_signature(guarded)

    @staticmethod
    def _new_window() -> dict[str, Any]:
        return dict(wall_ns=time.monotonic_ns(), busy_ns=0, max_busy_ns=0, calls=0,
                    errors=0)

    def _window_start(self) -> dict[str, Any]:
        w = self._new_window()
        w['sim_t'] = self.rt.sim.t
        w['steps'] = self.rt.counters['steps']
        w['predictions'] = self.rt.counters['predictions']
        return w

    def _busy(self, t0: int) -> None:
        busy = time.thread_time_ns() - t0
        w = self._window
        w['busy_ns'] += busy
        w['calls'] += 1
        if busy > w['max_busy_ns']:
            w['max_busy_ns'] = busy

    def _warn(self, cause: str, text: str) -> None:
        """Log ``text`` at most once per LOG_THROTTLE_S for each ``cause`` (a command
        rejection never hides a parameter rejection or a simulation error)."""
        self.last_error = text
        line = self._throttle(cause, text)
        if line:
            self.get_logger().warning(line)

    # ---- stamped references (event-driven) -----------------------------------------------
    def _on_reference(self, msg: JointState) -> None:
        """One stamped sample: validated, pushed through the pipeline, its correction(s)
        and prediction(s) published, all in this callback."""
        t0 = time.thread_time_ns()
        if self._building is not None:
            self._swap_prepared()
        pos = msg.position
        if len(pos) == 0:
            self._reject_message('empty_position', 'no position[0]')
            return
        names = msg.name
        if len(names) and names[0] != self._worm_input_joint:
            self._reject_message('wrong_joint', f'joint {names[0]!r}; this node takes '
                                 f'{self._worm_input_joint!r}')
            return
        st = msg.header.stamp
        stamp = st.sec * _NS + st.nanosec
        if self._mode != 'stamped':
            self._enter_mode('stamped')
        x = pos[0]
        out = self.rt.push(stamp, x, now_ns=self._clock.now().nanoseconds)
        self._handle(out, REFERENCE_TOPIC, stamp, value=x)
        self._busy(t0)

    def _reject_message(self, reason: str, text: str) -> None:
        self.counters['rejected_' + reason] += 1
        self._warn('reference_' + reason, f'rejected {REFERENCE_TOPIC}: {reason} ({text}); '
                   f'{self.counters["rejected_" + reason]} so far')

    def _enter_mode(self, mode: str) -> None:
        """Start the timers of an input path, stop those of the other."""
        self._mode = mode
        if mode == 'stamped':
            self._tick_timer.cancel()
            self._watch_timer.reset()
        else:
            self._watch_timer.cancel()
            self._hold_timer.cancel()
            self._last_mono_ns = 0
            self._tick_timer.reset()

    def _on_watch(self) -> None:
        """Slow timer of the stamped path: notices a paused stream (held output starts).
        After a stall of this node itself (the watch came late) it waits one more period:
        the samples queued meanwhile must be taken first, or they would be found stale."""
        if self._building is not None:
            self._swap_prepared()
        now = self._clock.now().nanoseconds          # the timer's own clock
        last, self._last_watch_ns = self._last_watch_ns, now
        if now - last > 2 * WATCH_PERIOD * _NS:
            return
        if self._hold_timer.is_canceled():
            self._handle(self.rt.hold(now), '', 0)

    def _on_hold(self) -> None:
        """At node.publish_rate_hz while the stamped stream is stale: the held prediction."""
        t0 = time.thread_time_ns()
        self._handle(self.rt.hold(self._clock.now().nanoseconds), '', 0)
        self._busy(t0)

    # ---- Float64 commands (tick-sampled) ---------------------------------------------------
    def _on_command(self, msg: Float64) -> None:
        """O(1): validate and queue the command (RealtimePredictor.push_command) with its
        reception time: the /clock reading with use_sim_time, else the monotonic clock."""
        t0 = time.thread_time_ns()
        clock = self._clock
        sim_time = clock.ros_time_is_active
        rt = self.rt
        if sim_time != rt.sim_time:                 # use_sim_time toggled: start afresh
            rt.sim_time = sim_time
            rt.reset()
        if self._mode != 'command':
            self._enter_mode('command')
        now = clock.now().nanoseconds if sim_time else self._monotonic_ns()
        self._handle(rt.push_command(now, msg.data), COMMAND_TOPIC, 0, value=msg.data)
        self._busy(t0)

    def _on_tick(self) -> None:
        t0 = time.thread_time_ns()
        if self._building is not None:
            self._swap_prepared()
        rt = self.rt
        stamp = self._clock.now()
        if rt.sim_time:
            now = stamp.nanoseconds
        else:
            now = self._monotonic_ns()
            if self._last_mono_ns:
                missed = (now - self._last_mono_ns + self._period_ns // 2) \
                    // self._period_ns - 1
                if missed > 0:
                    self.counters['missed_ticks'] += missed
            self._last_mono_ns = now
        out = rt.tick(now)
        if out.predictions or out.corrections or out.events:
            self.counters['ticks'] += 1
            # on the wall clock the pipeline runs on the monotonic clock: the JointState
            # carries the ROS time of the tick
            self._handle(out, '', 0, stamp_ns=None if rt.sim_time else stamp.nanoseconds)
            if rt.compensator is not None and self._pub_ff.get_subscription_count():
                self._f_ff.data = rt.last_delta   # the correction of the newest sample
                self._pub_ff.publish(self._f_ff)
        self._busy(t0)

    # ---- output ----------------------------------------------------------------------------
    def _handle(self, out: Output, topic: str, stamp: int, value: float | None = None,
                stamp_ns: int | None = None) -> None:
        """Log what the pipeline reported and publish its corrections and predictions.
        ``stamp_ns``: publish the predictions with this stamp instead of their own."""
        if out.rejected is not None:
            r = out.rejected.value
            what = f'stamp {stamp} ns, value {value!r}' if topic == REFERENCE_TOPIC \
                else f'value {value!r}'
            n = self.rt.counters['rejected_' + r]
            self._warn(f'{topic}_{r}', f'rejected {topic} ({what}): {r}; {n} so far')
        for e in out.events:
            if e.level == 'info':
                self.get_logger().info(e.message)
            else:
                self._warn(e.kind, e.message)
                if e.kind == 'simulation_error':
                    self._window['errors'] += 1
        if out.corrections and self._mode == 'stamped':
            self._publish_corrections(out.corrections)
        preds = out.predictions
        if preds:
            check = self._check
            for p in preds:
                check.predicted_ns(p.stamp_ns if stamp_ns is None else stamp_ns, p.theta)
            if self._pub_js.get_subscription_count() or \
                    self._pub_err.get_subscription_count() or \
                    self._pub_worm.get_subscription_count():
                for p in preds:
                    self._publish_prediction(p, p.stamp_ns if stamp_ns is None else stamp_ns)
            if preds[-1].held and self._mode == 'stamped':
                self.counters['held_predictions'] += len(preds)
        if self._mode == 'stamped':
            hold = self._hold_timer
            if out.stale:
                if hold.is_canceled():
                    hold.reset()
            elif not hold.is_canceled():
                hold.cancel()

    def _on_measured(self, msg: JointState) -> None:
        """Encoder angles: residual measured - predicted at the message's stamp (the
        reception time if unstamped) on ~/prediction_residual; the model check rejects and
        counts bad samples."""
        st = msg.header.stamp
        stamp = st.sec * _NS + st.nanosec
        if stamp == 0:
            stamp = self._clock.now().nanoseconds
        try:
            joints, residual = self._check.measured_message_ns(stamp, msg.name, msg.position)
        except ValueError as exc:
            self._warn('measured_rejected', f'rejected {MEASURED_TOPIC}: {exc}')
            return
        if self._pub_res.get_subscription_count():
            r = self._res
            r.header.stamp.sec, r.header.stamp.nanosec = divmod(stamp, _NS)
            r.name = joints
            r.position = residual.tolist()
            self._pub_res.publish(r)

    def _publish_corrections(self, corrections: list) -> None:
        """Stamped path: ~/compensated_command and ~/feedforward for each correction."""
        cc, ff = self._cc, self._f_ff
        pub_cc = self._pub_cc.get_subscription_count()
        pub_ff = self._pub_ff.get_subscription_count()
        for c in corrections:
            if pub_cc:
                cc.header.stamp.sec, cc.header.stamp.nanosec = divmod(c.stamp_ns, _NS)
                cc.position[0] = c.theta1_ref + c.delta
                self._pub_cc.publish(cc)
            if pub_ff:
                ff.data = c.delta
                self._pub_ff.publish(ff)

    def _publish_prediction(self, p: Prediction, stamp_ns: int) -> None:
        js = self._js
        if self._pub_js.get_subscription_count():
            js.header.stamp.sec, js.header.stamp.nanosec = divmod(stamp_ns, _NS)
            js.position = p.position
            js.velocity = p.velocity
            js.effort = p.effort
            self._pub_js.publish(js)
        if self._pub_err.get_subscription_count():
            self._f_err.data = p.positioning_error
            self._pub_err.publish(self._f_err)
        if self._pub_worm.get_subscription_count():
            self._f_worm.data = p.worm_error
            self._pub_worm.publish(self._f_worm)

    # ---- parameters --------------------------------------------------------------------------
    def _evaluate(self, params: list[Parameter]) -> tuple[str, Config | None]:
        """('', candidate) if the model parameters in ``params`` form a usable set, else
        (reason, None).  Non-model parameters (qos_overrides, use_sim_time) are left to
        rclpy.  The result of the last call is remembered (pre-set and on-set callbacks
        see the same list)."""
        key = tuple((p.name, p.type_, repr(p.value)) for p in params)
        if self._evaluated is not None and self._evaluated[0] == key:
            return self._evaluated[1], self._evaluated[2]
        overrides = {}
        reason = ''
        for p in params:
            if not is_model_parameter(p.name):
                continue
            if self.describe_parameter(p.name).read_only:
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
                candidate = self.config.replace(overrides)
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
            self.counters['rejected_parameter_sets'] += 1
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
        """Accepted: the new pipeline configuration (compensator design, the simulator's
        trial) is prepared in a worker thread; :meth:`_swap_prepared` swaps it in on the
        executor thread (guard condition), between two samples."""
        cfg, self._accepted = self._accepted, None
        if cfg is None:
            return
        self.config = cfg
        self.counters['accepted_parameter_sets'] += 1
        self._building = self._builder.submit(self.rt.prepare, cfg)
        self._swap_timer.reset()
        names = ', '.join(p.name for p in params if is_model_parameter(p.name))
        self.get_logger().info(f'parameters accepted: {names}')

    def _swap_prepared(self) -> None:
        fut = self._building
        if fut is None or not fut.done():
            return
        self._building = None
        self._swap_timer.cancel()
        try:
            prepared = fut.result()
            if prepared.config is self.config:   # else a newer set superseded it
                self.rt.reconfigure(prepared)
        except (ConfigError, ValueError) as exc:
            self.counters['parameter_build_errors'] += 1
            self._warn('parameters', f'could not apply parameters: {exc}')

    # ---- diagnostics -------------------------------------------------------------------------
    def diagnostic_statuses(self) -> list[diag.DiagnosticStatus]:
        """The statuses of /diagnostics (resets the per-window figures)."""
        w, self._window = self._window, self._window_start()
        now = self._window
        wall = max(1e-9, (now['wall_ns'] - w['wall_ns']) * 1e-9)
        rt, c, rc = self.rt, self.counters, self.rt.counters
        steps = now['steps'] - w['steps']
        n_pred = now['predictions'] - w['predictions']
        sim = rt.sim
        st = sim.stats
        name, hw = self.get_name(), 'worm_gear_sim'
        if not rt.started:
            level, msg = diag.WARN, (f'waiting for the first {REFERENCE_TOPIC} or '
                                     f'{COMMAND_TOPIC}')
        elif w['errors']:
            level, msg = diag.ERROR, f'{w["errors"]} simulation error(s): {rt.last_error}'
        elif rt.stale:
            level, msg = diag.WARN, ('input stream stale: the reference rests at its last '
                                     'value; publishing the held prediction')
        else:
            level, msg = diag.OK, 'running'
        sim_vals = {
            'input': self._mode or 'none', 'time_base': 'sim' if rt.sim_time else 'wall',
            'simulated_time_s': sim.t, 'stale': rt.stale,
            'real_time_factor': (now['sim_t'] - w['sim_t']) / wall,
            'steps_per_prediction': steps / n_pred if n_pred else 0.0,
            'compute_load': w['busy_ns'] * 1e-9 / wall,
            'max_callback_cpu_ms': w['max_busy_ns'] * 1e-6, 'callbacks': w['calls'],
            'ticks': c['ticks'], 'missed_ticks': c['missed_ticks'],
            'held_predictions': c['held_predictions'],
            'newton_subdivisions': st['subdivision_events'], 'newton_substeps': st['substeps'],
            'max_newton_solves_per_step': st['max_solves_per_step'],
            **{k: rc[k] for k in ('predictions', 'steps', 'overruns', 'dropped_time_ns',
                                  'resyncs', 'clock_restarts', 'stale_events',
                                  'late_for_simulation', 'simulation_errors')},
            'last_error': rt.last_error,
        }
        node_rejects = sum(c[f'rejected_{r}'] for r in NODE_REJECT_REASONS)
        rejected = rc['rejected_samples'] + node_rejects + c['rejected_parameter_sets']
        in_vals = {k: rc[k] for k in (
            'samples_received', 'samples_accepted', 'rejected_samples',
            *(f'rejected_{r}' for r in REJECT_REASONS),
            'commands_received', 'commands_used', 'commands_merged', 'commands_restamped',
            'commands_dropped', 'merged_samples', 'rest_samples', 'stream_relocks',
            'stream_outliers', 'reconfigurations')}
        in_vals.update({f'rejected_{r}': c[f'rejected_{r}'] for r in NODE_REJECT_REASONS})
        in_vals.update({k: c[k] for k in ('rejected_parameter_sets', 'accepted_parameter_sets',
                                          'parameter_build_errors')})
        in_vals['command_timing'] = self.config.node.command_timing
        in_vals['stale_after_ms'] = rt.stale_after_ns * 1e-6
        in_vals['last_stamp_ns'] = rt.last_stamp_ns
        in_vals['last_error'] = self.last_error
        in_level = diag.WARN if (rejected or rt.stale) else diag.OK
        in_msg = ', '.join(m for m in (
            f'{rejected} rejected input(s)' if rejected else '',
            'stream stale' if rt.stale else '') if m) or 'ok'
        comp = rt.compensator
        ff_level = diag.OK if comp is not None and not rc['compensation_errors'] \
            else diag.ERROR
        ff_vals = {'available': comp is not None,
                   'applied_to_prediction': rt.apply_compensation,
                   'preview_time_s': rt.preview_ns * 1e-9,
                   'pending_corrections': rt.pending,
                   'corrections': rc['corrections'],
                   'corrections_dropped': rc['corrections_dropped'],
                   'last_correction_rad': rt.last_delta,
                   'compensation_errors': rc['compensation_errors'],
                   'error': rt.compensation_error}
        return [
            diag.status(name, 'simulation', level, msg, sim_vals, hw),
            diag.status(name, 'inputs', in_level, in_msg, in_vals, hw),
            diag.status(name, 'feedforward', ff_level,
                        'ok' if ff_level == diag.OK else (rt.compensation_error or
                                                          'compensation errors'), ff_vals, hw),
            self._check_status(name, hw),
        ]

    def _check_status(self, name: str, hw: str) -> diag.DiagnosticStatus:
        """The live model check (measured_joint_states vs the prediction)."""
        st = self._check.status_ns(self._clock.now().nanoseconds)
        level = {'OK': diag.OK, 'WARN': diag.WARN, 'STALE': diag.STALE}[st.level]
        return diag.status(name, 'model check', level, st.message, st.values, hw)

    def publish_diagnostics(self) -> None:
        if self._building is not None:
            self._swap_prepared()
        self._pub_diag.publish(diag.array(self._clock.now().to_msg(),
                                          self.diagnostic_statuses()))

    def destroy_node(self) -> None:
        self._builder.shutdown(wait=False, cancel_futures=True)
        super().destroy_node()


def make_executor(kind: str, context: Any = None) -> Any:
    """'events' (rclpy.experimental.EventsExecutor) or 'single_threaded'."""
    if kind == 'events':
        from rclpy.experimental import EventsExecutor
        return EventsExecutor(context=context)
    if kind == 'single_threaded':
        return SingleThreadedExecutor(context=context)
    raise ValueError(f'unknown executor {kind!r} (events | single_threaded)')


def spin_until_shutdown(executor: Any, context: Any = None, slice_s: float = 1.0) -> None:
    """Spin until the context shuts down (Ctrl-C, SIGTERM, rclpy.shutdown).

    The loop runs ``spin_until_future_complete`` on a future that never completes, with a
    finite ``slice_s``: with ros-rclpy 9.1.2 from PyPI, ``EventsExecutor.spin()`` (an
    unbounded deadline) busy-waits at 100 % CPU and never dispatches wall-clock timers, while
    a bounded deadline works (0.1 core for an empty 1 kHz timer).  Each slice processes
    every event until its deadline, so this is not a ``spin_once`` loop.
    """
    ctx = context if context is not None else rclpy.get_default_context()
    never = Future()
    while ctx.ok():
        executor.spin_until_future_complete(never, timeout_sec=slice_s)


def _parse_args(argv: list[str]) -> argparse.Namespace:
    ap = argparse.ArgumentParser(
        prog='worm_gear_sim_node',
        description='Worm-gear drive model in real time (parameters: --ros-args '
                    '--params-file config/worm_gear_sim.yaml).')
    ap.add_argument('--executor', choices=('events', 'single_threaded'), default=None,
                    help='override the node.executor parameter')
    return ap.parse_args(argv)


#: Errors of the parameters given at start-up: one line and exit code 2 (``startup``).
#: ValueError covers numerically unusable values (LinAlgError is one) until the core proves
#: a set usable itself.
STARTUP_CONFIG_ERRORS = (ConfigError, ParameterException, ValueError, ArithmeticError)


def main(args: list[str] | None = None) -> int:
    """Entry point of ``worm_gear_sim_node`` and ``python -m worm_gear_sim.node`` (through
    :func:`worm_gear_sim.ros.startup.node_main`, which installs the signal handlers before
    the heavy imports).

    Returns 0 after Ctrl-C / SIGTERM at any time (no traceback), 2 after one line naming a
    configuration error (broken, missing or unreadable params file, malformed ``-p``,
    unknown or misspelt parameter, invalid or unusable value).  Portable across rclpy 7
    (Jazzy) and 9 (Kilted): ``rclpy.init`` + ``try/finally rclpy.try_shutdown()``.
    """
    startup.install_signal_handlers()
    argv = list(sys.argv if args is None else args)
    bad = startup.check_params_files(argv)
    if bad:
        return startup.config_error(bad)
    try:   # parses --ros-args, params files included: errors end here, before rclpy.init
        rest = remove_ros_args(args=argv)
    except RCLError as exc:
        return startup.config_error(startup.clean_rcl_message(exc))
    opts = _parse_args(rest[1:])
    try:
        rclpy.init(args=argv)
    except RCLError as exc:
        return startup.config_error(startup.clean_rcl_message(exc))
    startup.set_phase('ros')        # from now on rclpy's handler shuts the context down
    try:
        if startup.signalled():     # a start-up signal whose SystemExit got swallowed
            return 0
        return _run(opts)
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
    finally:
        startup.set_phase('stopping')
        _quietly(rclpy.try_shutdown)


def _run(opts: argparse.Namespace) -> int:
    context = rclpy.get_default_context()
    try:
        node = WormGearSimNode()
    except STARTUP_CONFIG_ERRORS as exc:
        if not context.ok():        # a signal shut the context down during declaration
            return 0
        return startup.config_error(f'invalid parameters: {exc}')
    except Exception:
        if not context.ok():
            return 0
        raise
    if not context.ok() or startup.signalled():   # Ctrl-C / SIGTERM during the build
        _quietly(node.destroy_node)
        return 0
    kind = opts.executor or node.config.node.executor
    executor = make_executor(kind)
    # Move everything allocated so far (numba, scipy, rclpy: a large heap) out of the
    # cyclic GC's reach: full collections of it took milliseconds and showed up as missed
    # ticks.
    gc.collect()
    gc.freeze()
    executor.add_node(node)
    node.get_logger().info(f'spinning with the {kind} executor')
    try:
        spin_until_shutdown(executor, context)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if context.ok():
            raise
        # The signal handler shut the context down while a callback was running (e.g. a
        # publish on a context being torn down): a normal shutdown.
    finally:
        startup.set_phase('stopping')
        _quietly(executor.shutdown, 1.0)
        _quietly(node.destroy_node)
    return 0


def _quietly(fn: Any, *args: Any) -> None:
    try:
        fn(*args)
    except Exception:  # noqa: BLE001 - best effort at shutdown
        pass


if __name__ == '__main__':
    sys.exit(main())
