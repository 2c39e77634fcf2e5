# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Compensation of a known trajectory (a ROS JointTrajectory): its timeline, its dense rates,
its compensated version."""
