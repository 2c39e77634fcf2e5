# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Small hostile-input items: a params YAML value ``1.6e8`` is a float (as the node's own
params parser reads it); the play limit's message shows the value and the limit apart and
the formula it checks."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from worm_gear_sim import Config, load_config
from worm_gear_sim._support.guarded_io import guarded_yaml_load
from worm_gear_sim.schema.validation import ConfigError

CONFIG = Path(__file__).resolve().parents[2] / 'config' / 'worm_gear_sim.yaml'


def test_exponent_floats_without_a_dot_are_floats(tmp_path):
    doc = guarded_yaml_load('a: 1.6e8\nb: 1e-3\nc: -2E+5\nd: 12\ne: 1e\nf: 0x1F', 'x')
    assert doc == {'a': 1.6e8, 'b': 1e-3, 'c': -2e5, 'd': 12, 'e': '1e', 'f': 31}
    text = CONFIG.read_text().replace('output_viscous_coefficient: 0.0',
                                      'output_viscous_coefficient: 1.6e2')
    assert text != CONFIG.read_text()
    (tmp_path / 'p.yaml').write_text(text)
    assert load_config(tmp_path / 'p.yaml').load.output_viscous_coefficient == 160.0


def test_a_play_just_over_the_limit_names_both_values_apart_and_the_formula():
    g = Config().geometry
    half = 0.5 * g.lead / g.gear_pitch_radius
    assert Config().replace({'mesh.backlash': float(np.nextafter(half, 0))})   # just under
    with pytest.raises(ConfigError) as err:
        Config().replace({'mesh.backlash': half})
    msg = str(err.value)
    assert f'{half!r} rad is more play' in msg and f'= {half!r} rad' in msg
    assert '0.5 geometry.lead / geometry.gear_pitch_radius' in msg and 'pi / z_g' not in msg
    over = float(np.nextafter(half, 1))
    with pytest.raises(ConfigError, match=f'{over!r} rad is more play'):
        Config().replace({'mesh.backlash': over})


def test_a_rejected_sample_of_an_offline_series_prints_a_plain_number():
    from worm_gear_sim import feedforward_series
    x = np.zeros(50)
    x[20] = 2000.0000000000018                       # beyond node.max_command_abs
    with pytest.raises(ValueError) as err:
        feedforward_series(Config(), np.arange(50) * 1e-3, x)
    assert 'theta1_ref = 2000.0000000000018)' in str(err.value), str(err.value)
    assert 'np.float64' not in str(err.value)
