# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Limits as a user hits them: the CLI as a subprocess.

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

from worm_gear_sim.params import Config
from worm_gear_sim.simulation import KEEP_ROWS

REPO = Path(__file__).resolve().parents[1]
DT = Config().integrator.time_step


def cli(*args, timeout=120):
    env = dict(os.environ, PYTHONPATH=str(REPO), MPLBACKEND='Agg')
    return subprocess.run([sys.executable, '-m', 'worm_gear_sim', *map(str, args)],
                          capture_output=True, text=True, env=env, timeout=timeout, cwd=REPO)


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
