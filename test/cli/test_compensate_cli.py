# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``compensate`` command: outputs, the `worm-gear-sim compensate` entry point, one-line errors."""

import numpy as np
import pytest

from worm_gear_sim.cli import main as cli_main


def test_compensate_writes_csv_and_png(tmp_path, capsys):
    out = tmp_path / 'sub' / 'run.csv'
    rc = cli_main(['compensate', '--end-time', '0.12', '-o', str(out)])
    assert rc == 0
    text = capsys.readouterr().out
    assert 'tracking_rms' in text and 'residual_peak' in text
    lines = out.read_text().splitlines()
    n_comment = sum(1 for line in lines if line.startswith('#'))
    data = np.genfromtxt(out, delimiter=',', names=True, skip_header=n_comment)
    assert {'deltarad', 'error_uncompensatedrad', 'error_compensatedrad'} <= set(data.dtype.names)
    assert data['ts'][-1] == pytest.approx(0.12, abs=2e-4)
    # the correction works: compensated error far below uncompensated after the move
    late = data['ts'] > 0.06
    assert np.abs(data['error_compensatedrad'][late]).max() < \
        0.1 * np.abs(data['error_uncompensatedrad'][late]).max()
    png = out.with_suffix('.png')
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def test_compensate_detuned_plant_without_plot(tmp_path, capsys):
    out = tmp_path / 'd.csv'
    rc = cli_main(['compensate', '--detune', 'flywheel_inertia=0.8', '--end-time', '0.1',
                                '--no-plot', '-o', str(out), '--set',
                                'compensation.preview_time=0.002'])
    assert rc == 0
    assert 'flywheel_inertia' in capsys.readouterr().out
    assert out.is_file() and not out.with_suffix('.png').exists()


@pytest.mark.parametrize('args, needle', [
    (['--detune', 'foo=1'], 'GROUP'),
    (['--detune', 'friction=-1'], '> 0'),
    (['--detune', 'friction=abc'], 'number'),
    (['--detune', 'friction'], 'GROUP=FACTOR'),
    (['--end-time', '0.02'], 'later than the end of the move'),
    (['--end-time', '-1'], '> 0'),
    (['--scenario', 'slew', '--end-time', '1'], 'has its own length'),
    (['--scenario', 'nope'], 'invalid choice'),
    (['--set', 'compensation.shaper=abc'], 'compensation.shaper'),
    (['--set', 'compensation.lag_order=5'], 'compensation.lag_order'),
    (['--record-every', '0'], 'record-every'),
    (['--config', '/nonexistent/x.yaml'], 'not found'),
])
def test_bad_arguments_one_line_error(tmp_path, capsys, args, needle):
    rc = cli_main(['compensate', *args, '--no-plot', '-o', str(tmp_path / 'x.csv')])
    assert rc != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and needle in err
    assert 'Traceback' not in err
