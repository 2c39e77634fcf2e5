# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""ament_python package: `colcon build` on a ROS 2 install, or `pip install .[ros]` in a venv."""

from glob import glob
from pathlib import Path

from setuptools import find_packages, setup

package_name = 'worm_gear_sim'
HERE = Path(__file__).resolve().parent


def requirements(name: str) -> list[str]:
    """The packages of requirements/<name>.txt (the ROS 2 wheels of a distro, the developer's
    tools): one list for scripts/setup_env.sh and the extras; the file is absent only outside
    a source tree."""
    path = HERE / 'requirements' / f'{name}.txt'
    if not path.is_file():
        return []
    lines = (ln.split('#', 1)[0].strip() for ln in path.read_text().splitlines())
    return [ln for ln in lines if ln and not ln.startswith('-')]


setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/urdf', glob('urdf/*.urdf')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
    ],
    # Only setuptools here, as in the ROS template: pkg_resources-style wrappers check these
    # at `ros2 run`, and apt-installed numpy/scipy carry no pip metadata.  The PyPI ROS wheels
    # must never be here: on a real ROS install they would shadow the system rclpy.
    install_requires=['setuptools'],
    extras_require={
        'core': ['numpy>=1.24', 'scipy>=1.10', 'numba>=0.58', 'pyyaml>=6', 'matplotlib>=3.7'],
        'studies': ['dask[distributed]>=2023.1', 'tqdm>=4.60'],
        # pip install .[ros] (Kilted, rclpy 9.x) or .[ros-jazzy] (Jazzy LTS, rclpy 7.1.x)
        'ros': requirements('ros-kilted'),
        'ros-jazzy': requirements('ros-jazzy'),
        # tests, lint, types, colcon, the docs site: requirements/dev.txt
        'dev': requirements('dev'),
    },
    zip_safe=True,
    maintainer='worm_gear_sim developers',
    maintainer_email='dev@worm-gear-sim.local',
    description='Real-time nonlinear dynamic model of a worm and worm-gear drive.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'worm_gear_sim_node = worm_gear_sim.ros.startup:node_main',
            'worm_gear_sim_pedestal = worm_gear_sim.ros.startup:pedestal_main',
            'worm_gear_sim_calibrate = worm_gear_sim.ros.calibrate:main',
            'worm_gear_sim_demo = worm_gear_sim.ros.demo_commander:main',
            'worm-gear-sim = worm_gear_sim.cli:main',
        ],
    },
)
