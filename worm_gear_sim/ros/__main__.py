# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``python -m worm_gear_sim.ros [--ros-args ...]``: the node (same as ``worm_gear_sim_node``).

It goes through :func:`worm_gear_sim.ros.startup.node_main`, which installs the start-up
signal handlers before the heavy imports (numpy, scipy, numba, rclpy).
"""

import sys

from .startup import node_main

if __name__ == '__main__':
    sys.exit(node_main())
