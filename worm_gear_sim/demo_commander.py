# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``python -m worm_gear_sim.demo_commander``: runs :mod:`worm_gear_sim.ros.demo_commander`.

Kept so that the documented command line works; importing this module imports nothing.
"""

if __name__ == '__main__':
    import sys

    from worm_gear_sim.ros.demo_commander import main

    sys.exit(main())
