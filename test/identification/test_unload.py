# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The unloading dither (``excitation.dither_profile``, ``visibility.mesh_lifts``,
:mod:`worm_gear_sim.identification.unload`): within the limits, at
the antenna mode; on a drive whose load holds the gear on one flank in every sweep, the
sweeps cannot tell the play from the load (two drives on the line b / 2 + T C = const give
the same sweeps within the noise) but the dither can (it lifts the gear off its flank, and
the two drives differ there by far more than the noise); the visibility then calls the play
and the load seen.  The whole calibration of such a drive is measured by
benchmarks/bench_calibration.py (seed 1, drive 0)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worm_gear_sim import Config
from worm_gear_sim.dynamics.modal import modes
from worm_gear_sim.identification.calibrate import plant_runner
from worm_gear_sim.identification.direct import DRAG, LOAD, PLAY, compliance
from worm_gear_sim.identification.excitation import Limits, design_excitation, dither_profile
from worm_gear_sim.identification.report import prediction_errors
from worm_gear_sim.identification.visibility import flank_changes, key_visibility, mesh_lifts

ARCMIN = math.pi / 180.0 / 60.0
LIMITS = Limits(0.5, 6.0, 1500.0, 2.0)
KEYS = [PLAY, LOAD, DRAG]
#: 2.8 arcmin, 4.75 N m against 1.5 N m of drag torque at the rate limit (6 rad/s of worm)
DRIVE = {PLAY: 2.8 * ARCMIN, LOAD: 4.75, DRAG: 14.4}


def test_the_dither_stays_within_the_limits_at_the_antenna_mode():
    lim = Limits(0.05, 2.0, 800.0, 2.0, start=0.3)
    prof = dither_profile(Config(), lim)
    dt = 1e-6
    t = np.arange(0.0, prof.duration, dt)
    x, v = prof.theta1(t), prof.theta1_dot(t)
    assert np.max(np.abs(x - lim.start)) <= lim.max_angle
    assert np.max(np.abs(v)) <= lim.max_rate * (1 + 1e-9)
    assert np.max(np.abs(np.gradient(v, dt))) <= lim.max_accel * 1.001
    assert np.max(np.abs(np.gradient(v, dt))) >= lim.max_accel * 0.99   # at the limit
    end = np.array([prof.duration])
    assert prof.theta1(end)[0] == pytest.approx(lim.start, abs=1e-12)
    assert prof.theta1_dot(end)[0] == pytest.approx(0.0, abs=1e-12)
    # the rate swings at the lowest mode: zero crossings twice a period
    f = float(modes(Config()).undamped_hz[0])
    body = v[(t > 0.01) & (t < prof.duration - 0.01)]
    crossings = np.count_nonzero(np.diff(np.sign(body)) != 0)
    assert crossings / (2 * f) == pytest.approx((prof.duration - 0.02), rel=0.15)


@pytest.fixture(scope='module')
def records():
    moves = design_excitation(LIMITS, KEYS, Config())
    assert [m.role for m in moves] == ['train', 'train', 'validate', 'reserve']
    truth = Config().replace(DRIVE)
    run = plant_runner(truth, 1e4, ('theta4',), 1e-6, 2 * math.pi / 2 ** 20)
    train = [run(m) for m in moves if m.role == 'train']
    dither = [run(m) for m in moves if m.role == 'reserve']
    return truth, train, dither


def test_the_sweeps_hold_one_flank_and_the_dither_lifts_the_gear(records):
    truth, train, dither = records
    assert not flank_changes(truth, train + dither)
    assert not mesh_lifts(truth, train)
    assert mesh_lifts(truth, dither)
    hidden = key_visibility(truth, train, KEYS)
    assert PLAY in hidden and LOAD in hidden
    assert not ({PLAY, LOAD} & set(key_visibility(truth, train + dither, KEYS)))


def test_the_dither_tells_two_drives_the_sweeps_cannot(records):
    """A drive with 30 % more load and the play that keeps b / 2 + T C: the sweeps see it
    within a few noise levels, the dither at > 10 times the sweeps' difference."""
    truth, train, dither = records
    c = compliance(truth)
    t_other = 1.3 * DRIVE[LOAD]
    other = truth.replace({LOAD: t_other,
                           PLAY: DRIVE[PLAY] - 2.0 * c * (t_other - DRIVE[LOAD])})
    assert other.mesh.backlash > 0

    def rms(cfg, recs):
        return max(r['theta4']['rms_rad'] for r in prediction_errors(cfg, recs))

    sweeps_truth, sweeps_other = rms(truth, train), rms(other, train)
    dither_truth, dither_other = rms(truth, dither), rms(other, dither)
    assert sweeps_other < 3 * sweeps_truth + 1e-6, (sweeps_other, sweeps_truth)
    assert dither_other > 10 * max(sweeps_other, dither_truth), (dither_other, sweeps_other)
