# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The node's interface names: topics (relative, remappable), queue depths and the reasons it
rejects input with.  One place for the node, its diagnostics and the demo servo; the
interface itself is described on docs/node.md."""

from __future__ import annotations

from ..realtime import Reject

__all__ = ['COMMAND_TOPIC', 'REFERENCE_TOPIC', 'REFERENCE_DEPTH', 'JOINT_STATES_TOPIC',
           'MEASURED_TOPIC', 'POSITIONING_ERROR_TOPIC', 'WORM_ERROR_TOPIC', 'FEEDFORWARD_TOPIC',
           'COMPENSATED_COMMAND_TOPIC', 'RESIDUAL_TOPIC', 'DIAGNOSTICS_TOPIC',
           'REJECT_REASONS', 'NODE_REJECT_REASONS']

COMMAND_TOPIC = 'worm_angle_command'               # in, std_msgs/Float64 (unstamped)
REFERENCE_TOPIC = 'worm_angle_reference'           # in, sensor_msgs/JointState (stamped)
REFERENCE_DEPTH = 1000   # every sample matters to the filter: reliable, keep last 1000 (1 s
#                          at 1 kHz: a stalled executor loses none)
JOINT_STATES_TOPIC = 'joint_states'                # out, theta1..theta4, rates, torques
MEASURED_TOPIC = 'measured_joint_states'           # in, the drive's encoders (model check)
POSITIONING_ERROR_TOPIC = '~/positioning_error'    # out, Float64
WORM_ERROR_TOPIC = '~/worm_error'                  # out, Float64
FEEDFORWARD_TOPIC = '~/feedforward'                # out, Float64 (delta)
COMPENSATED_COMMAND_TOPIC = '~/compensated_command'  # out, JointState (theta1_ref + delta)
RESIDUAL_TOPIC = '~/prediction_residual'           # out, JointState (measured - predicted)
DIAGNOSTICS_TOPIC = '/diagnostics'                 # out, diagnostic_msgs/DiagnosticArray
REJECT_REASONS = tuple(r.value for r in Reject)          # the pipeline's (core) reasons
NODE_REJECT_REASONS = ('empty_position', 'wrong_joint')  # message-level, checked by the node
