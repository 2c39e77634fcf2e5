# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The ROS 2 wing: the only part of worm_gear_sim that imports rclpy.

Topics, QoS, parameters, timers and diagnostics; every computation is a call into the core
(:mod:`worm_gear_sim.config.usable`, :mod:`worm_gear_sim.dynamics.simulation`, ...).
"""
