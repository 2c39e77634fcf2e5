# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The mesh clearance ``mesh.backlash``: without play the trajectories are the golden ones
of the kernel without play, within a rounding tolerance; with play the lost motion of a
slow reversal is the play, no contact event gains energy, halving the step converges, and
the result agrees with an independent event-driven Radau solution of the same equations
written here."""

from pathlib import Path

import numpy as np
import pytest
from methods import METHODS, method_overrides
from scalar_command import piecewise_quadratic
from scipy.integrate import solve_ivp

from worm_gear_sim import Config, SampledProfile, simulate
from worm_gear_sim.dynamics.derived import derive
from worm_gear_sim.dynamics.layout import P_CGKG_LIN, P_CWKW_LIN
from worm_gear_sim.dynamics.load import LoadSignal
from worm_gear_sim.dynamics.model import DriveModel, pack_parameters
from worm_gear_sim.schema.validation import ConfigError

ARCMIN = np.pi / (180 * 60)
DATA = Path(__file__).resolve().parents[1] / 'data'


#: Rounding sensitivity of these records, measured: the slew with its command scaled by
#: 1 + 1e-15 differs by up to 3e-11 (set-valued) and 3.4e-8 (regularized friction, steep
#: at zero slip) of each column's largest value.  Records written on another CPU (numba
#: compiles for the host) may differ by as much; the golden comparison allows 30x that.
NO_PLAY_RTOL = 1e-6


def test_zero_play_reproduces_the_trajectories_before_play():
    """mesh.backlash = 0 (the default): the paper's move and a slew with reversals under
    load, set-valued and regularized friction, equal the golden trajectories of the kernel
    without play (test/data/make_no_play_golden.py: when they were written) within
    NO_PLAY_RTOL of each column's largest value (the file was written on another CPU); and
    in one run the resting flank, which only matters with play, changes nothing, bit for
    bit (the play logic is inert at b = 0)."""
    gold = np.load(DATA / 'no_play_golden.npz')

    def close(tr, ref):
        got = np.column_stack([tr.theta, tr.omega])
        assert got.shape == ref.shape
        err = np.abs(got - ref).max(axis=0) / np.abs(ref).max(axis=0)
        assert err.max() <= NO_PLAY_RTOL, err
        return got

    for fric in ('set_valued', 'regularized'):
        cfg = Config().replace({'friction.direction': fric})
        assert cfg.mesh.backlash == 0.0
        base = close(simulate(cfg, t_end=0.03, record_every=25), gold[f'paper_{fric}'])
        t = np.array([0.0, 0.01, 0.02, 0.03, 0.04])
        th = np.array([0.0, 0.02, -0.01, 0.015, 0.015])
        c2 = cfg.replace({'load.output_torque': 1.5})
        close(simulate(c2, profile=SampledProfile(t, th, 'linear'), t_end=0.04,
                       record_every=25), gold[f'slew_{fric}'])
        for flank in ('coast', 'center'):
            tr = simulate(cfg.replace({'mesh.initial_flank': flank}), t_end=0.03,
                          record_every=25)
            assert np.array_equal(np.column_stack([tr.theta, tr.omega]), base), flank


@pytest.mark.parametrize('fric', ['set_valued', 'regularized'])
@pytest.mark.parametrize('arcmin', [0.5, 2.0, 5.0])
def test_lost_motion_of_a_slow_reversal_is_the_play(fric, arcmin):
    """The worm turns the gear forward at 1e-3 rad/s, then back, without load: the lag of
    the gear behind the rigid motion changes by the play at the reversal, within 2 %
    (a small viscous drag on the antenna stops the gear inside the play; without it the
    free gear rattles between the flanks)."""
    b = arcmin * ARCMIN
    cfg = Config().replace({'mesh.backlash': b, 'friction.direction': fric,
                            'load.output_torque': 0.0, 'load.output_viscous_coefficient': 2.0})
    opi = DriveModel(cfg).output_per_input
    w = 1e-3 / opi                                     # worm rate: gear at 1e-3 rad/s
    T = 3.0
    tr = simulate(cfg, profile=SampledProfile(np.array([0.0, T, 2 * T]),
                                              np.array([0.0, w * T, 0.0]), 'linear'),
                  t_end=2 * T, record_every=100)
    lag = tr.theta1 * opi - tr.theta[:, 1]
    fwd, back = lag[np.searchsorted(tr.t, 2.5)], lag[np.searchsorted(tr.t, 5.5)]
    assert tr.stats['failed_steps'] == 0
    assert abs((fwd - back) / b - 1.0) <= 0.02, (fwd - back) / b


def _rattle(dt: float, play: float = 2 * ARCMIN):
    """Linear mesh, no friction, no damping, no drag: a fast 0.3 rad move, then the
    command held while the gear rattles in the play (hundreds of contact events)."""
    cfg = Config().replace({'mesh.backlash': play, 'mesh.stiffness_model': 'linear',
                            'friction.model': 'off', 'load.output_torque': 0.0,
                            'load.output_viscous_coefficient': 0.0,
                            'integrator.time_step': dt, 'mesh.initial_flank': 'center',
                            'integrator.worm_frequency_matching': False})
    t = np.array([0.0, 0.005, 0.2])
    th = np.array([0.0, 0.3, 0.3])
    return cfg, simulate(cfg, profile=SampledProfile(t, th, 'linear'), t_end=0.2)


@pytest.mark.parametrize('dt', [4e-6, 2e-6])
def test_no_contact_event_gains_energy(dt):
    """With the command held, the drive is conservative: through hundreds of contact losses and
    impacts its energy never rises above its value at the hold by more than 1e-6 of it
    (measured 1.3e-7 at 4 us; without the split at the contact instant the trapezoidal
    rule gained 1.7e-4)."""
    cfg, tr = _rattle(dt)
    E = tr.energy(cfg)
    i0 = int(np.searchsorted(tr.t, 0.0051))
    assert tr.stats['contact_events'] >= 150 and tr.stats['failed_steps'] == 0
    gain = float(np.max(E[i0:] - E[i0])) / E[i0]
    assert gain <= 1e-6, gain


def test_halving_the_step_converges():
    """A reversal move with impacts at 4, 2 and 1 us: the antenna angle's error against
    the 0.5 us run falls as the step halves (second order away from the events)."""
    b = 2 * ARCMIN
    cfg0 = Config().replace({'mesh.backlash': b, 'load.output_torque': 0.0,
                             'load.output_viscous_coefficient': 0.5})
    prof = SampledProfile(np.array([0.0, 0.01, 0.02, 0.03]),
                          np.array([0.0, 0.2, -0.1, -0.1]), 'linear')

    def antenna(dt):
        tr = simulate(cfg0.replace({'integrator.time_step': dt}), profile=prof,
                      t_end=0.03, record_every=int(round(4e-6 / dt)))
        return tr.theta[:, 2]

    ref = antenna(5e-7)
    errs = [np.max(np.abs(antenna(dt) - ref)) for dt in (4e-6, 2e-6, 1e-6)]
    scale = np.ptp(ref)
    assert errs[0] > errs[1] > errs[2], errs
    assert errs[2] <= 1e-3 * scale, (errs, scale)


#: The variable step's tolerances where these checks run the fixed step at 0.5 us.
PLAY_TOL = (1e-12, 1e-11)


def _radau_play_config(b: float, method: str = 'fixed') -> Config:
    """The drive the event-driven Radau checks use: linear mesh, no friction, play ``b``,
    centred at the start, a little antenna drag, 0.5 us steps (``method``: the variable
    step at PLAY_TOL instead)."""
    return Config().replace({'mesh.backlash': b, 'mesh.stiffness_model': 'linear',
                             'friction.model': 'off', 'load.output_torque': 0.0,
                             'load.output_viscous_coefficient': 0.5,
                             'mesh.initial_flank': 'center', 'integrator.time_step': 5e-7,
                             'integrator.worm_frequency_matching': False,
                             **method_overrides(method, *PLAY_TOL)})


def _radau_with_play(cfg: Config, prof: SampledProfile, breaks, times, load=None,
                     damping=None):
    """The drive with play written out here (linear mesh, no friction), integrated by Radau
    from contact event to contact event (events at q = +-r_g b / 2) and between the kinks
    of the command (and of ``load``, a load torque signal in place of the constant).
    ``damping``: (C in contact, C inside the play), acting on the velocities relative to
    the rigid motion of theta1."""
    d = derive(cfg)
    p = pack_parameters(cfg)
    g = cfg.geometry
    lw, rw, rg = d.l_w, g.worm_pitch_radius, g.gear_pitch_radius
    sl, cl = np.sin(d.lead_angle), np.cos(d.lead_angle)
    cphi = np.cos(g.pressure_angle)
    kgws = 1 / p[P_CWKW_LIN] + 1 / p[P_CGKG_LIN] + cphi * sl * sl / d.k_gs \
        + cphi * cl * cl / d.k_ws
    h = 0.5 * rg * cfg.mesh.backlash
    M = np.array([d.J_w, d.J_g, d.J_4])
    cout, T = cfg.load.output_viscous_coefficient, cfg.load.output_torque

    rigid = np.array([1.0, lw / rg, lw / rg])
    leg = {'open': False}          # the damping of a leg: fixed from its start (below)
    theta1 = piecewise_quadratic(prof.theta1, breaks)
    theta1_dot = piecewise_quadratic(prof.theta1_dot, breaks)

    def rhs(t, y):
        th1 = theta1(t)
        q = lw * y[0] - rg * y[1]
        pen = q - h if q > h else q + h if q < -h else 0.0
        wn = pen * cl / kgws
        Q2 = -rw * cphi * sl * wn - d.K_w * (y[0] - th1)
        Q3 = rg * cphi * cl * wn - d.K_g * (y[1] - y[2])
        Q4 = -d.K_g * (y[2] - y[1]) - cout * y[5] - \
            (T if load is None else float(load.torque(np.array([t]))[0]))
        Q = np.array([Q2, Q3, Q4])
        if damping is not None:
            C = damping[1] if leg['open'] else damping[0]
            Q -= C @ (y[3:] - rigid * theta1_dot(t))
        return np.r_[y[3:], Q / M]

    def edge(sign):
        def ev(t, y):
            return lw * y[0] - rg * y[1] - sign * h
        ev.terminal = True
        return ev

    u0 = np.array([0.0, 0.0, 0.0])
    y = np.r_[u0, 0.0, 0.0, 0.0]
    out = np.empty((len(times), 3))
    # rtol 1e-8: converged for a 1 % check (measured on the move out and back: the reference
    # differs from the one at 1e-10 by 1.6e-8 of theta4's range, Newmark by 7e-6), 3x faster
    tol = dict(method='Radau', rtol=1e-8, atol=np.r_[np.full(3, 1e-14), np.full(3, 1e-11)],
               dense_output=True)
    for a, b in zip(breaks[:-1], breaks[1:]):
        t = a
        events = True
        while t < b:
            q, dq = lw * y[0] - rg * y[1], lw * y[3] - rg * y[4]
            # inside the play, or on its edge moving in (just after a contact loss)
            leg['open'] = abs(q) < h * (1 - 1e-9) or (abs(q) <= h * (1 + 1e-9) and q * dq < 0)
            if events:
                sol = solve_ivp(rhs, (t, b), y, events=(edge(1.0), edge(-1.0)), **tol)
            else:       # just after an event (on the edge): a short leg without events
                sol = solve_ivp(rhs, (t, min(b, t + 2e-8)), y, **tol)
            assert sol.status >= 0, sol.message
            t_end = sol.t[-1]
            sel = (times >= t) & (times <= t_end)
            if sel.any():
                out[sel] = sol.sol(times[sel])[:3].T
            y = sol.y[:, -1]
            events = not (events and sol.status == 1)
            t = t_end
    return out


_PLAY_REFS: dict[str, np.ndarray] = {}


def _play_reference(name: str, compute) -> np.ndarray:
    """The Radau reference of one check, computed once for both methods (the same drive,
    command and sample times: Radau's equations do not depend on the method)."""
    if name not in _PLAY_REFS:
        _PLAY_REFS[name] = compute()
    return _PLAY_REFS[name]


@pytest.mark.parametrize('method', METHODS)
def test_play_agrees_with_an_event_driven_radau_solution(method):
    """Linear mesh, friction off, 2 arcmin of play, a move out and back with the gear
    leaving one flank and striking the other: Newmark (0.5 us) against Radau with the
    contact events located, theta2 and theta4 within 1 % of their range."""
    b = 2 * ARCMIN
    cfg = _radau_play_config(b, method)
    breaks = (0.0, 0.005, 0.01, 0.015)
    prof = SampledProfile(np.array(breaks), np.array([0.0, 0.15, -0.05, -0.05]), 'linear')
    tr = simulate(cfg, profile=prof, t_end=breaks[-1], record_every=40)
    ref = _play_reference('out and back', lambda: _radau_with_play(cfg, prof, breaks, tr.t))
    for j in (0, 2):
        err = np.max(np.abs(tr.theta[:, j] - ref[:, j]))
        assert err <= 0.01 * np.ptp(ref[:, j]), (j, err, np.ptp(ref[:, j]))


@pytest.mark.parametrize('method', METHODS)
def test_structural_damping_does_not_act_across_the_open_play(method):
    """Rayleigh damping (alpha 50 /s, beta 1e-5 s) with 2 arcmin of play: while the worm
    moves inside the play the gear and the antenna stay exactly where they are (before,
    the damping matrix of the engaged mesh dragged them along); on the move out and back
    the result agrees with Radau whose damping inside the play is written out here (alpha
    on the worm against its motor end, beta on the two shafts only), theta2 and theta4
    within 1 % of their range."""
    b = 2 * ARCMIN
    cfg = _radau_play_config(b, method).replace({'damping.rayleigh_alpha': 50.0,
                                                 'damping.rayleigh_beta': 1e-5})
    d = derive(cfg)
    half = 0.5 * b * cfg.geometry.gear_pitch_radius / d.l_w     # half the play, worm angle
    inside = SampledProfile(np.array([0.0, 0.001, 0.004, 0.01]),
                            np.array([0.0, 0.0, 0.8 * half, 0.8 * half]), 'linear')
    tr = simulate(cfg, profile=inside, t_end=0.01, record_every=40)
    assert tr.theta[-1, 0] == pytest.approx(0.8 * half, rel=0.02)   # the worm moved
    assert np.max(np.abs(tr.theta[:, 1:])) < 1e-15                  # the gear did not
    from worm_gear_sim.dynamics.modal import damping_matrix
    a, beta = cfg.damping.rayleigh_alpha, cfg.damping.rayleigh_beta
    shafts = np.array([[d.K_w, 0, 0], [0, d.K_g, -d.K_g], [0, -d.K_g, d.K_g]])
    c_open = np.diag([a * d.J_w, 0.0, 0.0]) + beta * shafts
    breaks = (0.0, 0.005, 0.01, 0.015)
    prof = SampledProfile(np.array(breaks), np.array([0.0, 0.15, -0.05, -0.05]), 'linear')
    tr = simulate(cfg, profile=prof, t_end=breaks[-1], record_every=40)
    assert tr.stats['contact_events'] >= 2
    ref = _play_reference('damped', lambda: _radau_with_play(
        cfg, prof, breaks, tr.t, damping=(damping_matrix(cfg), c_open)))
    for j in (0, 2):
        err = np.max(np.abs(tr.theta[:, j] - ref[:, j]))
        assert err <= 0.01 * np.ptp(ref[:, j]), (j, err, np.ptp(ref[:, j]))


class _SineLoad(LoadSignal):
    """A smooth reversing load torque A sin(2 pi f t) (a LoadSignal of the caller's own)."""

    def __init__(self, amplitude: float, freq: float) -> None:
        self.amplitude, self.freq = amplitude, freq

    def torque(self, t):
        return self.amplitude * np.sin(2 * np.pi * self.freq * np.asarray(t, float))


@pytest.mark.parametrize('method', METHODS)
def test_play_under_a_reversing_load_agrees_with_an_event_driven_radau_solution(method):
    """The worm held still, 2 arcmin of play, a load torque reversing at 20 Hz (+-8 N m):
    the antenna is thrown from flank to flank through the play by the load alone (the gear
    rattles: ~19 contact events).  Newmark (0.5 us) against Radau with the contact events
    located: theta2, theta3, theta4 within 1 % of their range (measured: 0.3 %, 2e-5,
    3e-6; theta2 is the worm's 1e-5 rad response to the impacts)."""
    b = 2 * ARCMIN
    cfg = _radau_play_config(b, method)
    load = _SineLoad(8.0, 20.0)
    t_end = 0.03
    prof = SampledProfile(np.array([0.0, t_end]), np.array([0.0, 0.0]), 'linear')
    tr = simulate(cfg, profile=prof, t_end=t_end, record_every=40, load=load)
    assert tr.stats['contact_events'] >= 2            # it really crosses the play
    assert np.ptp(tr.theta[:, 1]) > b                 # the gear swings through all of it
    ref = _play_reference('reversing load',
                          lambda: _radau_with_play(cfg, prof, (0.0, t_end), tr.t, load=load))
    for j in (0, 1, 2):
        err = np.max(np.abs(tr.theta[:, j] - ref[:, j]))
        assert err <= 0.01 * np.ptp(ref[:, j]), (j, err, np.ptp(ref[:, j]))


@pytest.mark.parametrize('value, words', [
    (-1e-4, 'mesh.backlash'), (float('nan'), 'mesh.backlash'), (float('inf'), 'mesh.backlash'),
    (0.09, 'tooth pitch'),
])
def test_bad_play_is_a_one_line_error_naming_the_key(value, words):
    with pytest.raises(ConfigError) as exc:
        Config().replace({'mesh.backlash': value})
    msg = str(exc.value)
    assert 'mesh.backlash' in msg and words in msg and '\n' not in msg, msg


@pytest.mark.parametrize('load, flank, side', [
    (2.0, 'coast', 1.0), (-2.0, 'drive', -1.0), (0.0, 'drive', 1.0), (0.0, 'coast', -1.0),
    (0.0, 'center', 0.0)])
def test_the_initial_state_rests_on_the_loaded_or_the_chosen_flank(load, flank, side):
    """Under a load the drive starts at rest on the loaded flank (whatever
    mesh.initial_flank says); without one on the flank chosen, with no tooth force."""
    from worm_gear_sim.dynamics.modal import static_equilibrium
    b = 2 * ARCMIN
    cfg = Config().replace({'mesh.backlash': b, 'load.output_torque': load,
                            'mesh.initial_flank': flank})
    m = DriveModel(cfg)
    u = static_equilibrium(m, 0.0)
    q = m.derived.l_w * u[0] - cfg.geometry.gear_pitch_radius * u[1]
    h = 0.5 * cfg.geometry.gear_pitch_radius * b
    if load:
        assert np.sign(q) == side and abs(q) > h
    else:
        assert q == pytest.approx(side * h, abs=1e-18)
    held = SampledProfile(np.array([0.0, 1.0]), np.array([0.0, 0.0]), 'linear')
    tr = simulate(cfg, profile=held, t_end=0.002)     # at rest: the command held, no motion
    assert np.max(np.abs(tr.omega)) <= 1e-9


# theta4 only: the worm's theta2 at 10 us is what the warning is about
@pytest.mark.filterwarnings('ignore::worm_gear_sim.dynamics.modal.StepResolutionWarning')
@pytest.mark.parametrize('arcmin, variant', [
    (0.5, {'friction.mu_kinetic': 0.055}),                    # friction off by 17 %
    (5.0, {'shafts.gear_bearing_axial_stiffness': 3.0e8}),    # other bearings
])
def test_identify_fits_the_play_and_predicts_a_held_out_reversal(arcmin, variant):
    """A drive with 0.5 or 5 arcmin of play that differs from the base in another,
    unfitted parameter; a slow reversal at low load (the move that shows the play),
    theta4 with noise and encoder steps: identify mesh.backlash from a 1 arcmin start; a
    held-out reversal move (other amplitude and speed) is predicted within 5 % theta4 RMS
    of its amplitude (the lag behind the rigid motion)."""
    from worm_gear_sim.identification import (
        FitOptions,
        identify,
        prediction_errors,
        record_from_model,
    )
    # the fit, not the step, is under test: 10 us (frequency-matched worm) resolves theta4
    # to 1e-4 of its oscillation (docs/performance.md) at 2.5x fewer steps than the default
    drag = {'load.output_viscous_coefficient': 2.0, 'integrator.time_step': 1e-5}
    truth = Config().replace({'mesh.backlash': arcmin * ARCMIN, **drag, **variant})
    # worm rate: the gear at 2e-3 rad/s, 2e-3 rad out and back (> the 5 arcmin play); the
    # former 1e-3 rad/s over 4 s fitted the same play, at twice the cost
    w = 2e-3 * 56.0
    slow = SampledProfile(np.array([0.0, 1.0, 2.0]), np.array([0.0, w, 0.0]), 'linear')
    rec = record_from_model(truth, slow, 2.0, sample_rate=1000, outputs=('theta4',),
                            noise_rad=2e-6, resolution_rad=1e-6, seed=2)
    base = Config().replace({'mesh.backlash': ARCMIN, **drag})
    res = identify(base, [rec], ['mesh.backlash'],
                   options=FitOptions(strategy='local', serial=True))
    assert res.trustworthy, res.problems
    assert res.values[0] == pytest.approx(arcmin * ARCMIN, rel=0.05)
    held = SampledProfile(np.array([0.0, 1.0, 1.5, 2.5]),
                          np.array([0.0, 0.15, 0.15, -0.05]), 'linear')
    val = record_from_model(truth, held, 2.5, sample_rate=1000, outputs=('theta4',),
                            noise_rad=2e-6, resolution_rad=1e-6, seed=3)
    err = prediction_errors(res.config, [val])[0]['theta4']
    # rel: RMS over the oscillation amplitude (half the range of theta4 less the rigid
    # motion: the lag, play included), the convention of `identify --validate`
    print(f'\n{arcmin} arcmin: fitted {res.values[0] / ARCMIN:.4f} arcmin, held-out rel '
          f'{err["rel"]:.4f}')
    assert err['rel'] <= 0.05, err


def test_a_record_without_a_reversal_says_the_play_is_not_seen():
    """One way only, the drive stays on one flank: the play cannot be seen, and the fit
    says so (whatever the play's size: 5 arcmin here)."""
    from worm_gear_sim.identification import FitOptions, identify, record_from_model
    drag = {'load.output_viscous_coefficient': 2.0}
    truth = Config().replace({'mesh.backlash': 5.0 * ARCMIN, **drag})
    one_way = record_from_model(truth, SampledProfile(np.array([0.0, 1.0]),
                                                      np.array([0.0, 0.1]), 'linear'),
                                1.0, sample_rate=1000, outputs=('theta4',))
    base = Config().replace({'mesh.backlash': ARCMIN, **drag})
    res = identify(base, [one_way], ['mesh.backlash'],
                   options=FitOptions(strategy='local', serial=True, max_nfev=5))
    assert any('play is not seen' in w for w in res.warnings), res.warnings
