# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The bounds of the work an offline command may be asked for, in one place.  A request
beyond a bound is refused before any work starts, with one line naming the option, the work
it means, the bound and the way out (:func:`check_work`: a CliError, exit status 2).

The bounds are the size of what a user could mean on one machine: beyond them a typing
slip (``--drives 1000000``, ``--sample-rate 1e8``) would run for days or fill the memory.
The size of a simulated run's CSV has its own option (``simulate --max-csv-size``)."""

from __future__ import annotations

from .common import CliError

__all__ = ['MAX_PASS_TRAJECTORIES', 'MAX_PASS_COMPENSATED_S', 'MAX_MISMATCH_DRIVES',
           'MAX_CALIBRATION_SAMPLES', 'CALIBRATION_S_PER_DRIVE', 'check_work', 'duration_text']

#: ``pass``: trajectories sent, and seconds of compensated trajectory in all (~0.1 s of CPU
#: and ~50 kB kept per second).
MAX_PASS_TRAJECTORIES = 1000
MAX_PASS_COMPENSATED_S = 3600.0
#: ``sweep mismatch --drives``: random drives, each one whole calibration.
MAX_MISMATCH_DRIVES = 1000
#: Seconds one calibration of ``sweep mismatch`` takes (for the message only: the median
#: of 17-55 s per drive in docs/compensation.md).
CALIBRATION_S_PER_DRIVE = 24.0
#: ``calibrate``: samples of all the records of one calibration (each sample: t, theta1 and
#: the measured angles, 8 bytes each).  The fit uses at most 200 000 samples of a record
#: (``identification.data.MAX_FIT_SAMPLES``), so more only costs memory.
MAX_CALIBRATION_SAMPLES = 5_000_000


def check_work(option: str, amount: float, bound: float, unit: str, work: str,
               way_out: str) -> None:
    """Refuse ``amount`` beyond ``bound``: ``'{option}: {work}; at most {bound} {unit}:
    {way_out}'`` (CliError, exit status 2).  ``work`` says what the request means (e.g.
    '1e+06 random drives, each a calibration of ~24 s: ~278 days')."""
    if not amount <= bound:
        raise CliError(f'{option}: {work}; at most {bound:g} {unit}: {way_out}')


def duration_text(seconds: float) -> str:
    """A duration for a person: '40 s', '12 min', '6.7 h', '278 days'."""
    if seconds < 120:
        return f'{seconds:.3g} s'
    if seconds < 7200:
        return f'{seconds / 60:.3g} min'
    if seconds < 2 * 86400:
        return f'{seconds / 3600:.3g} h'
    return f'{seconds / 86400:.3g} days'
