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
from worm_gear_sim.compensation.play_crossing import flank_series
from worm_gear_sim.compensation.streaming import Compensator
from worm_gear_sim.dynamics.model import DriveModel
from worm_gear_sim.joint_trajectory.compensate import antenna_error, trajectory_model
from worm_gear_sim.realtime import feedforward_series
from worm_gear_sim.studies.mismatch import sector_scan

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


def _state(longest: float = 0.0106, shortest: float = 0.003, coef: float = 1e9) -> np.ndarray:
    """A flank state (compensation.filters._F_*) on the drive flank, soft crossing on; ``coef``
    large: the stray never shortens the crossing."""
    from worm_gear_sim.compensation import filters as c
    f = np.zeros(12)
    f[0], f[c._F_ON], f[c._F_SOFT] = 1.0, 1.0, 1.0
    f[c._F_LONG], f[c._F_SHORT], f[c._F_COEF] = longest, shortest, coef
    f[c._F_TPREV] = -math.inf
    return f


def test_a_linear_demand_is_crossed_centred_on_its_zero():
    """D = 2 N m/s x (1 s - t), sampled at 1 kHz: the crossing starts at the first sample
    with the zero within half the longest crossing (5.3 ms), is centred on the zero (1 s:
    the flank term half-way, 0) and ends as far after it; the flank term falls from +1 to
    -1 along the smooth step, -1 after."""
    from worm_gear_sim.compensation.filters import _flank_at
    state = _state()
    t = np.arange(0.98, 1.02, 1e-3)
    out = np.array([_flank_at(tk, 2.0 * (1.0 - tk), state) for tk in t])
    first = int(np.argmax(out < 1.0))                   # the first sample inside it
    start = t[first - 1]
    assert 1.0 - start <= 0.5 * 0.0106 + 1e-12 < 1.0 - t[first - 2]
    assert np.all(out[:first] == 1.0) and np.all(np.diff(out) <= 1e-15)
    assert abs(out[np.argmin(np.abs(t - 1.0))]) < 1e-9          # the zero: half-way
    end = 1.0 + (1.0 - start)
    assert np.all(out[t >= end + 1e-9] == -1.0) and np.all(out[t < end - 1e-9] > -1.0)


def test_a_zero_that_does_not_come_ends_on_the_flank_the_demand_needs():
    """The demand heads for zero, then turns back before it (a grazing that stays on the
    drive flank): the crossing that was planned ends, and the worm returns to +1."""
    from worm_gear_sim.compensation.filters import _flank_at
    state = _state()
    t = np.arange(0.99, 1.03, 1e-3)
    d = 2.0 * np.abs(t - 1.0) + 1e-3                    # least at 1 s, never zero
    out = np.array([_flank_at(tk, dk, state) for tk, dk in zip(t, d)])
    assert out.min() < 1.0                              # a crossing was planned ...
    assert out[-1] == 1.0                               # ... and the drive flank is back
