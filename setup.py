# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""ament_python package: `colcon build` on a ROS 2 install, or `pip install .[ros]` in a venv."""

from glob import glob

from setuptools import find_packages, setup

package_name = 'worm_gear_sim'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
    ],
    # Only setuptools here, as in the ROS template: pkg_resources-style wrappers check these
    # at `ros2 run`, and apt-installed numpy/scipy carry no pip metadata.  The PyPI ROS wheels
    # must never be here: on a real ROS install they would shadow the system rclpy.
    install_requires=['setuptools'],
    extras_require={
        'core': ['numpy>=1.24', 'scipy>=1.10', 'numba>=0.58', 'pyyaml>=6', 'matplotlib>=3.7'],
        'studies': ['dask[distributed]>=2023.1', 'tqdm>=4.60'],
        'ros': ['ros-rclpy', 'ros-std-msgs', 'ros-sensor-msgs', 'ros-diagnostic-msgs',
                'ros-rosgraph-msgs', 'ros-rcl-interfaces', 'ros-rmw-fastrtps-cpp'],
        'test': ['pytest', 'ruff', 'colcon-core', 'colcon-ros', 'colcon-python-setup-py'],
    },
    zip_safe=True,
    maintainer='worm_gear_sim developers',
    maintainer_email='dev@worm-gear-sim.local',
    description='Real-time nonlinear dynamic model of a worm and worm-gear drive.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'worm_gear_sim_node = worm_gear_sim.ros.startup:node_main',
            'worm_gear_sim_demo = worm_gear_sim.ros.demo_commander:main',
            'worm-gear-sim = worm_gear_sim.cli:main',
        ],
    },
)
