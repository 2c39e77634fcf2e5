# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""What a parameter set is: its sections, units and ranges, and the checks of each value (pure
data, the bottom floor)."""
