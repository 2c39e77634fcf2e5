# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``worm-gear-sim adapt``: the CSV's columns equal the twin's run for the same arguments,
the figure is written, bad options are one-line errors."""

from __future__ import annotations

import numpy as np
import pytest
from processes import cli_in_process

from worm_gear_sim.config.files import load_config
from worm_gear_sim.config.usable import Config
from worm_gear_sim.studies.adaptation_twin import run_twin


@pytest.fixture(scope='module')
def plant_file(tmp_path_factory):
    path = tmp_path_factory.mktemp('adapt') / 'plant.yaml'
    r = cli_in_process('params', '--set', 'load.output_torque=2.0', '--set',
                       'load.output_viscous_coefficient=10', '--set',
                       'mesh.worm_error_harmonics=[2e-5,-1e-5]', '--format', 'yaml',
                       '--output', path)
    assert r.returncode == 0, r.stderr
    return path


def test_adapt_writes_the_twins_columns_and_a_figure(plant_file, tmp_path):
    out = tmp_path / 'run.csv'
    r = cli_in_process('adapt', '--plant', plant_file, '--scenario', 'sector', '--duration',
                       '0.6', '--set', 'adaptation.window=0.2', '--seed', '4', '-o', out)
    assert r.returncode == 0, r.stderr
    assert out.with_suffix('.png').is_file()
    lines = [ln for ln in out.read_text().splitlines() if not ln.startswith('#')]
    assert lines[0].split(',') == ['t', 'theta1_ref', 'error_uncompensated',
                                   'error_compensated']
    data = np.array([[float(v) for v in ln.split(',')] for ln in lines[1:]])
    run = run_twin(load_config(plant_file), Config().replace({'adaptation.window': 0.2}),
                   'sector', 0.6, seed=4)
    assert data.shape == (run.t.size, 4)
    ref = np.column_stack([run.t, run.theta1_ref, run.error_uncompensated,
                           run.error_compensated])
    np.testing.assert_allclose(data, ref, rtol=1e-9, atol=1e-15)   # %.12g in the CSV


@pytest.mark.parametrize('args, words', [
    (('--duration', '0'), '--duration'),
    (('--duration', 'nan'), '--duration'),
    (('--duration', '1', '--noise', '-1'), '--noise'),
    (('--duration', '1', '--preview', '2'), '--preview'),
])
def test_adapt_bad_options(plant_file, tmp_path, args, words):
    r = cli_in_process('adapt', '--plant', plant_file, '--scenario', 'sector', *args, '-o',
                       tmp_path / 'x.csv')
    assert r.returncode != 0 and words in r.stderr and 'Traceback' not in r.stderr


def test_adapt_output_must_be_csv(plant_file, tmp_path):
    r = cli_in_process('adapt', '--plant', plant_file, '--scenario', 'slew', '--duration',
                       '1', '-o', tmp_path / 'x.txt')
    assert r.returncode != 0 and '.csv' in r.stderr
