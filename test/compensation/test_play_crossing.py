# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The soft crossing of the mesh play on known trajectories
(worm_gear_sim.compensation.play_crossing) and the studies built on it
(worm_gear_sim.studies.mismatch, ``sweep crossing`` and ``sweep mismatch``)."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from worm_gear_sim import Config
from worm_gear_sim.compensation.play_crossing import (
    flank_offset,
    flank_series,
    open_worm_rate,
    smooth_step,
    soft_feedforward_series,
    worm_ringing_cancel,
)
from worm_gear_sim.compensation.start_from_rest import (
    START_WINDOW_PERIODS,
    open_mesh_cancel,
    rest_starts,
    start_modes,
    start_ringing_cancel,
)
from worm_gear_sim.compensation.streaming import Compensator
from worm_gear_sim.dynamics.layout import AUX_Q, AUX_WN
from worm_gear_sim.dynamics.model import DriveModel
from worm_gear_sim.dynamics.profiles import SampledProfile, TrapezoidalProfile
from worm_gear_sim.dynamics.simulation import simulate
from worm_gear_sim.joint_trajectory.compensate import (
    antenna_error,
    trajectory_feedforward,
    trajectory_model,
)
from worm_gear_sim.realtime import feedforward_series
from worm_gear_sim.studies.mismatch import benefit, mismatched, sector_scan, slew_reversals

ARCMIN = math.pi / (180 * 60)
#: a sector-scan drive whose flank changes near the scan's edges (drag > inertia torque)
SCAN_DRIVE = {'mesh.backlash': 1.0 * ARCMIN, 'load.output_torque': 0.5,
              'load.output_viscous_coefficient': 10.0}


@pytest.fixture(scope='module')
def scan():
    """The ±5° sector scan (4 s) with perfect knowledge: the plant, the move, the
    streaming corrections with the centring preview (the step crossing) and the soft ones."""
    plant = Config().replace(SCAN_DRIVE)
    m = trajectory_model(DriveModel(plant))
    move = sector_scan(plant)
    fs = flank_series(m, move.t, move.theta1)
    soft, plans = soft_feedforward_series(m, move.t, move.theta1)
    return plant, m, move, fs, soft, plans


def test_smooth_step_is_a_gentle_step():
    u = np.linspace(-0.5, 1.5, 2001)
    s = smooth_step(u)
    assert s[0] == 0.0 and s[-1] == 1.0 and np.all(np.diff(s) >= 0.0)
    assert smooth_step(0.5) == pytest.approx(0.5, abs=1e-15)
    h = 1e-4                       # first and second derivatives vanish at both ends
    for end in (0.0, 1.0):
        d1 = (smooth_step(end + h) - smooth_step(end - h)) / (2 * h)
        d2 = (smooth_step(end + h) - 2 * smooth_step(end) + smooth_step(end - h)) / h ** 2
        assert abs(d1) < 1e-9 and abs(d2) < 1e-5


def test_the_flank_series_is_the_offline_twin(scan):
    """The streaming compensator run by flank_series gives the corrections of
    feedforward_series (the node's pipeline) with its step crossings
    (``compensation.soft_crossing`` off: flank_series plans its own) exactly, float or
    nanosecond times."""
    _, m, move, fs, _, _ = scan
    step = m.config.replace({'compensation.soft_crossing': False})
    assert np.array_equal(fs.delta, feedforward_series(step, move.t, move.theta1))
    ns = np.round(move.t[:800] * 1e9).astype(np.int64) + 123   # (the end rests: cut it)
    assert np.array_equal(flank_series(m, ns, move.theta1[:800]).delta[:700],
                          fs.delta[:700])


def test_the_crossings_follow_the_demand_and_keep_the_rest_offset(scan):
    """Each crossing contains the sign change of the mesh torque demand and ends on the
    flank of the demand's new sign; away from the crossings the corrections are the
    streaming ones bit for bit, so at rest after a move the worm takes up exactly half the
    play, on the flank the move ended on."""
    plant, m, move, fs, soft, plans = scan
    assert len(plans) == 2
    inside = np.zeros(move.t.size, bool)
    for p in plans:
        assert p.start < p.zero < p.end and p.end - p.start > 3e-3
        assert p.start_flank == -p.end_flank
        after = np.interp(p.end + 2e-3, fs.t, fs.demand)
        assert np.sign(after) == p.end_flank
        inside |= (move.t >= p.start) & (move.t < p.end)
    assert np.array_equal(soft[~inside], fs.delta[~inside])
    assert not np.array_equal(soft[inside], fs.delta[inside])
    h_input = fs.flank_step                         # half the play in worm angle
    steps = (soft - fs.delta)[inside] / h_input    # planned flank - streaming flank
    assert np.all(np.abs(steps) <= 2.0 + 1e-12)
    # at rest: a move back, no load, from the drive flank: to the coast flank to
    # accelerate, back to the drive flank to stop (no load: it stays there)
    rest = Config().replace({'mesh.backlash': 2 * ARCMIN})
    mr = trajectory_model(DriveModel(rest))
    t = np.arange(0, 0.4, 1e-3)
    x = TrapezoidalProfile(-0.05, 0.1, 0.03, t0=0.05).theta1(t)
    d_soft, pl = soft_feedforward_series(mr, t, x)
    d_step = feedforward_series(mr, t, x)
    assert [(p.start_flank, p.end_flank) for p in pl] == [(1.0, -1.0), (-1.0, 1.0)]
    assert all(p.end - p.start > 3e-3 for p in pl)
    assert d_soft[-1] == d_step[-1]
    half = 0.5 * rest.mesh.backlash / mr.output_per_input    # r_g b / 2 / l_w
    assert d_soft[-1] == pytest.approx(half, rel=1e-9)



def test_the_worm_crosses_the_play_without_ringing_on_its_shaft(scan):
    """While the mesh is open the worm is alone on its shaft, J_w theta2'' = -K_w (theta2 -
    theta1): integrated independently (scipy DOP853 on the command's straight lines)
    through each planned crossing, the sampled smooth step leaves it oscillating; with the
    two samples moved by worm_ringing_cancel (the only change) it leaves < 2 % of that."""
    from scipy.integrate import solve_ivp
    _, m, move, fs, soft, plans = scan
    jw, kw = m.derived.J_w, m.derived.K_w
    assert open_worm_rate(m) == pytest.approx(math.sqrt(kw / jw))      # undamped drive
    fix = worm_ringing_cancel(m, fs.t, plans, fs.flank_step)
    assert np.array_equal(np.flatnonzero(fix), np.flatnonzero(soft - (
        fs.delta + (flank_offset(fs.t, plans, fs.rest_flank) - fs.flank) * fs.flank_step)))
    for p in plans:
        k0, k1 = np.searchsorted(fs.t, [p.start - 2e-3, p.end + 3e-3])
        t = fs.t[k0:k1]
        step = (flank_offset(t, [p], p.start_flank) - p.start_flank) * fs.flank_step
        assert np.count_nonzero(fix[k0:k1]) == 2
        ring = []
        for u in (step, step + fix[k0:k1]):
            def shaft(tt, y, t=t, u=u):
                return [y[1], -kw / jw * (y[0] - np.interp(tt, t, u))]
            sol = solve_ivp(shaft, (t[0], t[-1]), [0.0, 0.0], method='DOP853', rtol=1e-11,
                            atol=1e-14, max_step=2e-5)
            twist, rate = sol.y[0, -1] - u[-1], sol.y[1, -1]
            ring.append(math.hypot(twist, rate / math.sqrt(kw / jw)))
        assert ring[0] > 1e-8 and ring[1] < 0.02 * ring[0], ring

def _touch_speeds(plant, t, command, windows):
    """The largest |dq/dt| [m/s] of the mesh approach at the instants the teeth touch
    (q leaves the play, |q| reaches h) in each (start, end) window."""
    m = DriveModel(plant)
    tr = simulate(m, SampledProfile(t, command), t_end=float(t[-1]), record_every=1,
                  theta1_initial=float(command[0]))
    q, h = tr.aux[:, AUX_Q], 0.5 * plant.mesh.backlash * plant.geometry.gear_pitch_radius
    free = np.abs(q) < h
    touch = np.flatnonzero(free[:-1] & ~free[1:]) + 1
    dq = np.abs(np.gradient(q, tr.t))[touch]
    tt = tr.t[touch]
    return [float(dq[(tt >= a) & (tt < b)].max(initial=0.0)) for a, b in windows]


def test_the_worm_reaches_the_new_flank_softly(scan):
    """Through the sector scan's first flank change: with the step the teeth strike the
    new flank at ~10x the speed of the micro-chatter that the small demand near its sign
    change already shows on the old flank (the undamped antenna mode's residual ringing
    lifts the teeth); with the soft crossing they touch no faster than that chatter."""
    plant, _, move, fs, soft, plans = scan
    p = plans[0]
    k = move.t < p.end + 0.05
    t, x = move.t[k], move.theta1[k]
    windows = [(p.start - 0.08, p.start), (p.start, p.end + 0.03)]
    before, v_soft = _touch_speeds(plant, t, x + soft[k], windows)
    _, v_step = _touch_speeds(plant, t, x + fs.delta[k], windows)
    assert v_soft < 0.2 * v_step, (v_soft, v_step)
    assert v_soft < 2.0 * before, (v_soft, before)


def test_the_sector_scan_gains_100x_with_perfect_knowledge(scan):
    """±5° sector scan, 1 arcmin of play, 0.5 N m and 10 N m s/rad: the soft crossing
    cuts the antenna error RMS >= 100x (measured 837x; the step crossing 38x)."""
    plant, _, move, fs, soft, _ = scan
    rms = [float(np.sqrt(np.mean(antenna_error(plant, move.t, move.theta1 + d,
                                               move.theta1) ** 2)))
           for d in (np.zeros_like(soft), fs.delta, soft)]
    assert rms[0] >= 100 * rms[2], rms
    assert rms[1] > 3 * rms[2], rms


def _mode_amplitude(t, e, omega, a, b):
    """Amplitude [rad] of the oscillation at ``omega`` in e over [a, b] (least squares,
    a cubic trend fitted out with it)."""
    sel = (t >= a) & (t <= b)
    tt = t[sel] - a
    x = np.column_stack([np.cos(omega * tt), np.sin(omega * tt)] + [tt ** k for k in range(4)])
    c, *_ = np.linalg.lstsq(x, e[sel], rcond=None)
    return math.hypot(c[0], c[1])


def test_the_start_of_a_known_scan_leaves_the_antenna_mode_at_rest():
    """The sector scan starts from rest with a step in acceleration: on the undamped model
    (1 arcmin, no load: the teeth stay on one flank until 1 s) the antenna mode rings for
    ever after it with the step crossing's corrections (0.31 urad); the trajectory path
    cancels that free vibration within the first three mode periods (measured 0.004 urad,
    0.012x), and its corrections are the soft crossing's bit for bit after them."""
    plant = Config().replace({'mesh.backlash': 1.0 * ARCMIN})
    move = sector_scan(plant, periods=0.1)               # 0.4 s of the scan
    m = trajectory_model(DriveModel(plant))
    soft, plans = soft_feedforward_series(m, move.t, move.theta1)
    known = trajectory_feedforward(m, move.t, move.theta1)
    assert all(p.start > 0.3 for p in plans)       # (the cut scan stops at 0.4 s)
    f_mode = Compensator(m).mode_frequency_hz
    window = START_WINDOW_PERIODS / f_mode
    late = move.t >= window
    assert np.array_equal(known[late], soft[late])
    assert 0.0 < np.abs(known - soft).max() < 3e-5            # worm angle [rad]
    ring = [_mode_amplitude(move.t, antenna_error(plant, move.t, move.theta1 + d,
                                                  move.theta1), 2 * math.pi * f_mode, 0.1, 0.3)
            for d in (soft, known)]
    assert ring[0] > 1e-7 and ring[1] < 0.05 * ring[0], ring



def _gear_ringing(t, w, a, b):
    """Amplitude of the gear mode (1 530-1 570 Hz, the best frequency) in w over [a, b]."""
    return max(_mode_amplitude(t, w, 2 * math.pi * f, a, b) for f in range(1530, 1571, 2))


def test_a_start_that_opens_the_mesh_leaves_the_gear_mode_at_rest():
    """Without load or drag a drive at rest carries no tooth force, and the first command
    segment (a velocity step) parts the teeth for ~0.3 ms whatever its slope: the linear
    start cancellation then leaves the gear mode ringing (0.039 N of mesh force, 12 % of
    the scan's 0.32 N).  With the open interval's free vibration simulated and cancelled
    the ringing is < 2 % (measured 0.0007 N, 0.2 %).  A loaded drive's mesh stays closed:
    no correction."""
    plant = Config().replace({'mesh.backlash': 0.5 * ARCMIN})
    move = sector_scan(plant, periods=0.05)             # 0.2 s of the scan
    m = trajectory_model(DriveModel(plant))
    d = trajectory_feedforward(m, move.t, move.theta1)
    u = move.theta1 + d
    tr = simulate(DriveModel(plant), SampledProfile(move.t, u), t_end=0.1, record_every=1,
                  theta1_initial=float(u[0]))
    w = tr.aux[:, AUX_WN]
    mean = float(w[tr.t >= 0.05].mean())
    assert 0.3 < mean < 0.35                           # N: the scan's inertia alone
    assert _gear_ringing(tr.t, w, 0.05, 0.1) < 0.02 * mean
    loaded = trajectory_model(DriveModel(plant.replace({'load.output_torque': 0.5})))
    soft, _ = soft_feedforward_series(loaded, move.t, move.theta1)
    slow, fast, window = start_modes(loaded, move.t, move.theta1 + soft)
    x = move.theta1 + soft
    x = x + start_ringing_cancel(move.t, x, slow, fast, window)
    assert not np.any(open_mesh_cancel(loaded, move.t, x, slow, len(fast), window))

def test_a_start_after_a_rest_leaves_the_gear_mode_at_rest_too():
    """The same start after 50 ms at rest (the corrected command, led by the centring
    preview, leaves its rest 2 samples before the reference): the soft crossing alone
    leaves the gear mode ringing (measured 0.025 N, 7.8 % of the mean force); cancelled
    there as at the first sample (measured 0.0008 N, 0.24 %), the rest left as it was."""
    plant = Config().replace({'mesh.backlash': 0.5 * ARCMIN})
    rest = 0.05
    move = sector_scan(plant, periods=0.05, rest=rest)
    m = trajectory_model(DriveModel(plant))
    soft, _ = soft_feedforward_series(m, move.t, move.theta1)
    d = trajectory_feedforward(m, move.t, move.theta1)
    ((r, k),) = rest_starts(move.theta1, move.theta1 + soft)
    assert r == 0 and 0.04 < move.t[k] < rest
    assert np.array_equal(d[:k + 1], soft[:k + 1]) and np.any(d != soft)
    ringing = []
    for delta in (soft, d):
        u = move.theta1 + delta
        tr = simulate(DriveModel(plant), SampledProfile(move.t, u), t_end=rest + 0.1,
                      record_every=1, theta1_initial=float(u[0]))
        w = tr.aux[:, AUX_WN]
        mean = float(w[tr.t >= rest + 0.05].mean())
        assert 0.3 < mean < 0.35
        ringing.append(_gear_ringing(tr.t, w, rest + 0.05, rest + 0.1) / mean)
    assert ringing[0] > 0.05 and ringing[1] < 0.02, ringing


def test_a_heavily_damped_antenna_mode_is_not_cancelled():
    """With 86 N m s/rad of drag the antenna mode's damping ratio is 0.95: its free
    vibration dies within the start transient, and cancelling what is left at its end
    took 8.6 mrad of worm angle on 0.4 s of the scan (0.35 rad on the 4 s scan: the
    compensation 698x -> 3.3x).  The mode is left out; the faster ones are still
    cancelled (a correction of tens of microradians)."""
    plant = Config().replace({'mesh.backlash': 4.0 * ARCMIN,
                              'load.output_viscous_coefficient': 86.0})
    move = sector_scan(plant, periods=0.1)
    m = trajectory_model(DriveModel(plant))
    soft, _ = soft_feedforward_series(m, move.t, move.theta1)
    slow, fast, _ = start_modes(m, move.t, move.theta1 + soft)
    assert slow is None and len(fast) == 2
    undamped = start_modes(Config().replace({'mesh.backlash': 4.0 * ARCMIN}), move.t,
                           move.theta1 + soft)[0]
    assert undamped is not None and undamped.imag == 0.0
    change = np.abs(trajectory_feedforward(m, move.t, move.theta1) - soft).max()
    assert 0.0 < change < 1e-4, change


def test_fast_reversals_keep_the_step_and_no_play_changes_nothing():
    """A reversal in a few milliseconds (the radar slew) leaves no time to coast: the
    crossing stays the streaming step (corrections equal); without play the known
    trajectory's corrections are feedforward_series'."""
    from worm_gear_sim.studies.compensation_eval import radar_slew_scenario
    cfg = Config().replace({'mesh.backlash': 2 * ARCMIN,
                            'load.output_viscous_coefficient': 2.0})
    m = trajectory_model(DriveModel(cfg))
    sc = radar_slew_scenario(cfg)
    d, plans = soft_feedforward_series(m, sc.times, sc.theta1_ref)
    assert plans and all(p.start == p.end for p in plans)
    assert np.array_equal(d, feedforward_series(m, sc.times, sc.theta1_ref))
    free = Config().replace({'load.output_viscous_coefficient': 2.0})
    assert np.array_equal(trajectory_feedforward(free, sc.times, sc.theta1_ref),
                          feedforward_series(free, sc.times, sc.theta1_ref))


def test_a_model_with_the_wrong_play_gains_less():
    """The mismatch study's machinery: on the slew reversals the drive's own model gains
    far more than one whose play is 30 % small."""
    drive = Config().replace({'mesh.backlash': 2 * ARCMIN, 'load.output_torque': 1.0,
                              'load.output_viscous_coefficient': 20.0})
    move = slew_reversals(drive)
    own = benefit(drive, None, move)
    off = benefit(drive, mismatched(drive, 'play', -0.3), move, own['raw_rms'])
    assert mismatched(drive, 'play', -0.3).mesh.backlash == pytest.approx(1.4 * ARCMIN)
    assert own['improvement'] > 10 * off['improvement'] > 10.0, (own, off)


def test_sweep_mismatch_runs_from_the_command_line(tmp_path, capsys):
    """``sweep mismatch`` with one axis, one error and one random drive (calibrated on
    the play alone with the local fit): CSVs, figure and the summary lines."""
    from worm_gear_sim.cli import main
    assert main(['sweep', 'mismatch', '-o', str(tmp_path), '--axes', 'play',
                 '--errors=0.1', '--drives', '1', '--serial', '--moves', 'slew',
                 '--calibrate-fit', 'mesh.backlash', '--fit-strategy', 'local']) == 0
    out = capsys.readouterr().out
    assert 'calibrate-then-compensate, slew' in out
    rows = list(csv.DictReader(open(tmp_path / 'mismatch.csv')))
    assert [(r['move'], r['axis'], float(r['error'])) for r in rows] == [('slew', 'play', 0.1)]
    drives = list(csv.DictReader(open(tmp_path / 'mismatch_drives.csv')))
    assert len(drives) == 1 and float(drives[0]['slew_raw_rms']) > 0
    assert (tmp_path / 'mismatch.png').stat().st_size > 10_000
    assert main(['sweep', 'mismatch', '-o', str(tmp_path), '--axes', 'gears']) == 2


def test_sweep_crossing_runs_from_the_command_line(tmp_path, capsys):
    """``sweep crossing`` on one case: the CSV row (raw, causal, step and soft), the figure
    and the summary; a bad grid is one line and status 2."""
    from worm_gear_sim.cli import main
    assert main(['sweep', 'crossing', '-o', str(tmp_path), '--plays', '1', '--loads', '0.5',
                 '--drags', '10']) == 0
    out = capsys.readouterr().out
    assert 'soft:' in out and 'crossing.png' in out
    (row,) = list(csv.DictReader(open(tmp_path / 'crossing.csv')))
    assert int(row['crossings']) == 2
    assert float(row['soft_x']) >= 100.0 > float(row['step_x'])
    assert float(row['stream_x']) >= 100.0 and 'stream:' in out
    assert (tmp_path / 'crossing.png').stat().st_size > 10_000
    assert main(['sweep', 'crossing', '-o', str(tmp_path), '--plays', '0']) == 2
