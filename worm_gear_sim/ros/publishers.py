# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The node's answers on the wire: the publishers of ``joint_states``, ``~/positioning_error``,
``~/worm_error``, ``~/feedforward`` and ``~/compensated_command`` with their QoS, and the
pre-built messages a sample only rewrites (:class:`PredictionPublishers`, a member of the
node).  What they carry is computed by the core (:class:`~worm_gear_sim.realtime.Prediction`,
:class:`~worm_gear_sim.realtime.Correction`); each publish goes through the node's
``_publish`` (a failure is counted, never fatal)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from ..realtime import Correction, Prediction
from ..topics import (
    COMPENSATED_COMMAND_TOPIC,
    FEEDFORWARD_TOPIC,
    JOINT_STATES_TOPIC,
    POSITIONING_ERROR_TOPIC,
    WORM_ERROR_TOPIC,
)
from .callbacks import NS
from .interface import REFERENCE_DEPTH

__all__ = ['PredictionPublishers']


class PredictionPublishers:
    """A member of :class:`~.node.WormGearSimNode`: the publishers and pre-built messages
    of the predictions and the corrections of ``node`` (an rclpy ``Node``), and their
    publishing through ``publish(pub, msg)`` (the node's: a failure is counted).
    ``joint_names``: the drive's joints (``node.joint_names``; the first is the worm
    input)."""

    def __init__(self, node: Node, joint_names: Sequence[str],
                 publish: Callable[[Any, Any], None]) -> None:
        self._publish = publish
        qos_state = QoSProfile(depth=10)
        overrides = QoSOverridingOptions.with_default_policies
        self._pub_js = node.create_publisher(JointState, JOINT_STATES_TOPIC, qos_state,
                                             qos_overriding_options=overrides())
        self._pub_err = node.create_publisher(Float64, POSITIONING_ERROR_TOPIC, qos_state)
        self._pub_worm = node.create_publisher(Float64, WORM_ERROR_TOPIC, qos_state)
        self._pub_ff = node.create_publisher(Float64, FEEDFORWARD_TOPIC,
                                             QoSProfile(depth=REFERENCE_DEPTH))
        self._pub_cc = node.create_publisher(JointState, COMPENSATED_COMMAND_TOPIC,
                                             QoSProfile(depth=REFERENCE_DEPTH),
                                             qos_overriding_options=overrides())
        # pre-built messages: a sample only rewrites their fields
        self._js = JointState()
        self._js.name = list(joint_names)
        self._cc = JointState()
        self._cc.name = [joint_names[0]]
        self._cc.position = [0.0]
        self._f_err, self._f_worm, self._f_ff = Float64(), Float64(), Float64()
        self._last_monitor_ns = -(1 << 62)       # stamp of the last monitoring message

    def predictions(self, preds: Sequence[Prediction], stamp_ns: int | None,
                    rate: float) -> None:
        """joint_states and both errors of each prediction (stamped ``stamp_ns``, None:
        its own stamp), at most ``rate`` [Hz] by stamps (0: each), when someone listens."""
        if not self.monitored():
            return
        for p in preds:
            ns = p.stamp_ns if stamp_ns is None else stamp_ns
            if rate > 0.0:                       # monitoring at its own rate (by stamps)
                if 0 <= ns - self._last_monitor_ns < 1e9 / rate:
                    continue
                self._last_monitor_ns = ns
            self.prediction(p, ns)

    def monitored(self) -> bool:
        """Someone listens to the predictions (joint states or either error)."""
        return bool(self._pub_js.get_subscription_count()
                    or self._pub_err.get_subscription_count()
                    or self._pub_worm.get_subscription_count())

    def corrections(self, corrections: Sequence[Correction]) -> None:
        """Stamped path: ~/compensated_command and ~/feedforward for each correction."""
        cc, ff = self._cc, self._f_ff
        pub_cc = self._pub_cc.get_subscription_count()
        pub_ff = self._pub_ff.get_subscription_count()
        for c in corrections:
            if pub_cc:
                cc.header.stamp.sec, cc.header.stamp.nanosec = divmod(c.stamp_ns, NS)
                cc.position[0] = c.theta1_ref + c.delta
                self._publish(self._pub_cc, cc)
            if pub_ff:
                ff.data = c.delta
                self._publish(self._pub_ff, ff)

    def latest_feedforward(self, delta: float) -> None:
        """Float64 path: the correction of the newest sample on ~/feedforward."""
        if self._pub_ff.get_subscription_count():
            self._f_ff.data = delta
            self._publish(self._pub_ff, self._f_ff)

    def prediction(self, p: Prediction, stamp_ns: int) -> None:
        """joint_states, ~/positioning_error and ~/worm_error of one prediction."""
        js = self._js
        if self._pub_js.get_subscription_count():
            js.header.stamp.sec, js.header.stamp.nanosec = divmod(stamp_ns, NS)
            js.position = p.position
            js.velocity = p.velocity
            js.effort = p.effort
            self._publish(self._pub_js, js)
        if self._pub_err.get_subscription_count():
            self._f_err.data = p.positioning_error
            self._publish(self._pub_err, self._f_err)
        if self._pub_worm.get_subscription_count():
            self._f_worm.data = p.worm_error
            self._publish(self._pub_worm, self._f_worm)
