# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The adaptation on drives that keep one flank (no drag, a load) and around the steps it
applies to its own model: known answers on synthetic residuals, and the blended hand-over
of a step's correction against the same step at once on an undamped drive."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worm_gear_sim.adaptation.estimator import Adapter, output_compliance
from worm_gear_sim.compensation.blend import BlendedCompensator
from worm_gear_sim.compensation.streaming import Compensator
from worm_gear_sim.config.usable import Config
from worm_gear_sim.dynamics.modal import modes
from worm_gear_sim.dynamics.model import DriveModel
from worm_gear_sim.joint_trajectory.compensate import antenna_error

RATE = 1000.0
KEYS = ['load.output_torque', 'load.output_viscous_coefficient', 'mesh.backlash']


@pytest.fixture(scope='module')
def cfg() -> Config:
    return Config().replace({'adaptation.keys': KEYS})


def sector(t: np.ndarray) -> np.ndarray:
    return -math.radians(5.0) * np.cos(2 * math.pi * t / 4.0)


def feed(ad: Adapter, t: np.ndarray, extra: np.ndarray, ratio: float,
         applied_at: float | None = None, bound: float = 0.0) -> None:
    """theta4 of the sector scan predicted, theta4 + extra measured; ``applied_at``: a step
    of the model (its load by as much as changes the static correction by ``bound`` [rad],
    the rest the same: no play in the model, no crossing of its own) whose samples start then,
    told when the samples reach 50 ms before it (as the node's adaptation, one sample delay
    behind)."""
    th4 = sector(t)
    for k in range(t.size):
        if applied_at is not None and abs(t[k] - (applied_at - 0.05)) < 0.5 / RATE:
            step = ad.applied_x.copy()
            step[ad.layout.i_load] += bound / max(abs(c) for c in output_compliance(ad.model))
            ad.applied(step, ad.model, at=applied_at)
        ad.update(float(t[k]), float(th4[k] + extra[k]), float(th4[k] / ratio),
                  float(th4[k]), float(th4[k]))


def test_a_step_of_the_model_is_not_read_as_the_drives_crossing(cfg):
    """A step of the residual where the model in use changed (its prediction moves with
    the step: a load whose windup changes the correction by 0.35 mrad) is no crossing of
    the drive's play: no torque-zero or play measurement from it.  The same step without a
    change of the model is one."""
    ratio = DriveModel(cfg).output_per_input
    t = np.arange(2.0, 4.0, 1.0 / RATE)
    noise = np.random.default_rng(3).normal(0.0, 2e-6, t.size)
    extra = np.where(t >= 3.0, 3e-4, 0.0) + noise
    seen = Adapter(cfg, cfg.adaptation)
    feed(seen, t, extra, ratio)
    assert seen.steps_seen == 1 and seen.flank_times == 1
    model_step = Adapter(cfg, cfg.adaptation)
    feed(model_step, t, extra, ratio, applied_at=3.0, bound=3.5e-4)
    assert model_step.steps_seen == 0 and model_step.flank_times == 0


def test_the_drives_crossing_is_seen_beside_a_smaller_step_of_the_model(cfg):
    """While the model is moved towards the estimate (a bounded step every 0.25 s) the
    drive may cross its play: a step of the residual larger than the most the model's step
    can make (its bound, here 0.1 mrad) is the drive's, and
    measured (it was ignored whenever a model step fell within the detector's window:
    measured on a drawn drive, both crossings of the first 4 s were missed that way and the
    model then crossed 0.3 s early for lack of that torque measurement)."""
    ratio = DriveModel(cfg).output_per_input
    t = np.arange(2.0, 4.0, 1.0 / RATE)
    noise = np.random.default_rng(3).normal(0.0, 2e-6, t.size)
    extra = np.where(t >= 3.0, 1e-3, 0.0) + noise
    ad = Adapter(cfg, cfg.adaptation)
    feed(ad, t, extra, ratio, applied_at=3.0, bound=1e-4)
    assert ad.steps_seen == 1 and ad.flank_times == 1
    small = Adapter(cfg, cfg.adaptation)       # a crossing within the model step's reach
    feed(small, t, np.where(t >= 3.0, 0.9e-4, 0.0) + noise, ratio, applied_at=3.0,
         bound=1e-4)
    assert small.steps_seen == 0 and small.flank_times == 0


def test_a_drive_on_one_flank_gets_its_offset_from_the_play_and_load(cfg):
    """No drag, a load far above the inertia torque: the drive stays on its drive flank,
    and play, load (and the gear's first harmonic) make one offset.  The load's own
    uncertainty stays wide, so the soft flank alone kept part of the play a noise and the
    estimate off the offset by ~0.13 mrad (measured); with the flank sure once no crossing
    is seen or estimated for a window, the estimate fits the residual to its noise."""
    ad = Adapter(cfg, cfg.adaptation)
    model = DriveModel(cfg)
    c = 0.5 * sum(output_compliance(model))
    t = np.arange(0.0, 8.0, 1.0 / RATE)
    offset = -c * 3.0 - 0.5 * 1.2e-3
    extra = offset + np.random.default_rng(4).normal(0.0, 2e-6, t.size)
    feed(ad, t, extra, model.output_per_input)
    est = ad.estimates()
    fitted = -c * est['load.output_torque'] - 0.5 * est['mesh.backlash']
    assert fitted == pytest.approx(offset, rel=0.02)
    assert ad.window_rms()['estimate'] < 1e-5            # 0.13 mrad without the sure flank
    assert est['mesh.backlash'] > 0.0 and est['load.output_torque'] > 0.0


def test_a_blended_step_of_the_correction_leaves_the_antenna_still():
    """An undamped drive (no drag: the antenna mode keeps any ringing): the correction of
    a load estimate 1 N m off replaced by the right one at once leaves the antenna ringing;
    blended over five antenna periods, less than 3 % of that."""
    plant = Config().replace({'load.output_torque': 3.0,
                              'load.output_viscous_coefficient': 0.0})
    wrong = plant.replace({'load.output_torque': 2.0})
    f0 = float(modes(DriveModel(plant)).frequencies_hz[0])
    t = np.arange(0.0, 0.6, 1.0 / RATE)
    ref = sector(t + 1.0) / DriveModel(plant).output_per_input
    swap = 0.2
    out = {}
    for how in ('at once', 'blended'):
        old, new = Compensator(DriveModel(wrong)), Compensator(DriveModel(plant))
        for comp in (old, new):
            comp.reset(float(ref[0]), 0.0)
        blend = BlendedCompensator(old, new, 5.0 / f0)
        delta = np.empty(t.size)
        for k, tk in enumerate(t):
            for comp in (old, new):
                comp.add_sample(float(tk), float(ref[k]))
            if tk < swap:
                delta[k] = old.evaluate(float(tk))
                new.evaluate(float(tk))
            elif how == 'at once':
                delta[k] = new.evaluate(float(tk))
            else:
                delta[k] = blend.evaluate(float(tk))
        err = antenna_error(plant, t, ref + delta, ref)
        late = t >= swap + 0.1                        # the ringing: its amplitude at f0
        tl = t[late]
        basis = np.column_stack([np.sin(2 * math.pi * f0 * tl), np.cos(2 * math.pi * f0 * tl),
                                 np.ones(tl.size), tl, tl ** 2])
        coef = np.linalg.lstsq(basis, err[late], rcond=None)[0]
        out[how] = float(math.hypot(coef[0], coef[1]))
        assert blend.blending == (how == 'at once')   # unused, or done by the end
    assert out['at once'] > 1e-5
    assert out['blended'] < 0.03 * out['at once']


def test_a_play_below_zero_taken_as_zero_keeps_the_offset(cfg):
    """On a drive that keeps one flank, load and play make one offset, which the estimate
    knows far better than either (their covariance is a ridge).  A play estimate a little
    below zero is applied as zero; the load takes the play's share (the candidate is
    conditioned on play = 0 with the covariance), so the offset the model applies stays the
    estimate's.  Zeroing the play alone would move it by half the play estimate."""
    ad = Adapter(cfg, cfg.adaptation)
    model = DriveModel(cfg)
    c = 0.5 * sum(output_compliance(model))
    t = np.arange(0.0, 8.0, 1.0 / RATE)
    extra = -c * 3.0 + np.random.default_rng(6).normal(0.0, 2e-6, t.size)
    feed(ad, t, extra, model.output_per_input)
    lay = ad.layout

    def offset(x: np.ndarray) -> float:
        return -c * x[lay.i_load] - 0.5 * x[lay.i_play]

    x = ad.theta.copy()
    x[lay.i_play] = -0.5 * math.sqrt(ad.P[lay.i_play, lay.i_play])    # within the bound
    x[lay.i_load] -= 0.5 * x[lay.i_play] / c                             # the same offset
    cand, why = ad.bounded(x)
    assert not why and cand[lay.i_play] == 0.0
    moved = abs(offset(cand) - offset(x))
    assert moved < 0.05 * 0.5 * abs(x[lay.i_play])       # zeroing alone: 0.5 |play|


def test_a_slow_step_is_a_crossing_only_where_the_estimate_lets_the_drive_cross(cfg):
    """The wide scale's step (a float of ~0.13 s) is taken as the drive's crossing only
    where the estimate's torque demand T + c omega4 + J alpha4 is within 3 sd of zero: a
    drive without drag under a load of 1.84 N m never crosses, and a smooth residual not
    yet learnt read as a slow step there took its estimate to a wrong basin (measured)."""
    ad = Adapter(cfg, cfg.adaptation)
    i_load, i_drag = ad.layout.i_load, ad.layout.i_drag
    assert ad._may_cross(-0.1, 0.1)                  # the prior: anything may cross
    ad.theta[i_load], ad.theta[i_drag] = 7.0, 6.0
    ad.P[:] = 0.0
    ad.P[i_load, i_load], ad.P[i_drag, i_drag] = 1.7 ** 2, 0.3 ** 2
    assert not ad._may_cross(-0.092, 0.155)          # T + c w = 6.4 +- 1.7 N m
    ad.theta[i_drag] = 60.0                          # T + c w = 1.5 +- 1.7: may cross
    assert ad._may_cross(-0.092, 0.155)
    # and the adapter takes such a step (play not adapted here: the filter would take the
    # float's samples as play before the wide window has them all)
    two = Config().replace({'adaptation.keys': KEYS[:2]})
    ratio = DriveModel(two).output_per_input
    t = np.arange(2.0, 4.0, 1.0 / RATE)
    x = np.clip((t - 3.0) / 0.13, 0.0, 1.0)
    fresh = Adapter(two, two.adaptation)
    feed(fresh, t, 6e-4 * x * x * (3.0 - 2.0 * x)
         + np.random.default_rng(3).normal(0.0, 2e-6, t.size), ratio)
    assert fresh.steps_seen == 1
