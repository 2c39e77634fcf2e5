# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The streaming soft crossing of the mesh play (``compensation.soft_crossing``): where the
mesh torque demand changes sign in the middle of a move (a drag that outgrows a load), the
streaming compensator predicts the zero from the demand's trend and crosses the play along
a smooth step centred on it, instead of in one command period.  Checked: the corrections
differ from the step crossing's only inside one window per change of flank, which holds
the demand's zero; the flank term moves monotonically across the play there; the antenna
error on the drive falls by far; the node's pipeline gives the same corrections; a
redesign in the middle of a crossing carries it on."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worm_gear_sim import Config
from worm_gear_sim.compensation import Compensator
from worm_gear_sim.dynamics.model import DriveModel
from worm_gear_sim.play_crossing import flank_series
from worm_gear_sim.realtime import feedforward_series
from worm_gear_sim.studies.mismatch import sector_scan
from worm_gear_sim.trajectory_compensation import antenna_error, trajectory_model

ARCMIN = math.pi / (180 * 60)
#: the drag (22 N m s/rad x 0.137 rad/s = 3 N m at the scan's top rate) outgrows the load
#: (2 N m): the flank changes twice per scan period in the middle of the motion
DRIVE = {'mesh.backlash': 3.0 * ARCMIN, 'load.output_torque': 2.0,
         'load.output_viscous_coefficient': 22.0}


@pytest.fixture(scope='module')
def scan():
    plant = Config().replace(DRIVE)
    m = trajectory_model(DriveModel(plant))        # the centring preview
    move = sector_scan(plant)
    steps = flank_series(m, move.t, move.theta1)   # the step crossings, and the demand
    soft = feedforward_series(m, move.t, move.theta1)
    return plant, m, move, steps, soft


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) of each run of True."""
    d = np.diff(np.concatenate(([0], mask.astype(int), [0])))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def test_the_corrections_differ_only_inside_one_window_per_change_of_flank(scan):
    _, m, move, steps, soft = scan
    t, f = steps.t, steps.flank
    changes = np.flatnonzero(np.diff(f) != 0.0) + 1
    assert changes.size >= 2                      # mid-motion flank changes on this drive
    windows = _runs(soft != steps.delta)
    assert len(windows) == changes.size
    period = 1.0 / Compensator(m).mode_frequency_hz
    dt = t[1] - t[0]
    d = steps.demand
    for (a, b), k in zip(windows, changes):
        assert a <= k < b + 1                     # the step crossing's sample is inside
        assert 3 * dt - 1e-12 <= (b - a) * dt <= period + dt
        zero = np.flatnonzero(np.sign(d[a - 1:b + 1]) != np.sign(d[a - 1]))
        assert zero.size and zero[0] + a - 1 < b + 1     # the demand's zero is inside
        # the flank term across the window: from the old flank to the new, monotonic
        term = f[a:b] + (soft[a:b] - steps.delta[a:b]) / steps.flank_step
        old, new = f[a - 1], f[b]
        assert np.all(np.abs(term) <= 1.0 + 1e-9)
        assert np.all(np.diff(term) * (new - old) >= -1e-9)
        assert term[0] != new and abs(term[-1] - new) < abs(term[0] - new)


def test_the_antenna_error_across_the_play_falls_by_far(scan):
    """The drive simulated under each command (straight lines between samples): the whole
    scan's RMS error with the soft crossing is at least 10x below the step crossing's (the
    step's impact rings the antenna mode for tens of ms)."""
    plant, _, move, steps, soft = scan
    t, x = move.t, move.theta1
    e_step = antenna_error(plant, t, x + steps.delta, x)
    e_soft = antenna_error(plant, t, x + soft, x)
    raw = antenna_error(plant, t, x, x)
    rms = [float(np.sqrt(np.mean(e ** 2))) for e in (raw, e_step, e_soft)]
    assert rms[2] <= rms[1] / 10.0, rms
    assert rms[0] / rms[2] >= 300.0, rms


def _direct(m: DriveModel, t: np.ndarray, x: np.ndarray, cut: int | None = None
            ) -> np.ndarray:
    """The Compensator driven directly as the pipeline drives it (each sample's correction
    evaluated once the samples up to its time plus the preview are in); at sample ``cut`` a
    redesign from the same model takes over the history (as a parameter update does)."""
    rel = np.round((t - t[0]) * 1e9).astype(np.int64)     # the pipeline's clock
    ts = rel * 1e-9
    comp = Compensator(m)
    comp.reset(float(x[0]), float(ts[0]))
    preview_ns = int(round(comp.preview * 1e9))
    out = np.empty(t.size)
    j = 0
    for i in range(t.size):
        if i == cut:
            new = Compensator(m)
            new.copy_history(comp)
            comp = new
        while j < t.size and (j <= i or rel[j - 1] < rel[i] + preview_ns):
            comp.add_sample(float(ts[j]), float(x[j]))
            j += 1
        out[i] = comp.evaluate(float(ts[i]))
        comp.trim(float(ts[i]))
    return out


def test_the_pipeline_and_the_compensator_alone_agree(scan):
    """The node's pipeline (feedforward_series is its offline twin) and the Compensator
    driven directly give the same soft crossings, bit for bit."""
    _, m, move, steps, soft = scan
    assert np.array_equal(_direct(m, steps.t, move.theta1), soft)


def test_a_redesign_in_the_middle_of_a_crossing_carries_it_on(scan):
    _, m, move, steps, soft = scan
    a, b = _runs(soft != steps.delta)[0]
    assert np.array_equal(_direct(m, steps.t, move.theta1, cut=(a + b) // 2), soft)
