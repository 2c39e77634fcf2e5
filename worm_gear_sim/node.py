# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``python -m worm_gear_sim.node``: runs :mod:`worm_gear_sim.ros.node` (the ROS wing).

Kept so that the documented command line works.  It goes through
:func:`worm_gear_sim.ros.startup.node_main`, which installs the start-up signal handlers
before the heavy imports; importing this module imports nothing.
"""

if __name__ == '__main__':
    import sys

    from worm_gear_sim.ros.startup import node_main

    sys.exit(node_main())
