# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The options of a calibration that every face of it shares (``worm-gear-sim calibrate``
and ``worm_gear_sim_calibrate``): the limits of the excitation as argparse options and the
:class:`~worm_gear_sim.identification.excitation.Limits` they give, and the measured angles
of a comma-separated option."""

from __future__ import annotations

import argparse
from typing import Any

from .data import OUTPUTS, IdentificationError

__all__ = ['add_limit_options', 'limits_of', 'angle_list']


def add_limit_options(p: argparse.ArgumentParser) -> None:
    """The excitation's limits (``worm-gear-sim calibrate`` and ``worm_gear_sim_calibrate``)."""
    g = p.add_argument_group('limits of the excitation (worm angle theta1)')
    g.add_argument('--max-angle', type=float, default=0.12, metavar='RAD',
                   help='travel each way from the start (default: %(default)s rad)')
    g.add_argument('--max-rate', type=float, default=6.0, metavar='RAD/S',
                   help='(default: %(default)s rad/s)')
    g.add_argument('--max-accel', type=float, default=1500.0, metavar='RAD/S2',
                   help='(default: %(default)s rad/s^2)')
    g.add_argument('--duration', type=float, default=2.0, metavar='S',
                   help='longest total time of the moves (default: %(default)s s)')
    g.add_argument('--start', type=float, default=0.0, metavar='RAD',
                   help='the current worm angle (default: %(default)s)')


def limits_of(args: argparse.Namespace) -> Any:
    """The :class:`~worm_gear_sim.identification.excitation.Limits` of the options of
    :func:`add_limit_options`."""
    from .excitation import Limits
    return Limits(args.max_angle, args.max_rate, args.max_accel, args.duration, args.start)


def angle_list(text: str | None, option: str) -> tuple[str, ...] | None:
    """``theta2,theta4`` -> ('theta2', 'theta4'), each one of the model's measurable angles
    (``identification.OUTPUTS``); IdentificationError naming ``option`` otherwise (None: not
    given)."""
    if text is None:
        return None
    names = tuple(dict.fromkeys(o.strip() for o in text.split(',') if o.strip()))
    bad = [o for o in names if o not in OUTPUTS]
    if bad or not names:
        raise IdentificationError(
            f'{option} {text}: ' + (f'{", ".join(bad)} is not' if bad else 'give')
            + f' one of {", ".join(OUTPUTS)} (comma-separated)')
    return names
