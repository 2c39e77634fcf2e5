# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``worm-gear-sim identify``: CSV and rosbag2 records in, a params file that the CLI,
``load_config()`` and the node load unchanged, a JSON report and figures out; every bad input
a one-line error with exit status 2."""

from __future__ import annotations

import json
import math
import signal
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from processes import start_logged, stop_and_read

from worm_gear_sim import load_config
from worm_gear_sim.cli import main
from worm_gear_sim.dynamics.profiles import SCurveProfile, TrapezoidalProfile
from worm_gear_sim.identification import record_from_model
from worm_gear_sim.records import BagStream, write_streams

KG = 'materials.gear_shaft_shear_modulus'
ZETA = 'damping.modal_damping_ratios[0]'
RES = 2 * math.pi / 2 ** 20
FAST = ['--serial', '--strategy', 'frequency+windows', '--no-progress']


@pytest.fixture(scope='module')
def truth():
    base = load_config()
    return base.replace({KG: base.materials.gear_shaft_shear_modulus * 1.3,
                         'damping.modal_damping_ratios': [0.01, 0.0, 0.0]})


def _record(truth, profile, seed, outputs=('theta4',)):
    return record_from_model(truth, profile, 0.15, 1e4, outputs, noise_rad=1e-6,
                             resolution_rad=RES, seed=seed)


def _csv(path: Path, rec, units: str = 'rad') -> Path:
    scale = {'rad': 1.0, 'urad': 1e6}[units]
    cols = [rec.t * 1e3, rec.theta1] + [rec.measured[o] * scale for o in rec.measured]
    head = ['t [ms]', 'theta1 [rad]'] + [f'{o} [{units}]' for o in rec.measured]
    np.savetxt(path, np.column_stack(cols), delimiter=',', header=','.join(head),
               comments='', fmt='%.15g')
    return path


@pytest.fixture(scope='module')
def fitted(tmp_path_factory, truth):
    """One CLI fit shared by the tests that read its outputs."""
    d = tmp_path_factory.mktemp('identify')
    a = _csv(d / 'move_a.csv', _record(truth, TrapezoidalProfile(0.1131, 0.02, 0.004, 0.005),
                                       1), units='urad')
    b = _csv(d / 'move_b.csv', _record(truth, SCurveProfile(-0.06, 0.012, 0.003, 0.002), 2))
    out = d / 'fitted.yaml'
    rc = main(['identify', str(a), '--fit', f'{KG},{ZETA}', '--validate', str(b), '-o',
               str(out), *FAST])
    assert rc == 0
    return out


def test_fit_outputs_report_and_yaml(fitted, truth):
    report = json.loads(fitted.with_suffix('.json').read_text())
    assert report['trustworthy'] is True and report['output_yaml'] == str(fitted)
    est = {p['key']: p for p in report['parameters']}
    k = est[KG]
    # within 4 standard deviations (interval calibration: test/identification/test_fit.py)
    sd = k['std_fitted_coordinate']
    assert abs(math.log(k['estimate'] / truth.materials.gear_shaft_shear_modulus)) < 4 * sd
    assert abs(est[ZETA]['estimate'] - 0.01) < 4 * 0.1 * est[ZETA]['std_fitted_coordinate']
    after = report['validation']['after'][0]['theta4']
    before = report['validation']['before'][0]['theta4']
    assert after['rel'] < 0.03 < before['rel']
    assert report['rms_after_rad']['theta4'] < 0.05 * report['rms_before_rad']['theta4']
    assert len(report['correlation']) == 2
    for png in report['figures']:
        assert Path(png).stat().st_size > 10_000
    # the YAML: node layout, every parameter, fitted values, comments with the intervals
    text = fitted.read_text()
    assert text.splitlines()[0].startswith('# worm_gear_sim parameters fitted by')
    assert f'{KG} = ' in text
    cfg = load_config(fitted)
    assert cfg.materials.gear_shaft_shear_modulus == pytest.approx(k['estimate'], rel=1e-12)
    assert cfg.damping.modal_damping_ratios[0] == pytest.approx(est[ZETA]['estimate'],
                                                                rel=1e-12)
    assert cfg.friction.direction == 'set_valued'       # the default law, kept
    unchanged = load_config().to_flat_dict()
    for key, v in cfg.to_flat_dict().items():
        if key not in (KG, 'damping.modal_damping_ratios'):
            assert v == unchanged[key], key


@pytest.mark.parametrize('argv', [
    ['simulate', '--end-time', '0.01', '--no-plot'],
    ['modes'],
    ['params'],
    ['compensate', '--end-time', '0.04', '--no-plot'],
])
def test_every_command_loads_the_fitted_yaml(fitted, tmp_path, argv, capsys):
    extra = ['-o', str(tmp_path / 'x.csv')] if argv[0] in ('simulate', 'compensate') else []
    assert main([*argv, '--config', str(fitted), *extra]) == 0
    if argv[0] == 'params':
        doc = json.loads(capsys.readouterr().out)
        assert doc['materials']['gear_shaft_shear_modulus'] == \
            load_config(fitted).materials.gear_shaft_shear_modulus


def test_bag_records(tmp_path, truth):
    rec = _record(truth, TrapezoidalProfile(0.1131, 0.02, 0.004, 0.005), 3,
                  outputs=('theta2', 'theta4'))
    names = tuple(load_config().node.joint_names)
    # epoch stamps with +-200 ns of jitter (off the model's dt grid)
    jitter = np.random.default_rng(0).integers(-200, 201, rec.t.size)
    stamps = np.int64(1_700_000_000_000_000_000) + np.round(rec.t * 1e9).astype(np.int64) + \
        jitter
    meas = np.column_stack([rec.measured['theta2'], rec.measured['theta4']])
    bag = write_streams(tmp_path / 'drive_bag', [
        BagStream('worm_angle_command', stamps, rec.theta1),
        BagStream('measured_joint_states', stamps, meas, 'joint_state',
                  (names[1], names[3]))], storage='mcap')
    out = tmp_path / 'fit.yaml'
    assert main(['identify', str(bag), '--fit', f'{KG},{ZETA}', '-o', str(out), *FAST]) == 0
    report = json.loads(out.with_suffix('.json').read_text())
    # theta2 sampled at 10 kHz: its 8.6 kHz worm mode lies above Nyquist, so it is named
    # and left out; chosen explicitly (--outputs) it is fitted too (here the records come
    # from the model itself, so even its aliased samples match)
    assert set(report['rms_after_rad']) == {'theta4'}
    assert 'not observable' in report['output_verdicts']['theta2']
    assert report['output_verdicts']['theta4'] == 'matched'
    assert main(['identify', str(bag), '--fit', f'{KG},{ZETA}', '-o', str(out), *FAST,
                 '--outputs', 'theta2,theta4']) == 0
    report = json.loads(out.with_suffix('.json').read_text())
    assert set(report['rms_after_rad']) == {'theta2', 'theta4'}
    est = {p['key']: p for p in report['parameters']}
    assert est[KG]['estimate'] == pytest.approx(truth.materials.gear_shaft_shear_modulus,
                                                rel=1e-3)
    # a bag without the named topic
    rc = main(['identify', str(bag), '--fit', KG, '-o', str(tmp_path / 'y.yaml'),
               '--joint-states-topic', 'encoders', *FAST])
    assert rc == 2


def _bad_csv(tmp_path: Path, kind: str, truth) -> Path:
    rec = _record(truth, TrapezoidalProfile(0.1131, 0.02, 0.004, 0.005), 4)
    p = _csv(tmp_path / f'{kind}.csv', rec)
    lines = p.read_text().splitlines()
    if kind == 'misnamed':
        lines[0] = lines[0].replace('theta1', 'theta_1')
    elif kind == 'no_measured':
        lines = [','.join(x.split(',')[:2]) for x in lines]
    elif kind == 'non_monotonic':
        lines[40], lines[41] = lines[41], lines[40]
    elif kind == 'duplicated':
        lines[41] = lines[40]
    elif kind == 'nan':
        f = lines[60].split(',')
        f[2] = 'nan'
        lines[60] = ','.join(f)
    elif kind == 'too_short':
        lines = lines[:8]
    p.write_text('\n'.join(lines) + '\n')
    return p


@pytest.mark.parametrize('kind, words', [
    ('misnamed', ["no column 'theta1'"]),
    ('no_measured', ['theta2', 'theta4']),
    ('non_monotonic', ['goes backwards']),
    ('duplicated', ['repeats the previous time']),
    ('nan', ['nan']),
    ('too_short', ['at least 20 samples']),
])
def test_bad_records_exit_2_one_line(tmp_path, truth, capsys, kind, words):
    p = _bad_csv(tmp_path, kind, truth)
    out = tmp_path / 'f.yaml'
    assert main(['identify', str(p), '--fit', KG, '-o', str(out), *FAST]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and 'Traceback' not in err, err
    assert err.startswith('worm-gear-sim: error:') and all(w in err for w in words), err
    assert not out.exists()


@pytest.mark.parametrize('args, words', [
    (['--fit', 'materials.gear_shaft_shear_modulu'], ['unknown parameter', 'did you mean']),
    (['--fit', 'friction.model'], ['friction.model', 'not numeric']),
    (['--fit', 'integrator.newton_max_iterations'], ['not a parameter of the drive']),
    (['--fit', KG, '--bounds', f'{KG}=1e11:1e10'], ['LO < HI']),
    (['--fit', KG, '--bounds', f'{ZETA}=0:0.1'], ['not among the --fit keys']),
    (['--fit', KG, '--serial', '--scheduler', 'tcp://127.0.0.1:1'], ['exclude']),
])
def test_bad_options_exit_2_one_line(tmp_path, truth, capsys, args, words):
    p = _csv(tmp_path / 'ok.csv', _record(truth, TrapezoidalProfile(0.1131, 0.02, 0.004,
                                                                    0.005), 5))
    out = tmp_path / 'f.yaml'
    argv = ['identify', str(p), '-o', str(out), '--no-progress', *args]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and all(w in err for w in words), err
    assert not out.exists()


def test_non_converging_fit_writes_no_yaml(tmp_path, truth, capsys):
    p = _csv(tmp_path / 'ok.csv', _record(truth, TrapezoidalProfile(0.1131, 0.02, 0.004,
                                                                    0.005), 6))
    out = tmp_path / 'f.yaml'
    argv = ['identify', str(p), '--fit', f'{KG},{ZETA}', '-o', str(out), '--serial',
            '--strategy', 'local', '--max-nfev', '2', '--no-progress', '--no-plot']
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and 'not trustworthy' in err[0] and 'did not converge' in err[0]
    assert not out.exists()
    report = json.loads(out.with_suffix('.json').read_text())
    assert report['trustworthy'] is False and report['output_yaml'] is None
    assert main([*argv, '--force']) == 0            # written anyway, and says so
    assert 'NOT TRUSTWORTHY' in out.read_text()
    load_config(out)


@pytest.mark.ros
def test_node_loads_the_fitted_yaml(fitted, ros_dds_context, ros_subprocess_env, tmp_path):
    pytest.importorskip('rclpy')
    import rclpy
    from rcl_interfaces.srv import GetParameters
    node = rclpy.create_node('identify_probe', context=ros_dds_context)
    from rclpy.executors import SingleThreadedExecutor
    ex = SingleThreadedExecutor(context=ros_dds_context)
    ex.add_node(node)
    proc, log = start_logged([sys.executable, '-m', 'worm_gear_sim.ros', '--ros-args',
                              '--params-file', str(fitted)], ros_subprocess_env,
                             tmp_path / 'node.txt')
    try:
        cli = node.create_client(GetParameters, '/worm_gear_sim/get_parameters')
        t0 = time.monotonic()
        while not cli.service_is_ready():
            assert proc.poll() is None, 'node exited'
            assert time.monotonic() - t0 < 90.0, 'node did not come up'
            ex.spin_once(timeout_sec=0.05)
        fut = cli.call_async(GetParameters.Request(
            names=[KG, 'damping.modal_damping_ratios']))
        ex.spin_until_future_complete(fut, timeout_sec=30.0)
        vals = fut.result().values
        cfg = load_config(fitted)
        assert vals[0].double_value == cfg.materials.gear_shaft_shear_modulus
        assert list(vals[1].double_array_value) == list(cfg.damping.modal_damping_ratios)
    finally:
        rc, text = stop_and_read(proc, log, signal.SIGINT, timeout=30.0)
        ex.shutdown()
        node.destroy_node()
    assert rc == 0 and 'Traceback' not in text, text


def test_an_aliased_output_is_named_and_the_others_still_give_a_yaml(tmp_path, capsys):
    """A drive that differs from the model where no fitted key reaches (a shorter, stiffer
    worm shaft: its worm mode moves), theta2 and theta4 sampled at 10 kHz: theta2's worm
    mode is above its Nyquist frequency, so no model can follow its phase.  The fit names
    theta2 as not observable (with the mode and the rate it needs), fits theta4, and writes
    the YAML; forced to fit theta2 too, the same fit is refused for theta2 (not matched)."""
    base = load_config()
    flat = base.to_flat_dict()
    truth = base.replace({KG: flat[KG] * 1.2, 'damping.modal_damping_ratios': [0.01, 0, 0],
                          'shafts.worm_shaft_length': flat['shafts.worm_shaft_length'] * 0.7})
    rec = _record(truth, TrapezoidalProfile(0.1131, 0.02, 0.004, 0.005), 5,
                  outputs=('theta2', 'theta4'))
    data = _csv(tmp_path / 'drive.csv', rec)
    out = tmp_path / 'fit.yaml'
    assert main(['identify', str(data), '--fit', f'{KG},{ZETA}', '-o', str(out), *FAST]) == 0
    printed = capsys.readouterr().out
    report = json.loads(out.with_suffix('.json').read_text())
    verdict = report['output_verdicts']
    assert verdict['theta4'] == 'matched' and report['trustworthy']
    assert 'not observable at this sampling' in verdict['theta2']
    assert '10000 Hz' in verdict['theta2'] and '8588 Hz mode' in verdict['theta2'], verdict
    assert 'not observable' in printed and out.exists()
    assert 'theta2: not observable' in out.read_text()          # named in the YAML's header
    est = {p['key']: p['estimate'] for p in report['parameters']}
    assert est[KG] == pytest.approx(flat[KG] * 1.2, rel=0.02)
    forced = tmp_path / 'forced.yaml'
    rc = main(['identify', str(data), '--fit', f'{KG},{ZETA}', '-o', str(forced), *FAST,
               '--outputs', 'theta2,theta4'])
    report = json.loads(forced.with_suffix('.json').read_text())
    assert rc == 2 and not forced.exists()
    assert report['output_verdicts']['theta2'].startswith('not matched'), report
    for bad, words in (('theta5', 'choose among'), ('theta3', 'not measured')):
        rc = main(['identify', str(data), '--fit', KG, '-o', str(tmp_path / 'b.yaml'), *FAST,
                   '--outputs', bad])
        assert rc == 2 and words in capsys.readouterr().err
