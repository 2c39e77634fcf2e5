# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The drive's dynamics (Chung & Shaw 2007): the equations and everything that runs them.

* :mod:`.model`: equations of motion, the packed parameter layout, :class:`DriveModel`;
* :mod:`.integrator`: the compiled Newmark-beta / Newton-Raphson hot loop;
* :mod:`.stepping`: the stepping integration (:class:`Stepper`) over the integrator;
* :mod:`.simulation`: the public run API (:class:`Simulator`, :func:`simulate`);
* :mod:`.trajectory`: what a run returns (:class:`Trajectory`, :class:`SimState`);
* :mod:`.modal`: static equilibrium, linearised modes, the damping matrix;
* :mod:`.profiles`: commanded worm-angle profiles; :mod:`.load`: the load torque on the gear;
* :mod:`.usability`: whether a parameter set can be simulated (the whole-set rules).

Import the public names from :mod:`worm_gear_sim`; this package's ``__init__`` exports
nothing, so each name has one home.
"""
