# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The offline CLI's limits under hostile arguments and files: a pass of overlapping
trajectories bounded before it starts (``--every`` tiny, ``--duration`` shorter than a
waypoint period); ``identify`` on a record with an absurd or a constant theta4 (one line,
no ZeroDivisionError, no 308-digit ratio); a single huge CSV line refused without reading
it whole; a record decimated for the fit says so in the sampling verdict and the report."""

from __future__ import annotations

import re
import tracemalloc

import numpy as np
import pytest
from processes import cli_in_process

from worm_gear_sim.records.csv_io import MAX_CSV_LINE_CHARS


def one_line_error(r, *fragments):
    assert r.returncode == 2, (r.returncode, r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('worm-gear-sim: error: '), r.stderr
    assert 'internal error' not in lines[0] and 'Traceback' not in r.stderr
    for f in fragments:
        assert f in lines[0], (f, lines[0])
    return lines[0]


@pytest.mark.parametrize('args, fragments', [
    (('--every', '1e-3'), ('--every = 0.001 s', '60001 trajectories', 'at most 1000')),
    (('--duration', '1200', '--every', '2'), ('601 trajectories', '12020 s', '3600 s')),
    (('--duration', '1e-9'), ('--duration = 1e-09 s', 'shorter than --waypoint-period',)),
    (('--chunk', '0.5', '--every', '0.5'), ('--chunk = 0.5 s',)),
    (('--waypoint-period', '1e-9'), ('--waypoint-period = 1e-09 s', 'at most 99998')),
])
def test_a_pass_whose_work_is_unbounded_or_empty_is_refused_at_once(args, fragments,
                                                                    tmp_path):
    one_line_error(cli_in_process('pass', '-o', tmp_path, *args), *fragments)
    assert not any(tmp_path.iterdir())


def _record(path, theta4):
    t = np.arange(200) * 1e-3
    with open(path, 'w') as fh:
        fh.write('t [s],theta1 [rad],theta4 [rad]\n')
        np.savetxt(fh, np.column_stack([t, 0.1 * np.sin(20 * t), theta4(t)]), fmt='%.17g',
                   delimiter=',')
    return path


@pytest.mark.parametrize('theta4, fragments', [
    (lambda t: np.where(np.arange(t.size) == 50, 1e300, 0.002 * np.sin(20 * t)),
     ('theta4 = 1e+300 rad at sample 50', 'beyond 1e+06 rad')),
    (lambda t: np.full(t.size, 0.25), ('theta4 is constant (0.25 rad', 'no measured motion')),
])
def test_identify_on_an_absurd_or_constant_theta4_is_one_clear_line(theta4, fragments,
                                                                   tmp_path):
    csv = _record(tmp_path / 'r.csv', theta4)
    line = one_line_error(cli_in_process('identify', csv, '--fit', 'geometry.flywheel_radius',
                                         '-o', tmp_path / 'f.yaml', '--serial'), *fragments)
    assert re.search(r'\d{20}', line) is None              # no 308-digit number
    assert not (tmp_path / 'f.yaml').exists()


def test_a_single_huge_csv_line_is_refused_without_reading_it_whole(tmp_path):
    from worm_gear_sim.records import RecordError, read_csv
    f = tmp_path / 'one_line.csv'
    with open(f, 'w') as fh:
        fh.write('t,theta1,theta4\n0,0,0\n')
        for _ in range(160):                        # 16 MB on line 3, no newline
            fh.write('1' * 100_000)
    tracemalloc.start()
    try:
        with pytest.raises(RecordError, match=f'line 3: over {MAX_CSV_LINE_CHARS}'):
            read_csv(f)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 20 * MAX_CSV_LINE_CHARS, peak      # ~1.3 MB, not the 16 MB line


def test_a_decimated_record_says_so_in_the_sampling_verdict_and_the_report(monkeypatch):
    from worm_gear_sim import Config
    from worm_gear_sim.identification import data
    from worm_gear_sim.identification.observability import sampling_check
    from worm_gear_sim.records import Record
    monkeypatch.setattr(data, 'MAX_FIT_SAMPLES', 300)
    t = np.arange(1000) * 1e-4
    rec = data.normalised(Record('long', t, 0.01 * np.sin(60 * t),
                                 {'theta4': 0.01 / 56 * np.sin(60 * t)}, 0), 0)
    assert rec.source == {data.FIT_EVERY: 4, data.RECORDED_SAMPLES: 1000}
    verdict = sampling_check(Config(), [rec])['theta4'].describe()
    assert 'the fit keeps every 4th sample of long, recorded at 10000 Hz' in verdict, verdict


def test_a_mismatch_sweep_of_a_million_drives_is_refused_at_once(tmp_path):
    """Each drive is a whole calibration (~24 s): 10^6 of them is refused before any work,
    with the bound of the same home as the pass's (cli.limits)."""
    from worm_gear_sim.cli.limits import MAX_MISMATCH_DRIVES
    line = one_line_error(cli_in_process('sweep', 'mismatch', '-o', tmp_path, '--drives',
                                         '1000000'),
                          '--drives 1000000', 'days', f'at most {MAX_MISMATCH_DRIVES} drives')
    assert 'calibration' in line
    assert not any(tmp_path.iterdir())


CALIBRATE = ('calibrate', '--fit', 'load.output_torque', '--plant')


@pytest.mark.parametrize('args, fragments', [
    (('--sample-rate', '1e8'), ('--sample-rate 1e+08 Hz', 'samples', 'GB of records',
                                'at most 5e+06 samples')),
    (('--measure', 'theta9'), ('--measure theta9', 'theta9 is not one of theta2, theta3, '
                                                   'theta4')),
    (('--measure', 'theta4', '--outputs', 'theta4,omega'), ('--outputs', 'omega')),
    (('--noise', 'nan'), ('--noise nan',)),
    (('--encoder-bits', '99'), ('--encoder-bits', '99')),
])
def test_calibrate_refuses_bad_recording_options_before_the_run(args, fragments, tmp_path):
    from worm_gear_sim.config.files import default_config_path
    r = cli_in_process(*CALIBRATE, default_config_path(), '-o', tmp_path / 'fitted.yaml',
                       *args)
    one_line_error(r, *fragments)
    assert 'move ' not in r.stdout            # nothing designed was run
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize('where', ['/proc/worm_gear_sim/fitted.yaml', 'a_file/fitted.yaml',
                                   'a_dir.yaml'])
def test_calibrate_checks_its_output_path_before_the_run(where, tmp_path):
    """An -o where the files cannot be written was found only after the whole run (a
    traceback-free error, but after the fit): now at once, and nothing runs."""
    from worm_gear_sim.config.files import default_config_path
    (tmp_path / 'a_file').write_text('x')
    (tmp_path / 'a_dir.yaml').mkdir()
    out = where if where.startswith('/') else tmp_path / where
    r = cli_in_process(*CALIBRATE, default_config_path(), '-o', out)
    one_line_error(r, f'-o {out}', 'nothing was run')
    assert 'move ' not in r.stdout
