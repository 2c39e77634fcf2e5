# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Calibration of play, load torque and drag: the sweeps stay within the limits;
the direct estimates from the constant-rate lags recover known play, load and drag; a
record that cannot show a key names it and the move to record; limits without room for a
slow reversal are a one-line error; one random drive end to end is accepted with the play
within 5 %.  The many-drive figures are in benchmarks/bench_calibration.py."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worm_gear_sim import Config
from worm_gear_sim.cli import main
from worm_gear_sim.identification import FitOptions, IdentificationError
from worm_gear_sim.identification.calibrate import calibrate, plant_runner
from worm_gear_sim.identification.direct import (
    DRAG,
    LOAD,
    PLAY,
    compliance,
    direct_estimates,
    steady_segments,
)
from worm_gear_sim.identification.excitation import Limits, design_excitation
from worm_gear_sim.identification.visibility import key_visibility

ARCMIN = math.pi / 180.0 / 60.0
KEYS = [PLAY, LOAD, DRAG]
ENCODER = 2 * math.pi / 2 ** 20
LIMITS = Limits(0.2, 6.0, 1500.0, 2.0)


def _drive(play_arcmin: float, load: float, drag: float, **more) -> Config:
    return Config().replace({PLAY: play_arcmin * ARCMIN, LOAD: load, DRAG: drag, **more})


@pytest.fixture(scope='module')
def sweeps():
    return design_excitation(LIMITS, KEYS, Config())


def _train(plant: Config, moves, seed: int = 0):
    run = plant_runner(plant, 1e4, ('theta4',), 1e-6, ENCODER, seed)
    return [run(m) for m in moves if m.role == 'train']


def test_the_sweeps_stay_within_the_limits_and_reverse_at_two_rates(sweeps):
    assert [m.role for m in sweeps] == ['train', 'train', 'validate', 'reserve']
    dt = 1e-5
    for m in sweeps:
        t = np.arange(0.0, m.t_end, dt)
        x = m.profile.theta1(t)
        v = m.profile.theta1_dot(t)
        assert np.max(np.abs(x - LIMITS.start)) <= LIMITS.max_angle * (1 + 1e-9)
        assert np.max(np.abs(v)) <= LIMITS.max_rate * (1 + 1e-9)
        assert np.max(np.abs(np.gradient(v, dt))) <= LIMITS.max_accel * 1.01
        assert np.allclose(np.gradient(x, dt)[1:-1], v[1:-1], atol=1e-3 * LIMITS.max_rate)
        assert x[-1] == pytest.approx(LIMITS.start, abs=1e-12)      # out and back
    assert sum(m.t_end for m in sweeps) <= LIMITS.duration
    rates = {round(s.rate, 6) for s in steady_segments(
        [_rec(m) for m in sweeps if m.role == 'train'], 1 / 56)}
    fast = max(rates)       # the rate limit, or lower so that the cruise lasts CRUISE_MIN
    assert sorted(rates) == pytest.approx([-fast, -fast / 4, fast / 4, fast], rel=1e-5)
    assert fast <= LIMITS.max_rate


def _rec(move):
    from worm_gear_sim.records import Record
    t = np.arange(0.0, move.t_end, 1e-4)
    th = move.profile.theta1(t)
    return Record(name=move.name, t=t, theta1=th, measured={'theta4': th / 56})


@pytest.mark.parametrize('play, load, drag', [(2.0, 0.3, 60.0), (0.5, 0.0, 20.0)])
def test_direct_estimates_from_slow_and_fast_reversals(sweeps, play, load, drag):
    """Lost motion between the ways -> play; the common lag -> load; the rate dependence ->
    drag: within 1 % (play) / 3 % (drag) / 0.02 N m (load) of the truth, before any fit."""
    recs = _train(_drive(play, load, drag), sweeps)
    est = direct_estimates(Config(), recs, KEYS)
    assert est is not None and est.play_seen
    assert est.values[PLAY] / ARCMIN == pytest.approx(play, rel=0.01)
    assert est.values[LOAD] == pytest.approx(load, abs=0.02)
    assert est.values[DRAG] == pytest.approx(drag, rel=0.03)


@pytest.mark.parametrize('play, load, drag', [(2.3, 0.99, 9.08), (3.3, 4.64, 44.0)])
def test_a_segment_floating_in_the_play_is_left_out(play, load, drag):
    """The drag at the fast rate back nearly cancels the load (net torque ~0.02 / -0.08 N m):
    the gear floats between the flanks on that segment, which fits neither flank's line.
    Left out, the other three (one flank) give the drag, and the floating segment (torque
    ~0) the load and the play: within 2 % / 0.1 N m / 3 % before any fit (with it, the load
    came out 3.5 x the truth or the stage gave up)."""
    wide = design_excitation(Limits(0.5, 6.0, 1500.0, 2.0), KEYS, Config())   # 6 rad/s
    recs = _train(_drive(play, load, drag), wide)
    est = direct_estimates(Config(), recs, KEYS)
    assert est is not None and est.play_seen and est.floating is not None
    assert est.floating.rate < 0 and abs(est.floating.rate) == max(
        abs(s.rate) for s in est.segments)
    assert est.values[PLAY] / ARCMIN == pytest.approx(play, rel=0.02)
    assert est.values[LOAD] == pytest.approx(load, abs=0.1)
    assert est.values[DRAG] == pytest.approx(drag, rel=0.03)


def test_one_rate_each_way_finds_the_play_along_the_play_drag_line():
    """Slew reversals at one rate (1.5 rad/s of worm, trapezoid-free: the user's record):
    the static lags give only b + 2 C c w, so the direct stage offers the play along that
    line and the simulation of the records picks it: play within 3 %, load within
    0.05 N m, drag within 5 %, before any fit (the teeth and bearings of the drive differ
    from the base's; benchmarks/bench_identify_reversals.py runs the whole identify)."""
    from worm_gear_sim.dynamics.profiles import SampledProfile
    from worm_gear_sim.identification.data import record_from_model
    from worm_gear_sim.identification.direct import best_on_family
    plant = _drive(3.0, 1.0, 50.0, **{'mesh.gear_tooth_stiffness_multiplier': 0.85,
                                      'shafts.gear_bearing_axial_stiffness': 1.5e8})
    t = np.array([0.0, 0.05, 0.317, 0.367, 0.9, 0.95, 1.483])
    x = np.array([0.0, 0.0, 0.4, 0.4, -0.4, -0.4, 0.4])
    rec = record_from_model(plant, SampledProfile(t, x, 'linear'), 1.483, 1000,
                            ('theta4',), 1e-6, 2 * math.pi / 2 ** 20, 0)
    est = direct_estimates(Config(), [rec], KEYS + ['mesh.gear_tooth_stiffness_multiplier'])
    assert est is not None and est.play_seen and len(est.family) >= 5
    plays = [v[PLAY] for v in est.family]
    assert min(plays) < 3 * ARCMIN < max(plays)          # the line brackets the true play
    vals, rows = best_on_family(Config(), [rec], est.family)
    assert len(rows) >= len(est.family)
    assert vals[PLAY] / ARCMIN == pytest.approx(3.0, rel=0.03), vals
    assert vals[LOAD] == pytest.approx(1.0, abs=0.05), vals
    assert vals[DRAG] == pytest.approx(50.0, rel=0.05), vals


def test_a_load_that_holds_one_flank_hides_the_play_and_says_which_move(sweeps):
    """5 N m of load and no drag: the gear never leaves its flank in the sweeps; the direct
    stage says the play is not seen, and the visibility lines name the play (a stop faster
    than the load's deceleration, or unload) and the load (not separable)."""
    plant = _drive(3.0, 5.0, 0.0)
    recs = _train(plant, sweeps)
    est = direct_estimates(Config(), recs, KEYS)
    assert est is not None and not est.play_seen
    lines = key_visibility(plant, recs, KEYS)
    assert set(lines) == {PLAY, LOAD}
    assert lines[PLAY].startswith('mesh.backlash: not seen') and 'unload' in lines[PLAY]
    assert 'deceleration' in lines[PLAY]
    # with drag, the line gives the worm rate above which the drag crosses the play
    # the largest load one flank allows (play 0: 5 N m + b / 2 C), the drag to exceed it
    drive = _drive(3.0, 5.0, 10.0)
    lines = key_visibility(drive, recs, KEYS)
    top = 5.0 + 0.5 * drive.mesh.backlash / compliance(drive)
    assert top > 5.5
    need = top / (10.0 * (1 / 56))
    assert f'{need:.3g} rad/s' in lines[PLAY] and f'{top:.3g} N m' in lines[PLAY]
    # the play alone fitted (the load known): the known load sets the rate
    lines = key_visibility(drive, recs, [PLAY, DRAG])
    assert f'{5.0 / (10.0 * (1 / 56)):.3g} rad/s' in lines[PLAY]


def test_a_record_without_constant_rate_segments_names_the_keys():
    """A step only (no constant-rate segment both ways): load and drag are named with the
    move to record; the fitted play of a drive whose gear crosses its play is seen."""
    from worm_gear_sim.identification.excitation import _steps
    moves = _steps(Limits(0.12, 6.0, 1500.0))
    plant = _drive(1.0, 0.0, 5.0)
    recs = _train(plant, moves[:1])
    lines = key_visibility(plant, recs, KEYS)
    assert 'slow reversal' in lines[LOAD] and 'two rates' in lines[DRAG]
    # the drag fitted without the load: nothing to confuse its wind-up with, it is seen
    assert DRAG not in key_visibility(plant, recs, [DRAG])
    assert DRAG in key_visibility(plant, recs, [LOAD, DRAG])


@pytest.mark.parametrize('argv', [['--max-angle', '0.05'], ['--max-angle', '0.1']])
def test_limits_without_room_for_a_slow_reversal_are_one_line(tmp_path, capsys, argv):
    with pytest.raises(IdentificationError, match='max_angle'):
        design_excitation(Limits(0.05, 6.0, 1500.0), [PLAY])
    rc = main(['calibrate', '--fit', PLAY, '--plant', 'unused.yaml', '-o',
               str(tmp_path / 'f.yaml'), *argv])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and 'max_angle' in err and 'slow reversal' in err
    assert len(err.splitlines()) == 1


def test_one_random_drive_end_to_end():
    """A drive of the family (1.7 arcmin, 0.8 N m, 45 N m s/rad (known), teeth x0.85 not
    fitted, gear bearing x1.2, 1 urad noise, 20-bit encoder), play and load fitted (two keys
    keep the test short): accepted, the play within 5 %, the load within 5 %, held-out theta4
    within 3 %."""
    plant = _drive(1.7, 0.8, 45.0, **{'mesh.gear_tooth_stiffness_multiplier': 0.85,
                                       'shafts.gear_bearing_axial_stiffness': 2.4e8})
    run = plant_runner(plant, 1e4, ('theta4',), 1e-6, ENCODER, 3)
    res = calibrate(Config().replace({DRAG: 45.0}), [PLAY, LOAD], LIMITS, run,
                    options=FitOptions(strategy='frequency', serial=True, ftol=1e-4, xtol=1e-4))
    assert res.accepted, res.reasons
    assert not res.not_seen
    assert res.estimate(PLAY) / ARCMIN == pytest.approx(1.7, rel=0.05)
    assert res.estimate(LOAD) == pytest.approx(0.8, rel=0.05)
    assert res.worst_held_out() < 0.03
