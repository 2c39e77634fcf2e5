# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The drive's crossing of the play from the residual's shape: the float's parabolic rise
(the drive crossed first) starts at the crossing, the arch (the model crossed first) tops
at it; known answers on synthetic residuals with encoder-like noise."""

from __future__ import annotations

import numpy as np
import pytest

from worm_gear_sim.adaptation.flank_timing import arch_top, float_onset

NOISE = 4e-6
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
