# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The node's interface names: its topics (relative, remappable; ``~/`` ones live under the
node's name) and their message types.  One copy for the node (:mod:`worm_gear_sim.ros`),
the bags the core reads and writes (:mod:`worm_gear_sim.records`) and the bag recorder;
pure data, no ROS imports.  The interface is described on docs/node.md."""

from __future__ import annotations

from ..schema.sections import NODE_NAME

__all__ = ['NODE_NAMESPACE', 'COMMAND_TOPIC', 'REFERENCE_TOPIC', 'JOINT_STATES_TOPIC',
           'MEASURED_TOPIC', 'POSITIONING_ERROR_TOPIC', 'WORM_ERROR_TOPIC', 'FEEDFORWARD_TOPIC',
           'COMPENSATED_COMMAND_TOPIC', 'RESIDUAL_TOPIC', 'DIAGNOSTICS_TOPIC', 'FLOAT64',
           'BACKDRIVE_MARGIN_TOPIC', 'LOAD_TORQUE_TOPIC', 'TRAJECTORY_TOPIC',
           'COMPENSATED_TRAJECTORY_TOPIC', 'PEDESTAL_TRAJECTORY_TOPIC',
           'JOINT_STATE', 'ANSWER_TOPICS', 'private_topic']

NODE_NAMESPACE = NODE_NAME          # the node's name: its ~/ topics live under it

COMMAND_TOPIC = 'worm_angle_command'               # in, std_msgs/Float64 (unstamped)
REFERENCE_TOPIC = 'worm_angle_reference'           # in, sensor_msgs/JointState (stamped)
JOINT_STATES_TOPIC = 'joint_states'                # out, theta1..theta4, rates, torques
MEASURED_TOPIC = 'measured_joint_states'           # in, the drive's encoders (model check)
LOAD_TORQUE_TOPIC = 'load_torque'                  # in, JointState: effort of the antenna
POSITIONING_ERROR_TOPIC = '~/positioning_error'    # out, answer (antenna joint)
WORM_ERROR_TOPIC = '~/worm_error'                  # out, answer (worm joint)
FEEDFORWARD_TOPIC = '~/feedforward'                # out, answer (delta, worm input joint)
COMPENSATED_COMMAND_TOPIC = '~/compensated_command'  # out, JointState (theta1_ref + delta)
RESIDUAL_TOPIC = '~/prediction_residual'           # out, JointState (measured - predicted)
BACKDRIVE_MARGIN_TOPIC = '~/backdrive_margin'      # out, answer (> 1: the worm holds)
TRAJECTORY_TOPIC = 'reference_trajectory'         # in, trajectory_msgs/JointTrajectory
PEDESTAL_TRAJECTORY_TOPIC = '~/reference_trajectory'  # the pedestal node's (/pedestal/...)
COMPENSATED_TRAJECTORY_TOPIC = '~/compensated_trajectory'  # out, JointTrajectory (dense)
DIAGNOSTICS_TOPIC = '/diagnostics'                 # out, diagnostic_msgs/DiagnosticArray

FLOAT64 = 'std_msgs/msg/Float64'
JOINT_STATE = 'sensor_msgs/msg/JointState'

#: The node's scalar answers: topic -> index into ``node.joint_names`` of the joint that
#: names the value.  Each is a sensor_msgs/JointState of that one joint, ``position[0]`` the
#: value, ``header.stamp`` the stamp of the sample it answers (std_msgs/Float64 with
#: ``node.float64_outputs``).  The back-drive margin (a ratio) is named after the gear joint:
#: the member whose load would back-drive the worm.
ANSWER_TOPICS = {POSITIONING_ERROR_TOPIC: 3, WORM_ERROR_TOPIC: 1, FEEDFORWARD_TOPIC: 0,
                 BACKDRIVE_MARGIN_TOPIC: 2}


def private_topic(topic: str, node: str = NODE_NAMESPACE) -> str:
    """A ``~/`` topic of ``node`` as a name relative to the namespace: '~/feedforward' ->
    'worm_gear_sim/feedforward'."""
    return f'{node}/{topic.removeprefix("~/")}'
