# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The fit's finite-difference Jacobian on threads: the same numbers as in the calling
thread, bit for bit (each column is the serial call), and a whole multi-start fit unchanged."""

from __future__ import annotations

import numpy as np
import pytest
from fit_case import KG, ZETA, fit_case

from worm_gear_sim import load_config
from worm_gear_sim.identification import (
    FitOptions,
    IdentificationError,
    Problem,
    fit_parameters,
    identify,
    jacobian,
)


@pytest.fixture(scope='module')
def case():
    return fit_case()


def test_jacobian_on_threads_equals_the_serial_one(case):
    base, rec = case
    problem = Problem(base, fit_parameters(base, [KG, ZETA]), [rec])
    x = np.array([0.05, 0.02])
    serial = jacobian(problem, x)
    forward = problem.jacobian(x, 0.03)
    problem.residuals(x)                              # r0 cached: the count is the columns'
    n_before = problem.n_evals
    problem.threads = 2
    threaded = jacobian(problem, x)
    assert problem.n_evals - n_before == 4           # every column point counted once
    assert np.isfinite(serial).all()
    assert np.array_equal(serial, threaded)
    assert np.array_equal(forward, problem.jacobian(x, 0.03))


def test_a_multistart_fit_is_the_same_on_one_or_two_threads(case):
    """The starts and the columns on two threads: every start as in the serial loop."""
    base, rec = case
    kw = dict(strategy='multistart', n_starts=2, serial=True, max_nfev=5)
    one = identify(base, [rec], [KG], options=FitOptions(threads=1, **kw))
    two = identify(base, [rec], [KG], options=FitOptions(threads=2, **kw))
    assert one.values == two.values and one.ci95 == two.ci95
    assert [s['cost'] for s in one.starts] == [s['cost'] for s in two.starts]
    assert [s['x'] for s in one.starts] == [s['x'] for s in two.starts]
    assert len(two.starts) == 2
    with pytest.raises(IdentificationError, match='threads'):
        identify(base, [rec], [KG], options=FitOptions(threads=0, **kw))


def test_a_candidate_set_is_built_once_and_simulates_the_same(case):
    """The fit simulates the model its usability check built (no second build), with the
    same residuals as a freshly built model."""
    from worm_gear_sim.dynamics.model import DriveModel
    from worm_gear_sim.dynamics.usability import usable_model
    from worm_gear_sim.identification import predict
    base, rec = case
    cfg = base.replace({KG: base.materials.gear_shaft_shear_modulus * 1.0123})
    model = usable_model(cfg)
    assert usable_model(cfg) is model                   # the check's own, kept
    assert model.config == cfg
    fresh, shared = predict(DriveModel(cfg), rec), predict(model, rec)
    assert np.array_equal(fresh['theta4'], shared['theta4'])
    # the integrator's damping, computed once per model and the same as a fresh model's
    from worm_gear_sim.dynamics.modal import stepping_damping
    played = DriveModel(base.replace({'mesh.backlash': 1e-3,
                                      'damping.modal_damping_ratios': [0.01, 0.0, 0.0]}))
    C = stepping_damping(played)
    assert C.shape == (6, 3) and stepping_damping(played) is C     # stacked: play
    assert np.array_equal(C, stepping_damping(DriveModel(played.config)))
    # the structural damping, kept per model too (the check's modes and the integrator's):
    # a caller's copy, the same numbers as a fresh model's
    from worm_gear_sim.dynamics.modal import damping_matrix
    D = damping_matrix(played)
    D[0, 0] += 1.0
    assert np.array_equal(damping_matrix(played), damping_matrix(DriveModel(played.config)))
    assert np.array_equal(damping_matrix(played), C[:3])


def test_the_remembered_command_gives_the_same_numbers(case):
    """predict with a memo (the fit's evaluations: the command interpolated on the
    integrator's grid once per record and window) equals predict without, bit for bit."""
    from worm_gear_sim.dynamics.profiles import SampledProfile
    from worm_gear_sim.identification import predict
    base, rec = case
    memo: dict = {}
    for t_end in (0.02, None, 0.02):
        plain = predict(base, rec, t_end)
        assert np.array_equal(plain['theta4'], predict(base, rec, t_end, memo)['theta4'])
        assert np.array_equal(plain['theta4'], predict(base, rec, t_end, memo)['theta4'])
    assert sorted(memo, key=str) == [0.02, None]
    prof = SampledProfile(rec.t, rec.theta1, remember=True)
    ref = SampledProfile(rec.t, rec.theta1)
    for grid in (np.linspace(0, 0.03, 7), np.linspace(0, 0.03, 7), np.linspace(0, 0.02, 7)):
        got = prof.theta1_dot(grid)
        assert np.array_equal(got, ref.theta1_dot(grid)) and not got.flags.writeable
        assert np.array_equal(prof.theta1(grid), ref.theta1(grid))
    assert prof.theta1(0.01) == ref.theta1(0.01)


def test_candidates_sharing_the_mesh_reuse_its_table_with_the_same_numbers():
    """A fit's candidates differ in shafts, inertias, damping or friction: the tooth
    compliance table (and the calibration of Eqs. 16-17) of their common mesh is built once
    and kept; a model built with the kept table equals one built from scratch, and a
    changed mesh gets its own table.  The check's natural modes are those of ``modes``."""
    from worm_gear_sim.dynamics import periodic
    from worm_gear_sim.dynamics.modal import modes, natural_modes
    from worm_gear_sim.dynamics.model import DriveModel
    base = load_config()
    sets = [base.replace({KG: base.materials.gear_shaft_shear_modulus * 1.1}),
            base.replace({'friction.mu_kinetic': 0.05}),
            base.replace({'mesh.worm_fit_b': base.mesh.worm_fit_b * 1.5})]
    kept = [DriveModel(c).p for c in sets]
    for c, p in zip(sets, kept):
        periodic._TABLES.clear()
        fresh = DriveModel(c).p
        assert np.array_equal(p, fresh)
    assert not np.array_equal(kept[0][-2060:], kept[2][-2060:])   # another mesh, its table
    hz, shapes = natural_modes(sets[0])
    m = modes(sets[0], include_damping=False)
    assert np.array_equal(hz, m.undamped_hz) and np.array_equal(shapes, m.shapes)
