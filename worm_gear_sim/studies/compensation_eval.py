# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Evaluation of the feed-forward compensator: reference scenarios (the paper's 18-step move,
a radar slew) streamed at the node's command rate, runs of a (possibly detuned) plant with
and without :class:`~worm_gear_sim.compensation.streaming.Compensator`, and the move metrics
(residual oscillation, settling time, static error, constant-rate tracking error)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..config.usable import Config
from ..dynamics.derived import derive
from ..dynamics.load import LoadSignal
from ..dynamics.modal import modes
from ..dynamics.model import DriveModel
from ..dynamics.profiles import SampledProfile, TrapezoidalProfile, motion_span
from ..dynamics.simulation import simulate
from ..realtime import feedforward_series

__all__ = ['Scenario', 'paper_step_scenario', 'radar_slew_scenario', 'run_scenario',
           'move_metrics', 'CompensationRun', 'DETUNINGS', 'detuned', 'detuning_cases',
           'RADAR_LOAD', 'SETTLE_TOLERANCE', 'SETTLE_HOLD', 'METRIC_FLOOR', 'METRICS',
           'improvement', 'not_worse']

SETTLE_TOLERANCE = 10e-6          # rad: settling band of theta4 about its target
SETTLE_HOLD = 0.05                # s: settled only if inside the band for the run's last 50 ms

#: Illustrative antenna load of the radar scenarios (the paper has none): a steady wind
#: torque on the antenna and the viscous drag of its bearing and seals.  With these values
#: the static wind-up (about 1.8e-4 rad at the antenna) is of the order of the ringing.
RADAR_LOAD = {'load.output_torque': 5.0, 'load.output_viscous_coefficient': 2.0}


@dataclass(frozen=True)
class Scenario:
    """A sampled reference move: samples at ``times`` (the servo's 1 kHz stream), the time
    ``move_end`` after which the reference rests, and the constant-rate intervals."""

    name: str
    times: np.ndarray
    theta1_ref: np.ndarray
    move_end: float
    constant_rate: tuple          # ((t_a, t_b), ...) where theta1_ref has a constant rate
    description: str = ''

    @property
    def t_end(self) -> float:
        return float(self.times[-1])


def _command_period(cfg: Config) -> float:
    """The servo streams theta1_ref at the node's rate."""
    return 1.0 / cfg.node.publish_rate_hz


def _sample_times(t_end: float, period: float) -> np.ndarray:
    """The servo's sample instants 0, period, ... up to t_end."""
    return np.arange(0.0, t_end + 0.5 * period, period)


def _piecewise_accel_profile(t0: float, segments, period: float, t_total: float):
    """Worm angle from (duration, acceleration) segments starting at rest at t0, sampled
    every ``period``; returns (times, theta1, rate-change instants).  For moves that are not
    a symmetric trapezoid (the slew's reversal); the paper's move is a TrapezoidalProfile."""
    times = _sample_times(t_total, period)
    th = np.zeros_like(times)
    knots = [t0]
    pos, vel, t = 0.0, 0.0, t0
    starts = []
    for dur, acc in segments:
        starts.append((t, pos, vel, acc))
        pos += vel * dur + 0.5 * acc * dur * dur
        vel += acc * dur
        t += dur
        knots.append(t)
    for (ts_, p0, v0, a0), te in zip(starts, knots[1:]):
        m = (times >= ts_) & (times < te)
        tau = times[m] - ts_
        th[m] = p0 + v0 * tau + 0.5 * a0 * tau * tau
    th[times >= knots[-1]] = pos
    return times, th, knots


def paper_step_scenario(cfg: Config, start: float = 0.01, t_end: float = 0.5,
                        period: float | None = None) -> Scenario:
    """The paper's 18-step move (:class:`~worm_gear_sim.dynamics.profiles.TrapezoidalProfile`:
    input.target_angle in input.move_time with input.accel_time ramps, 0.1131 rad in 20 ms
    with 4 ms ramps by default) from ``start``, sampled every ``period`` (default: the node's
    command period, 1 / node.publish_rate_hz)."""
    period = _command_period(cfg) if period is None else period
    inp = cfg.input
    T, ta, A = inp.move_time, inp.accel_time, inp.target_angle
    move = TrapezoidalProfile(A, T, ta, t0=start)
    times = _sample_times(t_end, period)
    return Scenario('paper_18_step', times, move.theta1(times), start + T, (move.cruise,),
                    f'18-step move {A:.6g} rad in {T * 1e3:g} ms ({ta * 1e3:g} ms ramps) '
                    f'from t = {start * 1e3:g} ms')


def radar_slew_scenario(cfg: Config, antenna_rate: float = 0.2,
                        antenna_acceleration: float = 60.0, cruise: float = 0.15,
                        start: float = 0.01, hold: float = 0.3,
                        period: float | None = None) -> Scenario:
    """Radar slew (the paper's introduction: a target turning sharply): start, track at
    +antenna_rate, reverse at the acceleration limit to -antenna_rate, track, stop, hold.
    Defaults: 0.2 rad/s (11.5 deg/s) with 60 rad/s^2 (reversal in 6.7 ms).  Angles are
    worm angles, sampled every ``period`` (default: 1 / node.publish_rate_hz)."""
    period = _command_period(cfg) if period is None else period
    ratio = derive(cfg).ratio                 # theta1 per theta4
    w = antenna_rate * ratio
    acc = antenna_acceleration * ratio
    ramp = w / acc
    segs = [(ramp, acc), (cruise, 0.0), (2 * ramp, -acc), (cruise, 0.0), (ramp, acc)]
    t_total = start + 4 * ramp + 2 * cruise + hold
    times, th, knots = _piecewise_accel_profile(start, segs, period, t_total)
    return Scenario('radar_slew', times, th, knots[-1],
                    ((knots[1], knots[2]), (knots[3], knots[4])),
                    f'slew at +/-{antenna_rate:g} rad/s antenna rate, '
                    f'{antenna_acceleration:g} rad/s^2 (reversal in {2e3 * ramp:.3g} ms), '
                    f'{cruise * 1e3:g} ms tracking each way, stop, hold {hold * 1e3:g} ms')


@dataclass
class CompensationRun:
    """A simulated scenario: plant response with the commanded theta1 = ref + delta."""

    scenario: Scenario
    delta: np.ndarray             # correction at the scenario's sample times
    trajectory: Any               # simulation.Trajectory
    error: np.ndarray             # theta4 - theta1_ref * l_w / r_g at the trajectory times
    metrics: dict


def run_scenario(plant: DriveModel | Config, scenario: Scenario,
                 compensator: DriveModel | Config | None,
                 record_every: int = 10, load: LoadSignal | None = None) -> CompensationRun:
    """Simulate ``plant`` (nonlinear, with friction) driven by the scenario's reference,
    plus the feed-forward of a compensator designed on ``compensator`` (None: without
    compensation); both a :class:`DriveModel` or a Config.  The command is streamed at the
    scenario's sample times and joined by straight lines, as the node does.  ``load``: a
    load torque signal on the plant in place of its constant (the compensator knows only
    its own ``load.output_torque``)."""
    plant = DriveModel.of(plant)
    t, x = scenario.times, scenario.theta1_ref
    delta = feedforward_series(compensator, t, x) if compensator is not None \
        else np.zeros_like(x)
    traj = simulate(plant, SampledProfile(t, x + delta), t_end=scenario.t_end,
                    record_every=record_every, theta1_initial=float(x[0] + delta[0]),
                    load=load)
    output_per_input = traj.output_per_input
    ref = np.interp(traj.t, t, x)
    err = traj.theta[:, 2] - ref * output_per_input
    mode_hz = float(modes(plant).frequencies_hz[0])
    command_end = scenario.move_end
    if compensator is not None:
        span = motion_span(t, x + delta)
        if span is not None:
            command_end = span[1]
    return CompensationRun(scenario, delta, traj, err,
                           move_metrics(traj.t, err, scenario, mode_hz, command_end))


def _static_offset(t: np.ndarray, e: np.ndarray, freq_hz: float) -> float:
    """Offset of e over the window by least squares on c + a cos wt + b sin wt (the ringing
    antenna mode removed), robust to a partial period."""
    w = 2 * math.pi * freq_hz
    A = np.column_stack([np.ones_like(t), np.cos(w * t), np.sin(w * t)])
    coef, *_ = np.linalg.lstsq(A, e, rcond=None)
    return float(coef[0])


def move_metrics(t: np.ndarray, e: np.ndarray, scenario: Scenario, mode_hz: float,
                 command_end: float | None = None, static_window: float = 0.1) -> dict:
    """Metrics of an output-error trace e = theta4 - theta1_ref l_w / r_g (rad, s).

    ``move_end`` is the end of the reference move; ``command_end`` (default: the same) the
    time after which the applied command (reference + correction) rests: a causal filter
    keeps correcting for its lag span after the reference stopped.

    - ``residual_peak``: max |e - static| after ``command_end`` (the residual oscillation);
    - ``post_move_peak``: max |e - static| after ``move_end`` (includes the correction's own
      transient; stricter);
    - ``settling_time``: from ``move_end`` until |e| stays within 10 urad (inf: not settled,
      i.e. still leaving the band during the run's last SETTLE_HOLD = 50 ms);
    - ``static_error``: |offset| of e over the last ``static_window`` (the ringing at the
      antenna mode fitted out by least squares);
    - ``tracking_rms``: RMS of e while the reference moves at constant rate.
    """
    # a grid time k dt equals a sample time only to round-off (4 us x 512750 = 2.0509999..)
    t_move = scenario.move_end - TIME_ROUNDING
    t_cmd = t_move if command_end is None else max(command_end - TIME_ROUNDING, t_move)
    last = t >= t[-1] - static_window
    static = _static_offset(t[last], e[last], mode_hz)
    dev = np.abs(e - static)
    resid = float(np.max(dev[t >= t_cmd]))
    post = float(np.max(dev[t >= t_move]))
    after = t >= t_move
    outside = np.nonzero(after & (np.abs(e) > SETTLE_TOLERANCE))[0]
    if outside.size == 0:
        settle = 0.0
    elif t[-1] - t[outside[-1]] < SETTLE_HOLD:
        settle = math.inf          # still leaving the band near the end of the run
    else:
        settle = float(t[outside[-1] + 1] - scenario.move_end)
    mask = np.zeros(t.shape, bool)
    for a, b in scenario.constant_rate:
        mask |= (t >= a) & (t <= b)
    rms = float(np.sqrt(np.mean(e[mask] ** 2))) if mask.any() else math.nan
    return {'residual_peak': resid, 'post_move_peak': post, 'settling_time': settle,
            'static_error': abs(static), 'tracking_rms': rms}


#: Times closer than this are the same instant (a grid time k dt against a sample time).
TIME_ROUNDING = 1e-9

#: Detuned plants for the robustness cases: +-20 % tooth stiffness, friction, flywheel.
DETUNINGS = {
    'tooth_stiffness': ('mesh.worm_tooth_stiffness_multiplier',
                        'mesh.gear_tooth_stiffness_multiplier'),
    'friction': ('friction.mu_kinetic', 'friction.mu_stribeck_drop',
                 'friction.constant_coefficient'),
    'flywheel_inertia': ('materials.flywheel_density',),
}


def detuned(cfg: Config, factors: dict) -> Config:
    """The plant with parameter groups scaled: ``factors`` maps DETUNINGS keys to factors
    (flywheel inertia scales with the flywheel density, J_4 = rho pi L R^4 / 2)."""
    flat = cfg.to_flat_dict()
    over = {}
    for group, f in factors.items():
        for key in DETUNINGS[group]:
            over[key] = flat[key] * f
    return cfg.replace(over)


#: Errors below this (0.1 urad, 1 % of the settling band) are at the resolution of the
#: simulation (Newton tolerance, the static-offset fit): both runs count as equal there.
METRIC_FLOOR = 1e-7
METRICS = ('residual_peak', 'post_move_peak', 'settling_time', 'static_error',
           'tracking_rms')


def improvement(metric: str, off: float, on: float) -> float:
    """off / on (larger is better).  Settling times: inf/inf -> 1, inf/finite -> inf.
    Angle metrics: nan when both are below METRIC_FLOOR (nothing to remove)."""
    if metric == 'settling_time':
        if math.isinf(off) and math.isinf(on):
            return 1.0
        if math.isinf(on):
            return 0.0
        if math.isinf(off) or on == 0.0:
            return math.inf if off > 0.0 else 1.0
        return off / on
    if off < METRIC_FLOOR and on < METRIC_FLOOR:
        return math.nan
    return off / max(on, METRIC_FLOOR)


def not_worse(metric: str, off: float, on: float, tolerance: float = 0.05) -> bool:
    """True if the compensated value is at most ``tolerance`` worse than uncompensated (or
    both are below the resolution floor)."""
    if metric == 'settling_time':
        return on <= off * (1.0 + tolerance) or (math.isinf(on) and math.isinf(off))
    return on <= max(off * (1.0 + tolerance), METRIC_FLOOR)


def detuning_cases() -> list[tuple[str, dict]]:
    """The plants of the robustness study: nominal, each group +-20 %, and the two corners
    that move the antenna mode most (soft teeth + heavy flywheel, stiff + light)."""
    cases: list[tuple[str, dict]] = [('nominal', {})]
    for g in DETUNINGS:
        for f in (0.8, 1.2):
            cases.append((f'{g} {f - 1:+.0%}', {g: f}))
    cases.append(('tooth -20% & flywheel +20%', {'tooth_stiffness': 0.8,
                                                 'flywheel_inertia': 1.2}))
    cases.append(('tooth +20% & flywheel -20%', {'tooth_stiffness': 1.2,
                                                 'flywheel_inertia': 0.8}))
    return cases
