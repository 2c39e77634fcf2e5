# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The back-drive margin (self-locking): against the analytic condition at zero speed, and
against a simulation in which the motor lets go: the antenna creeps exactly when the margin
is below 1."""

import math

import numpy as np
import pytest

from worm_gear_sim import Config, Simulator
from worm_gear_sim.dynamics.derived import derive
from worm_gear_sim.dynamics.model import DriveModel


def analytic(cfg: Config) -> float:
    """mu(0) / (cos(phi_n) tan(lam)): the textbook self-locking condition of a worm drive."""
    fr = cfg.friction
    mu0 = {'stribeck': fr.mu_kinetic + fr.mu_stribeck_drop, 'constant': fr.constant_coefficient,
           'off': 0.0}[fr.model]
    lam = derive(cfg).lead_angle
    return mu0 / (math.cos(cfg.geometry.pressure_angle) * math.tan(lam))


@pytest.mark.parametrize('over', [{}, {'friction.model': 'constant'},
                                  {'friction.model': 'off'},
                                  {'geometry.lead_angle': 0.08, 'friction.mu_kinetic': 0.02}])
def test_margin_at_rest_is_the_analytic_condition(over):
    cfg = Config().replace(over)
    m = DriveModel(cfg)
    assert m.backdrive_margin() == pytest.approx(analytic(cfg), rel=1e-12)
    # independent of the load's magnitude (Coulomb friction: W_f and the demand scale with W_n)
    for load in (0.5, 50.0):
        assert DriveModel(cfg.replace({'load.output_torque': load})).backdrive_margin() == \
            pytest.approx(m.backdrive_margin(), rel=1e-12)


def test_margin_falls_with_the_sliding_speed_on_eq18():
    m = DriveModel(Config())
    rest = m.backdrive_margin()
    moving = m.backdrive_margin(np.array([50.0, 50.0 / 56.0, 50.0 / 56.0]))
    assert 2.0 < rest < 3.0 and moving < rest          # mu_kinetic < mu(0)


def _creep_after_release(margin: float) -> float:
    """A 5 N m load held at rest by the motor; then the motor lets go (the worm shaft's
    stiffness to the motor divided by 1e6: no torque reaches the worm) and 50 ms pass.
    Returns |delta theta4| [rad].  Constant set-valued friction scaled to the margin."""
    base = Config().replace({'friction.model': 'constant', 'load.output_torque': 5.0})
    mu_req = 1.0 / analytic(base.replace({'friction.constant_coefficient': 1.0}))
    cfg = base.replace({'friction.constant_coefficient': margin * mu_req})
    assert DriveModel(cfg).backdrive_margin() == pytest.approx(margin, rel=1e-9)
    sim = Simulator(cfg, theta1=0.0)
    sim.advance_to(0.01, 0.0)                          # held: at rest
    th4 = sim.state.theta[2]
    g = cfg.materials.worm_shaft_shear_modulus
    sim.reconfigure(cfg.replace({'materials.worm_shaft_shear_modulus': g * 1e-6}))
    sim.advance_to(0.06, 0.0)
    return abs(sim.state.theta[2] - th4)


@pytest.mark.parametrize('margin, creeps', [(0.9, True), (0.98, True), (1.02, False),
                                            (1.5, False)])
def test_the_antenna_creeps_exactly_when_the_margin_is_below_one(margin, creeps):
    """Measured: 8.4e-3 rad (0.9), 1.8e-3 (0.98) against 9.8e-8 (1.02, 1.5: the elastic
    relaxation of the released shaft)."""
    moved = _creep_after_release(margin)
    if creeps:
        assert moved > 1e-4, moved
    else:
        assert moved < 1e-6, moved       # the shaft's elastic relaxation: 9.8e-8 rad


def test_the_params_document_reports_the_margin_and_reads_back(tmp_path):
    """`worm-gear-sim params` (params_document) carries the margin at rest among the derived
    quantities; a params JSON written with it reads back (its derived block is checked)."""
    import json

    from worm_gear_sim.config.files import load_params_json, params_document, params_json_dump
    cfg = Config().replace({'friction.model': 'constant', 'friction.constant_coefficient': 0.03})
    doc = params_document(cfg)
    assert doc['derived']['backdrive_margin'] == pytest.approx(analytic(cfg), rel=1e-12)
    assert doc['derived']['backdrive_margin'] < 1.0
    f = tmp_path / 'p.json'
    f.write_text(params_json_dump(doc, None))
    assert json.loads(f.read_text())['derived']['backdrive_margin'] < 1.0
    assert load_params_json(f) == cfg
