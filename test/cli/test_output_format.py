# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""What the CLI prints for numbers at their limits: an undamped model's damping
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


def test_compensate_table_never_prints_inf_for_settling():
    import math

    from worm_gear_sim.cli.compensate import metric_row
    assert metric_row('settling_time', math.inf, math.inf).split()[1:4] == \
        ['never', 'never', '-']
    assert metric_row('settling_time', math.inf, 0.0034).split()[1:4] == \
        ['never', '0.0034', 'settles']
    assert metric_row('settling_time', 0.01, math.inf).split()[1:4] == \
        ['0.01', 'never', 'never']
    assert metric_row('settling_time', 0.01, 0.002).split()[3] == '5x'
    assert metric_row('residual_peak', 3.231e-4, 1.196e-6).split()[1:4] == \
        ['0.0003231', '1.196e-06', '270x']
    assert metric_row('static_error', 1e-9, 4e-12).split()[3] == 'n/a'   # both at the floor


def test_compensate_cli_with_a_detuned_plant(tmp_path, capsys):
    from worm_gear_sim.cli import main
    rc = main(['compensate', '--detune', 'flywheel_inertia=0.8', '-o',
               str(tmp_path / 'c.csv'), '--no-plot'])
    out = capsys.readouterr().out
    assert rc == 0
    row = next(ln for ln in out.splitlines() if ln.startswith('settling_time'))
    assert 'inf' not in row and row.split()[1:4] == ['never', 'never', '-'], out
