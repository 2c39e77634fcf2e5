# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The equations: Jacobian, symmetry, mesh stiffness mean, friction direction, modes."""

import math

import numpy as np
import pytest

from worm_gear_sim import Config, modes
from worm_gear_sim.dynamics.equations import forces, linear_stiffness, tooth_stiffness
from worm_gear_sim.dynamics.layout import P_LW, P_RG, P_RW, P_SINL
from worm_gear_sim.dynamics.model import pack_parameters

VARIANTS = {
    'default': {},
    'linear': {'mesh.stiffness_model': 'linear', 'friction.model': 'constant'},
    'paper_friction': {'friction.direction': 'paper'},
    'no_compliance_friction': {'friction.in_compliance': False},
    'paper_lead': {'geometry.lead_convention': 'paper', 'friction.model': 'constant'},
    'load': {'load.output_torque': 3.0, 'load.output_viscous_coefficient': 0.5},
    'sawtooth_mapping': {'mesh.contact_mapping': 'sawtooth'},
    'tanh_friction': {'friction.direction': 'regularized'},
    'periodic_error': {'mesh.worm_error_harmonics': [2e-4, -1e-4, 1e-4, 5e-5, -5e-5, 3e-5],
                       'mesh.gear_error_harmonics': [3e-4, 1e-4, -1e-4, 2e-4]},
}


@pytest.mark.parametrize('name', sorted(VARIANTS))
def test_analytic_jacobian_matches_finite_differences(name):
    p = pack_parameters(Config().replace(VARIANTS[name]))
    rng = np.random.default_rng(7)
    for _ in range(25):
        u = np.array([0.3, 0.3 / 56, 0.3 / 56]) * rng.uniform(-1, 1) \
            + rng.normal(0, [2e-5, 2e-6, 2e-4])
        v = rng.normal(0, [3.0, 0.05, 0.05])
        if rng.random() < 0.3:       # near stick, inside the friction regularisation zone
            v[0] = rng.normal(0, 2e-3)
        th1 = u[0] + rng.normal(0, 1e-5)
        Q, dQdu, dQdv, _ = forces(p, u, v, th1)
        for j in range(3):
            for which, jac, h in (('u', dQdu, 1e-9), ('v', dQdv, 1e-7)):
                def q_at(step, which=which, j=j, u=u, v=v, th1=th1):
                    uu, vv = u.copy(), v.copy()
                    (uu if which == 'u' else vv)[j] += step
                    return forces(p, uu, vv, th1)[0]
                # 4th-order central difference
                fd = (-q_at(2 * h) + 8 * q_at(h) - 8 * q_at(-h) + q_at(-2 * h)) / (12 * h)
                # tolerance: relative, plus the round-off noise floor of the differences
                noise = 100 * np.finfo(float).eps * np.abs(Q) / h
                assert np.all(np.abs(jac[:, j] - fd) <= 1e-5 * np.abs(fd) + noise
                              + 1e-7 * np.abs(jac).max()), \
                    (name, which, j, jac[:, j], fd)


def test_frictionless_mesh_is_conservative_only_with_consistent_lead():
    cfg = Config().replace({'friction.model': 'off', 'mesh.stiffness_model': 'linear'})
    u, v = np.array([0.1, 0.1 / 56 - 3e-6, 0.0018]), np.zeros(3)
    _, K, _, _ = forces(pack_parameters(cfg), u, v, 0.1)
    assert np.allclose(K, K.T, rtol=1e-12, atol=1e-9)         # symmetric: virtual work holds
    table = cfg.replace({'geometry.lead_angle': math.radians(3 + 41 / 60)})
    _, K2, _, _ = forces(pack_parameters(table), u, v, 0.1)
    asym = abs(K2[0, 1] - K2[1, 0]) / abs(K2[0, 1])
    assert asym == pytest.approx(1 - 55.06 / 56, abs=2e-3)    # torque ratio 55.06 vs 56


def test_mean_tooth_stiffness_over_a_mesh_cycle():
    p = pack_parameters(Config())
    phases = np.linspace(0, 2 * math.pi, 20001)[:-1]
    # mesh phase = (theta2 + z_g theta3) / 2: sweep theta2 over one worm revolution per 2 rad
    k = np.array([tooth_stiffness(p, 2 * ph, 0.0)[:2] for ph in phases])
    assert k[:, 0].mean() == pytest.approx(3.5e8, rel=0.01)
    assert k[:, 1].mean() == pytest.approx(2.5e8, rel=0.01)
    # the curves really vary over the cycle (Eqs. 16-17 are not constant)
    assert k[:, 0].max() / k[:, 0].min() == pytest.approx(math.exp(360 * 0.000656069), rel=1e-3)
    assert k[:, 1].min() < 2.5e8 < k[:, 1].max()


def test_drive_model_names_the_quantities_the_kernel_uses():
    """DriveModel's named quantities against values worked out from the parameters by hand
    (and the calibration against a numerical cycle mean), and the packed vector it shares
    with the kernels equals a fresh packing."""
    from worm_gear_sim import DriveModel
    cfg = Config().replace({'geometry.module': 4.0, 'mesh.worm_tooth_stiffness_multiplier': 3.0})
    m = DriveModel(cfg)
    assert np.array_equal(m.p, pack_parameters(cfg)) and DriveModel.of(m) is m
    cw, cg = m.linear_tooth_stiffness
    assert cw == pytest.approx(3.5e8 * 3.0 * 4.0 / 2) and cg == pytest.approx(2.5e8 * 2)
    assert m.linear_mesh_compliance == pytest.approx(1 / cw + 1 / cg)
    assert m.output_per_input == pytest.approx(0.001 / 0.056, rel=1e-7)
    assert m.rigid_motion == pytest.approx([1.0, 0.001 / 0.056, 0.001 / 0.056], rel=1e-7)
    assert not m.mesh_is_linear and DriveModel(cfg.replace(
        {'mesh.stiffness_model': 'linear'})).mesh_is_linear
    assert m.friction_is_set_valued
    for other in ({'friction.direction': 'regularized'}, {'friction.model': 'off'}):
        assert not DriveModel(Config().replace(other)).friction_is_set_valued
    # x0: the cosine mapping x = x0 + 180 (1 - cos s) deg gives cycle means c_w k_w, c_g k_g
    x0w, x0g = DriveModel(Config()).contact_origins_deg
    s = np.linspace(0.0, 2 * math.pi, 20001)[:-1]
    x = 180.0 * (1 - np.cos(s))
    for x0, a, b, mean in ((x0w, 19.38843319, 0.000656069, 3.5e8),
                           (x0g, 19.64527077, -0.00055956, 2.5e8)):
        k = 2.0 * math.exp(a) * (np.exp(b * (x0 + x)) + np.exp(b * (x0 + x + 360)))
        assert k.mean() == pytest.approx(mean, rel=1e-9)


def test_tooth_stiffness_scales_with_module():
    """M multiplies Eqs. 16-17; the calibration refers to the paper's M2."""
    phases = np.linspace(0, 2 * math.pi, 2001)[:-1]
    for module in (1.0, 2.0, 5.0):
        p = pack_parameters(Config().replace({'geometry.module': module}))
        k = np.array([tooth_stiffness(p, 2 * ph, 0.0)[:2] for ph in phases])
        assert k[:, 0].mean() == pytest.approx(3.5e8 * module / 2, rel=0.01)
        assert k[:, 1].mean() == pytest.approx(2.5e8 * module / 2, rel=0.01)


@pytest.mark.parametrize('direction', ['set_valued', 'regularized'])
def test_friction_coefficient_eq18_in_si(direction):
    p = pack_parameters(Config().replace({'friction.direction': direction}))
    # mu from the friction force of a loaded, sliding mesh: mu_eff = W_f / W_n
    for v_s, expected in ((1e-2, 0.0470713 + 0.1056549 * math.exp(-math.sqrt(1e-2 / 0.07454))),
                          (1.0, 0.0470713 + 0.1056549 * math.exp(-math.sqrt(1.0 / 0.07454)))):
        w2 = v_s / (p[P_RW] * math.cos(math.asin(p[P_SINL])))
        u = np.array([1e-4, 0.0, 0.0])
        _, _, _, aux = forces(p, u, np.array([w2, 0.0, 0.0]), 1e-4)
        if direction == 'regularized':
            assert aux['mu'] == pytest.approx(expected * math.tanh(v_s / 1e-4), rel=1e-9)
        else:       # slip branch; the cusp rounding (v_c = 1e-7 m/s) moves mu by ~1e-6 here
            assert aux['mu'] == pytest.approx(expected, rel=1e-5)
            _, _, _, back = forces(p, u, np.array([-w2, 0.0, 0.0]), 1e-4)
            assert back['mu'] == pytest.approx(-expected, rel=1e-5)      # opposes sliding
    assert 0.152 < 0.0470713 + 0.1056549 < 0.154          # mu(0) = 0.153, Eq. 18


@pytest.mark.parametrize('name', ['default', 'linear', 'no_compliance_friction'])
def test_friction_always_dissipates(name):
    """Power of the mesh forces minus the conservative part = -W_f v_s <= 0."""
    p = pack_parameters(Config().replace(VARIANTS[name]))
    rng = np.random.default_rng(3)
    lw, rg, rw = p[P_LW], p[P_RG], p[P_RW]
    for _ in range(500):
        u = np.array([0.0, 0.0, 0.0]) + rng.normal(0, [1e-5, 1e-6, 1e-6])
        v = rng.normal(0, [1.0, 0.02, 0.02])
        _, _, _, a = forces(p, u, v, u[0])
        mesh_power = -a['F_X'] * rw * v[0] + a['F_Y'] * rg * v[1]
        qdot = lw * v[0] - rg * v[1]
        normal_power = -(a['W_n'] * math.cos(Config().geometry.pressure_angle)
                         * math.cos(math.asin(p[P_SINL]))) * qdot
        friction_power = mesh_power - normal_power
        assert friction_power <= 1e-12 * (abs(mesh_power) + 1e-12)
        assert friction_power == pytest.approx(-a['mu'] * a['W_n'] * a['v_s'], rel=1e-9,
                                               abs=1e-15)


def test_paper_direction_can_feed_energy():
    """The paper's fixed sign does positive work when the sliding reverses."""
    p = pack_parameters(Config().replace(VARIANTS['paper_friction']))
    u = np.array([1e-4, 0.0, 0.0])
    _, _, _, a = forces(p, u, np.array([-1.0, 0.0, 0.0]), 1e-4)
    assert -a['mu'] * a['W_n'] * a['v_s'] > 0


def test_modes_match_independent_reference():
    """docs/model-notes.md: 94.5, 1561, 8588 Hz (frictionless, linear mesh, motor end held),
    confirmed by an independent torsional FE package."""
    cfg = Config().replace({'mesh.stiffness_model': 'linear', 'friction.model': 'off'})
    m = modes(cfg)
    assert m.undamped_hz == pytest.approx([94.5, 1561.0, 8588.0], rel=2e-3)
    assert np.allclose(m.damping_ratios, 0, atol=1e-9)
    # mode shapes: 1 is the flywheel on the gear shaft, 3 is the worm on its shaft
    assert abs(m.shapes[2, 0]) == 1.0 and abs(m.shapes[0, 2]) == 1.0
    K = linear_stiffness(pack_parameters(cfg))
    assert np.allclose(K, K.T)
    # shaft inertia lumped on the worm moves the top mode (docs/model-notes.md: to ~3.6 kHz)
    m2 = modes(cfg.replace({'shafts.worm_shaft_inertia_fraction': 1 / 3}))
    assert 3000 < m2.undamped_hz[2] < 4000


def test_modal_damping_ratios_are_realised():
    cfg = Config().replace({'mesh.stiffness_model': 'linear', 'friction.model': 'off',
                            'damping.modal_damping_ratios': [0.02, 0.05, 0.1]})
    m = modes(cfg)
    assert m.damping_ratios == pytest.approx([0.02, 0.05, 0.1], rel=1e-6)


def test_overdamped_mode_keeps_the_table_aligned():
    """Under load the friction at rest (tanh law: viscous of slope mu/v_eps) over-damps the
    worm mode: it is reported in its own row (damped frequency 0, zeta > 1), the other rows
    keep their frequencies."""
    m = modes(Config().replace({'load.output_torque': 5.0,
                                'friction.direction': 'regularized'}))
    assert m.undamped_hz == pytest.approx([94.5, 1555.0, 8588.0], rel=5e-3)
    assert m.frequencies_hz[0] == pytest.approx(94.5, rel=5e-3)
    assert m.frequencies_hz[1] == pytest.approx(1566.0, rel=5e-3)
    assert m.frequencies_hz[2] == 0.0 and m.damping_ratios[2] > 1.0


def _rigid_end_frequencies(cfg: Config) -> np.ndarray:
    """Independent 2-DOF reference for the drive without flywheel: the massless gear shaft
    ends free (assumption 8), so it carries no torque; worm on K_w, gear on the mesh only.
    Written from the parameters (Eqs. 7-10 frictionless), not from modal.py."""
    from worm_gear_sim.dynamics.derived import derive
    d = derive(cfg)
    g, m = cfg.geometry, cfg.mesh
    sl, cl, cphi = math.sin(d.lead_angle), math.cos(d.lead_angle), math.cos(g.pressure_angle)
    kgws = (1 / m.worm_tooth_stiffness_linear + 1 / m.gear_tooth_stiffness_linear
            + cphi * sl * sl / d.k_gs + cphi * cl * cl / d.k_ws)
    kY = cphi * cl * cl / kgws
    lw, rg = d.l_w, g.gear_pitch_radius
    K = np.array([[d.K_w + lw * lw * kY, -lw * rg * kY], [-lw * rg * kY, rg * rg * kY]])
    Minv_sqrt = np.diag([d.J_w ** -0.5, d.J_g ** -0.5])
    return np.sqrt(np.linalg.eigvalsh(Minv_sqrt @ K @ Minv_sqrt)) / (2 * math.pi)


@pytest.mark.parametrize('mesh_model', ['linear', 'nonlinear'])
def test_no_flywheel_is_the_rigid_free_end(mesh_model):
    """flywheel_enabled false = assumption 8: no extra degree of freedom (no 2.43 kHz mode of
    a lumped shaft-end inertia), the gear mode at the rigid-end value (1466 Hz)."""
    cfg = Config().replace({'geometry.flywheel_enabled': False,
                            'mesh.stiffness_model': mesh_model, 'friction.model': 'off'})
    ref = _rigid_end_frequencies(cfg)
    assert ref[0] == pytest.approx(1466, rel=1e-3)
    m = modes(cfg)
    assert len(m.undamped_hz) == 2                          # no spurious third mode
    assert m.undamped_hz == pytest.approx(ref, rel=2e-3)
    # theta4 follows theta3 in the shapes (rigid end)
    assert np.allclose(m.shapes[2], m.shapes[1], atol=1e-12)


def test_no_flywheel_end_inertia_is_explicit():
    """A documented end inertia brings the third degree of freedom back on request."""
    cfg = Config().replace({'geometry.flywheel_enabled': False, 'mesh.stiffness_model': 'linear',
                            'friction.model': 'off'})
    assert len(modes(cfg.replace({'geometry.shaft_end_inertia': 1e-4})).undamped_hz) == 3
    # the end inertia only counts without the flywheel
    a = modes(Config().replace({'geometry.shaft_end_inertia': 1e-4})).undamped_hz
    assert a == pytest.approx(modes(Config()).undamped_hz, rel=1e-12)


def test_no_flywheel_theta4_follows_theta3_under_load():
    """Without flywheel theta4 is the free shaft end: theta4 = theta3 - T_load/K_g at every
    step of a move (the massless shaft transmits the load torque, no dynamics of its own)."""
    from worm_gear_sim import simulate
    from worm_gear_sim.dynamics.derived import derive
    for T in (0.0, 2.0):
        cfg = Config().replace({'geometry.flywheel_enabled': False, 'load.output_torque': T})
        tr = simulate(cfg, t_end=0.03)
        K_g = derive(cfg).K_g
        assert np.all(np.isfinite(tr.theta)) and tr.stats['failed_steps'] == 0
        assert np.abs(tr.theta4 - (tr.theta3 - T / K_g)).max() <= 1e-12 * np.abs(
            tr.theta3).max() + 1e-15


@pytest.mark.parametrize('mapping, jump_w, jump_g', [('cosine', 0.0, 0.0),
                                                     ('sawtooth', 0.266, -0.183)])
def test_tooth_hand_over(mapping, jump_w, jump_g):
    """The sawtooth contact mapping jumps by e^{360 b} - 1 at each hand-over (27 % worm,
    18 % gear); the default cosine mapping is continuous (steps between neighbouring
    phases shrink with the spacing) and spans the same fitted range."""
    p = pack_parameters(Config().replace({'mesh.contact_mapping': mapping,
                                          'mesh.phase_offset': 0.0}))
    n = 100000
    ph = np.linspace(0, 4 * math.pi, 2 * n + 1)          # two cycles, theta2 = 2 phase
    k = np.array([tooth_stiffness(p, 2 * x, 0.0)[:2] for x in ph])
    rel = np.diff(k, axis=0) / k[:-1]
    big = np.abs(rel).max(axis=0)
    if jump_w == 0.0:
        assert np.all(big < 20 * 2 * math.pi / n * 0.24)   # smooth: |dk/k| <= 0.24 per rad
    else:
        i = np.argmax(np.abs(rel[:, 0]))
        assert rel[i, 0] == pytest.approx(math.exp(-360 * 0.000656069) - 1, rel=1e-3)
        assert rel[i, 1] == pytest.approx(math.exp(360 * 0.00055956) - 1, rel=1e-3)
        assert abs(math.exp(360 * 0.000656069) - 1 - jump_w) < 2e-3
        assert abs(math.exp(-360 * 0.00055956) - 1 - jump_g) < 2e-3
    assert k[:, 0].max() / k[:, 0].min() == pytest.approx(math.exp(360 * 0.000656069),
                                                          rel=1e-3)


def test_default_phase_starts_at_the_mean_mesh_stiffness():
    """At theta = 0 the default phase offset puts the mesh stiffness k_Y (teeth in series
    with the bearings, what the dynamics see) at its cycle mean."""
    from worm_gear_sim.dynamics.equations import mesh_stiffness_y
    p = pack_parameters(Config())
    ph = np.linspace(0, 2 * math.pi, 20001)[:-1]
    kY = np.array([mesh_stiffness_y(p, 2 * x, 0.0) for x in ph])
    assert mesh_stiffness_y(p, 0.0, 0.0) == pytest.approx(kY.mean(), rel=1e-5)
    assert kY.max() / kY.min() > 1.005                      # it does vary over the cycle
