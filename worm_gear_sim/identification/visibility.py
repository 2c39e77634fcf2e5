# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Which fitted keys the records can show, and for each one they cannot, one line naming the
key and the move to record.

The play needs a flank change (or a lift off the flank, :mod:`.unload`), load and drag
need constant-rate segments; judged on the fitted values.  docs/identification.md
("Limits").
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from ..dynamics.model import DriveModel
from ..dynamics.stepping import SimulationError
from ..records import Record
from .data import predict
from .direct import DRAG, LOAD, PLAY, Segment, compliance, steady_segments

__all__ = ['flank_changes', 'key_visibility', 'mesh_lifts', 'LIFT_SHARE']

#: The gear counts as lifted off its flank when it leaves it by this share of the play.
LIFT_SHARE = 0.05


def _approaches(cfg: Any, records: Sequence[Record]) -> Iterator[tuple[np.ndarray, float]]:
    """The model ``cfg``'s mesh approach q = l_w theta2 - r_g theta3 (Eq. 8 without the
    periodic error) over each record it can run, with the flank's place in q, r_g b / 2
    (nothing when the model has no play)."""
    b = cfg.mesh.backlash
    if not b > 0:
        return
    m = DriveModel(cfg)
    lw, rg = m.derived.l_w, cfg.geometry.gear_pitch_radius
    for r in records:
        try:
            p = predict(m, r)
        except (SimulationError, ValueError):
            continue
        yield lw * p['theta2'] - rg * p['theta3'], 0.5 * rg * b


def flank_changes(cfg: Any, records: Sequence[Record]) -> bool:
    """Whether the model ``cfg`` (with play > 0) touches both flanks in some record."""
    return any(float(np.max(q)) >= edge * (1 - 1e-6) and float(np.min(q)) <= -edge * (1 - 1e-6)
               for q, edge in _approaches(cfg, records))


def mesh_lifts(cfg: Any, records: Sequence[Record]) -> bool:
    """Whether the model ``cfg`` (play > 0) lifts the gear off the flank it rests on by
    LIFT_SHARE of the play in some record (without it reaching the other flank)."""
    for q, edge in _approaches(cfg, records):
        side = 1.0 if float(np.median(q)) >= 0 else -1.0
        if float(np.max(edge - side * q)) >= LIFT_SHARE * 2.0 * edge:
            return True
    return False


def key_visibility(cfg: Any, records: Sequence[Record], keys: Sequence[str],
                   segments: Sequence[Segment] | None = None) -> dict[str, str]:
    """{key: one line naming the key and the move to record} for each fitted key of play,
    load and drag the records cannot show, judged with the fitted config ``cfg``."""
    out: dict[str, str] = {}
    m = DriveModel(cfg)
    u = m.output_per_input
    segs = list(segments) if segments is not None else steady_segments(records, u)
    rates = [s.rate for s in segs]
    both_ways = any(r > 0 for r in rates) and any(r < 0 for r in rates)
    T, c = cfg.load.output_torque, cfg.load.output_viscous_coefficient
    w_max = max((abs(r) for r in rates), default=0.0)
    play_hidden = False
    if PLAY in keys and not flank_changes(cfg, records) and not (
            LOAD in keys and abs(T) > 0 and mesh_lifts(cfg, records)):
        play_hidden = True
        # with the load fitted too, one flank fixes only b / 2 + T C: the load may be as
        # large as that sum over C (play 0), and the move named must cross the play then
        top = abs(T) + (0.5 * cfg.mesh.backlash / compliance(cfg) if LOAD in keys else 0.0)
        which = ('the largest load torque these records allow' if LOAD in keys
                 else 'the load torque')
        if c > 0 and abs(T) > 0:
            need = top / (c * u)
            how = (f'record a reversal at a constant worm rate above {need:.3g} rad/s (the '
                   f'drag torque then exceeds {which}, {top:.3g} N m; the '
                   f'records reach {w_max:.3g} rad/s), or unload the axis')
        elif abs(T) > 0:
            J4 = m.derived.J_4 + m.derived.J_g
            how = (f'record a stop with a worm deceleration above '
                   f'{top / (J4 * u):.3g} rad/s^2 (the inertia torque then exceeds '
                   f'{which}, {top:.3g} N m), or unload the axis')
        else:
            how = ('record a slow reversal (constant worm rate both ways, travel beyond the '
                   'play at the worm)')
        out[PLAY] = (f'{PLAY}: not seen: the gear stays on one flank in every record, so the '
                     f'play is not seen; {how}')
    if LOAD in keys:
        if not both_ways:
            out[LOAD] = (f'{LOAD}: not seen: no record moves at a constant worm rate both '
                         'ways; record a slow reversal (e.g. slew reversals at a constant '
                         'rate)')
        elif play_hidden:
            out[LOAD] = (f'{LOAD}: not separable from the play: with one flank throughout, '
                         'the records show only the sum of the load wind-up and half the '
                         'play; record the move named for mesh.backlash')
    if DRAG in keys and LOAD in keys:
        # one rate one way cannot tell the drag's wind-up from the load's; fitted without
        # the load, the drag shows in any motion (a zero column is the report's check)
        distinct = {round(math.copysign(abs(r), r), 6) for r in rates}
        if len(distinct) < 2:
            out[DRAG] = (f'{DRAG}: not seen: the records hold {len(distinct)} constant-rate '
                         'segment(s); record constant-rate segments at two rates or both '
                         'ways')
    return out
