# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The node's answers on the wire: the publishers of ``joint_states``, ``~/positioning_error``,
``~/worm_error``, ``~/feedforward``, ``~/compensated_command`` and ``~/backdrive_margin`` with
their QoS, and the pre-built messages a sample only rewrites (:class:`PredictionPublishers`,
a member of the node).  What they carry is computed by the core
(:class:`~worm_gear_sim.realtime.Prediction`, :class:`~worm_gear_sim.realtime.Correction`,
the model's back-drive margin); each publish goes through the node's ``_publish`` (a failure
is counted, never fatal).

Every answer carries the stamp of the sample it answers: the scalar answers
(:data:`~worm_gear_sim.records.topics.ANSWER_TOPICS`) are sensor_msgs/JointState of one named
joint, or std_msgs/Float64 (no stamp) with ``node.float64_outputs``."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from ..realtime import Correction, Prediction
from ..records.topics import (
    ANSWER_TOPICS,
    BACKDRIVE_MARGIN_TOPIC,
    COMPENSATED_COMMAND_TOPIC,
    FEEDFORWARD_TOPIC,
    JOINT_STATES_TOPIC,
    POSITIONING_ERROR_TOPIC,
    WORM_ERROR_TOPIC,
)
from .callbacks import NS
from .interface import REFERENCE_DEPTH

__all__ = ['PredictionPublishers', 'Answer']


class Answer:
    """One scalar answer topic: a publisher and its pre-built message, a JointState of the
    one joint ``joint`` (``position[0]`` the value, ``header.stamp`` the stamp of the sample
    it answers), or a Float64 when ``float64``."""

    def __init__(self, node: Node, topic: str, joint: str, qos: QoSProfile,
                 float64: bool) -> None:
        self.float64 = float64
        self.pub = node.create_publisher(Float64 if float64 else JointState, topic, qos)
        self.msg: Any = Float64() if float64 else JointState(name=[joint], position=[0.0])

    def listened(self) -> int:
        return self.pub.get_subscription_count()

    def fill(self, stamp_ns: int, value: float) -> Any:
        """The message of ``value`` answering the sample stamped ``stamp_ns``."""
        m = self.msg
        if self.float64:
            m.data = value
        else:
            m.header.stamp.sec, m.header.stamp.nanosec = divmod(stamp_ns, NS)
            m.position[0] = value
        return m


class PredictionPublishers:
    """A member of :class:`~.node.WormGearSimNode`: the publishers and pre-built messages
    of the predictions and the corrections of ``node`` (an rclpy ``Node``), and their
    publishing through ``publish(pub, msg)`` (the node's: a failure is counted).
    ``joint_names``: the drive's joints (``node.joint_names``; the first is the worm
    input); ``float64``: the scalar answers as std_msgs/Float64 (``node.float64_outputs``)."""

    def __init__(self, node: Node, joint_names: Sequence[str],
                 publish: Callable[[Any, Any], None], float64: bool = False) -> None:
        self._publish = publish
        self._clock = node.get_clock()
        qos_state = QoSProfile(depth=10)
        overrides = QoSOverridingOptions.with_default_policies
        self._pub_js = node.create_publisher(JointState, JOINT_STATES_TOPIC, qos_state,
                                             qos_overriding_options=overrides())

        def answer(topic: str, qos: QoSProfile) -> Answer:
            return Answer(node, topic, joint_names[ANSWER_TOPICS[topic]], qos, float64)

        self._err = answer(POSITIONING_ERROR_TOPIC, qos_state)
        self._worm = answer(WORM_ERROR_TOPIC, qos_state)
        self._ff = answer(FEEDFORWARD_TOPIC, QoSProfile(depth=REFERENCE_DEPTH))
        self._margin = answer(BACKDRIVE_MARGIN_TOPIC, qos_state)
        self._pub_cc = node.create_publisher(JointState, COMPENSATED_COMMAND_TOPIC,
                                             QoSProfile(depth=REFERENCE_DEPTH),
                                             qos_overriding_options=overrides())
        # pre-built messages: a sample only rewrites their fields
        self._js = JointState()
        self._js.name = list(joint_names)
        self._cc = JointState()
        self._cc.name = [joint_names[0]]
        self._cc.position = [0.0]
        self._last_monitor_ns = -(1 << 62)       # stamp of the last monitoring message
        self.last_prediction_ns: int | None = None   # stamp of the newest prediction

    def predictions(self, preds: Sequence[Prediction], stamp_ns: int | None,
                    rate: float) -> None:
        """joint_states and both errors of each prediction (stamped ``stamp_ns``, None:
        its own stamp), at most ``rate`` [Hz] by stamps (0: each), when someone listens."""
        if preds:
            self.last_prediction_ns = preds[-1].stamp_ns if stamp_ns is None else stamp_ns
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
        return bool(self._pub_js.get_subscription_count() or self._err.listened()
                    or self._worm.listened())

    def corrections(self, corrections: Sequence[Correction]) -> None:
        """Stamped path: ~/compensated_command and ~/feedforward for each correction, with
        the stamp of the sample it corrects."""
        cc, ff = self._cc, self._ff
        pub_cc = self._pub_cc.get_subscription_count()
        pub_ff = ff.listened()
        for c in corrections:
            if pub_cc:
                cc.header.stamp.sec, cc.header.stamp.nanosec = divmod(c.stamp_ns, NS)
                cc.position[0] = c.theta1_ref + c.delta
                self._publish(self._pub_cc, cc)
            if pub_ff:
                self._publish(ff.pub, ff.fill(c.stamp_ns, c.delta))

    def latest_feedforward(self, delta: float) -> None:
        """Float64 path: the correction of the newest sample on ~/feedforward, stamped as
        the tick's prediction."""
        if self._ff.listened():
            stamp = self.last_prediction_ns
            if stamp is None:
                stamp = self._clock.now().nanoseconds
            self._publish(self._ff.pub, self._ff.fill(stamp, delta))

    def backdrive_margin(self, margin: Callable[[], float], started: bool) -> None:
        """~/backdrive_margin, when someone listens: ``margin()``, computed from the newest
        predicted state, stamped as that prediction (not ``started``: the margin at rest,
        stamped with the node's clock)."""
        if self._margin.listened():
            stamp = self.last_prediction_ns if started else None
            if stamp is None:
                stamp = self._clock.now().nanoseconds
            self._publish(self._margin.pub, self._margin.fill(stamp, margin()))

    def prediction(self, p: Prediction, stamp_ns: int) -> None:
        """joint_states, ~/positioning_error and ~/worm_error of one prediction."""
        js = self._js
        if self._pub_js.get_subscription_count():
            js.header.stamp.sec, js.header.stamp.nanosec = divmod(stamp_ns, NS)
            js.position = p.position
            js.velocity = p.velocity
            js.effort = p.effort
            self._publish(self._pub_js, js)
        for answer, value in ((self._err, p.positioning_error), (self._worm, p.worm_error)):
            if answer.listened():
                self._publish(answer.pub, answer.fill(stamp_ns, value))
