# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""ROS 2 node ``worm_gear_sim``: the worm-gear model running in real time beside a servo.

:class:`WormGearSimNode`, an I/O shell around the core's ``RealtimePredictor``: topics,
QoS and timers, each callback handing its message to the core in a line.  It owns its
parts as members: ``publishing`` (:mod:`.publishers`), ``adaptation`` (:mod:`.adaptation`),
``trajectories`` (:mod:`.trajectory_bridge`) and the parameter updates
(:mod:`.param_updates`).  Topics, parameters and diagnostics: docs/node.md; run it with
``worm_gear_sim_node --ros-args --params-file config/worm_gear_sim.yaml``.
"""

from __future__ import annotations

import time
import warnings
from typing import Any

from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from ..adaptation.warmup import warm_up
from ..config.usable import Config, config_from_mapping
from ..dynamics.load import ElasticLimitCheck
from ..dynamics.modal import StepResolutionWarning
from ..realtime import Output, RealtimePredictor
from ..realtime.model_check import ModelCheck
from ..records.topics import (
    COMMAND_TOPIC,
    DIAGNOSTICS_TOPIC,
    LOAD_TORQUE_TOPIC,
    MEASURED_TOPIC,
    REFERENCE_TOPIC,
    RESIDUAL_TOPIC,
)
from ..schema.sections import NODE_NAME
from . import diagnostics as diag
from .adaptation import NodeAdaptation
from .callbacks import (
    NS,
    LogThrottle,
    SameNameWatch,
    guard_message,
    guard_timer,
    one_joint_sample,
    stamp_ns,
)
from .clock_guard import guard_clock_source
from .interface import NODE_REJECT_REASONS, REFERENCE_DEPTH
from .param_updates import ParameterUpdates
from .params_bridge import check_overrides, declare_config, file_defaults, parameter_type
from .publishers import PredictionPublishers
from .ready import log_ready
from .statuses import CallbackLoad, backdrive_status, model_check_status, node_statuses
from .trajectory_bridge import TrajectoryBridge, trajectory_status

__all__ = ['WormGearSimNode', 'WATCH_PERIOD']

LOG_THROTTLE_S = 2.0   # at most one log line per cause every 2 s (bursts of bad input)
WATCH_PERIOD = 0.02    # s: the slow timer that notices a paused stamped stream
# s: lateness allowed to a stamped sample before the stream is declared stale (held output,
# rest samples): scheduling stalls of a loaded sender shorter than this change nothing
STALE_MARGIN = 0.1


class WormGearSimNode(Node):
    """Real-time worm-gear prediction; see the module docstring for the interface.

    ``defaults`` sets the declaration defaults (``--params-file`` and ``parameter_overrides``
    still win); ``adaptation`` False: no live adaptation member (``adaptation.enabled`` is
    ignored, said once); other keyword arguments (``context``, ``parameter_overrides``,
    ``cli_args``, ``namespace``) go to :class:`rclpy.node.Node`.  Raises
    :class:`ConfigError` when the declared values do not form a usable configuration or
    name an unknown parameter.
    """

    def __init__(self, node_name: str = NODE_NAME, *, defaults: Config | None = None,
                 adaptation: bool = True, **kwargs: Any):
        super().__init__(node_name, **kwargs)
        self._clock = self.get_clock()
        self._monotonic_ns = time.monotonic_ns    # the wall time base (tests replace it)
        values = declare_config(self, defaults if defaults is not None else file_defaults())
        types = {name: parameter_type(v) for name, v in values.items()}
        cfg = config_from_mapping(values, source='ROS parameters')
        with warnings.catch_warnings():     # logged below through ROS, not Python's stderr
            warnings.simplefilter('ignore', StepResolutionWarning)
            self.rt = RealtimePredictor(cfg, sim_time=self._clock.ros_time_is_active,
                                        stale_margin=STALE_MARGIN)
            # every kernel this configuration runs, before subscribing and "ready" (.warmup)
            self.kernels = warm_up(cfg, adaptation=adaptation)
        self._worm_input_joint = cfg.node.joint_names[0]

        self.counters: dict[str, Any] = dict(
            **{f'rejected_{r}': 0 for r in NODE_REJECT_REASONS},
            ticks=0, missed_ticks=0, held_predictions=0, rejected_parameter_sets=0,
            accepted_parameter_sets=0, parameter_build_errors=0, rejected_clock_messages=0,
            publish_failures=0, same_name_nodes=0, loads_beyond_elastic_limit=0)
        self._elastic = ElasticLimitCheck()
        self.last_error = ''
        self._throttle = LogThrottle(LOG_THROTTLE_S)
        self.load = CallbackLoad(self.rt)
        self._mode = ''                          # 'stamped' | 'command' once input came
        self._last_mono_ns = 0
        self._last_watch_ns = 0
        self._period_ns = int(round(1e9 / cfg.node.publish_rate_hz))
        guard_clock_source(self, self._on_bad_clock)
        self._check = ModelCheck.of(cfg.node)
        self._antenna_joint = cfg.node.joint_names[3]
        self.publishing = PredictionPublishers(self, cfg.node.joint_names, self._publish,
                                               cfg.node.float64_outputs)
        self._create_monitoring_publishers()
        self._create_subscriptions()
        # trajectories of the worm input joint (a ros2_control joint_trajectory_controller's
        # language): compensated whole on a worker thread (.trajectory_bridge)
        self.trajectories = TrajectoryBridge(
            self, lambda: {self.rt.model.config.node.joint_names[0]: self.rt.model}, self.counters,
            self._warn, self._publish, self._guard_message)
        check_overrides(self)
        self._create_timers(cfg)
        self.adaptation = NodeAdaptation(self, self.rt, cfg, self._warn, self._publish,
                                         self._rebuild) if adaptation else None
        # parameter sets: validated on the parameter service, built in a worker thread
        hooks = {} if self.adaptation is None else dict(
            pipeline=self.adaptation.pipeline, swapped=self.adaptation.swapped)
        self._params = ParameterUpdates(self, self.rt, cfg, types, self.counters, self._warn,
                                        self._guard, **hooks)
        log_ready(self, cfg, self.kernels)

    def _create_monitoring_publishers(self) -> None:
        """/diagnostics, ~/prediction_residual and its message."""
        self._pub_diag = self.create_publisher(diag.DiagnosticArray, DIAGNOSTICS_TOPIC, 1)
        self._pub_res = self.create_publisher(JointState, RESIDUAL_TOPIC, QoSProfile(depth=10))
        self._res = JointState()

    def _create_subscriptions(self) -> None:
        """The inputs: Float64 commands, encoder angles, load torques, stamped references."""
        overrides = QoSOverridingOptions.with_default_policies
        reliable = QoSProfile(depth=REFERENCE_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
        for msg_type, topic, callback, qos in (
                (Float64, COMMAND_TOPIC, self._on_command, qos_profile_sensor_data),
                (JointState, MEASURED_TOPIC, self._on_measured, qos_profile_sensor_data),
                (JointState, LOAD_TORQUE_TOPIC, self._on_load, reliable),
                (JointState, REFERENCE_TOPIC, self._on_reference, reliable)):
            self.create_subscription(msg_type, topic, self._guard_message(callback), qos,
                                     qos_overriding_options=overrides())

    def _create_timers(self, cfg: Config) -> None:
        """The tick runs only on the Float64 path, the held output only while the stamped
        stream is stale; the watch is slow.  They start cancelled.  Then diagnostics, and
        the look for another node of this name (discovery needs a moment: a few times)."""
        period = 1.0 / cfg.node.publish_rate_hz
        self._tick_timer = self.create_timer(period, self._guard(self._on_tick))
        self._hold_timer = self.create_timer(period, self._guard(self._on_hold))
        self._watch_timer = self.create_timer(WATCH_PERIOD, self._guard(self._on_watch))
        for t in (self._tick_timer, self._hold_timer, self._watch_timer):
            t.cancel()
        self._diag_timer = self.create_timer(cfg.node.diagnostic_period,
                                             self._guard(self.publish_diagnostics))
        self.same_names = SameNameWatch(self, self.counters, self._guard)

    # ---- read-only views (tests, diagnostics) --------------------------------------------
    @property
    def config(self) -> Config:
        """The parameter set in force (the last one accepted)."""
        return self._params.config

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
        return self._params.pending

    # ---- helpers -------------------------------------------------------------------------
    def _rebuild(self) -> None:
        """The declared set prepared again and swapped in (the adaptation's reset)."""
        self._params.rebuild()

    def _guard(self, callback: Any) -> Any:
        """Timer callback that ends quietly when the context shuts down (.callbacks)."""
        return guard_timer(self.context, callback)

    def _guard_message(self, callback: Any) -> Any:
        """Subscription callback that ends quietly when the context shuts down."""
        return guard_message(self.context, callback)

    def _publish(self, pub: Any, msg: Any) -> None:
        """``pub.publish(msg)``; a failure is logged (throttled) and counted in
        ``publish_failures`` and the callback goes on: a failed publish (the middleware
        out of resources under load, a context shutting down) never ends the node nor
        leaves the pipeline half-updated (it publishes only after the pipeline's step)."""
        try:
            pub.publish(msg)
        except Exception as exc:  # noqa: BLE001 - RCLError and friends
            if not self.context.ok():
                return                              # shutting down: quiet
            self.counters['publish_failures'] += 1
            self._warn('publish_failed', f'publish on {pub.topic_name} failed '
                       f'({type(exc).__name__}: {exc}); '
                       f'{self.counters["publish_failures"]} so far')

    def _on_bad_clock(self, problem: str) -> None:
        """A /clock message that is no time (rclpy would raise in the executor)."""
        self.counters['rejected_clock_messages'] += 1
        self._warn('clock_rejected', f'rejected /clock message: {problem}; '
                   f'{self.counters["rejected_clock_messages"]} so far')

    def _warn(self, cause: str, text: Any) -> None:
        """Log ``text`` at most once per LOG_THROTTLE_S for each ``cause`` (a command
        rejection never hides a parameter rejection or a simulation error); ``text`` may be
        a callable that makes it, called only when it is logged (a flood costs no text)."""
        line = self._throttle(cause, text)
        self.last_error = text if isinstance(text, str) else line or self.last_error
        if line:
            self.get_logger().warning(line)

    # ---- stamped references (event-driven) -----------------------------------------------
    def _on_reference(self, msg: JointState) -> None:
        """One stamped sample: validated, pushed through the pipeline, its correction(s)
        and prediction(s) published, all in this callback."""
        t0 = time.thread_time_ns()
        self._params.swap_prepared()
        sample = one_joint_sample(msg, msg.position, 'position', self._worm_input_joint, '',
                                  self._reject_message)
        if sample is None:
            return
        stamp, theta1_ref = sample
        if self._mode != 'stamped':
            self._enter_mode('stamped')
        out = self.rt.push(stamp, theta1_ref, now_ns=self._clock.now().nanoseconds)
        self._handle(out, REFERENCE_TOPIC, stamp, value=theta1_ref)
        self.load.busy(t0)

    def _on_load(self, msg: JointState) -> None:
        """One stamped load torque sample on the antenna (effort[0], N m): to the pipeline,
        which applies it in stamp order with the references."""
        sample = one_joint_sample(msg, msg.effort, 'effort', self._antenna_joint, 'load_',
                                  self._reject_load)
        if sample is None:
            return
        stamp, torque = sample
        reason = self.rt.push_load(stamp, torque, now_ns=self._clock.now().nanoseconds)
        if reason is not None:
            n = self.rt.counters['rejected_load_' + reason.value]
            self._warn('load_' + reason.value, f'rejected {LOAD_TORQUE_TOPIC}: '
                       f'load_{reason.value}; {n} so far')
        elif over := self._elastic(self.rt.model, torque):      # taken, implausible
            self.counters['loads_beyond_elastic_limit'] = self._elastic.count
            self._warn('load_elastic', over)

    def _reject_load(self, reason: str, text: str) -> None:
        self.counters['rejected_' + reason] += 1
        self._warn(reason, f'rejected {LOAD_TORQUE_TOPIC}: {reason} ({text}); '
                   f'{self.counters["rejected_" + reason]} so far')

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
        self._params.swap_prepared()
        now = self._clock.now().nanoseconds          # the timer's own clock
        last, self._last_watch_ns = self._last_watch_ns, now
        if now - last > 2 * WATCH_PERIOD * NS:
            return
        if self._hold_timer.is_canceled():
            self._handle(self.rt.hold(now), '', 0)

    def _on_hold(self) -> None:
        """At node.publish_rate_hz while the stamped stream is stale: the held prediction."""
        t0 = time.thread_time_ns()
        self._handle(self.rt.hold(self._clock.now().nanoseconds), '', 0)
        self.load.busy(t0)

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
        self.load.busy(t0)

    def _on_tick(self) -> None:
        t0 = time.thread_time_ns()
        self._params.swap_prepared()
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
            if rt.compensator is not None:
                self.publishing.latest_feedforward(rt.last_delta)
        self.load.busy(t0)

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
                    self.load.error()
        if out.corrections and self._mode == 'stamped':
            self.publishing.corrections(out.corrections)
        preds = out.predictions
        if preds:
            check = self._check
            for p in preds:
                check.predicted_ns(p.stamp_ns if stamp_ns is None else stamp_ns, p.theta)
            self.publishing.predictions(preds, stamp_ns, self.config.node.monitor_rate_hz)
            if preds[-1].held and self._mode == 'stamped':
                self.counters['held_predictions'] += len(preds)
        if self._mode == 'stamped':
            hold = self._hold_timer
            if out.stale:
                if hold.is_canceled():
                    hold.reset()
            elif not hold.is_canceled():
                hold.cancel()
        if self.adaptation is not None:
            self.adaptation.predictions(out, stamp_ns)

    def _on_measured(self, msg: JointState) -> None:
        """Encoder angles (stamped, or at the reception time): the live model check, then
        the adaptation."""
        stamp = stamp_ns(msg.header.stamp) or self._clock.now().nanoseconds
        self._residual(stamp, msg)
        if self.adaptation is not None:
            self.adaptation.measured(stamp, msg.name, msg.position)

    def _residual(self, stamp: int, msg: JointState) -> None:
        """Residual measured - predicted at ``stamp`` on ~/prediction_residual; the model
        check's admission rejects and counts bad and surplus samples (a few comparisons
        each)."""
        check = self._check
        got = check.offer_ns(stamp, msg.name, msg.position)
        if isinstance(got, str):
            self._warn('measured_' + got, lambda: check.rejection_text(got))
            return
        joints, residual = got
        if self._pub_res.get_subscription_count():
            r = self._res
            r.header.stamp.sec, r.header.stamp.nanosec = divmod(stamp, NS)
            r.name = joints
            r.position = residual.tolist()
            self._publish(self._pub_res, r)

    # ---- diagnostics -------------------------------------------------------------------------
    def diagnostic_statuses(self) -> list[diag.DiagnosticStatus]:
        """The statuses of /diagnostics (closes the load window)."""
        name, hardware_id = diag.identity(self)
        margin, at_rest = self.backdrive_margins()
        statuses = node_statuses(name, self.rt, self.counters, self.load, self._mode,
                                 self.config.node.command_timing, self.last_error) + \
            [trajectory_status(name, self.counters, self.trajectories, hardware_id),
             model_check_status(name, self._check, self._clock.now().nanoseconds)] + \
            ([] if self.adaptation is None else [self.adaptation.status(name)]) + \
            [backdrive_status(name, margin, at_rest, self.config.node.backdrive_margin_warn)]
        for s in statuses:
            s.hardware_id = hardware_id
        return statuses

    def backdrive_margins(self) -> tuple[float, float]:
        """(margin at the predicted state's sliding speed, margin at rest): the core's
        DriveModel.backdrive_margin."""
        model = self.rt.model
        sim = self.rt.sim
        now = model.backdrive_margin(sim.state.omega if self.rt.started else None)
        return now, model.backdrive_margin()

    def publish_diagnostics(self) -> None:
        self._params.swap_prepared()
        self.publishing.backdrive_margin(lambda: self.backdrive_margins()[0], self.rt.started)
        self._publish(self._pub_diag, diag.array(self._clock.now().to_msg(),
                                                 self.diagnostic_statuses()))
        if self.adaptation is not None:
            self.adaptation.publish()

    def destroy_node(self) -> None:
        self._params.shutdown()
        if self.adaptation is not None:
            self.adaptation.shutdown()
        self.trajectories.shutdown()
        super().destroy_node()
