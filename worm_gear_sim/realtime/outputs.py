# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""What the real-time pipeline hands back: the records of one call (:class:`Output` with its
:class:`Correction`, :class:`Prediction` and :class:`Event` items, or the :class:`Reject`
reason of a sample), the names of its counters, and a configuration made ready for a swap
(:class:`Prepared`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum

from ..compensation.streaming import Compensator
from ..dynamics.model import DriveModel
from ..schema.parameters import Parameters

__all__ = ['Reject', 'Correction', 'Prediction', 'Event', 'Output', 'Prepared',
           'COUNTER_NAMES']


class Reject(StrEnum):
    """Why a sample was rejected (counter ``rejected_<value>``)."""

    NAN = 'nan'
    INF = 'inf'
    OUT_OF_RANGE = 'out_of_range'     # |theta1_ref| > node.max_command_abs
    JUMP = 'jump'                     # change > node.max_command_jump (until confirmed)
    ZERO_STAMP = 'zero_stamp'         # stamp == 0 (unset header)
    NEGATIVE_STAMP = 'negative_stamp'  # stamp < 0 (a negative header.stamp.sec)
    TOO_OLD = 'too_old'               # stamp < now - max_stamp_age
    TOO_NEW = 'too_new'               # stamp > now + max_stamp_lead
    DUPLICATE = 'duplicate'           # stamp equal to the last accepted sample's
    OUT_OF_ORDER = 'out_of_order'     # stamp before the last accepted sample's


@dataclass(frozen=True, slots=True)
class Correction:
    """Feed-forward for one accepted sample: command ``compensated`` at ``stamp_ns``."""

    stamp_ns: int
    theta1_ref: float        # the sample [rad]
    delta: float             # correction to ADD [rad] (~/feedforward)

    @property
    def compensated(self) -> float:
        """theta1_ref + delta [rad] (~/compensated_command)."""
        return self.theta1_ref + self.delta


@dataclass(frozen=True, slots=True)
class Prediction:
    """The simulated drive at ``stamp_ns`` (the instant it predicts; the state lies on the
    dt grid point at or just before it)."""

    stamp_ns: int
    theta1: float            # command as applied [rad]
    theta1_dot: float        # [rad/s]
    theta: tuple             # (theta2, theta3, theta4) [rad]
    omega: tuple             # (omega2, omega3, omega4) [rad/s]
    effort: tuple            # Simulator.joint_torques(): K_w twist, r_w F_X, r_g F_Y,
    #                          K_g twist [N m]
    reference: float         # theta1_ref the positioning error is measured against [rad]
    positioning_error: float  # theta4 - reference l_w / r_g [rad] (~/positioning_error)
    worm_error: float        # theta2 - theta1 [rad] (~/worm_error)
    held: bool = False       # held: the stream is stale, the last command is held

    @property
    def position(self) -> tuple:
        """JointState.position: theta1..theta4."""
        return (self.theta1, *self.theta)

    @property
    def velocity(self) -> tuple:
        """JointState.velocity: theta1_dot, omega2..omega4."""
        return (self.theta1_dot, *self.omega)


@dataclass(frozen=True, slots=True)
class Event:
    """Something the node should log once.  ``kind``: started, stream_resumed (``level``
    'info'); resync, clock_restart, stream_stale, overrun, simulation_error,
    compensation_error, input_changed ('warn').  The counters say how often."""

    kind: str
    message: str
    level: str = 'warn'


@dataclass(slots=True)
class Output:
    """What one call produced.  ``accepted``/``rejected``: the pushed sample's fate
    (``push``/``push_command``); ``stale``: the stream is stale after this call."""

    accepted: bool = False
    rejected: Reject | None = None
    corrections: list = field(default_factory=list)
    predictions: list = field(default_factory=list)
    events: list = field(default_factory=list)
    stale: bool = False


@dataclass(frozen=True)
class Prepared:
    """A configuration made ready for :meth:`RealtimePredictor.reconfigure` (its model
    built once, the compensator designed, the simulator's parameters checked)."""

    model: DriveModel
    compensator: Compensator | None
    error: str = ''          # compensator design failure (the swap keeps running without)

    @property
    def config(self) -> Parameters:
        return self.model.config


COUNTER_NAMES = (
    'samples_received', 'samples_accepted', 'rejected_samples',
    *(f'rejected_{r.value}' for r in Reject),
    'commands_received', 'commands_used', 'commands_merged', 'commands_restamped',
    'commands_dropped', 'merged_samples', 'rest_samples', 'corrections',
    'corrections_dropped', 'predictions', 'late_for_simulation', 'resyncs',
    'clock_restarts', 'input_switches', 'stale_events',
    'stale_retractions', 'overruns', 'dropped_time_ns', 'steps',
    'simulation_errors', 'compensation_errors', 'reconfigurations', 'stream_relocks',
    'stream_outliers',
    # the load torque input (push_load): the same rules as the reference samples
    'load_samples_received', 'load_samples_accepted', 'rejected_load_samples',
    *(f'rejected_load_{r.value}' for r in Reject if r is not Reject.JUMP),
    'late_load_samples')
