# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A load torque on the antenna that varies in time (worm_gear_sim.dynamics.load): a constant
signal equals the constant key bit for bit; a varying one agrees with an independent Radau
solution of the same equations; the wind model has the documented statistics and spectrum
and is reproducible; bad samples are one-line errors; CSV records carry the load into the
prediction and the CLI."""

from __future__ import annotations

import math

import numpy as np
import pytest
from methods import METHODS, method_overrides
from scalar_command import piecewise_quadratic
from scipy.integrate import solve_ivp
from scipy.signal import welch

from worm_gear_sim import Config, SampledProfile, simulate
from worm_gear_sim.cli import main as cli_main
from worm_gear_sim.dynamics.equations import mesh_forces
from worm_gear_sim.dynamics.layout import P_J4, P_JG, P_JW, P_KG, P_TLOAD
from worm_gear_sim.dynamics.load import LoadSignal, SampledLoad, WindLoad
from worm_gear_sim.dynamics.modal import static_equilibrium
from worm_gear_sim.dynamics.model import pack_parameters
from worm_gear_sim.identification.data import predict, record_from_model
from worm_gear_sim.records import Record, RecordError, read_csv


class _SmoothLoad(LoadSignal):
    """T(t) = mean + a sin(2 pi f t) + b sin(2 pi 3.7 f t): a smooth right-hand side."""

    def __init__(self, mean: float, a: float, b: float, f: float) -> None:
        self.mean, self.a, self.b, self.f = mean, a, b, f

    def torque(self, t):
        w = 2 * np.pi * self.f * np.asarray(t, float)
        return self.mean + self.a * np.sin(w) + self.b * np.sin(3.7 * w)

    def torque_at(self, t: float) -> float:
        """The same at one instant (Radau's right-hand side)."""
        w = 2 * math.pi * self.f * t
        return self.mean + self.a * math.sin(w) + self.b * math.sin(3.7 * w)


@pytest.mark.parametrize('over', [
    {},                                                        # set-valued friction
    {'friction.model': 'stribeck', 'friction.direction': 'regularized'},
    {'mesh.backlash': 5.8e-4},                                 # 2 arcmin of play
], ids=['set_valued', 'stribeck', 'play'])
def test_a_constant_load_signal_equals_the_constant_key_bit_for_bit(over):
    cfg = Config().replace(over)
    keyed = simulate(cfg.replace({'load.output_torque': 4.0}), t_end=0.05)
    signal = simulate(cfg, t_end=0.05, load=SampledLoad([0.0, 1.0], [4.0, 4.0]))
    assert np.array_equal(keyed.theta, signal.theta)
    assert np.array_equal(keyed.omega, signal.omega)
    # the caller's model keeps its constant: the kernel works on a copy
    assert pack_parameters(cfg)[P_TLOAD] == 0.0


# Radau's tolerance: converged (measured: the reference at 1e-8 differs from the one at 1e-10
# by 7e-8 of the load's effect on theta2 and 3e-10 on theta4, and err/effect below is the same
# to 4 digits: 3.56e-4 and 2.49e-6), 3x faster than 1e-10 (8.5 s instead of 26 s)
RTOL = 1e-8


def _radau(cfg: Config, load: _SmoothLoad, times: np.ndarray, breaks) -> np.ndarray:
    """The model's equations (mesh_forces with no constant load) with -T(t) added to the
    antenna's equation, integrated by Radau from rest under T(0)."""
    p = pack_parameters(cfg)
    assert p[P_TLOAD] == 0.0
    M = np.array([p[P_JW], p[P_JG], p[P_J4]])
    prof = SampledProfile(np.array(breaks), np.array([0.0, 0.0, 0.08, 0.08]), 'linear')
    theta1 = piecewise_quadratic(prof.theta1, breaks)

    def rhs(t, y):
        f = mesh_forces(p, y[0], y[1], y[2], y[3], y[4], y[5], theta1(t))
        q4 = f[2] - load.torque_at(t)
        return np.array([y[3], y[4], y[5], f[0] / M[0], f[1] / M[1], q4 / M[2]])

    def jac(t, y):
        f = mesh_forces(p, y[0], y[1], y[2], y[3], y[4], y[5], theta1(t))
        kg = p[P_KG]
        J = np.zeros((6, 6))
        J[0, 3] = J[1, 4] = J[2, 5] = 1.0
        J[3:, :3] = np.array([[f[3], f[4], 0.0], [f[5], f[6], kg], [0.0, kg, -kg]]) / M[:, None]
        J[3:, 3:] = np.array([[f[7], f[8], 0.0], [f[9], f[10], 0.0], [0.0, 0.0, 0.0]]) \
            / M[:, None]
        return J

    p0 = p.copy()
    p0[P_TLOAD] = float(load.torque(np.array([0.0]))[0])
    y = np.r_[static_equilibrium(p0, 0.0), 0.0, 0.0, 0.0]
    out = np.empty((len(times), 3))
    for a, b in zip(breaks[:-1], breaks[1:]):
        sel = (times >= a) & (times <= b)
        sol = solve_ivp(rhs, (a, b), y, method='Radau', jac=jac, rtol=RTOL,
                        atol=np.r_[np.full(3, 1e-4 * RTOL), np.full(3, 0.1 * RTOL)],
                        dense_output=True)
        assert sol.success, sol.message
        out[sel] = sol.sol(times[sel])[:3].T
        y = sol.y[:, -1]
    return out, prof


_REFS: dict[str, tuple] = {}


@pytest.mark.parametrize('method', METHODS)
def test_a_varying_load_agrees_with_radau(method):
    """Nonlinear mesh, tanh friction (a smooth right-hand side), a move under a load of
    5 +- 4 N m varying at 60 and 222 Hz: Newmark (50 ns; the variable step at the
    tolerances of test_against_radau's 50 ns checks) against Radau, theta2 and theta4 within
    0.1 % of the motion the load causes (the difference to the run without it)."""
    cfg = Config().replace({'friction.direction': 'regularized', 'integrator.time_step': 5e-8,
                            **method_overrides(method, 5e-15, 5e-14)})
    load = _SmoothLoad(5.0, 3.0, 1.0, 60.0)
    breaks = (0.0, 0.004, 0.012, 0.025)
    t_end = breaks[-1]
    times = np.linspace(0.0, t_end, 2501)
    if 'ref' not in _REFS:              # Radau's equations do not depend on the method
        _REFS['ref'] = _radau(cfg, load, times, breaks)
    ref, prof = _REFS['ref']
    tr = simulate(cfg, profile=prof, t_end=t_end, record_every=200, load=load)
    bare = simulate(cfg, profile=prof, t_end=t_end, record_every=200)
    assert np.allclose(tr.t, times, atol=1e-12)
    for j in (0, 2):
        effect = np.ptp(tr.theta[:, j] - bare.theta[:, j])   # what the load does
        err = np.max(np.abs(tr.theta[:, j] - ref[:, j]))
        assert effect > 1e-6, effect
        assert err <= 1e-3 * effect, (j, err, effect)


def test_a_slow_load_ramp_ends_in_the_static_deflection():
    """Friction off, the worm held: a load ramped slowly to 6 N m leaves the antenna at the
    static equilibrium under 6 N m (an invariant of the equations, not of the integrator)."""
    cfg = Config().replace({'friction.model': 'off'})
    load = SampledLoad([0.0, 0.2, 1.0], [0.0, 6.0, 6.0])
    prof = SampledProfile(np.array([0.0, 1.0]), np.array([0.0, 0.0]))
    tr = simulate(cfg, profile=prof, t_end=1.0, record_every=250, load=load)
    p6 = pack_parameters(cfg)
    p6[P_TLOAD] = 6.0
    rest = static_equilibrium(p6, 0.0)
    assert abs(rest[2]) > 1e-5                               # a real deflection
    last = tr.t > 0.9            # 9.45 periods of the lightly damped 94.5 Hz mode, which
    # the ramp's end kink excites (~1e-6 rad): the mean is the rest
    np.testing.assert_allclose(tr.theta[last].mean(axis=0), rest, rtol=0,
                               atol=1e-3 * abs(rest[2]))
    assert np.ptp(tr.theta[last, 2]) < 0.02 * abs(rest[2])


def test_wind_has_the_documented_mean_intensity_and_spectrum():
    w = WindLoad(mean=10.0, intensity=0.2, time_scale=0.5, seed=11)
    t = np.arange(0.0, 2000.0, 0.01)
    x = w.gust_ratio(t)
    T = w.torque(t)
    assert abs(x.std() - 0.2) < 0.02, x.std()              # sigma_u / U
    assert abs(T.mean() - 10.0) < 0.3, T.mean()            # the mean torque
    f, pxx = welch(x, fs=100.0, nperseg=8192)
    band = (f > 0.02) & (f < 2.0)                          # around the corner 1/(2 pi tau)
    ratio = pxx[band] / w.spectrum(f[band])
    assert 0.75 < np.median(ratio) < 1.25, np.median(ratio)
    assert np.all((ratio > 0.3) & (ratio < 3.0))


def test_wind_is_reproducible_in_any_pieces_and_differs_by_seed():
    t = np.linspace(0.0, 30.0, 30001)
    whole = WindLoad(5.0, 0.15, 1.0, seed=4).torque(t)
    w = WindLoad(5.0, 0.15, 1.0, seed=4)
    pieces = np.concatenate([w.torque(t[:10]), w.torque(t[10:20000]), w.torque(t[20000:])])
    assert np.array_equal(whole, pieces)
    other = WindLoad(5.0, 0.15, 1.0, seed=5).torque(t)
    assert np.max(np.abs(other - whole)) > 0.1
    calm = WindLoad(5.0, 0.0, 1.0).torque(t)
    assert np.all(calm == 5.0)


@pytest.mark.parametrize('args, words', [
    ((float('nan'), 0.1), 'mean torque'), ((1e6, 0.1), 'mean torque'),
    ((5.0, -0.1), 'gust intensity'), ((5.0, 1.5), 'gust intensity'),
    ((5.0, 0.1, 0.0), 'time scale'), ((5.0, 0.1, 1.0, -1), 'seed')])
def test_bad_wind_parameters_are_one_line_errors(args, words):
    with pytest.raises(ValueError, match=words) as exc:
        WindLoad(*args)
    assert '\n' not in str(exc.value)


@pytest.mark.parametrize('times, values, words', [
    ([0.0, 1.0], [0.0, float('nan')], 'sample 1'), ([0.0, 1.0], [0.0, float('inf')], 'sample 1'),
    ([0.0, 1.0], [0.0, 2e5], 'beyond'), ([0.0, 1.0, 1.0], [0.0, 1.0, 2.0], 'sample 2'),
    ([0.0, 2.0, 1.0], [0.0, 1.0, 2.0], 'increase'), ([0.0, 1.0], [0.0], 'equal-length')])
def test_bad_load_samples_are_one_line_errors(times, values, words):
    with pytest.raises(ValueError, match=words) as exc:
        SampledLoad(times, values)
    assert '\n' not in str(exc.value)


def _write(path, rows, header='t [s],theta1 [rad],theta4 [rad],load_torque [N*m]'):
    path.write_text(header + '\n' + '\n'.join(','.join(str(v) for v in r) for r in rows) + '\n')
    return path


def test_a_csv_load_column_is_read_with_its_unit_and_drives_the_prediction(tmp_path):
    cfg = Config()
    wind = WindLoad(8.0, 0.2, 0.05, seed=2)
    rec = record_from_model(cfg, SampledProfile(np.array([0.0, 0.01, 0.03, 0.06]),
                                                np.array([0.0, 0.0, 0.05, 0.05])),
                            0.06, sample_rate=5e3, load=wind)
    assert rec.load_torque is not None and np.ptp(rec.load_torque) > 1.0
    rows = np.column_stack([rec.t, rec.theta1, rec.measured['theta4'],
                            rec.load_torque * 1e3])
    path = _write(tmp_path / 'r.csv', rows.tolist(),
                  header='t [s],theta1 [rad],theta4 [rad],load_torque [mN*m]')
    back = read_csv(path)
    np.testing.assert_allclose(back.load_torque, rec.load_torque, rtol=1e-12)
    pred = predict(cfg, back)['theta4']
    np.testing.assert_allclose(pred, rec.measured['theta4'], rtol=0, atol=1e-9)
    without = predict(cfg, Record(name='x', t=back.t, theta1=back.theta1,
                                  measured=back.measured))['theta4']
    assert np.max(np.abs(without - pred)) > 1e-5          # the load matters in the fit


@pytest.mark.parametrize('cell, header, words', [
    ('nan', 'load_torque', 'not a finite load torque'),
    ('2e5', 'load_torque', 'beyond'),
    ('1', 'load_torque [lbf*ft]', 'unknown torque unit')])
def test_bad_csv_load_cells_name_the_line_and_column(tmp_path, cell, header, words):
    path = _write(tmp_path / 'bad.csv', [[0.0, 0.0, 0.0, 0.0], [0.001, 0.0, 0.0, cell]],
                  header=f't,theta1,theta4,{header}')
    with pytest.raises(RecordError, match=words) as exc:
        read_csv(path)
    assert '\n' not in str(exc.value)


def test_the_cli_runs_a_csv_load_column_and_a_wind(tmp_path, capsys):
    t = np.arange(0.0, 0.1, 0.001)
    rows = np.column_stack([t, np.where(t > 0.01, 0.05, 0.0), 5.0 + 3.0 * np.sin(40 * t)])
    path = _write(tmp_path / 'cmd.csv', rows.tolist(), header='t,theta1,load_torque')
    base = ['--quiet', 'simulate', '--no-plot']
    assert cli_main(base + ['--csv', str(path), '-o', str(tmp_path / 'a.csv')]) == 0
    assert 'load torque on the antenna: load torque sampled at 100 points' in \
        (tmp_path / 'a.csv').read_text()[:2000]
    assert cli_main(base + ['--end-time', '0.05', '--wind', '20,0.15,0.5,3', '-o',
                            str(tmp_path / 'w.csv')]) == 0
    assert 'wind: mean 20 N m' in (tmp_path / 'w.csv').read_text()[:2000]
    capsys.readouterr()
    for bad in ('20', '20,3', '20,0.1,x'):
        assert cli_main(base + ['--wind', bad, '-o', str(tmp_path / 'x.csv')]) == 2, bad
        assert '--wind' in capsys.readouterr().err
    assert cli_main(base + ['--csv', str(path), '--wind', '20,0.1', '-o',
                            str(tmp_path / 'y.csv')]) == 2
    assert 'give one load' in capsys.readouterr().err


def test_the_play_and_gust_studies_measure_what_the_feedforward_cannot_cover():
    """sweep play / gust in small: without play the feed-forward cuts the slew's antenna
    error > 10x; with 2 arcmin of play, blind to it, much less, and the static error is
    half the play; with the backlash inverse the static error is gone and the slew's error
    is less than half the blind one (the reversal itself: ``sweep reversal``);
    compensated, the error grows with the gust intensity."""
    from worm_gear_sim.studies.backlash_reversal import ARCMIN
    from worm_gear_sim.studies.play_gust import gust_rows, play_rows
    rows = {(r['x'], r['series']): r for r in play_rows(Config(), (0.0, 2.0))}
    off0, on0 = rows[0.0, 'uncompensated'], rows[0.0, 'compensated']
    off2, blind2 = rows[2.0, 'uncompensated'], rows[2.0, 'blind']
    on2 = rows[2.0, 'compensated']
    assert off0['rms_err4'] > 10 * on0['rms_err4']
    assert off2['rms_err4'] > off0['rms_err4'] and blind2['rms_err4'] > 5 * on0['rms_err4']
    assert abs(blind2['static_err4']) == pytest.approx(ARCMIN, rel=0.2)   # half of 2 arcmin
    assert abs(on2['static_err4']) < 0.01 * ARCMIN
    assert on2['rms_err4'] < 0.5 * blind2['rms_err4']
    gust = {(r['x'], r['series']): r for r in gust_rows(Config(), (0.0, 0.2), seeds=(1,))}
    # compensated, the gusts are what is left (the uncompensated error is dominated by the
    # mean wind-up, which one seed's gusts can raise or lower)
    assert gust[0.2, 'compensated']['rms_err4'] > 3 * gust[0.0, 'compensated']['rms_err4']
