# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""What the adaptation reads from the residual around crossings of the play, on synthetic
residuals with known answers: the periodic error not yet learnt is no crossing, and a
measured crossing carries the path's acceleration, not the predicted antenna's shaking."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worm_gear_sim.adaptation.estimator import Adapter
from worm_gear_sim.adaptation.flank_timing import LEVEL_WINDOW, WINDOW, FlankTiming
from worm_gear_sim.config.usable import Config
from worm_gear_sim.dynamics.model import DriveModel

RATE = 1000.0
#: A drive's worm harmonics [rad], orders 1-3 (drawn with the benchmark's --error-max 100:
#: the drive on which the "step" below was measured).
WORM = [21.9e-6, -75.5e-6, -29.5e-6, -98.1e-6, -96.2e-6, 55.0e-6]


def test_periodic_error_not_yet_learnt_is_no_crossing():
    """The sector scan predicted without the drive's worm error, measured with it (100
    urad harmonics, nothing else): over the first 3 s, while the harmonics are still
    learnt, the residual's bends at the scan's peak rate made the step detector report a
    crossing of the play (a "step" of 67 urad at 0.88 s on the benchmark's drive, which
    set the load and drag far off); the harmonics' share of the step, known to the
    estimate's covariance, is taken off now, and no crossing is reported."""
    cfg = Config()
    ad = Adapter(cfg, cfg.adaptation)
    ratio = DriveModel(cfg).output_per_input
    t = np.arange(0.0, 3.0, 1.0 / RATE)
    th4 = -math.radians(5.0) * np.cos(2 * math.pi * t / 4.0)
    th2 = th4 / ratio
    err = sum(WORM[2 * k] * np.sin((k + 1) * th2) + WORM[2 * k + 1] * np.cos((k + 1) * th2)
              for k in range(3))
    meas = th4 + err + np.random.default_rng(5).normal(0.0, 1e-6, t.size)
    for k in range(t.size):
        ad.update(float(t[k]), float(meas[k]), float(th2[k]), float(th4[k]), float(th4[k]))
    assert ad.steps_seen == 0 and ad.flank_times == 0


def test_a_measured_crossing_has_the_paths_acceleration():
    """The model crossed its play at t_m = 0.5 s and the drive 12 ms later (the residual's
    arch tops there).  The predicted antenna shakes after the model's crossing (alpha4
    swings by 0.8 rad/s^2 at 95 Hz, decaying in 20 ms, as measured on the sector scan);
    the path's acceleration is 0.2 rad/s^2.  The measurement's alpha4 (it sets the
    torque-zero measurement and the cost of a mistimed crossing) is the path's within 5 %,
    not the shaking's (0.49 rad/s^2 at the crossing)."""
    ft = FlankTiming()
    t_m, dt, alpha, w0 = 0.5, 0.012, 0.2, -0.06
    t = np.arange(0.0, t_m + WINDOW + LEVEL_WINDOW + 0.01, 1.0 / RATE)
    after = np.clip(t - t_m, 0.0, None)
    shake = np.where(t >= t_m, 0.8 * np.exp(-after / 0.02) * np.sin(2 * math.pi * 95 * after),
                     0.0)
    a4 = alpha + shake
    w4 = w0 + np.concatenate([[0.0], np.cumsum(0.5 * (a4[1:] + a4[:-1]) / RATE)])
    t_p = t_m + dt                    # s = +1: the arch opposite to the step, -s
    r = np.where(np.abs(t - t_p) < dt, -0.5 * alpha * (dt ** 2 - (t - t_p) ** 2), 0.0)
    got = None
    for k in range(t.size):
        if abs(t[k] - t_m) < 0.5 / RATE:
            ft.model_flank_changed(float(t[k]), 1.0, -1.0)
        ft.push(float(t[k]), float(r[k]), float(w4[k]), float(a4[k]))
        if ft.event_due(float(t[k])):
            got = ft.ready(float(t[k]), 5e-4, 1e-5, 5e-4, 5e-7)
    assert got is not None
    assert got[0] == pytest.approx(t_p, abs=2e-3)
    assert abs(float(np.interp(got[0], t, a4)) - alpha) > 0.1     # the shaking, there
    assert got[2] == pytest.approx(alpha, rel=0.05)
    assert got[1] == pytest.approx(w0 + alpha * t_p, abs=2e-3)


def test_the_twin_lists_the_crossings_it_measured():
    """A drive with a negative load crosses its play where its torque demand T + c omega4
    + J alpha4 passes zero (0.516 s on the sector scan, the demand computed here along the
    commanded path); the adapter lists the crossing it measured there (time, rates, the
    time sd it weighed it with, how), within that sd (the step detector found it 61 ms
    late and weighed it as 2 ms before it timed a step where its rise starts), and the twin
    hands the list over (what ``bench_adaptation.py --crossing-times`` weighs against the
    drive's own zeros)."""
    from worm_gear_sim.dynamics.inverse import gear_torque_demand
    from worm_gear_sim.studies.adaptation_twin import run_twin
    plant = Config().replace({'mesh.backlash': 5.8e-4, 'load.output_torque': -2.0,
                              'load.output_viscous_coefficient': 20.0})
    start = Config().replace({'adaptation.keys': ['load.output_torque',
                                                  'load.output_viscous_coefficient',
                                                  'mesh.backlash'],
                              'adaptation.window': 0.5, 'adaptation.step_interval': 0.1})
    run = run_twin(plant, start, 'sector', 1.2, seed=3)
    m = DriveModel.of(plant)
    w4 = np.gradient(m.output_per_input * run.theta1_ref, run.t)
    demand = np.array([gear_torque_demand(m.p, w, a, 0.0, 0.0, False)
                       for w, a in zip(w4, np.gradient(w4, run.t))])
    k = int(np.nonzero(np.diff(np.sign(demand)))[0][0])
    assert run.t[k] == pytest.approx(0.516, abs=2e-3)
    assert len(run.crossings) == 1
    t_p, w_p, a_p, sd, how = run.crossings[0]
    assert how in ('step', 'wide step', 'onset', 'arch', 'area') and sd > 0.0
    assert abs(t_p - run.t[k]) <= sd
    assert w_p == pytest.approx(w4[np.searchsorted(run.t, t_p)], abs=5e-3)


def _event(r: np.ndarray, t: np.ndarray, t_m: float, noise: float, play: float = 8e-4):
    """The model crossed at t_m (flank +1 -> -1, s = +1: the arch is below the level)."""
    ft = FlankTiming()
    w4 = -0.06 + 0.2 * (t - t_m)
    got = None
    for k in range(t.size):
        if abs(t[k] - t_m) < 0.5 / RATE:
            ft.model_flank_changed(float(t[k]), 1.0, -1.0)
        ft.push(float(t[k]), float(r[k]), float(w4[k]), 0.2)
        if ft.event_due(float(t[k])):
            got = ft.ready(float(t[k]), play, 1e-5, play, noise)
    return got


@pytest.mark.parametrize('seed', range(5))
def test_the_impact_on_the_new_flank_is_no_arch_a_real_arch_still_is(seed):
    """With the model equal to the drive (the adapter started at a drawn drive's own values:
    play 2.80', load 0.48 N m, drag 8.65), the residual after the common crossing held a
    transient of 56 urad, 33 ms at its base (the impact on the new flank, timed slightly apart by
    the plant and the prediction), over ~2.5 urad of noise. Read as an arch it put the
    drive's crossing 20.9 ms after its torque zero, weighed as 2 ms, and the window then
    charged the drive's own values for that mistiming and stepped the model away from them.
    Its curvature is ~2.5x the float's (|alpha4| / 2): no arch.  A real arch as small (the
    model crossing 20 ms early at 0.2 rad/s^2: 40 urad) still is one, at its top."""
    rng = np.random.default_rng(seed)
    t_m, noise = 0.5, 4e-6                      # (the default adaptation.measurement_noise)
    t = np.arange(0.0, t_m + WINDOW + LEVEL_WINDOW + 0.01, 1.0 / RATE)
    jitter = rng.normal(0.0, 2.5e-6, t.size)
    u = (t - t_m - 0.004) / 0.033               # (as measured: 56 urad, 33 ms at its base)
    impact = np.where((u > 0.0) & (u < 1.0), -56e-6 * np.sin(math.pi * np.clip(u, 0, 1)), 0.0)
    got = _event(impact + jitter, t, t_m, noise)
    assert got is None or got[3] != 'arch', got
    dt = 0.02
    t_p = t_m + dt
    arch = np.where(np.abs(t - t_p) < dt, -0.5 * 0.2 * (dt ** 2 - (t - t_p) ** 2), 0.0)
    got = _event(arch + jitter, t, t_m, noise)
    assert got is not None and got[3] == 'arch', got
    assert got[0] == pytest.approx(t_p, abs=3e-3)


def test_a_crossing_found_late_is_measured_and_its_samples_do_not_teach_the_estimate():
    """A drive whose first crossing (its torque demand's zero, 2.457 s on the sector scan)
    comes while the model in use, a step or two from nominal, keeps one flank.  The step
    detector finds it ~0.15 s later; meanwhile the samples after it entered the estimate
    as if on the old flank and moved it (before: load -2.1 N m, play 4.2e-4 against the
    drive's 2.0 N m and 8.5e-4), and the detector judged the step with that estimate's
    periodic error, which had taken the step in (before: no crossing measured at all).
    Now the detector judges a window by the estimate from before it, and a crossing found
    rolls the estimate back to before the crossing: the play is within 10 % of the drive's
    and the load over the drag (the zero's rate) within 10 %.  The model in use moves its
    load and drag first (they decide when it crosses), its play last."""
    from worm_gear_sim.dynamics.inverse import gear_torque_demand
    from worm_gear_sim.studies.adaptation_twin import run_twin
    plant = Config().replace({'mesh.backlash': 8.5e-4, 'load.output_torque': 2.0,
                              'load.output_viscous_coefficient': 22.0})
    run = run_twin(plant, Config(), 'sector', 3.3, seed=6)
    m = DriveModel.of(plant)
    w4 = np.gradient(m.output_per_input * run.theta1_ref, run.t)
    demand = np.array([gear_torque_demand(m.p, w, a, 0.0, 0.0, False)
                       for w, a in zip(w4, np.gradient(w4, run.t))])
    zeros = run.t[np.nonzero(np.diff(np.sign(demand)))[0]]
    assert zeros.size == 1 and zeros[0] == pytest.approx(2.457, abs=2e-3)
    assert len(run.crossings) == 1
    t_p, w_p, _, sd, _ = run.crossings[0]
    assert abs(t_p - zeros[0]) <= sd
    est = run.estimates
    assert est['mesh.backlash'] == pytest.approx(8.5e-4, rel=0.1)
    assert est['load.output_torque'] / est['load.output_viscous_coefficient'] == \
        pytest.approx(2.0 / 22.0, rel=0.1)
    assert len(run.steps) >= 3
    first = run.steps[0][1]
    assert first['mesh.backlash'] == 0.0 and first['load.output_torque'] > 0.0


def test_a_step_that_flips_the_models_flank_is_no_crossing_of_the_model():
    """A step applied to the model in use (play 3e-4, load 0 -> 3 N m at rest) turns its
    torque demand positive at once: the flank changes because the set changed, not the
    motion.  That is no model crossing: no flank-change event is opened, the step detector
    is not blocked by it, and the residual's step the flip makes (the model's play) is added
    to what the detector allows for the step."""
    cfg = Config().replace({'mesh.backlash': 3e-4,
                            'adaptation.keys': ['load.output_torque', 'mesh.backlash']})
    ad = Adapter(cfg, cfg.adaptation)
    ratio = DriveModel(cfg).output_per_input
    t = np.arange(0.0, 0.6, 1.0 / RATE)
    th4 = -1e-3 * t * t                  # a slow start the other way: demand below zero
    flips = []
    for k in range(t.size):
        if k == 300:
            step = ad.applied_x.copy()
            step[ad.layout.i_load] = 3.0
            ad.applied(step, ad.model, at=float(t[k]))
            bound, model_flank_t = ad._applied_bound, ad._model_flank_t
        before = ad._flank_m
        ad.update(float(t[k]), float(th4[k]), float(th4[k] / ratio), float(th4[k]),
                  float(th4[k]))
        if ad._flank_m != before and before != 0.0:
            flips.append(float(t[k]))
    assert flips == [pytest.approx(0.3)]
    assert ad._timing.events == 0 and ad._model_flank_t == model_flank_t < 0.3
    assert ad._applied_bound == pytest.approx(bound + 3e-4)


def test_a_step_inside_a_flank_change_events_window_drops_it_even_after_a_later_step():
    """A flank-change event of the model (its crossing at t_m, measured from the residual
    over t_m +- WINDOW, levels included) is no measurement when a step applied to the model
    falls inside that window: the step moves the residual too.  Any recent step counts,
    not only the last: a step at t_m - 0.13 s followed by one at t_m + 0.37 s (after the
    window, before the event is due) dropped nothing before (measured: a small-load drive
    whose event so read a crossing 0.25 s early, at a rate 3x too small)."""
    cfg = Config().replace({'mesh.backlash': 3e-4})
    called = []
    for steps, dropped in (([0.87, 1.37], True), ([0.5, 1.37], False), ([], False)):
        ad = Adapter(cfg, cfg.adaptation)
        ad._timing.ready = lambda *a, **k: called.append(a[0])     # (reached: measured)
        for at in steps:
            ad.applied(ad.applied_x.copy(), ad.model, at=at)
        t_m = 1.0
        ad._timing._event = (t_m, 1.0)
        n = len(called)
        ad._flank_time_update(t_m + WINDOW + LEVEL_WINDOW + 0.01, 20.0)
        assert (len(called) == n) == dropped, steps
        assert ad._timing._event is None or not dropped
