# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The feed-forward across the mesh play (``compensation.backlash_inverse``): without play
the corrections are those of the code before it existed, bit for bit; with play the worm
takes up half the play on the flank the move's torque needs (exactly, at rest), the flank
follows the sign of the torque demand, the live pipeline equals the offline twin, and on
reversal moves the antenna error falls as measured in docs/compensation.md."""

import math
from pathlib import Path

import numpy as np
import pytest

from worm_gear_sim import Config, DriveModel
from worm_gear_sim.compensation.streaming import Compensator, centring_preview
from worm_gear_sim.dynamics.derived import derive
from worm_gear_sim.realtime import feedforward_series
from worm_gear_sim.studies.backlash_reversal import reversal_case
from worm_gear_sim.studies.compensation_eval import (
    RADAR_LOAD,
    paper_step_scenario,
    radar_slew_scenario,
    run_scenario,
)

ARCMIN = math.pi / (180 * 60)
DATA = Path(__file__).resolve().parents[1] / 'data'
CASES = {'causal': {}, 'preview': {'compensation.preview_time': 0.0025},
         'dynamic': {'compensation.model_inverse': True}}


#: The corrections' rounding sensitivity, measured: the same series with the reference
#: scaled by 1 + 1e-15 differs by up to 1.3e-12 of its largest correction (the filter design
#: amplifies rounding ~1000x), and the golden file written on another CPU (numba compiles for
#: the host: FMA, vector width) differs here by up to 5.7e-13.  The golden comparison allows
#: 100x the measured sensitivity; any change of the law moves the corrections by far more.
FF_RTOL = 1e-10


def test_zero_play_reproduces_the_corrections_before_the_inverse():
    """mesh.backlash = 0: with the backlash inverse on, the corrections of the paper's move
    and of the radar slew under load (both friction laws; causal, with a preview and with
    the dynamic inverse) equal those with it off, bit for bit in one run on one machine; and
    both equal those the code wrote before the inverse existed (test/data/make_ff_golden.py)
    within FF_RTOL of the largest correction (the file was written on another CPU)."""
    gold = np.load(DATA / 'ff_golden.npz')
    for fric in ('set_valued', 'regularized'):
        for name, extra in CASES.items():
            cfg = Config().replace({'friction.direction': fric, **extra})
            for key, c, scenario in (('paper', cfg, paper_step_scenario),
                                     ('slew', cfg.replace(RADAR_LOAD), radar_slew_scenario)):
                sc = scenario(c)
                on, off = (feedforward_series(
                    c.replace({'compensation.backlash_inverse': inv}), sc.times,
                    sc.theta1_ref) for inv in (True, False))
                assert np.array_equal(on, off), (key, fric, name)
                ref = gold[f'{key}_{fric}_{name}']
                np.testing.assert_allclose(on, ref, rtol=0,
                                           atol=FF_RTOL * np.abs(ref).max())


@pytest.mark.parametrize('extra, flank', [
    ({'load.output_torque': 3.0}, 1.0), ({'load.output_torque': -3.0}, -1.0),
    ({'mesh.initial_flank': 'drive'}, 1.0), ({'mesh.initial_flank': 'coast'}, -1.0),
    ({'mesh.initial_flank': 'center'}, 0.0)])
def test_at_rest_the_worm_takes_up_half_the_play_on_the_resting_flank(extra, flank):
    """At rest the correction with play exceeds the one without by exactly the half play
    (r_g b / 2 along the approach, l_w per worm radian) on the flank the drive rests on;
    with the inverse off (blind) it is the one without play."""
    b = 2 * ARCMIN
    base = Config().replace(extra)
    cfg = base.replace({'mesh.backlash': b})
    d = derive(cfg)
    c_play, c_none = Compensator(cfg), Compensator(base)
    c_blind = Compensator(cfg.replace({'compensation.backlash_inverse': False}))
    for c in (c_play, c_none, c_blind):
        c.reset(0.01, 0.0)
    x = [c.update(0.001 * k, 0.01) for c in (c_play, c_none, c_blind) for k in range(1, 4)]
    half = 0.5 * cfg.geometry.gear_pitch_radius * b / d.l_w
    assert c_play.flank == flank and c_blind.flank == 0.0
    assert x[2] - x[5] == pytest.approx(flank * half, rel=1e-12, abs=1e-18)
    assert x[8] == x[5]


def test_the_compensated_drive_with_play_rests_exactly_on_the_reference():
    """A move and a hold under load, 2 arcmin of play: the compensated antenna ends on the
    reference to 1 % of the half play; blind, it is off by the half play (the lost
    motion)."""
    cfg = Config().replace({**RADAR_LOAD, 'mesh.backlash': 2 * ARCMIN,
                            'damping.modal_damping_ratios': [0.03, 0.03, 0.03]})
    sc = radar_slew_scenario(cfg)
    half = ARCMIN                                      # of 2 arcmin, at the antenna
    last = {}
    for name, comp in (('on', cfg),
                       ('blind', cfg.replace({'compensation.backlash_inverse': False}))):
        run = run_scenario(cfg, sc, comp)
        last[name] = float(np.mean(run.error[run.trajectory.t > sc.t_end - 0.05]))
    assert abs(last['on']) < 0.01 * half, last
    assert abs(last['blind']) == pytest.approx(half, rel=0.1), last


def test_the_flank_follows_the_sign_of_the_torque_demand():
    """A slew with drag only: the drive flank while tracking forward, the coast flank from
    the start of the reversal while decelerating, back to the drive flank for the stop
    (which decelerates the backward motion), and it stays there at rest."""
    cfg = Config().replace({'load.output_viscous_coefficient': 2.0,
                            'mesh.backlash': 2 * ARCMIN})
    sc = radar_slew_scenario(cfg)
    comp = Compensator(cfg)
    comp.reset(float(sc.theta1_ref[0]), float(sc.times[0]))
    flanks = np.array([(comp.update(t, x), comp.flank)[1]
                       for t, x in zip(sc.times[1:], sc.theta1_ref[1:])])
    t = sc.times[1:]
    (a, b), (c, e) = sc.constant_rate
    assert np.all(flanks[(t > a + 0.01) & (t < b)] == 1.0)
    assert np.all(flanks[(t > b + 0.006) & (t < e)] == -1.0)
    assert np.all(flanks[t > e + 0.01] == 1.0)
    assert np.count_nonzero(np.diff(flanks)) == 2        # no chatter: two changes only


def test_live_equals_offline_and_a_redesign_keeps_the_flank():
    """With play, streaming the samples one by one gives the offline twin's corrections
    (to 1e-12 rad: the twin times the samples in integer nanoseconds); a redesign in the
    middle of the reversal (copy_history) keeps the flank in contact and changes no
    correction."""
    cfg = Config().replace({'load.output_viscous_coefficient': 2.0,
                            'mesh.backlash': 2 * ARCMIN})
    sc = radar_slew_scenario(cfg)
    b = sc.constant_rate[0][1]

    def stream(redesign_at):
        comp = Compensator(cfg)
        comp.reset(float(sc.theta1_ref[0]), float(sc.times[0]))
        out = [comp.evaluate(float(sc.times[0]))]
        for t, x in zip(sc.times[1:], sc.theta1_ref[1:]):
            out.append(comp.update(t, x))
            if abs(t - redesign_at) < 1e-9:
                assert comp.flank == -1.0
                new = Compensator(cfg)
                new.copy_history(comp)
                assert new.flank == -1.0
                comp = new
        return np.array(out)

    live = stream(-1.0)
    assert np.array_equal(stream(b + 0.004), live)
    off = feedforward_series(cfg, sc.times, sc.theta1_ref)
    assert np.max(np.abs(live - off)) <= 1e-12


@pytest.mark.parametrize('load', ['drag', 'load'])
def test_the_reversal_error_falls_as_measured(load):
    """2 arcmin of play, 3 % damping, the radar slew's reversal (docs/compensation.md,
    ``sweep reversal``).  The targets: >= 10x against the uncompensated drive, >= 3x
    with the play off by +-30 %.  Met with the centring preview (measured 85x drag / 53x
    load); causal the crossing comes late (measured 4.0x / 1.8x); with the play off by
    30 % the offset it leaves bounds the gain near 3.3x, and an overestimate strikes the
    flank at the traverse speed (measured -30 %: 2.5x / 3.6x, +30 %: 1.25x / 1.15x).
    Asserted: the targets where met, and that every miss is still no worse than the
    blind feed-forward, so a regression cannot hide behind a documented miss."""
    pv = {r['series']: r['improvement'] for r in reversal_case(Config(), 'slew', load, True)}
    assert pv['compensated'] >= 10.0, pv
    assert pv['play -30%'] >= 2.0 and pv['play +30%'] >= 1.0, pv
    assert min(pv['play -30%'], pv['play +30%']) >= 0.85 * pv['blind'], pv
    assert pv['no play'] >= 10.0, pv
    causal = {r['series']: r['improvement'] for r in reversal_case(
        Config(), 'slew', load, False, play_errors=())}
    assert causal['compensated'] > 1.4 * causal['blind'], causal


def test_a_known_trajectory_with_play_is_compensated_with_the_centring_preview():
    """compensate_trajectory (the pedestal's path) knows the future: with play and no
    preview configured it uses the centring preview (its corrections are the offline
    twin's with that preview, except over the start transient after the initial rest,
    where the start's free vibration is cancelled), and the antenna error around the
    reversal falls >= 10x against the raw trajectory."""
    from worm_gear_sim.compensation.start_from_rest import START_WINDOW_PERIODS, rest_starts
    from worm_gear_sim.joint_trajectory.compensate import compensate_trajectory, trajectory_model
    cfg = Config().replace({'load.output_viscous_coefficient': 2.0, 'mesh.backlash': 2 * ARCMIN,
                            'damping.modal_damping_ratios': [0.03, 0.03, 0.03]})
    no_play = trajectory_model(DriveModel(cfg.replace({'mesh.backlash': 0.0})))
    assert no_play.config.compensation.preview_time == 0.0       # unchanged without play
    sc = radar_slew_scenario(cfg)
    out = compensate_trajectory(cfg, sc.times, sc.theta1_ref, settle=0.0)
    pv = cfg.replace({'compensation.preview_time': centring_preview(cfg)})
    twin = feedforward_series(pv, out.t, out.reference)
    ((_, k),) = rest_starts(out.reference, out.reference + twin)
    late = out.t > out.t[k] + START_WINDOW_PERIODS / Compensator(pv).mode_frequency_hz
    same = late | (np.arange(out.t.size) <= k)
    assert np.array_equal(out.delta[same], twin[same]) and not np.all(same)
    (_, a), (b, _) = sc.constant_rate
    win = (out.t > a - 0.05) & (out.t < b + 0.1)
    rms = [float(np.sqrt(np.mean(e[win] ** 2))) for e in (out.raw_error, out.predicted_error)]
    assert rms[0] >= 10 * rms[1], rms


def test_sweep_reversal_writes_the_study(tmp_path, capsys):
    """``worm-gear-sim sweep reversal``: CSV (every move x load x preview x series), PNG and
    the table; the compensated slew with the centring preview is the figure of the docs."""
    import csv

    from worm_gear_sim.cli import main
    assert main(['sweep', 'reversal', '-o', str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert 'reversal RMS' in out and 'wrote' in out
    rows = list(csv.DictReader(open(tmp_path / 'reversal.csv')))
    assert len(rows) == 2 * 2 * 2 * 6
    assert (tmp_path / 'reversal.png').stat().st_size > 10_000
    best = [r for r in rows if r['move'] == 'slew' and r['load'] == 'drag'
            and float(r['preview_ms']) > 0 and r['series'] == 'compensated']
    assert float(best[0]['improvement']) >= 10.0
