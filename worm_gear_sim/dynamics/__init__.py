# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The drive's dynamics (Chung & Shaw 2007): the equations and everything that runs them.

:mod:`.equations` (Eqs. 1-18 compiled), :mod:`.model` (:class:`DriveModel`),
:mod:`.integrator` (the compiled hot loop),
:mod:`.stepping`, :mod:`.simulation`, :mod:`.trajectory`, :mod:`.modal`, :mod:`.profiles`,
:mod:`.load`, :mod:`.usability`.  Import the public names from :mod:`worm_gear_sim`; this
package's ``__init__`` exports nothing, so each name has one home.
"""
