# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A parameter set proven usable (:class:`Config`), its files in and out, and the pedestal's
file of several drives."""
