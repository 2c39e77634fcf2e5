# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Limits as a user hits them: the CLI's whole entry point (``cli.main``, in this process).

6: ``--set`` of list parameters (the documented ``damping.modal_damping_ratios=0.01,0,0``,
``node.joint_names``) works and bad lists give one line naming the key.
8: a huge ``--end-time`` is refused at once with the estimate and the way out; long runs
stream their CSV (bounded memory)."""

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from processes import cli_in_process

from worm_gear_sim.config.usable import Config
from worm_gear_sim.dynamics.simulation import KEEP_ROWS

REPO = Path(__file__).resolve().parents[2]
DT = Config().integrator.time_step


def cli(*args, timeout=None):
    """The CLI's whole entry point in this process (``timeout`` kept for the callers)."""
    return cli_in_process(*args)


def one_line_error(r, *fragments):
    assert r.returncode == 2, (r.returncode, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('worm-gear-sim: error: '), r.stderr
    assert 'Traceback' not in r.stderr
    for f in fragments:
        assert f in lines[0], (f, lines[0])


def test_set_list_parameters():
    r = cli('params', '--set', 'damping.modal_damping_ratios=0.01,0,0',
            '--set', 'node.joint_names=in,worm,gear,antenna')
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc['damping']['modal_damping_ratios'] == [0.01, 0.0, 0.0]
    assert doc['node']['joint_names'] == ['in', 'worm', 'gear', 'antenna']
    r = cli('params', '--set', 'damping.modal_damping_ratios=[0.02, 0.01, 0]',
            '--set', "node.joint_names=['a', 'b', 'c', 'd']")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc['damping']['modal_damping_ratios'] == [0.02, 0.01, 0.0]
    assert doc['node']['joint_names'] == ['a', 'b', 'c', 'd']


def test_set_list_reaches_the_model(tmp_path):
    """The documented example really damps: the antenna's ringing decays with it."""
    r = cli('modes', '--set', 'damping.modal_damping_ratios=0.01,0,0')
    assert r.returncode == 0, r.stderr
    first = [ln for ln in r.stdout.splitlines() if ln.startswith('1 ')][0].split()
    assert float(first[3]) == pytest.approx(0.01, rel=0.05)       # zeta of mode 1


@pytest.mark.parametrize('setting, fragments', [
    ('damping.modal_damping_ratios=0.01,0', ['damping.modal_damping_ratios', '3 entries']),
    ('damping.modal_damping_ratios=0.01,x,0', ['damping.modal_damping_ratios[1]', 'number']),
    ('damping.modal_damping_ratios=2,0,0', ['damping.modal_damping_ratios[0]', '<= 1']),
    ('node.joint_names=a,b,c', ['node.joint_names', '4 entries']),
    ('node.joint_names=a,a,b,c', ['node.joint_names', 'unique']),
])
def test_set_bad_lists_name_the_key(setting, fragments):
    one_line_error(cli('params', '--set', setting), *fragments)


def test_huge_end_time_is_refused_up_front(tmp_path):
    t = time.monotonic()
    r = cli('simulate', '--end-time', '1e4', '-o', tmp_path / 'x.csv')
    assert time.monotonic() - t < 60          # no integration, no allocation of the run
    one_line_error(r, '--end-time 10000 s', 'GB of CSV', '--max-csv-size', '--output-rate')
    assert not (tmp_path / 'x.csv').exists()
    one_line_error(cli('simulate', '--end-time', '1e300', '-o', tmp_path / 'x.csv'),
                   'input.end_time')          # beyond the declared range
    one_line_error(cli('simulate', '--end-time', '0.01', '--max-csv-size', '0',
                       '-o', tmp_path / 'x.csv'), '--max-csv-size')
    # the in-memory path (--npz needs every row) has its own memory limit
    one_line_error(cli('simulate', '--end-time', '1e3', '--output-rate', '0',
                       '--max-csv-size', '1e6', '--npz',
                       tmp_path / 'x.npz', '-o', tmp_path / 'x.csv'), '--npz', 'max_bytes',
                   f'{1e3 / DT:.2g} rows')           # every step of the default dt


def test_long_run_streams_every_row(tmp_path):
    """A run longer than the plot's row budget: the CSV has every row, the summary says
    the plot/metrics used a thinned copy."""
    out = tmp_path / 'long.csv'
    t_end = 1.0                               # 250000 steps of the default dt > KEEP_ROWS
    r = cli('simulate', '--end-time', t_end, '--output-rate', '0', '-o', out, '--no-plot')
    assert r.returncode == 0, r.stderr
    rows = sum(1 for line in open(out) if not line.startswith('#')) - 1
    assert rows == round(t_end / DT) + 1 > KEEP_ROWS
    assert 'plot and metrics from' in r.stdout


# ---- hostile parameter files: one line naming the file and the limit, exit 2 ----------------
ALIAS_BOMB = '\n'.join(['a: &a ["x","x","x","x","x","x","x","x","x"]'] + [
    f'{chr(98 + i)}: &{chr(98 + i)} [*{chr(97 + i)},*{chr(97 + i)},*{chr(97 + i)},'
    f'*{chr(97 + i)},*{chr(97 + i)},*{chr(97 + i)},*{chr(97 + i)},*{chr(97 + i)},'
    f'*{chr(97 + i)}]' for i in range(8)]) + '\n'


@pytest.mark.parametrize('kind', ['alias_bomb', 'deep_yaml', 'deep_json', 'binary', 'huge',
                                  'nul'])
def test_hostile_config_files_are_named_errors(tmp_path, kind):
    """A 1 kB YAML alias bomb (expands to 9^9 strings: it reached 5.7 GB), a 5 000-deep
    YAML or JSON, a binary file, a file over the size limit, a NUL byte: each one line
    naming the file (and the limit), exit 2, at once."""
    from worm_gear_sim._support.guarded_io import MAX_CONFIG_BYTES, MAX_CONFIG_DEPTH
    f = tmp_path / {'deep_json': 'p.json', 'binary': 'p.bin'}.get(kind, 'p.yaml')
    if kind == 'alias_bomb':
        assert len(ALIAS_BOMB) < 1100
        f.write_text(ALIAS_BOMB)
    elif kind == 'deep_yaml':
        f.write_text('[' * 5000 + ']' * 5000 + '\n')
    elif kind == 'deep_json':
        f.write_text('{"a": ' * 5000 + '1' + '}' * 5000)
    elif kind == 'binary':
        f.write_bytes(bytes(range(256)) * 4)
    elif kind == 'huge':
        f.write_text('# padding\n' * (MAX_CONFIG_BYTES // 10 + 1))
    else:
        f.write_text('integrator:\n  time_step: 4.0e-6\x00\n')
    t0 = time.monotonic()
    r = cli('simulate', '--config', f, '--no-plot', '-o', tmp_path / 'o.csv', timeout=60)
    elapsed = time.monotonic() - t0
    want = {'alias_bomb': 'aliases are not supported',
            'deep_yaml': f'nested deeper than {MAX_CONFIG_DEPTH} levels',
            'deep_json': 'nested too deep', 'binary': 'not a text file',
            'huge': f'at most {MAX_CONFIG_BYTES} bytes', 'nul': 'NUL byte'}[kind]
    one_line_error(r, str(f), want)
    assert elapsed < 30, elapsed            # no expansion: refused before any work


def test_the_package_has_one_guarded_yaml_loader():
    """One loader for every YAML the package reads (the node's file defaults, the CLI's
    --config, params documents, bag metadata): guarded_io.guarded_yaml_load."""
    import inspect

    import worm_gear_sim._support.guarded_io as gio
    assert inspect.getsource(gio).count('yaml.load(') == 1
    for mod in (REPO / 'worm_gear_sim').rglob('*.py'):
        if mod.name != 'guarded_io.py':
            text = mod.read_text()
            assert 'yaml.safe_load' not in text and 'yaml.load(' not in text, mod


@pytest.mark.parametrize('content', ['', 'just a string\n', ALIAS_BOMB])
def test_a_bag_with_a_bad_metadata_yaml_is_a_named_error(tmp_path, content):
    """An empty metadata.yaml gave "'NoneType' object is not subscriptable"; an alias bomb
    would expand: one line naming the bag, exit 2."""
    bag = tmp_path / 'bag'
    bag.mkdir()
    (bag / 'metadata.yaml').write_text(content)
    r = cli('simulate', '--bag', bag, '--no-plot', '-o', tmp_path / 'o.csv', timeout=60)
    one_line_error(r, str(bag), 'not a readable rosbag2 bag')


def test_a_csv_header_over_the_line_limit_is_a_named_error(tmp_path):
    """A header of 200 kB (csv's own field limit is 128 kB: it was "internal error",
    exit 1): one line naming the file, the line and the limit, exit 2."""
    from worm_gear_sim.records.csv_io import MAX_CSV_LINE_CHARS
    f = tmp_path / 'wide.csv'
    f.write_text('t,theta1,' + ','.join(f'c{i}' for i in range(40_000)) + '\n0,0\n')
    r = cli('simulate', '--csv', f, '--no-plot', '-o', tmp_path / 'o.csv', timeout=60)
    one_line_error(r, str(f), 'line 1', f'at most {MAX_CSV_LINE_CHARS}')


READ_PEAK = """
import sys, tracemalloc
from worm_gear_sim.records import read_csv
tracemalloc.start()
rec = read_csv(sys.argv[1])
print(len(rec.t), tracemalloc.get_traced_memory()[1])
"""


def test_reading_a_large_csv_takes_memory_of_the_order_of_its_size(tmp_path):
    """100 000 rows (4.3 MB): the reader streams the file; the peak of what it allocates
    (tracemalloc: Python objects and numpy) is below 2x the file's size (8 bytes per value
    kept: measured 0.6x for 1 million rows; the former reader held the text, a list of
    lines and a Decimal per row: 10.6x)."""
    import numpy as np
    f = tmp_path / 'big.csv'
    n = 100_000
    t = np.arange(n) * 1e-4
    with open(f, 'w') as fh:
        fh.write('t [s],theta1 [rad],theta4 [rad]\n')
        np.savetxt(fh, np.column_stack([t, 0.1 * np.sin(t), 0.0025 * np.sin(t)]),
                   fmt=['%.4f', '%.12g', '%.12g'], delimiter=',')
    size = f.stat().st_size
    env = dict(os.environ, PYTHONPATH=str(REPO))
    r = subprocess.run([sys.executable, '-c', READ_PEAK, str(f)], capture_output=True,
                       text=True, env=env, timeout=300, cwd=REPO)
    assert r.returncode == 0, r.stderr
    rows, grew = map(int, r.stdout.split())
    assert rows == n
    print(f'\n{size / 1e6:.0f} MB CSV: peak of {grew / 1e6:.0f} MB allocated while reading')
    assert grew < 2 * size, (grew, size)


def test_long_records_are_decimated_for_the_fit(monkeypatch):
    """A record longer than MAX_FIT_SAMPLES keeps every k-th sample for the fit."""
    import numpy as np

    from worm_gear_sim.identification import data
    from worm_gear_sim.records import Record
    monkeypatch.setattr(data, 'MAX_FIT_SAMPLES', 300)
    t = np.arange(1000) * 1e-4
    rec = Record('r', t, 0.01 * t, {'theta4': 0.01 * t / 40}, 0)
    assert data.decimation(1000) == 4 and data.decimation(300) == 1
    out = data.normalised(rec, 0)
    assert len(out.t) == 250 and out.t[1] == t[4]
    assert out.measured['theta4'][1] == rec.measured['theta4'][4]
