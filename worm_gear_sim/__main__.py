# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``python -m worm_gear_sim``: the offline CLI (same as ``worm-gear-sim``)."""

import sys

from .cli import main

if __name__ == '__main__':
    sys.exit(main())
