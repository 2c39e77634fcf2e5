# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The worm-gear-sim CLI: every command on a small case, params round trip, bad input."""

import csv
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from worm_gear_sim import cli
from worm_gear_sim.config.files import default_config_path
from worm_gear_sim.config.usable import Config

REPO = Path(__file__).resolve().parents[2]
SHORT = ['--end-time', '0.03']       # the move ends at 0.02 s
PNG_MAGIC = b'\x89PNG\r\n\x1a\n'


def run(capsys, *argv):
    status = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return status, out, err


def assert_png(path: Path, min_bytes: int = 10_000):
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC, path
    assert len(data) >= min_bytes, (path, len(data))


def read_csv(path: Path):
    with open(path) as fh:
        rows = list(csv.reader(line for line in fh if not line.startswith('#')))
    return rows[0], rows[1:]


def assert_finite_columns(header, rows, columns):
    for c in columns:
        i = header.index(c)
        vals = [float(r[i]) for r in rows]
        assert vals and all(math.isfinite(v) for v in vals), c


def assert_one_line_error(status, err, *fragments):
    assert status != 0
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith('worm-gear-sim') and ' error: ' in lines[0], err
    assert 'Traceback' not in err
    for f in fragments:
        assert f in lines[0], (f, lines[0])


# ---- commands on small cases ------------------------------------------------------------
def test_simulate_writes_csv_and_png(tmp_path, capsys):
    out = tmp_path / 'run.csv'
    status, stdout, _ = run(capsys, 'simulate', *SHORT, '-o', out, '--record-every', '2')
    assert status == 0
    header, rows = read_csv(out)
    names = [h.split('[')[0] for h in header]
    for c in ('t', 'theta1', 'theta2', 'theta3', 'theta4', 'omega2', 'omega4',
              'normal_force', 'mu', 'worm_error', 'output_error'):
        assert c in names
    steps = round(0.03 / Config().integrator.time_step)     # the default step
    assert len(rows) == steps // 2 + 1        # every 2nd step, plus t = 0
    assert_finite_columns(header, rows, header)
    assert float(rows[-1][0]) == pytest.approx(0.03)
    assert_png(out.with_suffix('.png'))
    assert 'rings at' in stdout and 'wrote' in stdout


def test_simulate_from_input_csv(tmp_path, capsys):
    prof = tmp_path / 'cmd.csv'
    prof.write_text('t,theta1\n0,0\n0.01,0.05\n0.02,0.05\n')
    out = tmp_path / 'o.csv'
    status, stdout, _ = run(capsys, 'simulate', '--csv', prof, *SHORT, '-o', out,
                            '--no-plot')
    assert status == 0 and not out.with_suffix('.png').exists()
    header, rows = read_csv(out)
    i = [h.split('[')[0] for h in header].index('theta1')
    assert float(rows[-1][i]) == pytest.approx(0.05)
    assert 'sampled 3 points' in stdout


def test_experiment_table_and_plot(tmp_path, capsys):
    status, stdout, _ = run(capsys, 'experiment', *SHORT, '-o', tmp_path, '--traces')
    assert status == 0
    header, rows = read_csv(tmp_path / 'experiment.csv')
    assert {(r[0], r[1]) for r in rows} == {(m, c) for m in ('nonlinear', 'linear')
                                            for c in ('kinematic', 'paper')}
    assert_finite_columns(header, rows, ['eq2', 'eq4', 'mean4', 'freq4_hz', 'amp2', 'amp4'])
    eq4 = {(r[0], r[1]): float(r[header.index('eq4')]) for r in rows}
    assert eq4['nonlinear', 'kinematic'] == pytest.approx(0.0020196, rel=1e-4)
    assert eq4['nonlinear', 'paper'] == pytest.approx(0.012689, rel=1e-4)
    assert_png(tmp_path / 'experiment.png')
    th, tr = read_csv(tmp_path / 'experiment_traces.csv')
    assert len(th) == 1 + 8 and len(tr) > 50
    assert 'nonlinear' in stdout and 'paper' in stdout


def test_sweep_paper_study_serial(tmp_path, capsys):
    status, stdout, _ = run(capsys, 'sweep', 'flywheel', *SHORT, '--serial', '--no-progress',
                            '-o', tmp_path)
    assert status == 0
    header, rows = read_csv(tmp_path / 'flywheel.csv')
    assert header[:4] == ['study', 'series', 'label', 'x']
    assert_finite_columns(header, rows, ['x', 'amp2', 'amp4', 'half_pp4', 'eq4', 'max_err4'])
    amp4 = {r[2]: float(r[header.index('amp4')]) for r in rows}
    assert amp4['with'] > 10 * amp4['without']           # paper Sec. 4.1
    assert_png(tmp_path / 'flywheel.png')
    params = json.loads((tmp_path / 'sweep_params.json').read_text())
    assert params['input']['end_time'] == 0.03


def test_sweep_on_an_existing_scheduler_equals_serial(tmp_path, capsys):
    import logging

    from distributed import LocalCluster
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                      dashboard_address=None, silence_logs=logging.ERROR) as cluster:
        status, stdout, _ = run(capsys, 'sweep', 'flywheel', *SHORT, '--scheduler',
                                cluster.scheduler_address, '--no-progress', '-o',
                                tmp_path / 'dask')
    assert status == 0 and 'Dask scheduler tcp://' in stdout
    assert run(capsys, 'sweep', 'flywheel', *SHORT, '--serial', '--no-progress', '-o',
               tmp_path / 'serial')[0] == 0
    a = (tmp_path / 'dask' / 'flywheel.csv').read_bytes()
    assert a == (tmp_path / 'serial' / 'flywheel.csv').read_bytes()   # same numbers


def test_sweep_on_threads_equals_serial(tmp_path, capsys):
    """The default engine (threads of this process) writes the serial run's bytes."""
    status, stdout, _ = run(capsys, 'sweep', 'flywheel', *SHORT, '--workers', '2',
                            '--no-progress', '-o', tmp_path / 'threads')
    assert status == 0 and 'on 2 threads' in stdout
    assert run(capsys, 'sweep', 'flywheel', *SHORT, '--serial', '--no-progress', '-o',
               tmp_path / 'serial')[0] == 0
    a = (tmp_path / 'threads' / 'flywheel.csv').read_bytes()
    assert a == (tmp_path / 'serial' / 'flywheel.csv').read_bytes()   # same numbers


def test_sweep_checks_each_case_at_its_step_and_a_refused_case_fails_its_row(tmp_path,
                                                                              capsys):
    """A shaft 10 000 times stiffer is checked at the smaller step it runs at (it was refused
    at the configured 4 us step, and that stopped the whole sweep, exit 2, nothing written);
    a value the model refuses fails its own row (CSV column error, a line on stderr), the
    others run, exit status 1."""
    status, stdout, err = run(capsys, 'sweep', '--param', 'materials.worm_shaft_shear_modulus',
                              '--values', '7.7e10,7.7e14,-1', '--end-time', '0.025',
                              '--serial', '--no-progress', '-o', tmp_path)
    assert status == 1, err
    header, rows = read_csv(tmp_path / 'custom.csv')
    by_label = {r[header.index('label')]: r for r in rows}
    assert set(by_label) == {'7.7e10', '7.7e14', '-1'}
    for label in ('7.7e10', '7.7e14'):
        assert math.isfinite(float(by_label[label][header.index('amp4')]))
        assert by_label[label][header.index('error')] == ''
    assert 'must be > 0' in by_label['-1'][header.index('error')]
    assert float(by_label['-1'][header.index('amp4')]) != float(by_label['-1'][
        header.index('amp4')])                                          # nan
    lines = err.strip().splitlines()
    assert any('-1 failed' in ln and 'must be > 0' in ln for ln in lines), err
    assert lines[-1].startswith('worm-gear-sim: 1 of 3 cases failed'), err
    assert 'must be > 0' in stdout                      # the table's error column
    assert_png(tmp_path / 'custom.png')


def test_every_case_of_the_paper_studies_passes_the_check_at_its_step():
    """``sweep all`` (the README's command) runs: no case of the paper's studies is refused
    when checked as it runs (studies.case_config)."""
    from worm_gear_sim.studies import PAPER_STUDIES, case_config, paper_study
    cfg = Config()
    for name in PAPER_STUDIES:
        for c in paper_study(name, cfg).cases:
            case_config(cfg, c.overrides)


def test_sweep_help_names_the_default_engine_of_the_code(capsys):
    from worm_gear_sim.studies.engine import DEFAULT_ENGINE, ENGINE_TEXT
    status, out, _ = run(capsys, 'sweep', '--help')
    assert status == 0
    text = ' '.join(out.split())
    assert f'Runs on {ENGINE_TEXT[DEFAULT_ENGINE]}' in text
    assert f'(default: {DEFAULT_ENGINE})' in text
    assert 'Dask LocalCluster with one worker process per core by default' not in text


def test_sweep_user_parameter_with_compare(tmp_path, capsys):
    status, stdout, _ = run(capsys, 'sweep', '--param', 'mesh.phase_offset', '--values',
                            '0,3', '--compare', 'input.move_time=0.02,0.025', '--name',
                            'phase', *SHORT, '--serial', '--no-progress', '-o', tmp_path)
    assert status == 0
    header, rows = read_csv(tmp_path / 'phase.csv')
    assert len(rows) == 4
    assert {r[header.index('x')] for r in rows} == {'0.0', '3.0'}
    assert len({r[1] for r in rows}) == 2                 # one series per compared value
    assert_finite_columns(header, rows, ['amp2', 'amp4'])
    assert_png(tmp_path / 'phase.png')
    eh, er = read_csv(tmp_path / 'phase_envelope.csv')       # worst case over move_time
    assert len(er) == 2 and all(r[eh.index('cases')] == '2' for r in er)
    for e in er:
        same_x = [float(r[header.index('amp4')]) for r in rows
                  if r[header.index('x')] == e[eh.index('x')]]
        assert float(e[eh.index('amp4')]) == max(same_x)
        assert e[eh.index('amp4_at')] in ('move_time=0.02', 'move_time=0.025')
    assert_png(tmp_path / 'phase_envelope.png')


def test_modes_outputs(tmp_path, capsys):
    status, stdout, _ = run(capsys, 'modes', '-o', tmp_path / 'm.csv', '--json',
                            tmp_path / 'm.json', '--plot', tmp_path / 'm.png')
    assert status == 0
    header, rows = read_csv(tmp_path / 'm.csv')
    f = [float(r[header.index('undamped_hz')]) for r in rows]
    assert f == pytest.approx([94.5, 1561, 8588], rel=0.01)   # docs/model-notes.md reference
    doc = json.loads((tmp_path / 'm.json').read_text())
    assert len(doc['modes']) == 3 and np.shape(doc['K']) == (3, 3)
    assert_png(tmp_path / 'm.png')
    assert 'steps/period' in stdout


# ---- params: reproducible runs ------------------------------------------------------------
def test_params_json_round_trip_is_bit_exact(tmp_path, capsys):
    sets = ['--set', 'mesh.stiffness_model=linear', '--set', 'friction.model=constant',
            '--set', 'mesh.phase_offset=0.7', '--end-time', '0.025']
    pj = tmp_path / 'p.json'
    status, _, err = run(capsys, 'params', *sets, '-o', pj)
    assert status == 0
    doc = json.loads(pj.read_text())
    assert doc['format'] == cli.PARAMS_FORMAT
    assert doc['derived']['ratio'] == pytest.approx(56.0)
    assert doc['derived']['natural_frequencies_hz'][0] == pytest.approx(94.5, rel=0.01)
    assert doc['mesh']['stiffness_model'] == 'linear'
    cfg_direct = cli.resolve_config(None, ['mesh.stiffness_model=linear',
                                           'friction.model=constant', 'mesh.phase_offset=0.7',
                                           'input.end_time=0.025'])
    assert cli.resolve_config(pj) == cfg_direct
    a, b = tmp_path / 'a', tmp_path / 'b'
    assert run(capsys, 'simulate', *sets, '-o', a.with_suffix('.csv'), '--no-plot',
               '--npz', a.with_suffix('.npz'))[0] == 0
    assert run(capsys, 'simulate', '--config', pj, '-o', b.with_suffix('.csv'), '--no-plot',
               '--npz', b.with_suffix('.npz'))[0] == 0
    za, zb = np.load(a.with_suffix('.npz')), np.load(b.with_suffix('.npz'))
    assert sorted(za.files) == sorted(zb.files)
    for k in za.files:
        assert za[k].tobytes() == zb[k].tobytes(), k            # bit for bit
    # the JSON of the JSON is the same JSON
    status, out, _ = run(capsys, 'params', '--config', pj)
    assert json.loads(out) == doc


def test_params_yaml_output_loads_back(tmp_path, capsys):
    y = tmp_path / 'p.yaml'
    assert run(capsys, 'params', '--format', 'yaml', '--set', 'geometry.flywheel_radius=0.1',
               '-o', y)[0] == 0
    assert cli.resolve_config(y) == Config().replace({'geometry.flywheel_radius': 0.1})


def test_params_default_equals_package_yaml(capsys):
    status, out, _ = run(capsys, 'params')
    assert status == 0
    doc = json.loads(out)
    assert cli.load_params_json('stdin.json', doc) == cli.resolve_config(default_config_path())


# ---- bad input: one line on stderr, non-zero exit, no traceback -----------------------------
@pytest.fixture
def broken_files(tmp_path):
    bad_yaml = tmp_path / 'broken.yaml'
    bad_yaml.write_text('worm_gear_sim:\n  ros__parameters:\n    mesh: [unclosed\n')
    bad_json = tmp_path / 'broken.json'
    bad_json.write_text('{"mesh": {"phase_offset": 0.1,}')
    doc = cli.params_document(Config())
    doc['derived']['J_4'] *= 1.5
    tampered = tmp_path / 'tampered.json'
    tampered.write_text(json.dumps(doc))
    return {'yaml': bad_yaml, 'json': bad_json, 'tampered': tampered}


@pytest.mark.parametrize('argv,fragments', [
    (['simulate', '--set', 'mesh.stifness_model=linear'],
     ['mesh.stifness_model', 'unknown parameter', 'did you mean mesh.stiffness_model']),
    (['simulate', '--set', 'mesh.stiffness_model=cubic'], ['must be one of']),
    (['simulate', '--set', 'integrator.time_step=fast'], ['must be a number']),
    (['simulate', '--set', 'integrator.time_step=-1'], ['must be > 0']),
    (['simulate', '--set', 'geometry.flywheel_enabled=maybe'], ['true or false']),
    (['params', '--set', 'mesh.phase_offset'], ['expected KEY=VALUE']),
    (['simulate', '--config', 'does/not/exist.yaml'], ['not found']),
    (['simulate', '--csv', 'missing.csv'], ['not found']),
    (['simulate', '--end-time', 'soon'], ['invalid float value']),
    (['frobnicate'], ['invalid choice']),
    ([], ['a command is required']),
    (['sweep', '--serial'], ['nothing to sweep']),
    (['sweep', 'gravity', '--serial'], ['unknown study']),
    (['sweep', '--param', 'mesh.phase_offset', '--range', '0:1', '--serial'], ['--range']),
    (['sweep', '--param', 'mesh.phase', '--values', '1', '--serial'], ['unknown parameter']),
    (['sweep', '--param', 'mesh.phase_offset', '--values', '1,x', '--serial'],
     ['must be a number']),
    (['sweep', '--param', 'mesh.phase_offset', '--values', '99', '--serial'], ['must be <=']),
    (['sweep', 'flywheel', '--workers', '0'], ['--workers']),
    (['modes', '--theta1', 'nan'], ['finite']),
    (['simulate', '--end-time', '0.01', '-o', 'x.txt'], ['.csv']),
])
def test_bad_arguments_give_one_line(capsys, tmp_path, monkeypatch, argv, fragments):
    monkeypatch.chdir(tmp_path)
    status, _, err = run(capsys, *argv)
    assert status == 2
    assert_one_line_error(status, err, *fragments)


@pytest.mark.parametrize('which,fragments', [
    ('yaml', ['broken YAML', 'line']), ('json', ['broken JSON']),
    ('tampered', ['derived.J_4', 'does not match'])])
def test_broken_config_files(capsys, broken_files, which, fragments):
    status, _, err = run(capsys, 'simulate', '--config', broken_files[which])
    assert_one_line_error(status, err, *fragments)


def test_run_failure_is_one_line(capsys, tmp_path, monkeypatch):
    from worm_gear_sim.dynamics import simulation

    def boom(*a, **k):
        raise simulation.SimulationError('integration stopped at t = 0.001 s: test')
    monkeypatch.setattr(simulation, 'simulate', boom)
    monkeypatch.setattr(simulation, 'simulate_to_csv', boom)
    status, _, err = run(capsys, 'simulate', '-o', tmp_path / 'x.csv')
    assert status == 1
    assert_one_line_error(status, err, 'simulation failed')


def test_subprocess_entry_point_errors_and_help(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get('PYTHONPATH', ''))
    bad = subprocess.run([sys.executable, '-m', 'worm_gear_sim', 'simulate', '--set',
                          'nope.key=1'], capture_output=True, text=True, cwd=tmp_path, env=env,
                         timeout=120)
    assert bad.returncode == 2 and bad.stdout == ''
    assert_one_line_error(bad.returncode, bad.stderr, 'nope.key')
    ok = subprocess.run([sys.executable, '-m', 'worm_gear_sim', 'sweep', '--help'],
                        capture_output=True, text=True, cwd=tmp_path, env=env, timeout=120)
    assert ok.returncode == 0 and '--scheduler' in ok.stdout and ok.stderr == ''


def test_every_command_module_registers_its_commands(capsys):
    """Each module of COMMAND_MODULES adds its commands; compensate is one of them."""
    parser = cli.build_parser()
    status, out, _ = run(capsys, '--help')
    assert status == 0
    for command in ('simulate', 'experiment', 'sweep', 'modes', 'params', 'compensate'):
        assert command in out
    assert parser.parse_args(['compensate', '--no-plot']).func.__module__ == \
        'worm_gear_sim.cli.compensate'


def test_run_png_shows_the_mesh_load_readably(tmp_path, monkeypatch):
    """run.png's bottom panel drew W_n and mu over the whole run: a barcode of the antenna's
    ringing (it changes flank every half period).  Now no panel draws the W_n curve over
    more than a few periods (the zoom), the whole run shows its range."""
    from worm_gear_sim.cli import plotting
    from worm_gear_sim.dynamics.simulation import simulate
    figs = []
    monkeypatch.setattr(plotting, 'save_figure', lambda fig, path: figs.append(fig) or Path(path))
    traj = simulate(Config().replace({'input.end_time': 0.15}))
    plotting.plot_trajectory(traj, tmp_path / 'run.png')
    curves = []
    for ax in figs[0].axes:
        if ax.get_ylabel() != 'W_n [N]':
            continue
        lo, hi = ax.get_xlim()
        for line in ax.get_lines():
            x, y = np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)
            y = y[(x >= lo) & (x <= hi)]
            if y.size > 10 and np.ptp(y) > 0:
                curves.append(int(np.count_nonzero(np.diff(np.sign(y)) != 0)))
    assert curves, 'no W_n curve drawn'
    assert max(curves) <= 10, curves          # <= 5 periods of the flank changes
    assert max(curves) >= 4, curves           # and the zoom shows some


def test_a_command_imports_only_what_it_runs():
    """``worm-gear-sim modes`` builds the parser of its own command only: the fit, Dask and
    matplotlib stay unimported (each CLI process pays for what it runs), and ``--help``
    still lists every command."""
    code = ('import sys, contextlib, io; from worm_gear_sim.cli import main\n'
            'with contextlib.redirect_stdout(io.StringIO()): rc = main(["modes"])\n'
            'heavy = [m for m in ("worm_gear_sim.identification.fit", "distributed", '
            '"matplotlib", "worm_gear_sim.studies") if m in sys.modules]\n'
            'print(rc, heavy)')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         timeout=120)
    assert out.stdout.strip() == '0 []', out.stdout + out.stderr
    helped = subprocess.run([sys.executable, '-m', 'worm_gear_sim', '--help'],
                            capture_output=True, text=True, timeout=120)
    from worm_gear_sim.cli import COMMANDS
    assert helped.returncode == 0 and all(c in helped.stdout for c in COMMANDS), helped.stdout
