# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The node's answers on the wire: the publishers of ``joint_states``, ``~/positioning_error``,
``~/worm_error``, ``~/feedforward`` and ``~/compensated_command`` with their QoS, and the
pre-built messages a sample only rewrites.  What they carry is computed by the core
(:class:`~worm_gear_sim.realtime.Prediction`, :class:`~worm_gear_sim.realtime.Correction`);
each publish goes through the node's ``_publish`` (a failure is counted, never fatal)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

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

__all__ = ['PredictionPublishing']


class PredictionPublishing:
    """Part of :class:`~.node.WormGearSimNode` (a mixin of an rclpy ``Node`` with a
    ``_publish(pub, msg)``): the publishers and pre-built messages of the predictions and
    the corrections, and their publishing."""

    create_publisher: Callable[..., Any]
    _publish: Callable[[Any, Any], None]

    def _create_prediction_publishers(self, joint_names: Sequence[str]) -> None:
        """``joint_names``: the drive's joints (``node.joint_names``; the first is the worm
        input)."""
        qos_state = QoSProfile(depth=10)
        overrides = QoSOverridingOptions.with_default_policies
        self._pub_js = self.create_publisher(JointState, JOINT_STATES_TOPIC, qos_state,
                                             qos_overriding_options=overrides())
        self._pub_err = self.create_publisher(Float64, POSITIONING_ERROR_TOPIC, qos_state)
        self._pub_worm = self.create_publisher(Float64, WORM_ERROR_TOPIC, qos_state)
        self._pub_ff = self.create_publisher(Float64, FEEDFORWARD_TOPIC,
                                             QoSProfile(depth=REFERENCE_DEPTH))
        self._pub_cc = self.create_publisher(JointState, COMPENSATED_COMMAND_TOPIC,
                                             QoSProfile(depth=REFERENCE_DEPTH),
                                             qos_overriding_options=overrides())
        # pre-built messages: a sample only rewrites their fields
        self._js = JointState()
        self._js.name = list(joint_names)
        self._cc = JointState()
        self._cc.name = [joint_names[0]]
        self._cc.position = [0.0]
        self._f_err, self._f_worm, self._f_ff = Float64(), Float64(), Float64()

    def _predictions_monitored(self) -> bool:
        """Someone listens to the predictions (joint states or either error)."""
        return bool(self._pub_js.get_subscription_count()
                    or self._pub_err.get_subscription_count()
                    or self._pub_worm.get_subscription_count())

    def _publish_corrections(self, corrections: Sequence[Correction]) -> None:
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

    def _publish_latest_feedforward(self, delta: float) -> None:
        """Float64 path: the correction of the newest sample on ~/feedforward."""
        if self._pub_ff.get_subscription_count():
            self._f_ff.data = delta
            self._publish(self._pub_ff, self._f_ff)

    def _publish_prediction(self, p: Prediction, stamp_ns: int) -> None:
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
