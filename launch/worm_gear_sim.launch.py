# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Launch the worm-gear node with the installed parameters; optionally the demo command
stream and robot_state_publisher (URDF of the drive, so RViz shows the ringing).

    ros2 launch worm_gear_sim worm_gear_sim.launch.py
    ros2 launch worm_gear_sim worm_gear_sim.launch.py demo:=true demo_pattern:=slew
    ros2 launch worm_gear_sim worm_gear_sim.launch.py robot_state_publisher:=true
    ros2 launch worm_gear_sim worm_gear_sim.launch.py params_file:=/path/to/my.yaml

Needs a ROS 2 install (launch, launch_ros; robot_state_publisher for that option): the
PyPI wheels of this project's venv do not include launch.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

PACKAGE = 'worm_gear_sim'
EXECUTABLE = 'worm_gear_sim_node'
DEMO_EXECUTABLE = 'worm_gear_sim_demo'
PARAMS = os.path.join('config', 'worm_gear_sim.yaml')
URDF = os.path.join('urdf', 'worm_gear_drive.urdf')


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory(PACKAGE)
    with open(os.path.join(share, URDF)) as f:
        robot_description = f.read()
    return LaunchDescription([
        DeclareLaunchArgument('params_file', default_value=os.path.join(share, PARAMS),
                              description='parameters of the node (YAML)'),
        DeclareLaunchArgument('demo', default_value='false',
                              description='also run the demo command stream'),
        DeclareLaunchArgument('demo_pattern', default_value='paper',
                              description='command pattern of the demo (paper, slew)'),
        DeclareLaunchArgument('robot_state_publisher', default_value='false',
                              description='publish /tf from joint_states and the URDF'),
        Node(package=PACKAGE, executable=EXECUTABLE, name='worm_gear_sim', output='screen',
             parameters=[LaunchConfiguration('params_file')]),
        Node(package=PACKAGE, executable=DEMO_EXECUTABLE, output='screen',
             arguments=['--pattern', LaunchConfiguration('demo_pattern')],
             condition=IfCondition(LaunchConfiguration('demo'))),
        Node(package='robot_state_publisher', executable='robot_state_publisher',
             output='screen', parameters=[{'robot_description': robot_description}],
             condition=IfCondition(LaunchConfiguration('robot_state_publisher'))),
    ])
