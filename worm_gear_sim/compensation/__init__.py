# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The feed-forward: the compensating filters, the streaming compensator, the play crossing and
the blend from one model to another."""
