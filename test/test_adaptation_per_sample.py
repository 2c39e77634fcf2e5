# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The adapter's compiled sample (:func:`~worm_gear_sim.adaptation.per_sample.sample_fast`)
against its Python twin (``Adapter._update``): the same stream through both gives the same
estimate, covariance, windowed sums and per-sample state bit for bit, sample by sample,
with every case of the Python path met on the way (the model in use crossing its play,
the flank-change events, the step detector finding the drive's crossings, the record
compacted).  And the step detector's compiled look against a plain numpy line fit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worm_gear_sim.adaptation import estimator
from worm_gear_sim.adaptation.estimator import Adapter
from worm_gear_sim.adaptation.flank_timing import STEP_GAP, STEP_SIDE, FlankTiming, detect_core
from worm_gear_sim.dynamics.model import DriveModel
from worm_gear_sim.params import Config

RATE = 1000.0
KEYS = ['load.output_torque', 'load.output_viscous_coefficient', 'mesh.backlash',
        'mesh.worm_error_harmonics']


def _state(ad: Adapter) -> list[np.ndarray]:
    tm = ad._timing
    return [ad.theta, ad.P, ad._S, ad._b, ad._sc, ad._st, tm._ts, tm._a[:tm._n]]


def test_the_compiled_sample_equals_the_python_path(monkeypatch):
    # a model with play and drag: its torque demand crosses zero on the scan, so the model
    # in use crosses its play (events), and the drive (another load) crosses elsewhere
    cfg = Config().replace({'adaptation.keys': KEYS, 'mesh.backlash': 2e-4,
                            'load.output_viscous_coefficient': 20.0,
                            'load.output_torque': 1.0})
    ratio = DriveModel(cfg).output_per_input
    t = np.arange(0.0, 9.0, 1.0 / RATE)
    t = t[(t < 4.0) | (t > 4.2)]                     # a pause: the rates restart
    th4 = -math.radians(5.0) * np.cos(2 * math.pi * t / 4.0)
    w4 = np.gradient(th4, t)
    drive_flank = np.sign(20.0 * w4 + 2.5)           # the drive's own crossings
    extra = (-0.5 * 4e-4 * drive_flank + 3e-6 * np.sin(th4 / ratio)
             + np.random.default_rng(5).normal(0.0, 1e-6, t.size))
    fast, slow = Adapter(cfg, cfg.adaptation), Adapter(cfg, cfg.adaptation)
    slow.update = slow._update                       # the Python path alone
    codes: dict[int, int] = {}
    compacted = 0
    compiled = estimator.sample_fast

    def counted(*args):
        code = compiled(*args)
        codes[code] = codes.get(code, 0) + 1
        return code

    monkeypatch.setattr(estimator, 'sample_fast', counted)
    for k in range(t.size):
        if k % 1500 == 700:                           # a step of the model in use
            for ad in (fast, slow):
                step = ad.applied_x.copy()
                step[0] += 0.2 * (1 if k % 3000 == 700 else -1)
                ad.applied(step, ad.model, at=float(t[k]) + 0.05)
        args = (float(t[k]), float(th4[k] + extra[k]), float(th4[k] / ratio),
                float(th4[k]), float(th4[k]))
        n_before = fast._timing._n
        assert fast.update(*args) == slow.update(*args), k
        compacted += fast._timing._n < n_before
        for a, b in zip(_state(fast), _state(slow)):
            assert np.array_equal(a, b, equal_nan=True), k
    # every case of the Python path was met, and the compiled path took most samples
    assert codes[-1] >= 10 and codes[1] > 5000 and codes[0] > 1000
    assert fast._timing.events > 0 and fast.steps_seen > 0 and fast.flank_times > 0
    assert compacted > 0                             # the record was compacted
    assert fast.estimates() == slow.estimates()


def _numpy_look(a: np.ndarray, t: float, noise: float) -> tuple[float, float] | None:
    """The step detector's look written with numpy: (t_p, step) or None."""
    span = 2 * STEP_SIDE + STEP_GAP
    centre = t - 0.5 * span
    rows = a[a[:, 0] >= t - span]
    x, r = rows[:, 0] - centre, rows[:, 1]
    left, right = x < -0.5 * STEP_GAP, x > 0.5 * STEP_GAP
    (kl, dl), (kr, dr) = (np.polyfit(x[m], r[m], 1) for m in (left, right))
    step = dr - dl
    if not (abs(step) > 15.0 * noise and abs(step) > 2.0 * max(abs(kl), abs(kr)) * STEP_GAP):
        return None
    mid = ~(left | right)
    level = r[mid] - (dl + kl * x[mid] + 0.5 * step)
    k = int(np.nonzero(np.sign(level[1:]) != np.sign(level[:-1]))[0][0])
    xm = x[mid]
    return centre + xm[k] - level[k] * (xm[k + 1] - xm[k]) / (level[k + 1] - level[k]), step


@pytest.mark.parametrize('size', [0.0, 2e-5, -3e-4])
def test_the_compiled_look_finds_the_step_a_line_fit_finds(size):
    rng = np.random.default_rng(int(abs(size) * 1e6))
    t = np.arange(1.0, 1.3, 1.0 / RATE)
    t_step = 1.2 - 0.5 * (2 * STEP_SIDE + STEP_GAP) + 0.004
    r = np.where(t > t_step, size, 0.0) + 1e-4 * (t - 1.0) + rng.normal(0.0, 1e-6, t.size)
    ft = FlankTiming()
    for k in range(t.size):
        ft.push(float(t[k]), float(r[k]), 0.1 * t[k], 0.0)
    at = float(t[200])
    got = detect_core(ft._a, ft._n, at, 1e-6, -math.inf, -math.inf, 0.0)
    ref = _numpy_look(ft._a[:ft._n], at, 1e-6)
    if size == 0.0:
        assert ref is None and not got[0]
        return
    assert ref is not None and got[0]
    assert got[1] == pytest.approx(ref[0], abs=1e-9)
    assert got[4] == pytest.approx(ref[1], rel=1e-9)
    assert got[1] == pytest.approx(t_step, abs=1.5e-3)
    assert got[2] == pytest.approx(0.1 * got[1], rel=1e-6)     # omega4 interpolated there
