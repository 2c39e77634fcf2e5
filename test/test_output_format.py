# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""What the CLI prints for numbers at their limits (issue 13.5): an undamped model's damping
ratios are the eigen-solver's round-off and are clean zeros; real damping still prints."""

from __future__ import annotations

import re

from worm_gear_sim import Config, modes


def _zetas(table: str) -> list[str]:
    rows = [ln.split() for ln in table.splitlines()[1:]]
    return [r[3] for r in rows]


def test_undamped_modes_print_zero_damping():
    res = modes(Config())
    assert list(res.damping_ratios) == [0.0, 0.0, 0.0]   # round-off (~1e-16) is no damping
    assert _zetas(res.table()) == ['0.000e+00'] * 3


def test_damped_modes_print_their_damping():
    res = modes(Config().replace({'damping.rayleigh_alpha': 1.0}))
    zetas = [float(z) for z in _zetas(res.table())]
    # Rayleigh alpha: zeta = alpha / (2 omega_n)
    for z, f in zip(zetas, res.undamped_hz):
        assert z == float(f'{1.0 / (4 * 3.141592653589793 * f):.3e}')
    assert not re.search(r'e-1[3-9]|e-2\d', res.table())
