# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``simulate --csv`` is honest about its input and sizes its output: every
case that used to run silently wrong now gives the right run or a one-line error."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worm_gear_sim import cli, load_config
from worm_gear_sim.dynamics.profiles import SampledProfile
from worm_gear_sim.dynamics.simulation import simulate
from worm_gear_sim.records import read_csv

EPOCH_S = 1_763_890_855


def run(capsys, *argv):
    status = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return status, out, err


def move_rows(n=9, dt=0.1, amp=0.05):
    """A command that moves at 0.1-0.2 s and again at 0.6-0.7 s (past the 0.5 s default)."""
    t = np.arange(n) * dt
    x = np.interp(t, [0, 0.1, 0.2, 0.6, 0.7, 1.0], [0, 0, amp, amp, 2 * amp, 2 * amp])
    return t, x


# The CSV's samples equal the reference's to the last bit or two (decimal times, degrees);
# the smooth tanh friction law keeps such differences at round-off, where the set-valued
# law's stick/slip decisions can amplify them (2e-7 of theta4, measured).
SMOOTH = ['--set', 'friction.direction=regularized']


def reference(t, x, t_end):
    cfg = load_config().replace({'integrator.time_step': 2e-5,
                                 'friction.direction': 'regularized'})
    return simulate(cfg, SampledProfile(t, x), t_end)


def test_csv_longer_than_end_time_default_runs_to_its_end(tmp_path, capsys):
    t, x = move_rows()
    f = tmp_path / 'cmd.csv'
    f.write_text('t,theta1\n' + ''.join(f'{a:.3f},{b:.17g}\n' for a, b in zip(t, x)))
    out = tmp_path / 'o.csv'
    status, stdout, _ = run(capsys, 'simulate', '--csv', f, '-o', out, '--no-plot',
                            '--set', 'integrator.time_step=2e-5', *SMOOTH)
    assert status == 0
    rec = read_csv(out)
    assert rec.duration == pytest.approx(0.8)            # not cut at input.end_time = 0.5
    ref = reference(t, x, 0.8)
    assert rec.theta1[-1] == pytest.approx(2 * 0.05)
    np.testing.assert_allclose(rec.measured['theta4'][-1], ref.theta4[-1], rtol=1e-9)
    assert 'input: cmd: 9 samples over 0.8 s' in stdout


def test_csv_epoch_degrees_swapped_columns_give_the_right_run(tmp_path, capsys):
    t, x = move_rows()
    lines = ''.join(f'{math.degrees(b)!r},{EPOCH_S}.{int(round(a * 1e9)):09d}\n'
                    for a, b in zip(t, x))
    f = tmp_path / 'pj.csv'
    f.write_text('# exported\ntheta1 [deg],t [s]\n' + lines)
    out = tmp_path / 'o.csv'
    status, stdout, _ = run(capsys, 'simulate', '--csv', f, '-o', out, '--no-plot',
                            '--set', 'integrator.time_step=2e-5', '--end-time', '0.3',
                            *SMOOTH)
    assert status == 0
    assert 't = 0 at 2025-11-23T09:40:55.000000000Z' in stdout
    assert 'cuts the record' in stdout
    rec = read_csv(out)
    ref = reference(t, x, 0.3)
    assert rec.duration == pytest.approx(0.3)
    np.testing.assert_allclose(rec.theta1[-1], 0.05, rtol=1e-12)   # degrees converted
    np.testing.assert_allclose(rec.measured['theta4'][-1], ref.theta4[-1], rtol=1e-9)
    assert np.ptp(rec.measured['theta4']) > 5e-4                   # it moved: not zeros
    assert f't0_ns = {EPOCH_S}000000000' in out.read_text()


def test_csv_end_time_past_the_record_holds_and_says_so(tmp_path, capsys):
    f = tmp_path / 'c.csv'
    f.write_text('t,theta1\n0,0\n0.01,0.02\n')
    status, stdout, _ = run(capsys, 'simulate', '--csv', f, '-o', tmp_path / 'o.csv',
                            '--no-plot', '--end-time', '0.03')
    assert status == 0 and 'held at its last value' in stdout
    assert read_csv(tmp_path / 'o.csv').duration == pytest.approx(0.03)


@pytest.mark.parametrize('text, words', [
    ('theta1,t\n0,0\n0.1,0.1\n', None),                          # swapped: fine
    ('time_s,theta1\n0,0\n1,1\n', ["no column 't'", 'time_s']),
    ('0,0\n1,1\n', ['no header line']),
    ('t,theta1\n0,0\n0.1,0.1\n0.1,0.2\n', ['line 4', 'duplicated']),
    ('t,theta1\n0,0\n0.2,0.1\n0.1,0.2\n', ['line 4', 'backwards']),
    ('t,theta1\n0,0\n0.1,nan\n', ['line 3', 'theta1']),
    ('t,theta1\n0,0\n', ['at least 2']),
    ('t,theta1 [grad]\n0,0\n1,1\n', ["unit 'grad'"]),
    (f't,theta1\n{EPOCH_S}000000000,0\n{EPOCH_S}001000000,0.1\n', ['t [ns]']),
])
def test_csv_errors_are_one_line_exit_2(tmp_path, capsys, text, words):
    f = tmp_path / 'bad.csv'
    f.write_text(text)
    status, _, err = run(capsys, 'simulate', '--csv', f, '-o', tmp_path / 'o.csv',
                         '--no-plot', '--end-time', '0.002')
    if words is None:
        assert status == 0, err
        return
    assert status == 2 and len(err.strip().splitlines()) == 1 and 'Traceback' not in err
    for w in words:
        assert w in err, (w, err)


def test_csv_column_mapping_and_usage_errors(tmp_path, capsys):
    f = tmp_path / 'pj.csv'
    f.write_text('__time,/cmd/data,/other\n0,0,5\n0.001,0.001,5\n')
    status, stdout, _ = run(capsys, 'simulate', '--csv', f, '--column', 'theta1=/cmd/data',
                            '-o', tmp_path / 'o.csv', '--no-plot')
    assert status == 0 and 'ignored: /other' in stdout
    status, _, err = run(capsys, 'simulate', '--column', 'theta1=x', '-o', tmp_path / 'o.csv')
    assert status == 2 and '--column needs --csv' in err
    status, _, err = run(capsys, 'simulate', '--csv', f, '--column', 'theta1', '-o',
                         tmp_path / 'o.csv')
    assert status == 2 and 'ROLE=NAME' in err
    status, _, err = run(capsys, 'simulate', '--output-rate', '-1', '-o', tmp_path / 'o.csv')
    assert status == 2 and 'output-rate' in err


def test_output_sized_by_default_every_step_on_request(tmp_path, capsys):
    a, b = tmp_path / 'a.csv', tmp_path / 'b.csv'
    status, stdout, _ = run(capsys, 'simulate', '--end-time', '0.05', '-o', a, '--no-plot')
    assert status == 0 and 'CSV rows at 10000 Hz' in stdout
    status, stdout, _ = run(capsys, 'simulate', '--end-time', '0.05', '-o', b, '--no-plot',
                            '--output-rate', '0')
    assert status == 0 and 'every step' in stdout
    ra, rb = read_csv(a), read_csv(b)
    dt = load_config().integrator.time_step
    k = round(1e-4 / dt)                                    # steps per 10 kHz row
    assert ra.t.size == 501 and rb.t.size == round(0.05 / dt) + 1
    # decimation keeps rows, not averages: the 10 kHz file is every k-th row of the full one
    np.testing.assert_array_equal(ra.t, rb.t[::k])
    np.testing.assert_array_equal(ra.measured['theta4'], rb.measured['theta4'][::k])
    # the stated precision: 12 significant digits (relative 5e-12), t to the nanosecond
    full = simulate(load_config(), t_end=0.05)
    for got, want in ((rb.measured['theta4'], full.theta4), (rb.theta1, full.theta1),
                      (rb.measured['theta2'], full.theta2)):
        assert np.all(np.abs(got - want) <= 5.01e-12 * np.abs(want) + 1e-300)
    np.testing.assert_array_equal(rb.t, np.round(full.t, 9))
    assert a.stat().st_size < b.stat().st_size / 9
