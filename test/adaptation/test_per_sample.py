# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The adapter's compiled sample (:mod:`worm_gear_sim.adaptation.per_sample`) against its
Python twin (:class:`PythonAdapter` below: the per-sample rule written in Python, as the
adapter ran it before it was compiled): the same stream through both gives the same
estimate, covariance, window (its triangular factor) and per-sample state bit for bit,
sample by sample, with every case met on the way (the model in use crossing its play, the
flank-change events, the step detector finding the drive's crossings, the record full).
And the step detector's compiled look against a plain numpy line fit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worm_gear_sim.adaptation import estimator
from worm_gear_sim.adaptation import per_sample as ps
from worm_gear_sim.adaptation.estimator import (
    ACCEL_TIME_CONSTANT,
    FLANK_HOLD_OFF,
    HUBER_SIGMAS,
    MAX_GAP,
    Adapter,
)
from worm_gear_sim.adaptation.flank_timing import ONSET_SHARE, STEP_GAP, STEP_SIDE, FlankTiming
from worm_gear_sim.adaptation.per_sample import Estimate, Reading, Weighing, _sample_step
from worm_gear_sim.config.usable import Config
from worm_gear_sim.dynamics.model import DriveModel

RATE = 1000.0
KEYS = ['load.output_torque', 'load.output_viscous_coefficient', 'mesh.backlash',
        'mesh.worm_error_harmonics']


class PythonAdapter(Adapter):
    """The adapter with its per-sample rule in Python (the twin of the compiled one)."""

    def update(self, t: float, theta4_meas: float, theta2: float, theta3: float,
               theta4_pred: float) -> bool:
        if t >= self._history.next:
            self._history.keep(t)
        dt = t - self._last_t
        self._last_t = t
        if not dt <= MAX_GAP:                       # first sample, or after a pause
            self._rates = 0
        if self._rates == 0:
            w4 = 0.0
            a4 = 0.0
        else:
            w4 = (theta4_pred - self._th4) / dt
            a_raw = (w4 - self._w4) / dt if self._rates > 1 else 0.0
            g = dt / (ACCEL_TIME_CONSTANT + dt)
            a4 = self._a4 + g * (a_raw - self._a4)
        self._th4, self._w4, self._a4 = theta4_pred, w4, a4
        if self._rates > 0:
            self._rate = 1.0 / dt
        self._rates += 1
        if self._rates < 3:
            self.samples_skipped += 1
            return False
        lay = self.layout
        th = self.theta
        # (item(): Python floats, the same numbers, cheaper arithmetic than numpy scalars)
        load = th.item(lay.i_load) if lay.i_load >= 0 else self._load0
        drag = th.item(lay.i_drag) if lay.i_drag >= 0 else self._drag0
        torque = self._inertia * a4 + drag * w4 + load
        flank = 1.0 if torque > 0.0 else -1.0 if torque < 0.0 else self._flank
        if flank != self._flank:
            self._flank, self._flank_t = flank, t
            self._cross_t = max(self._cross_t, t)          # (the estimate's crossing)
        # the flank of the model in use: where it differs, one of the two is wrong and the
        # residual holds a flank error the linear picture does not have
        ax = self.applied_x
        drag_m = ax.item(lay.i_drag) if lay.i_drag >= 0 else self._drag0
        torque_m = self._inertia * a4 + drag_m * w4 + \
            (ax.item(lay.i_load) if lay.i_load >= 0 else self._load0)
        flank_m = 1.0 if torque_m > 0.0 else -1.0 if torque_m < 0.0 else self._flank_m
        timing = self._timing
        timing.push(t, theta4_meas - theta4_pred, w4, a4, theta2, theta3)
        if flank_m != self._flank_m:
            if lay.i_play < 0 and self._play0 > 0.0 or lay.i_play >= 0 and \
                    self.applied_x[lay.i_play] > 0.0:   # the model crosses its play here
                if self._flipped_by_step(t, self._flank_m):   # (the set's change: none)
                    self._applied_bound += self.applied_x[lay.i_play] if lay.i_play >= 0 \
                        else self._play0
                else:
                    timing.model_flank_changed(t, self._flank_m, flank_m)
                    self._model_flank_t = t
            self._flank_m, self._flank_t = flank_m, max(self._flank_t, t)
        self._flank_time_update(t, drag)
        self._step_update(t, drag)
        # a flank change within the hold-off ahead (the torques' rates: c alpha4)
        ahead = FLANK_HOLD_OFF * a4
        soon = torque * (torque + drag * ahead) < 0.0 or \
            torque_m * (torque_m + drag_m * ahead) < 0.0
        if soon or t - self._flank_t < FLANK_HOLD_OFF or t < self._hold_until:
            self.samples_skipped += 1
            return False
        c_pos, c_neg = self._compliance
        compliance = c_pos if w4 > 0.0 else c_neg if w4 < 0.0 else 0.5 * (c_pos + c_neg)
        s = self.settings
        lam = math.exp(-dt / s.window)
        # the flank is sure when the drive stays on one: no crossing measured or estimated
        # for a window (the model in use's do not count) and the load outweighs twice the
        # recent drag and inertia torques.  Else load and play, one offset on such a drive,
        # leave the load's own uncertainty wide and the soft flank the play a noise for ever
        sure = lay.i_play >= 0 and t - self._cross_t > s.window and abs(load) > 2.0 * (
            max(drag, 0.0) * self._w_max + self._inertia * self._a_max)
        _sample_step(Estimate(th, self.P, self._std2, self._phi, self._R, self._sc), ax,
                     self._lay,
                     Reading(theta2, theta3, w4, flank, flank_m, torque, compliance,
                             theta4_meas - theta4_pred),
                     Weighing(dt / s.memory, lam, s.measurement_noise ** 2, HUBER_SIGMAS,
                              sure))
        self._w_max = max(abs(w4), self._w_max * lam)
        self._a_max = max(abs(a4), self._a_max * lam)
        if math.isnan(self._first_t):
            self._first_t = t
        self.samples_used += 1
        return True


def _state(ad: Adapter) -> list[np.ndarray]:
    tm = ad._timing
    # (the scratch of the compiled sample, st[X_*], is its own)
    return [ad.theta, ad.P, ad._R, ad._sc, ad._st[:ps.X_DT], tm._ts, tm._a[:tm._n]]


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
    fast, slow = Adapter(cfg, cfg.adaptation), PythonAdapter(cfg, cfg.adaptation)
    codes: dict[int, int] = {}
    compacted = 0
    compiled = estimator.sample_head

    def counted(*args):
        code = compiled(*args)
        codes[code] = codes.get(code, 0) + 1
        return code

    monkeypatch.setattr(estimator, 'sample_head', counted)
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
    assert codes[ps.USED] > 5000 and codes[ps.SKIPPED] > 1000 and codes[ps.NEED_ROOM] >= 1
    assert codes[ps.CROSSED] >= 4 and codes[ps.PYTHON] >= 4
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
    t_mid = xm[k] - level[k] * (xm[k + 1] - xm[k]) / (level[k + 1] - level[k])
    # back from the middle to the rise's ONSET_SHARE, then to where a cube would start
    low = r - (dl + kl * x + ONSET_SHARE * step)
    up = np.sign(low) == np.sign(step)
    last = int(np.searchsorted(x, t_mid))
    i = max(j for j in range(1, last + 1) if up[j] and not up[j - 1])
    t_s = x[i - 1] - low[i - 1] * (x[i] - x[i - 1]) / (low[i] - low[i - 1])
    t_0 = t_s - (t_mid - t_s) / ((0.5 / ONSET_SHARE) ** (1 / 3) - 1)
    return centre + t_0, step


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
    got = ft.detect(at, 1e-6, -math.inf)          # (the compiled detect_core)
    ref = _numpy_look(ft._a[:ft._n], at, 1e-6)
    if size == 0.0:
        assert ref is None and got is None
        return
    assert ref is not None and got is not None
    assert got[0] == pytest.approx(ref[0], abs=1e-9)
    assert got[3] == pytest.approx(ref[1], rel=1e-9)
    assert got[0] == pytest.approx(t_step, abs=1.5e-3)
    assert got[1] == pytest.approx(0.1 * got[0], rel=1e-6)     # omega4 interpolated there
