# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The node's interface: topic names and message types (from the core's
:mod:`worm_gear_sim.topics`, which the bag reader and writer share), the queue depth of the
reference stream and the reasons the node rejects input with.  The interface itself is
described on docs/node.md."""

from __future__ import annotations

from ..realtime import Reject
from ..topics import (
    BACKDRIVE_MARGIN_TOPIC,
    COMMAND_TOPIC,
    COMPENSATED_COMMAND_TOPIC,
    DIAGNOSTICS_TOPIC,
    FEEDFORWARD_TOPIC,
    JOINT_STATES_TOPIC,
    LOAD_TORQUE_TOPIC,
    MEASURED_TOPIC,
    POSITIONING_ERROR_TOPIC,
    REFERENCE_TOPIC,
    RESIDUAL_TOPIC,
    WORM_ERROR_TOPIC,
)

__all__ = ['COMMAND_TOPIC', 'REFERENCE_TOPIC', 'REFERENCE_DEPTH', 'JOINT_STATES_TOPIC',
           'MEASURED_TOPIC', 'POSITIONING_ERROR_TOPIC', 'WORM_ERROR_TOPIC', 'FEEDFORWARD_TOPIC',
           'COMPENSATED_COMMAND_TOPIC', 'RESIDUAL_TOPIC', 'DIAGNOSTICS_TOPIC',
           'BACKDRIVE_MARGIN_TOPIC', 'LOAD_TORQUE_TOPIC', 'REJECT_REASONS',
           'NODE_REJECT_REASONS']

REFERENCE_DEPTH = 1000   # every sample matters to the filter: reliable, keep last 1000 (1 s
#                          at 1 kHz: a stalled executor loses none)
REJECT_REASONS = tuple(r.value for r in Reject)          # the pipeline's (core) reasons
NODE_REJECT_REASONS = ('empty_position', 'wrong_joint',   # message-level, checked by the
                       'load_empty_effort', 'load_wrong_joint')   # node
