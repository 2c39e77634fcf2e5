# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Launch a two-axis pedestal (azimuth + elevation worm drives) in one process: one node per
drive in its namespace (/azimuth/worm_gear_sim, /elevation/worm_gear_sim) and the pedestal
node that splits and merges two-joint trajectories (/pedestal/compensated_trajectory).

    ros2 launch worm_gear_sim pedestal.launch.py
    ros2 launch worm_gear_sim pedestal.launch.py pedestal_file:=/path/to/my_pedestal.yaml

N drives: list them in the pedestal file (docs/pedestal.md).  Needs a ROS 2 install.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

PACKAGE = 'worm_gear_sim'
EXECUTABLE = 'worm_gear_sim_pedestal'
PEDESTAL = os.path.join('config', 'pedestal.yaml')


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory(PACKAGE)
    return LaunchDescription([
        DeclareLaunchArgument('pedestal_file', default_value=os.path.join(share, PEDESTAL),
                              description='the drives of the pedestal (YAML)'),
        Node(package=PACKAGE, executable=EXECUTABLE, output='screen',
             arguments=['--pedestal', LaunchConfiguration('pedestal_file')]),
    ])
