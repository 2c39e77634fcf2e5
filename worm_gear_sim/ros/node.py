# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""ROS 2 node ``worm_gear_sim``: the worm-gear model running in real time beside a servo.

A thin adapter around the core: every number it publishes comes from
:class:`~worm_gear_sim.simulation.Simulator`, :func:`~worm_gear_sim.params.derive` and the
feed-forward :class:`~worm_gear_sim.compensation.Compensator`; there is no physics here.

Interface (SI units, rad; relative, remappable names):

* subscribes ``worm_angle_command`` (std_msgs/Float64, theta1 [rad]); sensor-data QoS
  (best effort, keep last 5) by default, overridable by ``qos_overrides.*`` parameters;
* publishes ``joint_states`` (sensor_msgs/JointState: theta1..theta4, rates, shaft torques),
  ``~/positioning_error`` (theta4 - theta1 l_w/r_g), ``~/worm_error`` (theta2 - theta1),
  ``~/feedforward`` (correction to add to theta1) and ``/diagnostics``;
* every model parameter is a declared ROS parameter (dotted names of
  :meth:`Config.to_flat_dict`), validated at run time by :meth:`Config.replace`.

Each accepted command is a sample of the reference at its reception time (the /clock
reading with ``use_sim_time``; on the wall clock as ``node.command_timing`` says); each tick
feeds the samples received since the previous one, in time order, to the compensator and
the simulator, and holds the last one up to the tick (docs/node.md, "Timing").

Run ``worm_gear_sim_node --ros-args --params-file config/worm_gear_sim.yaml`` (or
``python -m worm_gear_sim.node ...``); ``--executor single_threaded`` overrides the
``node.executor`` parameter.
"""

from __future__ import annotations

import argparse
import collections
import copy
import gc
import inspect
import math
import sys
import time
from typing import Any

import rclpy
from rcl_interfaces.msg import SetParametersResult
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy_impl
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from rclpy.qos_overriding_options import QoSOverridingOptions
from rclpy.task import Future
from rclpy.utilities import remove_ros_args
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from ..params import NODE_NAME, SECTIONS, Config, ConfigError, config_from_mapping, load_config
from ..params import _suggest as suggest_name
from ..simulation import SimulationError, Simulator
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

try:  # the node must work (and say so) without the compensator
    from ..compensation import Compensator
    COMPENSATION_IMPORT_ERROR: str = ''
except ImportError as _exc:  # pragma: no cover - depends on the checkout
    Compensator = None  # type: ignore[assignment,misc]
    COMPENSATION_IMPORT_ERROR = f'{type(_exc).__name__}: {_exc}'

__all__ = ['WormGearSimNode', 'LogThrottle', 'CommandQueue', 'main', 'file_defaults',
           'make_executor', 'spin_until_shutdown', 'COMMAND_TOPIC', 'JOINT_STATES_TOPIC',
           'REJECT_REASONS', 'COMMAND_QUEUE_LENGTH', 'STALE_PERIODS', 'StreamClock']

RCLError = _rclpy_impl.RCLError          # RCLInvalidROSArgsError derives from it

COMMAND_TOPIC = 'worm_angle_command'
JOINT_STATES_TOPIC = 'joint_states'
REJECT_REASONS = ('nan', 'inf', 'out_of_range', 'jump')
LOG_THROTTLE_S = 2.0  # at most one log line per cause every 2 s (bursts of bad input)
COMMAND_QUEUE_LENGTH = 16  # accepted commands kept between two ticks (the oldest dropped)
STALE_PERIODS = 3.5  # no command for this many tick periods: the reference is taken as resting
STALE_MAX_INTERVAL = 0.05  # s: sample intervals longer than this are pauses, not a rate
HOLD_EPS = 0.5e-9  # s: 'hold' steps just after the sample time (stamps are whole ns)
STREAM_GAIN = 0.02  # steady alpha of the stream clock (a memory of about 50 samples)
STREAM_WINDOW = 0.35  # periods: a stamp further from its grid slot is an outlier
STREAM_OUTLIER_RATE = 0.3  # re-lock when the outlier rate (1/8 smoothing) exceeds this


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


class StreamClock:
    """The time grid of a steady command stream, recovered from its reception stamps.

    A servo computes its commands on a regular grid; they reach the node's callback after
    a varying delay (DDS and executor latency: p10 ~100 us, p90 ~280 us on the
    development VM), which would reach the feed-forward as time jitter of the samples.  An
    alpha-beta tracker follows the grid's phase and period: each stamp is assigned the
    nearest grid slot after the previous sample (missed commands skip slots) and its
    deviation from the slot corrects phase and period, with least-squares gains while it
    acquires (exact for the first two stamps), then ``gain`` (critically damped).  A
    stamp further than ``window`` periods from its slot is an outlier and does not
    correct the tracker: a late one (a delayed callback) is placed on its slot, an early
    one (commands that queued up behind a stall, or a faster stream) on the previous
    sample's time, so that it replaces that sample's value (CommandQueue and Compensator
    merge equal times).  An outlier rate above ``max_outlier_rate`` (exponentially
    smoothed over ~8 stamps: three outliers in a row, or a new rate or phase) or a pause
    longer than ``max_period_ns`` re-lock: the stamp is taken as it is,
    with its interval as the period guess (if shorter than ``max_period_ns``).  The output
    never decreases while tracking and lags the grid by the mean delay (a constant); a
    stream at an integer fraction of the rate keeps the period (it skips slots).
    """

    def __init__(self, period_ns: float, gain: float = STREAM_GAIN,
                 window: float = STREAM_WINDOW, max_outlier_rate: float = STREAM_OUTLIER_RATE,
                 max_period_ns: float = 5e7) -> None:
        if not (0.0 < gain <= 1.0 and 0.0 < window < 0.5 and period_ns > 0.0
                and 0.0 < max_outlier_rate < 1.0):
            raise ValueError('StreamClock: need period_ns > 0, 0 < gain <= 1, '
                             '0 < window < 0.5, 0 < max_outlier_rate < 1')
        self.gain, self.window = float(gain), float(window)
        self.max_outlier_rate = float(max_outlier_rate)
        self.beta = gain * gain / (2.0 - gain)
        self.period0, self.max_period = float(period_ns), float(max_period_ns)
        self.relocks = 0
        self.outliers = 0                     # outliers placed on their slot, in all
        self.reset()

    def reset(self) -> None:
        self.period = self.period0            # estimated stream period [ns]
        self._t: float | None = None          # last output [ns]
        self._raw: int | None = None          # last reception stamp [ns]
        self._k = 0                           # stamps since the last (re)lock
        self._rate = 0.0                      # smoothed outlier rate

    def __call__(self, ns: int) -> int:
        """The sample time [ns] for a command received at ``ns``."""
        prev, self._raw = self._raw, ns
        t = self._t
        if t is not None and ns - t <= self.max_period:
            m = max(1, round((ns - t) / self.period))        # grid slots since the last
            pred = t + m * self.period
            e = ns - pred
            if abs(e) <= self.window * self.period:
                self._rate *= 0.875
                self._k += 1
                k = self._k
                self._t = pred + max(2.0 * (2 * k - 1) / (k * (k + 1)), self.gain) * e
                self.period += max(6.0 / (k * (k + 1)), self.beta) * e / m
                return int(round(self._t))
            self._rate += 0.125 * (1.0 - self._rate)
            if self._rate <= self.max_outlier_rate:
                self.outliers += 1
                if e > 0.0:               # late (a delayed callback): on its slot
                    self._t = pred
                # early (a stalled stream catching up, a faster one): on the previous
                # sample's time, whose value it replaces (CommandQueue / Compensator merge)
                return int(round(self._t))
        if t is not None:
            self.relocks += 1
        if prev is not None and 0 < ns - prev <= self.max_period:
            self.period = float(ns - prev)
        self._t = float(ns)
        self._k = 1
        self._rate = 0.0
        return ns


class CommandQueue:
    """Accepted commands with their reception stamps, waiting for the next tick.

    ``push`` is O(1); at most ``maxlen`` samples are kept (on overflow the OLDEST is
    dropped and counted in :attr:`dropped`).  :meth:`take` turns them into the samples of
    one tick: times (ns on the node's time base) strictly increasing in (last tick, tick].
    """

    def __init__(self, maxlen: int = COMMAND_QUEUE_LENGTH) -> None:
        self._q: collections.deque = collections.deque(maxlen=maxlen)
        self.dropped = 0          # lost to overflow
        self.merged = 0           # stamp not after the previous sample: value replaced it
        self.restamped = 0        # stamp not after the previous tick: placed later

    def __len__(self) -> int:
        return len(self._q)

    def push(self, base: str, ns: int, value: float) -> None:
        if len(self._q) == self._q.maxlen:
            self.dropped += 1
        self._q.append((base, ns, value))

    def clear(self) -> int:
        """Forget the queued samples; returns how many there were."""
        n = len(self._q)
        self._q.clear()
        return n

    def take(self, base: str, last_ns: int, tick_ns: int, restamp: bool = True
             ) -> list[tuple[int, float]]:
        """The samples of the tick at ``tick_ns`` (previous tick at ``last_ns``):
        ``[(ns, value)]`` in reception order with strictly increasing times.

        * a stamp after the tick stays queued for a later tick, and so does every sample
          received after it;
        * a stamp not after the previous sample's is merged with it (same time, newest
          value): never a zero or negative time step;
        * ``restamp`` (``use_sim_time``): a stamp not after the previous tick (received
          after that tick but before /clock moved on, or a stamp on another time base)
          cannot act in the past: the sample takes the next time the node knows, that of
          the next sample (which supersedes it) or, if none follows, the tick.  Without
          ``restamp`` such a stamp is kept (smoothed stream times; the caller clamps what
          the simulator has already integrated).
        """
        out: list[tuple[int, float]] = []
        late: float | None = None
        q = self._q
        while q:
            b, ns, v = q[0]
            if b != base:
                ns = last_ns
            elif ns > tick_ns:
                break
            q.popleft()
            if out:
                if ns <= out[-1][0]:
                    out[-1] = (out[-1][0], v)
                    self.merged += 1
                else:
                    out.append((ns, v))
            elif restamp and ns <= last_ns:
                self.restamped += 1
                if late is not None:
                    self.merged += 1
                late = v
            else:
                if late is not None:
                    self.merged += 1
                    late = None
                out.append((ns, v))
        if late is not None:
            out.append((tick_ns, late))
        return out


def file_defaults() -> Config:
    """Declaration defaults: the package's YAML (source tree or installed share/), falling
    back to the code defaults, which equal it (a test checks this)."""
    try:
        return load_config()
    except ConfigError:
        return Config()


class WormGearSimNode(Node):
    """Real-time worm-gear prediction; see the module docstring for the interface.

    ``defaults`` sets the declaration defaults (``--params-file`` and ``parameter_overrides``
    still win); other keyword arguments (``context``, ``parameter_overrides``, ``cli_args``,
    ``namespace``) go to :class:`rclpy.node.Node`.  Raises :class:`ConfigError` when the
    declared values do not form a valid configuration.
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
        self.sim = Simulator(cfg, theta1=0.0, t0=0.0)
        self._warm_up()
        self.output_per_input = self.sim.derived.output_per_input

        # --- command input state -----------------------------------------------------------
        self._cmd: float | None = None           # latest accepted command theta1_ref [rad]
        self._queue = CommandQueue()             # accepted commands with reception stamps
        self._stream = StreamClock(1e9 / cfg.node.publish_rate_hz)   # wall-clock stamps
        self._started = False
        self._origin_ns = 0                      # clock reading at t = 0 of the simulator
        self._time_base = ''                     # 'sim' or 'wall' (monotonic)
        self._last_t = 0.0                       # relative time of the last tick [s]
        self._last_ns = 0                        # clock reading of the last tick
        self._last_mono_ns = 0
        self._ref = 0.0                          # last reference sample fed [rad]
        self._ref_now = 0.0                      # reference the last correction applies to
        self._held = 0.0                         # command the simulator holds [rad]
        self._sample_t = 0.0                     # time of the last reference sample [s]
        self._sample_dt = 0.0                    # interval between the last two samples [s]
        self._comp_t = 0.0                       # time of the compensator's last sample [s]
        self._comp_dirty = False                 # redesigned: re-evaluate without a sample
        self._delta = 0.0                        # last good feed-forward correction [rad]
        self._comp_idle = False                  # compensator paused (no consumer)
        self._pending_config: Config | None = None

        self.counters: dict[str, Any] = dict(
            commands_received=0, commands_used=0, commands_superseded=0, commands_dropped=0,
            commands_merged=0, commands_restamped=0, max_commands_per_tick=0,
            rejected_commands=0, **{f'rejected_{r}': 0 for r in REJECT_REASONS},
            ticks=0, missed_ticks=0, overruns=0, dropped_time=0.0, clock_backwards=0,
            simulation_errors=0, compensation_errors=0, rejected_parameter_sets=0,
            accepted_parameter_sets=0, steps=0, max_steps_per_tick=0)
        self.last_error = ''
        self._throttle = LogThrottle(LOG_THROTTLE_S)
        self._window = self._new_window()

        # --- feed-forward --------------------------------------------------------------
        self.compensator = None
        self.compensation_error = COMPENSATION_IMPORT_ERROR
        self._make_compensator(cfg)

        # --- ROS interfaces --------------------------------------------------------------
        qos_state = QoSProfile(depth=10)
        overrides = QoSOverridingOptions.with_default_policies()
        self._pub_js = self.create_publisher(JointState, JOINT_STATES_TOPIC, qos_state,
                                             qos_overriding_options=overrides)
        self._pub_err = self.create_publisher(Float64, '~/positioning_error', qos_state)
        self._pub_worm = self.create_publisher(Float64, '~/worm_error', qos_state)
        self._pub_ff = self.create_publisher(Float64, '~/feedforward', qos_state)
        self._pub_diag = self.create_publisher(diag.DiagnosticArray, '/diagnostics', 1)
        self._sub = self.create_subscription(
            Float64, COMMAND_TOPIC, self._on_command, qos_profile_sensor_data,
            qos_overriding_options=QoSOverridingOptions.with_default_policies())

        self._js = JointState()
        self._js.name = list(cfg.node.joint_names)
        self._f_err, self._f_worm, self._f_ff = Float64(), Float64(), Float64()
        self._period_ns = int(round(1e9 / cfg.node.publish_rate_hz))

        self._check_overrides()

        self.add_pre_set_parameters_callback(self._pre_set)
        self.add_on_set_parameters_callback(self._on_set)
        self.add_post_set_parameters_callback(self._post_set)

        self._timer = self.create_timer(1.0 / cfg.node.publish_rate_hz,
                                        self._guard(self._on_tick))
        self._diag_timer = self.create_timer(cfg.node.diagnostic_period,
                                             self._guard(self.publish_diagnostics))
        self.get_logger().info(
            f'ready: dt = {self.sim.dt:g} s, {cfg.node.publish_rate_hz:g} Hz, ratio '
            f'1:{1.0 / self.output_per_input:.6g}; '
            f'waiting for {self.resolve_topic_name(COMMAND_TOPIC)}')
        if self.compensator is None:
            self.get_logger().error(
                f'feed-forward unavailable ({self.compensation_error}); ~/feedforward is not '
                'published and the prediction is uncompensated')

    # ---- helpers -----------------------------------------------------------------------
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
        # The EventsExecutor calls inspect.signature() on every timer callback (to decide on
        # passing TimerInfo); a ready-made signature makes that O(1) (~20 us a tick less).
        guarded.__signature__ = inspect.Signature()  # type: ignore[attr-defined]
        return guarded

    def _warm_up(self) -> None:
        """Run the compiled kernel once so the first tick pays no load/compile time."""
        self.sim.advance_to(10 * self.sim.dt, 0.0)
        self.sim.reset(0.0, 0.0)

    @staticmethod
    def _new_window() -> dict[str, Any]:
        return dict(wall_ns=time.monotonic_ns(), busy_ns=0, max_busy_ns=0, sim_time=0.0,
                    ticks=0, steps=0, overruns=0, errors=0)

    def _make_compensator(self, cfg: Config) -> None:
        if Compensator is None:
            self.compensator = None
            return
        try:
            self.compensator = Compensator(cfg)
            self.compensation_error = ''
        except Exception as exc:  # noqa: BLE001 - any failure: keep running uncompensated
            self.compensator = None
            self.compensation_error = f'{type(exc).__name__}: {exc}'
            self.get_logger().error(f'compensator could not be built: {self.compensation_error}')

    def _redesign_compensator(self, cfg: Config) -> None:
        """New plant or compensation settings: redesign, keeping the reference history when
        the compensator can (``reconfigure``), else rebuild and restart it at the command."""
        comp = self.compensator
        if comp is not None and hasattr(comp, 'reconfigure'):
            try:
                comp.reconfigure(cfg)
                self._comp_dirty = True
                return
            except Exception as exc:  # noqa: BLE001 - fall back to a fresh compensator
                self._compensation_failed(exc)
        self._make_compensator(cfg)
        self._comp_dirty = True
        if self.compensator is not None and self._started:
            try:
                self.compensator.reset(self._ref, self._last_t)
                self._comp_t = self._last_t
            except Exception as exc:  # noqa: BLE001
                self._compensation_failed(exc)

    def _warn(self, cause: str, text: str) -> None:
        """Log ``text`` at most once per LOG_THROTTLE_S for each ``cause`` (a command
        rejection never hides a parameter rejection or a simulation error)."""
        self.last_error = text
        line = self._throttle(cause, text)
        if line:
            self.get_logger().warning(line)

    # ---- command input ---------------------------------------------------------------
    def _on_command(self, msg: Float64) -> None:
        """O(1): validate, stamp and queue the command (a sample of theta1_ref at its
        reception time: the /clock reading with use_sim_time, else the monotonic clock as
        node.command_timing says); the physics runs only in the tick."""
        c = self.counters
        c['commands_received'] += 1
        v = msg.data
        reason = ''
        if math.isnan(v):
            reason = 'nan'
        elif math.isinf(v):
            reason = 'inf'
        elif abs(v) > self.config.node.max_command_abs:
            reason = 'out_of_range'
        elif self._cmd is not None and abs(v - self._cmd) > self.config.node.max_command_jump:
            reason = 'jump'
        if reason:
            c['rejected_commands'] += 1
            c['rejected_' + reason] += 1
            limit = {'out_of_range': f' (|theta1| > node.max_command_abs = '
                                     f'{self.config.node.max_command_abs:g} rad)',
                     'jump': f' (|change| > node.max_command_jump = '
                             f'{self.config.node.max_command_jump:g} rad from {self._cmd!r})'
                     }.get(reason, '')
            self._warn('command_' + reason, f'rejected worm_angle_command {v!r}: {reason}{limit}; '
                       f'{c["rejected_commands"]} rejected so far')
            return
        self._cmd = v
        clock = self._clock
        if clock.ros_time_is_active:
            self._queue.push('sim', clock.now().nanoseconds, v)
        else:
            timing = self.config.node.command_timing
            if timing == 'reception':
                self._queue.push('wall', self._monotonic_ns(), v)
            elif timing == 'stream':
                self._queue.push('wall', self._stream(self._monotonic_ns()), v)
            else:               # 'tick': no time of its own, restamped to the next tick
                self._queue.push('wall', self._last_ns, v)

    # ---- the tick ---------------------------------------------------------------------
    def _now(self) -> tuple[str, int, Any]:
        """(time base, nanoseconds on that base, ROS stamp)."""
        clock = self._clock
        now = clock.now()
        if clock.ros_time_is_active:
            return 'sim', now.nanoseconds, now
        return 'wall', self._monotonic_ns(), now

    def _on_tick(self) -> None:
        busy0 = time.thread_time_ns()
        base, ns, stamp = self._now()
        if not self._started:
            if self._cmd is None:
                return
            samples = self._start(base, ns)
        else:
            samples = None
            if base != self._time_base:  # use_sim_time toggled: re-anchor, integrate nothing
                self._origin_ns = ns - int(round(self._last_t * 1e9))
                self._last_ns = ns
                self._time_base = base
        t = (ns - self._origin_ns) * 1e-9
        if t <= self._last_t and self.counters['ticks']:
            if t < self._last_t:
                self.counters['clock_backwards'] += 1
                self._warn('clock_backwards', f'clock went backwards ({self._last_t:.9f} s '
                           f'-> {t:.9f} s since start); tick ignored, state kept')
            return                      # no time has passed: nothing new to publish
        if base == 'wall':
            self._count_missed(ns)
        c = self.counters
        if samples is None:
            samples = self._take_samples(base, ns)
        drives = self._feedforward(t, samples)
        steps = self._advance(t, drives)
        self._last_t = t
        self._last_ns = ns
        applied = self.config.node.compensation_applied and self.compensator is not None
        self._publish(stamp, self._ref_now if applied else None, self._delta)
        w = self._window
        w['ticks'] += 1
        w['steps'] += steps
        busy = time.thread_time_ns() - busy0
        w['busy_ns'] += busy
        if busy > w['max_busy_ns']:
            w['max_busy_ns'] = busy
        c['ticks'] += 1
        c['steps'] += steps
        if steps > c['max_steps_per_tick']:
            c['max_steps_per_tick'] = steps

    def _take_samples(self, base: str, ns: int) -> list[tuple[int, float]]:
        """This tick's command samples (see :meth:`CommandQueue.take`), counted."""
        q, c = self._queue, self.counters
        samples = q.take(base, self._last_ns, ns,
                         restamp=base == 'sim' or self.config.node.command_timing == 'tick')
        c['commands_used'] += len(samples)
        if len(samples) > c['max_commands_per_tick']:
            c['max_commands_per_tick'] = len(samples)
        c['commands_dropped'], c['commands_merged'] = q.dropped, q.merged
        c['commands_restamped'] = q.restamped
        c['commands_superseded'] = q.dropped + q.merged
        return samples

    def _start(self, base: str, ns: int) -> list[tuple[int, float]]:
        """First tick: start at rest at the latest command, which is the sample at t = 0
        (earlier queued commands are superseded by it)."""
        self._time_base = base
        self._origin_ns = ns
        self._last_t = 0.0
        self._last_ns = ns
        q = self._queue
        q.merged += max(q.clear() - 1, 0)
        self.counters['commands_used'] += 1
        self.counters['commands_superseded'] = q.dropped + q.merged
        self.counters['commands_merged'] = q.merged
        self.sim.reset(self._cmd, 0.0)
        self._ref = self._ref_now = self._held = self._cmd
        self._sample_t = self._comp_t = 0.0
        self._sample_dt = 0.0
        if self.compensator is not None:
            try:
                self.compensator.reset(self._cmd, 0.0)
            except Exception as exc:  # noqa: BLE001
                self._compensation_failed(exc)
        self._started = True
        self.get_logger().info(f'first command {self._cmd:.9g} rad: simulation started '
                               f'({base} time)')
        return [(ns, self._cmd)]

    def _count_missed(self, mono: int) -> None:
        """Wall time: periods lost between this tick and the previous one."""
        if self._last_mono_ns:
            gap = mono - self._last_mono_ns
            missed = int((gap + self._period_ns // 2) // self._period_ns) - 1
            if missed > 0:
                self.counters['missed_ticks'] += missed
        self._last_mono_ns = mono

    def _feedforward(self, t: float, samples: list[tuple[int, float]]
                     ) -> list[tuple[float, float]]:
        """Feed the samples, in time order, to the compensator; returns the simulator's
        command samples [(t_i, theta1_i)]: theta1_ref, or theta1_ref + delta when
        ``node.compensation_applied``.

        With ``compensation.preview_time`` P the servo streams its reference P ahead:
        delta is for t_i - P and so is the reference it is added to
        (``Compensator.reference``).  The compensator sees the samples only (joined by
        straight lines), not the simulator's hold up to the tick.  Without a new sample it
        is updated only when redesigned (re-evaluated at its last sample) or when the
        stream has stopped (no sample for STALE_PERIODS tick periods, or for twice the last
        sample interval if that is longer): the reference then rests, a sample at the
        tick."""
        origin = self._origin_ns
        comp = self.compensator
        applied = self.config.node.compensation_applied and comp is not None
        if comp is not None and not (applied or self._pub_ff.get_subscription_count()):
            self._comp_idle = True       # nobody uses it: save its cost (tens of us a tick)
            comp = None
        ok = comp is not None
        if ok and self._comp_idle:       # consumers are back: restart from the reference
            try:
                comp.reset(self._ref, self._last_t)
                self._comp_t = self._last_t
                self._comp_idle = False
            except Exception as exc:  # noqa: BLE001
                self._compensation_failed(exc)
                ok = False
        drives: list[tuple[float, float]] = []
        after_ns = self._last_ns + 1 if self.counters['ticks'] else origin
        for ns, v in samples:
            ti = (ns - origin) * 1e-9
            if ti > self._sample_t:
                self._sample_dt = ti - self._sample_t
            self._sample_t = ti
            self._ref = self._ref_now = v
            if ok:   # a smoothed stream time may precede the compensator's last sample
                ok = self._update_compensator(comp, max(ti, self._comp_t), v)
            drive = self._ref_now + self._delta if applied else v
            # ... or the previous tick, up to which the simulator has already integrated
            ts = ti if ns >= after_ns else (after_ns - origin) * 1e-9
            if drives and ts <= drives[-1][0]:
                drives[-1] = (drives[-1][0], drive)
            else:
                drives.append((ts, drive))
        if not samples and ok:
            stale = max(STALE_PERIODS * self._period_ns * 1e-9,
                        2.0 * min(self._sample_dt, STALE_MAX_INTERVAL))
            if t - self._comp_t > stale:             # the stream stopped: reference rests
                t_eval = t
            elif self._comp_dirty:                   # redesigned: same sample, new design
                t_eval = self._comp_t
            else:
                return drives
            if self._update_compensator(comp, t_eval, self._ref) and applied:
                drives.append((t, self._ref_now + self._delta))
        return drives

    def _update_compensator(self, comp: Any, t: float, ref: float) -> bool:
        """One Compensator.update; on failure keep the last good correction."""
        try:
            d = float(comp.update(t, ref))
            r = float(getattr(comp, 'reference', ref))
            if not (math.isfinite(d) and math.isfinite(r)):
                raise ValueError(f'non-finite correction {d!r}')
        except Exception as exc:  # noqa: BLE001 - a compensator bug must not stop the node
            self._compensation_failed(exc)
            return False
        self._comp_t = t
        self._comp_dirty = False
        self._delta, self._ref_now = d, r
        return True

    def _compensation_failed(self, exc: Exception) -> None:
        self.counters['compensation_errors'] += 1
        self._warn('compensation', f'feed-forward failed ({type(exc).__name__}: {exc}); '
                   f'keeping the last correction {self._delta:.3g} rad')

    def _advance(self, t: float, drives: list[tuple[float, float]]) -> int:
        """Integrate up to the tick time ``t`` through the command samples ``drives``
        [(t_i, theta1_i)], then hold the last command up to ``t``.  ``linear``: theta1
        moves linearly from the previous sample (or the hold point at the previous tick)
        to each sample; ``hold``: theta1 steps to each sample at its time (the first dt
        grid point at or after it)."""
        sim = self.sim
        behind = t - sim.t
        cap = self.config.node.max_catch_up
        if behind > cap:
            sim.resync(t - cap)   # samples before t - cap are only registered, not integrated
            self.counters['overruns'] += 1
            self.counters['dropped_time'] += behind - cap
            self._window['overruns'] += 1
            self._warn('overrun', f'{behind:.4g} s behind: integrated the last {cap:g} s '
                       '(node.max_catch_up) and dropped the rest')
        t_before = sim.t
        held = self._held
        if drives:
            self._held = drives[-1][1]
        steps = 0
        try:
            if sim.interpolation == 'hold':
                for ti, di in drives:
                    steps += sim.advance_to(ti - HOLD_EPS, held)
                    held = di
            else:
                for ti, di in drives:
                    steps += sim.advance_to(ti, di)
                    held = di
            steps += sim.advance_to(t, held)
        except (SimulationError, ValueError) as exc:
            self.counters['simulation_errors'] += 1
            self._window['errors'] += 1
            self._warn('simulation', f'simulation error: {exc}; keeping the last good state '
                       f'(t = {sim.t:.6f} s) and continuing from t = {t:.6f} s')
            sim.resync(t)
        self._window['sim_time'] += sim.t - t_before
        return steps

    def _publish(self, stamp: Any, ref: float | None, delta: float) -> None:
        st = self.sim.state
        th, om = st.theta, st.omega
        js = self._js
        js.header.stamp = stamp.to_msg()
        js.position = [st.theta1, float(th[0]), float(th[1]), float(th[2])]
        js.velocity = [st.theta1_dot, float(om[0]), float(om[1]), float(om[2])]
        js.effort = self.sim.joint_torques().tolist()
        if self._pub_js.get_subscription_count():   # publishing to nobody still costs
            self._pub_js.publish(js)
        # Uncompensated: the reference is the simulated command itself (exactly the batch
        # Trajectory.output_error); compensated: the servo's reference theta1_ref.
        reference = st.theta1 if ref is None else ref
        if self._pub_err.get_subscription_count():
            self._f_err.data = float(th[2]) - reference * self.output_per_input
            self._pub_err.publish(self._f_err)
        if self._pub_worm.get_subscription_count():
            self._f_worm.data = float(th[0]) - st.theta1
            self._pub_worm.publish(self._f_worm)
        if self.compensator is not None and self._pub_ff.get_subscription_count():
            self._f_ff.data = delta
            self._pub_ff.publish(self._f_ff)

    # ---- parameters ----------------------------------------------------------------------
    def _evaluate(self, params: list[Parameter]) -> tuple[str, Config | None]:
        """('', candidate) if the model parameters in ``params`` form a valid set, else
        (reason, None).  Non-model parameters (qos_overrides, use_sim_time) are left to
        rclpy."""
        overrides = {}
        for p in params:
            if not is_model_parameter(p.name):
                continue
            if self.describe_parameter(p.name).read_only:
                return f'{p.name} is read-only (structural); restart the node to change it', None
            if p.type_.value != self._types[p.name]:
                return (f'{p.name}: wrong type {p.type_.name}, expected '
                        f'{Parameter.Type(self._types[p.name]).name}'), None
            overrides[p.name] = to_core_value(p.value)
        if not overrides:
            return '', None
        try:
            candidate = self.config.replace(overrides)
            trial = copy.copy(self.sim)     # shallow: reconfigure() only reads the state
            trial.reconfigure(candidate)
        except (ConfigError, ValueError) as exc:
            return str(exc), None
        return '', candidate

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
        if reason:
            return SetParametersResult(successful=False, reason=reason)
        self._pending_config = candidate
        return SetParametersResult(successful=True)

    def _post_set(self, params: list[Parameter]) -> None:
        cfg, self._pending_config = self._pending_config, None
        if cfg is None:
            return
        try:
            self.sim.reconfigure(cfg)
        except ValueError as exc:  # pragma: no cover - _evaluate ran the same call
            self._warn('parameters', f'could not apply parameters: {exc}')
            return
        self.sim.interpolation = cfg.node.command_interpolation
        if cfg.node.command_timing != self.config.node.command_timing:
            self._stream.reset()
        self.output_per_input = self.sim.derived.output_per_input
        old = self.config
        self.config = cfg
        self.counters['accepted_parameter_sets'] += 1
        before = old.to_flat_dict()
        if Compensator is not None and any(
                before[k] != v for k, v in cfg.to_flat_dict().items()
                if not k.startswith('input.') and k not in ('node.compensation_applied',
                                                             'node.command_timing')):
            self._redesign_compensator(cfg)
        names = ', '.join(p.name for p in params if is_model_parameter(p.name))
        self.get_logger().info(f'parameters applied: {names}')

    # ---- diagnostics -------------------------------------------------------------------
    def diagnostic_statuses(self) -> list[diag.DiagnosticStatus]:
        """The statuses of /diagnostics (resets the per-window figures)."""
        w, self._window = self._window, self._new_window()
        wall = max(1e-9, (self._window['wall_ns'] - w['wall_ns']) * 1e-9)
        c = self.counters
        st = self.sim.stats
        name, hw = self.get_name(), 'worm_gear_sim'
        if not self._started:
            level, msg = diag.WARN, f'waiting for the first {COMMAND_TOPIC}'
        elif w['errors']:
            level, msg = diag.ERROR, f'{w["errors"]} simulation error(s): {self.last_error}'
        elif w['overruns']:
            level, msg = diag.WARN, f'{w["overruns"]} overrun(s): catch-up capped'
        else:
            level, msg = diag.OK, 'running'
        sim_vals = {
            'time_base': self._time_base or 'none', 'simulated_time_s': self.sim.t,
            'real_time_factor': w['sim_time'] / wall,
            'compute_load': w['busy_ns'] * 1e-9 / wall,
            'max_tick_cpu_ms': w['max_busy_ns'] * 1e-6,
            'steps_per_tick': w['steps'] / w['ticks'] if w['ticks'] else 0.0,
            'max_steps_per_tick': c['max_steps_per_tick'], 'ticks': c['ticks'],
            'missed_ticks': c['missed_ticks'], 'overruns': c['overruns'],
            'dropped_time_s': c['dropped_time'], 'clock_backwards': c['clock_backwards'],
            'newton_subdivisions': st['subdivision_events'], 'newton_substeps': st['substeps'],
            'max_newton_solves_per_step': st['max_solves_per_step'],
            'simulation_errors': c['simulation_errors'], 'last_error': self.last_error,
        }
        rejected = c['rejected_commands'] + c['rejected_parameter_sets']
        in_level = diag.WARN if rejected else diag.OK
        in_vals = {k: c[k] for k in (
            'commands_received', 'commands_used', 'commands_superseded', 'commands_dropped',
            'commands_merged', 'commands_restamped', 'max_commands_per_tick',
            'rejected_commands',
            *(f'rejected_{r}' for r in REJECT_REASONS), 'rejected_parameter_sets',
            'accepted_parameter_sets')}
        in_vals['command_timing'] = self.config.node.command_timing
        in_vals['stream_period_ms'] = self._stream.period * 1e-6
        in_vals['stream_relocks'] = self._stream.relocks
        in_vals['stream_outliers'] = self._stream.outliers
        in_vals['last_command'] = 'none' if self._cmd is None else repr(self._cmd)
        in_vals['last_error'] = self.last_error
        ff_level = diag.OK if self.compensator is not None and not c['compensation_errors'] \
            else diag.ERROR
        ff_vals = {'available': self.compensator is not None,
                   'computed': self.compensator is not None and not self._comp_idle,
                   'applied_to_prediction': self.config.node.compensation_applied,
                   'last_correction_rad': self._delta,
                   'compensation_errors': c['compensation_errors'],
                   'error': self.compensation_error}
        return [
            diag.status(name, 'simulation', level, msg, sim_vals, hw),
            diag.status(name, 'inputs', in_level,
                        f'{rejected} rejected input(s)' if rejected else 'ok', in_vals, hw),
            diag.status(name, 'feedforward', ff_level,
                        'ok' if ff_level == diag.OK else (self.compensation_error or
                                                          'compensation errors'), ff_vals, hw),
        ]

    def publish_diagnostics(self) -> None:
        self._pub_diag.publish(diag.array(self._clock.now().to_msg(),
                                          self.diagnostic_statuses()))


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
    if not context.ok():            # Ctrl-C / SIGTERM while the node was being built
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
