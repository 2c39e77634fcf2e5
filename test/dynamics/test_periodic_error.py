# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The periodic transmission error e(theta2, theta3) in the mesh approach
q = l_w theta2 - r_g theta3 + r_g e: empty harmonics change nothing, the keys are validated,
the kinematics follow e analytically, and the Newmark result agrees with an independent Radau
solution of the equations written out here (not the kernel's)."""

import math
from dataclasses import dataclass

import numpy as np
import pytest
from methods import METHODS, method_overrides
from scipy.integrate import solve_ivp

from worm_gear_sim import Config, make_profile, simulate
from worm_gear_sim.dynamics.equations import forces, mesh_approach, transmission_error
from worm_gear_sim.dynamics.modal import static_equilibrium
from worm_gear_sim.dynamics.model import DriveModel, pack_parameters
from worm_gear_sim.dynamics.profiles import Profile
from worm_gear_sim.dynamics.simulation import Simulator
from worm_gear_sim.schema.validation import ConfigError

WORM = [2e-5, -1e-5, 0.0, 8e-6, 5e-6, 3e-6]          # orders 1-3 [rad at the gear]
GEAR = [1.5e-5, 1e-5]                                 # order 1


def error_of(worm, gear, th2, th3):
    """e(theta2, theta3) written out from the definition (numpy, not the kernel)."""
    th2, th3 = np.asarray(th2, float), np.asarray(th3, float)
    e = np.zeros(np.broadcast(th2, th3).shape)
    for k in range(len(worm) // 2):
        e = e + worm[2 * k] * np.sin((k + 1) * th2) + worm[2 * k + 1] * np.cos((k + 1) * th2)
    for m in range(len(gear) // 2):
        e = e + gear[2 * m] * np.sin((m + 1) * th3) + gear[2 * m + 1] * np.cos((m + 1) * th3)
    return e


def test_empty_harmonics_change_nothing():
    """[] and explicit zeros: the same packed model but the harmonic count, and the same
    trajectory to the last bit (an exact 0.0 contribution, forces and Jacobian factors 1)."""
    base = Config()
    zeros = base.replace(**{'mesh.worm_error_harmonics': [0.0] * 6,
                            'mesh.gear_error_harmonics': [0.0, 0.0]})
    pb, pz = pack_parameters(base), pack_parameters(zeros)
    assert pb.shape == pz.shape
    assert np.count_nonzero(pb != pz) == 2      # the two order counts, nothing else
    assert mesh_approach(pb, 0.3, 0.004) == mesh_approach(pz, 0.3, 0.004)
    tb = simulate(base, t_end=0.006)
    tz = simulate(zeros, t_end=0.006)
    assert np.array_equal(tb.theta, tz.theta) and np.array_equal(tb.omega, tz.omega)


@pytest.mark.parametrize('key,value,words', [
    ('mesh.worm_error_harmonics', [1e-5, 2e-5, 3e-5], 'odd'),
    ('mesh.gear_error_harmonics', [1e-6] * 18, 'at most 8 orders'),
    ('mesh.worm_error_harmonics', [float('nan'), 0.0], 'finite'),
    ('mesh.gear_error_harmonics', [2e-3, 0.0], '<= 0.001'),
    ('mesh.worm_error_harmonics', [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 9e-4, 9e-4], 'too steep'),
    ('mesh.worm_error_harmonics', 'abc', 'list'),
])
def test_harmonics_are_validated(key, value, words):
    with pytest.raises(ConfigError) as exc:
        Config().replace(**{key: value})
    assert exc.value.key.startswith(key) and words in str(exc.value), str(exc.value)


def test_kernel_error_matches_its_definition():
    p = pack_parameters(Config().replace(**{'mesh.worm_error_harmonics': WORM,
                                            'mesh.gear_error_harmonics': GEAR}))
    rng = np.random.default_rng(3)
    for th2, th3 in rng.uniform(-300, 300, (20, 2)):
        e, e2, e3, e22, e33 = transmission_error(p, th2, th3)
        h = 1e-5
        assert e == pytest.approx(error_of(WORM, GEAR, th2, th3), abs=1e-18)
        for d, d2, f in ((e2, e22, lambda x, a=th2, b=th3: error_of(WORM, GEAR, a + x, b)),
                         (e3, e33, lambda x, a=th2, b=th3: error_of(WORM, GEAR, a, b + x))):
            assert d == pytest.approx((f(h) - f(-h)) / (2 * h), rel=1e-6, abs=1e-14)
            assert d2 == pytest.approx((f(h) - 2 * f(0) + f(-h)) / h ** 2, rel=1e-3,
                                       abs=1e-9)


@dataclass(frozen=True)
class ConstantRate(Profile):
    rate: float

    def theta1(self, t):
        return self.rate * np.asarray(t, float)

    def theta1_dot(self, t):
        return np.full_like(np.asarray(t, float), self.rate)


def test_kinematics_follow_the_error():
    """Friction off, no load, linear mesh, the worm at a slow constant rate (one revolution
    per second: order 3 at 3 Hz, far below the 94.5 Hz antenna mode): the mesh carries next
    to no force, q = 0, so r_g theta3 = l_w theta2 + r_g e, theta4 = theta3 and theta2 =
    theta1: theta4 - theta1 l_w / r_g = +e(theta2, theta3) within 1 % of its amplitude."""
    cfg = Config().replace(**{'friction.model': 'off', 'mesh.stiffness_model': 'linear',
                              'mesh.worm_error_harmonics': WORM,
                              'mesh.gear_error_harmonics': GEAR})
    m = DriveModel(cfg)
    lw, rg = m.derived.l_w, cfg.geometry.gear_pitch_radius
    w = 2.0 * math.pi
    sim = Simulator(m)
    u = sim.state.theta
    assert mesh_approach(m.p, u[0], u[1]) == pytest.approx(0.0, abs=1e-16)   # rest: q = 0
    _, e2, e3, _, _ = transmission_error(m.p, u[0], u[1])
    w3 = w * (lw + rg * e2) / (rg * (1.0 - e3))           # start on the path (q' = 0)
    sim.reset(0.0, theta=u, omega=[w, w3, w3])
    tr = sim.run(ConstantRate(w), 1.0, record_every=250)
    e = error_of(WORM, GEAR, tr.theta2, tr.theta3)
    amplitude = 0.5 * (e.max() - e.min())
    assert amplitude > 2e-5
    dev = np.abs(tr.theta4 - tr.theta1 * lw / rg - e).max()
    assert dev <= 0.01 * amplitude, dev / amplitude


def test_rest_with_play_keeps_the_flank():
    """Without a load a drive with play rests with q on the flank's edge, e included."""
    for flank, sign in (('drive', 1.0), ('coast', -1.0), ('center', 0.0)):
        cfg = Config().replace(**{'mesh.backlash': 5.8e-4, 'mesh.initial_flank': flank,
                                  'mesh.worm_error_harmonics': WORM,
                                  'mesh.gear_error_harmonics': GEAR})
        p = pack_parameters(cfg)
        u = static_equilibrium(p, 0.7)
        h = 0.5 * cfg.geometry.gear_pitch_radius * cfg.mesh.backlash
        assert mesh_approach(p, u[0], u[1]) == pytest.approx(sign * h, abs=1e-15)



# a drawn drive that Config.replace refused as "not computable" (LinAlgError: singular):
# play 2.8', a load of 1.7 mN m, no drag, worm and gear harmonics of ~25 urad
LIGHT_WORM = [-2.374712720158434e-05, 2.7684335734145273e-05, 3.10860054659768e-06,
              1.4861404720791301e-05, -3.7457882161965165e-06, 2.5873719477458386e-05]
LIGHT_GEAR = [1.860234850691995e-05, -2.5516682588879443e-05]


@pytest.mark.parametrize('load', [0.0017379841870615548, -0.0017379841870615548, 1e-4, 2e-6,
                                  0.5])
@pytest.mark.parametrize('theta1', [0.0, 0.7, -2.3])
def test_a_light_load_with_play_and_gear_error_rests_on_its_flank(load, theta1):
    """Under a load the rest is the drive without play shifted onto the loaded flank; the
    gear error moves with the shifted gear, and under a load of a few mN m its change put the
    start back inside the clearance (zero mesh stiffness: a singular Newton matrix, the set
    refused). The rest is now a root of Q on the loaded flank, q beyond the half clearance
    by the deflection under that load (the force balance: the mesh carries the load)."""
    cfg = Config().replace(**{'mesh.backlash': 0.0008209763031268989,
                              'load.output_torque': load,
                              'load.output_viscous_coefficient': 0.0,
                              'mesh.worm_error_harmonics': LIGHT_WORM,
                              'mesh.gear_error_harmonics': LIGHT_GEAR})
    m = DriveModel(cfg)
    u = static_equilibrium(m, theta1)
    Q, dQdu, _, _ = forces(m.p, u, np.zeros(3), theta1)
    floor = 64 * np.finfo(float).eps * (np.abs(dQdu) @ np.abs(u))   # the terms' round-off
    assert np.all(np.abs(Q) <= floor), (Q, floor)
    h = 0.5 * cfg.geometry.gear_pitch_radius * cfg.mesh.backlash
    q = mesh_approach(m.p, u[0], u[1])
    flank = math.copysign(1.0, load)
    assert flank * q > h                          # in contact on the loaded flank
    assert np.linalg.cond(dQdu) < 1e14            # not in the clearance

# ---- an independent Radau solution of the same equations, written out ----------------------
def _written_out_rhs(cfg: Config, prof):
    """Eqs. 8-13 with the periodic error from docs/model-notes.md, in numpy: linear mesh,
    constant friction with tanh direction, friction outside KGWS; the normal force acts
    through dq/dtheta (torque factors g2 = (dq/dth2)/l_w, g3 = -(dq/dth3)/r_g), friction
    along the thread with v_s = r_w cos(lam) th2' + r_g sin(lam) th3'."""
    m = DriveModel(cfg)
    d, g = m.derived, cfg.geometry
    lw, rw, rg = d.l_w, g.worm_pitch_radius, g.gear_pitch_radius
    lam, phi = d.lead_angle, g.pressure_angle
    sl, cl, cphi = math.sin(lam), math.cos(lam), math.cos(phi)
    cwkw, cgkg = m.linear_tooth_stiffness
    kgws = 1.0 / cwkw + 1.0 / cgkg + cphi * sl * sl / d.k_gs + cphi * cl * cl / d.k_ws
    mu0, veps = cfg.friction.constant_coefficient, cfg.friction.regularization_velocity
    worm, gear = cfg.mesh.worm_error_harmonics, cfg.mesh.gear_error_harmonics
    J = np.array([d.J_w, d.J_g, d.J_4])

    wk = [(k + 1, worm[2 * k], worm[2 * k + 1]) for k in range(len(worm) // 2)]
    gk = [(k + 1, gear[2 * k], gear[2 * k + 1]) for k in range(len(gear) // 2)]

    def rhs(t, y):
        th2, th3, th4, w2, w3, w4 = y
        e = e2 = e3 = 0.0
        for k, s, c in wk:
            e += s * math.sin(k * th2) + c * math.cos(k * th2)
            e2 += k * (s * math.cos(k * th2) - c * math.sin(k * th2))
        for k, s, c in gk:
            e += s * math.sin(k * th3) + c * math.cos(k * th3)
            e3 += k * (s * math.cos(k * th3) - c * math.sin(k * th3))
        q = lw * th2 - rg * th3 + rg * e
        g2, g3 = (lw + rg * e2) / lw, 1.0 - e3
        v_s = rw * cl * w2 + rg * sl * w3
        mu = mu0 * math.tanh(v_s / veps) * (1.0 if q >= 0 else -1.0)
        Wn = q * cl / kgws
        th1 = float(prof.theta1(np.array([t]))[0])
        Q2 = -rw * (cphi * sl * g2 + mu * cl) * Wn - d.K_w * (th2 - th1)
        Q3 = rg * (cphi * cl * g3 - mu * sl) * Wn - d.K_g * (th3 - th4)
        Q4 = -d.K_g * (th4 - th3)
        return np.array([w2, w3, w4, Q2 / J[0], Q3 / J[1], Q4 / J[2]])
    return rhs


_RADAU: dict[bytes, np.ndarray] = {}


@pytest.mark.parametrize('method', METHODS)
def test_against_written_out_radau(method):
    """A 3 rad worm slew in 20 ms (the harmonics pass at up to 45 Hz... 140 Hz, through the
    94.5 Hz antenna mode): Newmark (dt = 0.5 us; the variable step at 1e-12 / 1e-11 rad per
    step) and Radau (rtol 1e-6) on the written-out equations agree on theta4 - theta1 l_w /
    r_g to 1 % of the error's own contribution (with minus without harmonics; measured
    2.4e-4 of it, 2.3e-6 at dt = 50 ns and rtol 1e-9)."""
    base = {'mesh.stiffness_model': 'linear', 'friction.model': 'constant',
            'friction.direction': 'regularized', 'integrator.time_step': 5e-7,
            'integrator.worm_frequency_matching': False,
            'input.target_angle': 3.0, 'input.move_time': 0.02, 'input.accel_time': 0.004,
            **method_overrides(method, 1e-12, 1e-11)}
    pe = {'mesh.worm_error_harmonics': [6e-5, -3e-5, 2e-5, 2e-5, -1e-5, 1e-5],
          'mesh.gear_error_harmonics': [4e-5, 3e-5]}
    t_end, stride = 0.024, 2000
    runs = {}
    for name, over in (('with', pe), ('without', {})):
        cfg = Config().replace(**base, **over)
        tr = simulate(cfg, t_end=t_end, record_every=stride)
        runs[name] = tr.theta4 - tr.theta1 * tr.output_per_input
        if name == 'with':
            times, ref_cfg, th1, ratio = tr.t, cfg, tr.theta1, tr.output_per_input
    if times.tobytes() not in _RADAU:   # Radau's equations do not depend on the method
        _RADAU[times.tobytes()] = _written_out_radau(ref_cfg, times, t_end)
    radau = _RADAU[times.tobytes()][:, 2] - th1 * ratio
    contribution = np.abs(runs['with'] - runs['without']).max()
    assert contribution > 2e-5
    dev = np.abs(runs['with'] - radau).max()
    assert dev <= 0.01 * contribution, dev / contribution


def _written_out_radau(ref_cfg: Config, times: np.ndarray, t_end: float) -> np.ndarray:
    """Radau (rtol 1e-6) on :func:`_written_out_rhs` from rest, between the command's kinks,
    at ``times``."""
    prof = make_profile(ref_cfg.input)
    y = np.r_[Simulator(ref_cfg).state.theta, 0.0, 0.0, 0.0]
    ref = np.empty((len(times), 3))
    for a, b in zip((0.0, 0.004, 0.016, 0.020), (0.004, 0.016, 0.020, t_end)):
        sol = solve_ivp(_written_out_rhs(ref_cfg, prof), (a, b), y, method='Radau',
                        rtol=1e-6, atol=np.r_[np.full(3, 1e-12), np.full(3, 1e-9)],
                        dense_output=True)
        assert sol.success, sol.message
        sel = (times >= a) & (times <= b)
        ref[sel] = sol.sol(times[sel])[:3].T
        y = sol.y[:, -1]
    return ref
