# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The drive's crossing of the play from the residual's shape: the float's parabolic rise
(the drive crossed first) starts at the crossing, the arch (the model crossed first) tops
at it; known answers on synthetic residuals with encoder-like noise."""

from __future__ import annotations

import numpy as np
import pytest

from worm_gear_sim.adaptation.estimator import RISE_TIME_SHARE, SWITCH_TIME_SD
from worm_gear_sim.adaptation.flank_timing import (
    STEP_GAP,
    STEP_SIDE,
    FlankTiming,
    arch_top,
    float_onset,
)

NOISE = 4e-6
PLAY = 4e-4
ALPHA = 0.2                      # rad/s^2, the sector scan's antenna acceleration


@pytest.mark.parametrize('t_p', [-0.060, -0.035])
def test_the_float_starts_at_the_drives_crossing(t_p):
    """|alpha| (t - t_p)^2 / 2 from the drive's crossing until the worm moves (t = -12 ms):
    the onset is found within 2 ms."""
    rng = np.random.default_rng(1)
    ts = np.arange(-0.3, -0.012, 1e-3)
    dev = 0.5 * ALPHA * np.clip(ts - t_p, 0.0, None) ** 2 + 1e-6 * rng.standard_normal(ts.size)
    got = float_onset(ts, dev, 5 * NOISE)
    assert got == pytest.approx(t_p, abs=2e-3)


def test_no_rise_no_onset():
    rng = np.random.default_rng(2)
    ts = np.arange(-0.3, -0.012, 1e-3)
    assert float_onset(ts, 3e-6 * rng.standard_normal(ts.size), 5 * NOISE) is None
    # a step (the worm's own move), not a parabola's root
    assert float_onset(ts, np.where(ts > -0.02, 1e-4, 0.0), 5 * NOISE) is None


@pytest.mark.parametrize('dt', [0.030, 0.060])
def test_the_arch_tops_at_the_drives_crossing(dt):
    """The model crossed dt early (t = 0): the arch |alpha| (dt^2 - (t - dt)^2) / 2 over
    [0, 2 dt] tops at the drive's crossing dt, found within 2 ms."""
    rng = np.random.default_rng(3)
    ts = np.arange(-0.025, 0.3, 1e-3)
    inside = (ts > 0) & (ts < 2 * dt)
    dev = np.where(inside, 0.5 * ALPHA * (dt ** 2 - (ts - dt) ** 2), 0.0) \
        + 1e-6 * rng.standard_normal(ts.size)
    assert arch_top(ts, dev, 5 * NOISE) == pytest.approx(dt, abs=2e-3)
    assert arch_top(ts, -dev, 5 * NOISE) is None          # the other sign: no arch
    assert arch_top(ts, 1e-3 * dev, 5 * NOISE) is None    # below the noise


def _event(r: np.ndarray, ts: np.ndarray, t_m: float) -> tuple | None:
    """The flank-change event at t_m (drive to coast flank, s = +1) over the residual r."""
    ft = FlankTiming()
    for t, x in zip(ts, r):
        ft.push(float(t), float(x), 0.1, ALPHA)
        if abs(t - t_m) < 0.5e-3:
            ft.model_flank_changed(float(t), 1.0, -1.0)
    return ft.ready(float(ts[-1]), PLAY, 10 * NOISE, PLAY, NOISE, 0.0)


@pytest.mark.parametrize('how, shift', [('onset', -0.040), ('arch', 0.040), ('area', 0.040)])
def test_each_method_names_itself(how, shift):
    """The event's measurement says how it was made (the estimator weighs the area formula's
    far less): a float's rise before the model's crossing (the drive crossed first), the
    arch after it (the model first), or a plain pulse of the play, neither: the area."""
    rng = np.random.default_rng(4)
    t_m = 1.0
    ts = np.arange(0.5, 1.45, 1e-3)
    if how == 'onset':          # the gear floats from t_p on, until the worm moves at t_m
        rise = 0.5 * ALPHA * np.clip(ts - (t_m + shift), 0.0, None) ** 2
        r = np.where(ts < t_m, rise, 0.0)
    elif how == 'arch':         # the worm left the gear early: the arch back onto the flank
        inside = (ts > t_m) & (ts < t_m + 2 * shift)
        r = -np.where(inside, 0.5 * ALPHA * (shift ** 2 - (ts - t_m - shift) ** 2), 0.0)
    else:                       # the prediction steps at t_m, the drive at t_m + shift
        r = np.where((ts >= t_m) & (ts < t_m + shift), -PLAY, 0.0)
    got = _event(r + 1e-6 * rng.standard_normal(ts.size), ts, t_m)
    assert got is not None and got[3] == how
    assert got[0] == pytest.approx(t_m + shift, abs=3e-3)


def _looks(r: np.ndarray, t: np.ndarray, noise: float = 1e-6) -> list[tuple]:
    """Every look of the step detector over the residual r(t) (omega4 = t, alpha4 = 1)."""
    ft = FlankTiming()
    found = []
    for k in range(t.size):
        ft.push(float(t[k]), float(r[k]), float(t[k]), 1.0)
        got = ft.detect(float(t[k]), noise, -np.inf)
        if got is not None:
            found.append(got)
    return found


@pytest.mark.parametrize('size', [1e-3, -6e-4])
def test_a_slow_crossing_is_found_on_the_wide_scale_at_its_onset(size):
    """A drive crossing near its top speed floats across the play in ~0.13 s (measured on a
    drawn drive, play 1 mrad): a smooth S of the residual that the steep scale (a 60 ms gap)
    reads as drift. The wide scale finds it once, its size within 2 %, its time where the
    float starts (ONSET_SHARE of the way: within the S's first quarter, where the middle
    would be 65 ms late; on the drawn drive the mesh torque passed zero 15-20 ms before
    the residual visibly left its line)."""
    t = np.arange(1.0, 2.5, 1e-3)
    t0, dur = 1.6, 0.13
    x = np.clip((t - t0) / dur, 0.0, 1.0)
    r = size * x * x * (3.0 - 2.0 * x) + np.random.default_rng(7).normal(0.0, 1e-6, t.size)
    found = _looks(r, t)
    assert len(found) == 1
    t_p, w_p, _, step, wide, _ = found[0]
    assert wide
    assert step == pytest.approx(size, rel=0.02)
    assert t0 <= t_p <= t0 + 0.25 * dur
    assert w_p == pytest.approx(t_p, abs=1e-3)


def _float(t: np.ndarray, t0: float, tau: float, size: float, seed: int) -> np.ndarray:
    """The residual of a drive crossing its play on its own: free of the worm from t0 on,
    the gear's acceleration off the path grows linearly from zero (the mesh torque passes
    zero), so the residual rises as (t - t0)^3 until the other flank stops it at ``size``
    after ``tau``; then the impact rings (95 Hz, 20 ms decay), with encoder-like noise."""
    x = np.clip((t - t0) / tau, 0.0, 1.0)
    after = np.clip(t - (t0 + tau), 0.0, None)
    ring = 0.03 * size * np.exp(-after / 0.02) * np.sin(2 * np.pi * 95.0 * after)
    return size * x ** 3 + ring + np.random.default_rng(seed).normal(0.0, 1e-6, t.size)


@pytest.mark.parametrize('tau, size', [(0.03, 8e-4), (0.05, -3e-4), (0.1, 8e-4)])
def test_a_crossing_on_the_steep_scale_is_timed_where_its_rise_starts(tau, size):
    """The steep scale times a step where the float starts, extrapolated from its 5 % and
    50 % crossings as a cube's, not at its middle (0.79 tau later: 24-79 ms here; 43-91 ms
    late on the drawn drives of bench_adaptation.py): within the time sd the estimator weighs it
    with (RISE_TIME_SHARE of the rise to the middle, itself 0.79 tau within 15 %). The size
    within 2 % (10 % when the float outlasts the 60 ms gap and its start bends the line
    before)."""
    t = np.arange(1.0, 2.5, 1e-3)
    t0 = 1.6
    found = _looks(_float(t, t0, tau, size, 7), t)
    assert len(found) == 1
    t_p, w_p, _, step, wide, rise = found[0]
    assert not wide
    assert step == pytest.approx(size, rel=0.02 if tau <= STEP_GAP else 0.1)
    assert rise == pytest.approx(0.5 ** (1 / 3) * tau, rel=0.15)
    assert abs(t_p - t0) <= max(SWITCH_TIME_SD, RISE_TIME_SHARE * rise)
    assert w_p == pytest.approx(t_p, abs=1e-3)


def test_a_quick_step_stays_on_the_steep_scale_and_a_smooth_path_is_no_step():
    """A crossing within the 60 ms gap that is no cube (a 20 ms ramp) is found on the steep
    scale, timed within its ramp; the residual of a scan not yet learnt (a sine of the
    scan's period, 0.5 mrad) is no step on either scale."""
    t = np.arange(1.0, 2.5, 1e-3)
    x = np.clip((t - 1.6) / 0.02, 0.0, 1.0)
    noise = np.random.default_rng(8).normal(0.0, 1e-6, t.size)
    found = _looks(8e-4 * x + noise, t)
    assert len(found) == 1 and not found[0][4]
    assert 1.59 <= found[0][0] <= 1.605 and found[0][5] < 0.02
    assert _looks(5e-4 * np.sin(2 * np.pi * t / 4.0) + noise, t) == []


@pytest.mark.parametrize('lag', [0.0005, 0.002])
def test_a_step_at_the_gaps_edge_is_timed_where_it_is_not_at_the_centre(lag):
    """A look whose left line ends just after the step (the first look after the detector
    was held, e.g. by a crossing of the model's) sees the step but no crossing of its middle
    in the gap; it was timed at the window's centre, 31 ms late with a 2 ms sd. Now that
    look finds nothing, and the next one, with the step in its gap, times it."""
    t = np.arange(1.0, 2.0, 1e-3)
    t_step = 1.5
    r = np.where(t >= t_step, 8e-4, 0.0) + np.random.default_rng(3).normal(0.0, 1e-6, t.size)
    first = t_step + STEP_SIDE + STEP_GAP + lag     # the step at -STEP_GAP / 2 - lag
    ft = FlankTiming()
    found = []
    for k in range(t.size):
        ft.push(float(t[k]), float(r[k]), float(t[k]), 1.0)
        if t[k] >= first - 1e-9:
            got = ft.detect(float(t[k]), 1e-6, -np.inf)
            if got is not None:
                found.append(got)
    assert len(found) == 1
    assert found[0][0] == pytest.approx(t_step, abs=1.5e-3)
