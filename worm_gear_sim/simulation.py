# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Public simulation API: a stepping :class:`Simulator` for real time and a batch
:func:`simulate` for studies.  Both drive the same compiled kernel
(:func:`worm_gear_sim.integrator.advance`) on the same grid t = t0 + k dt.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .integrator import (
    N_STATS,
    S_EVALS,
    S_FAILED,
    S_MAX_SOLVES,
    S_SOLVES,
    S_STEPS,
    S_SUBDIV_EVENTS,
    S_SUBSTEPS,
    S_VERIFIED,
    STATUS_NONFINITE,
    STATUS_OK,
    advance,
    advance_segment,
    consistent_acceleration,
)
from .modal import damping_matrix, static_equilibrium
from .model import (
    AUX_CGKG,
    AUX_CWKW,
    AUX_FX,
    AUX_FY,
    AUX_MU,
    AUX_Q,
    AUX_VS,
    AUX_WN,
    N_AUX,
    P_RIGID3,
    energy_series,
    generalized_forces,
    mechanical_energy,
    pack_parameters,
)
from .params import Config, derive
from .profiles import Profile, make_profile

__all__ = ['Simulator', 'Trajectory', 'SimulationError', 'SimState', 'simulate']


class SimulationError(RuntimeError):
    """The integrator could not advance (non-finite state or Newton failure)."""


@dataclass(frozen=True)
class SimState:
    """Snapshot of the drive at time t (angles rad, rates rad/s, accelerations rad/s^2)."""

    t: float
    theta1: float
    theta1_dot: float
    theta: np.ndarray     # (theta2, theta3, theta4)
    omega: np.ndarray
    alpha: np.ndarray


@dataclass
class Trajectory:
    """Time series of a run; row 0 is the initial state."""

    t: np.ndarray
    theta1: np.ndarray
    theta1_dot: np.ndarray
    theta: np.ndarray        # (n, 3): theta2, theta3, theta4
    omega: np.ndarray
    alpha: np.ndarray
    aux: np.ndarray          # (n, N_AUX): W_n, mu, cwkw, cgkg, v_s, F_X, F_Y, q
    output_ratio: float      # l_w / r_g: rigid theta4 per theta1
    profile: str = ''
    stats: dict = field(default_factory=dict)

    theta2 = property(lambda self: self.theta[:, 0])
    theta3 = property(lambda self: self.theta[:, 1])
    theta4 = property(lambda self: self.theta[:, 2])
    normal_force = property(lambda self: self.aux[:, AUX_WN])
    friction_coefficient = property(lambda self: self.aux[:, AUX_MU])
    sliding_velocity = property(lambda self: self.aux[:, AUX_VS])

    @property
    def worm_error(self) -> np.ndarray:
        """theta2 - theta1 [rad]: worm body behind/ahead of the command."""
        return self.theta[:, 0] - self.theta1

    @property
    def output_error(self) -> np.ndarray:
        """theta4 - theta1 l_w / r_g [rad]: antenna positioning error."""
        return self.theta[:, 2] - self.theta1 * self.output_ratio

    def energy(self, config: Config) -> np.ndarray:
        """Kinetic + shaft torsion + mesh energy 0.5 k_Y q^2 [J] at every row."""
        p = pack_parameters(config)
        return energy_series(p, np.ascontiguousarray(self.theta),
                             np.ascontiguousarray(self.omega), np.ascontiguousarray(self.theta1))

    def columns(self) -> dict[str, np.ndarray]:
        a = self.aux
        return {
            't': self.t, 'theta1': self.theta1, 'theta1_dot': self.theta1_dot,
            'theta2': self.theta[:, 0], 'theta3': self.theta[:, 1], 'theta4': self.theta[:, 2],
            'omega2': self.omega[:, 0], 'omega3': self.omega[:, 1], 'omega4': self.omega[:, 2],
            'alpha2': self.alpha[:, 0], 'alpha3': self.alpha[:, 1], 'alpha4': self.alpha[:, 2],
            'normal_force': a[:, AUX_WN], 'mu': a[:, AUX_MU], 'sliding_velocity': a[:, AUX_VS],
            'worm_tooth_stiffness': a[:, AUX_CWKW], 'gear_tooth_stiffness': a[:, AUX_CGKG],
            'force_x': a[:, AUX_FX], 'force_y': a[:, AUX_FY], 'mesh_deflection': a[:, AUX_Q],
            'worm_error': self.worm_error, 'output_error': self.output_error,
        }

    def to_csv(self, path: str | Path, header_comment: str = '') -> None:
        """Write all columns (SI units, rad) with a commented header."""
        cols = self.columns()
        units = {'t': 's', 'normal_force': 'N', 'force_x': 'N', 'force_y': 'N',
                 'mu': '1', 'sliding_velocity': 'm/s', 'worm_tooth_stiffness': 'N/m',
                 'gear_tooth_stiffness': 'N/m', 'mesh_deflection': 'm'}
        names = [f'{k}[{_csv_unit(k, units)}]' for k in cols]
        data = np.column_stack(list(cols.values()))
        comment = f'# worm_gear_sim; profile: {self.profile}\n'
        if header_comment:
            comment += ''.join(f'# {line}\n' for line in header_comment.splitlines())
        with open(path, 'w') as fh:
            fh.write(comment)
            fh.write(','.join(names) + '\n')
            np.savetxt(fh, data, delimiter=',', fmt='%.12g')


def _csv_unit(name: str, units: dict[str, str]) -> str:
    if name in units:
        return units[name]
    if name == 'theta1_dot' or name.startswith('omega'):
        return 'rad/s'
    if name.startswith('alpha'):
        return 'rad/s^2'
    return 'rad'


class Simulator:
    """Stateful Newmark integrator of the worm-gear drive on a fixed grid t0 + k dt.

    Real time: call :meth:`advance_to` with the current time and the latest command; the
    command is a sample at that time and theta1 is interpolated from the previous sample
    (``interpolation='linear'``) or applied at once (``'hold'``).  Batch: :meth:`run`.
    """

    def __init__(self, config: Config, theta1: float = 0.0, t0: float = 0.0,
                 interpolation: str | None = None):
        self.config = config
        self.p = pack_parameters(config)
        self.C = damping_matrix(config, self.p)
        self.derived = derive(config)
        self.dt = config.integrator.time_step
        self.interpolation = interpolation or config.node.command_interpolation
        self._stats = np.zeros(N_STATS, dtype=np.int64)
        self._ctl = np.array([1.0, 0.0])      # Newton controller: contraction, since verify
        self.reset(theta1, t0)

    # ---- state ---------------------------------------------------------------------------
    def reset(self, theta1: float = 0.0, t0: float = 0.0, theta=None, omega=None) -> None:
        """Start at time t0 with command theta1; by default at rest in static equilibrium."""
        if not (math.isfinite(theta1) and math.isfinite(t0)):
            raise ValueError('reset: theta1 and t0 must be finite')
        self._t0 = float(t0)
        self._k = 0
        self._u = static_equilibrium(self.p, theta1) if theta is None else \
            np.array(theta, float)
        self._v = np.zeros(3) if omega is None else np.array(omega, float)
        self._a = np.zeros(3)
        self._theta1 = float(theta1)
        self._theta1_dot = 0.0
        self._cmd_t = self._t0
        self._cmd_value = float(theta1)
        consistent_acceleration(self.p, self.C, self._u, self._v, self._theta1, 0.0, self._a)
        self._ctl[:] = (1.0, 0.0)

    def reconfigure(self, config: Config) -> None:
        """Swap in new (already validated) parameters, keeping time, state and command.
        The time step cannot change (it is read-only in the node)."""
        if config.integrator.time_step != self.dt:
            raise ValueError('integrator.time_step cannot change on a running simulator')
        p = pack_parameters(config)
        C = damping_matrix(config, p)
        a = np.zeros(3)
        consistent_acceleration(p, C, self._u, self._v, self._theta1, self._theta1_dot, a)
        if not np.all(np.isfinite(a)):
            raise ValueError('the new parameters give a non-finite acceleration')
        self.config, self.p, self.C, self.derived, self._a = config, p, C, derive(config), a
        self._ctl[:] = (1.0, 0.0)

    @property
    def t(self) -> float:
        """Simulated time of the current state (exactly t0 + k dt)."""
        return self._t0 + self._k * self.dt

    @property
    def state(self) -> SimState:
        return SimState(self.t, self._theta1, self._theta1_dot, self._u.copy(),
                        self._v.copy(), self._a.copy())

    @property
    def stats(self) -> dict[str, int]:
        s = self._stats
        return {'steps': int(s[S_STEPS]), 'newton_solves': int(s[S_SOLVES]),
                'force_evaluations': int(s[S_EVALS]),
                'subdivision_events': int(s[S_SUBDIV_EVENTS]),
                'substeps': int(s[S_SUBSTEPS]), 'max_solves_per_step': int(s[S_MAX_SOLVES]),
                'failed_steps': int(s[S_FAILED]), 'verified_steps': int(s[S_VERIFIED])}

    def forces(self) -> dict[str, float]:
        """Mesh quantities at the current state (W_n, mu, stiffnesses, F_X, F_Y, q)."""
        Q, aux = np.zeros(3), np.zeros(N_AUX)
        generalized_forces(self.p, self._u, self._v, self._theta1, Q, np.zeros((3, 3)),
                           np.zeros((3, 3)), aux)
        names = ('W_n', 'mu', 'cwkw', 'cgkg', 'v_s', 'F_X', 'F_Y', 'q')
        return dict(zip(names, aux.tolist())) | {'Q2': Q[0], 'Q3': Q[1], 'Q4': Q[2]}

    def joint_torques(self) -> np.ndarray:
        """Shaft torques for JointState.effort [N m]: motor on worm shaft K_w (theta1 -
        theta2), mesh torque on the worm r_w F_X, on the gear r_g F_Y, gear shaft
        K_g (theta3 - theta4)."""
        return np.array(self.joint_state()[2])

    def joint_state(self) -> tuple[tuple, tuple, tuple]:
        """The JointState fields at the current state, as tuples of floats: position
        (theta1..theta4 [rad]), velocity (theta1_dot, omega2..omega4 [rad/s]) and effort
        (:meth:`joint_torques` [N m]); one compiled force evaluation into reused buffers
        (the real-time path publishes this for every sample)."""
        buf = self.__dict__.get('_force_buf')
        if buf is None:
            buf = self._force_buf = (np.zeros(3), np.zeros((3, 3)), np.zeros((3, 3)),
                                     np.zeros(N_AUX))
        u, v, th1 = self._u, self._v, self._theta1
        generalized_forces(self.p, u, v, th1, buf[0], buf[1], buf[2], buf[3])
        aux = buf[3]
        g, d = self.config.geometry, self.derived
        u2, u3, u4 = float(u[0]), float(u[1]), float(u[2])
        return ((th1, u2, u3, u4), (self._theta1_dot, float(v[0]), float(v[1]), float(v[2])),
                (d.K_w * (th1 - u2), g.worm_pitch_radius * float(aux[AUX_FX]),
                 g.gear_pitch_radius * float(aux[AUX_FY]), d.K_g * (u3 - u4)))

    def energy(self) -> float:
        return float(mechanical_energy(self.p, self._u, self._v, self._theta1))

    # ---- stepping --------------------------------------------------------------------------
    def advance_to(self, t_target: float, theta1: float | None = None) -> int:
        """Integrate whole steps up to ``t_target`` with ``theta1`` as the command sample at
        ``t_target`` (None: hold the last command).  Returns the number of steps taken;
        raises SimulationError (state unchanged past the last good step) on failure."""
        if theta1 is None:
            theta1 = self._cmd_value
        if not (math.isfinite(t_target) and math.isfinite(theta1)):
            raise ValueError('advance_to: t_target and theta1 must be finite')
        n = int(math.floor((t_target - self.t) / self.dt + 1e-9))
        if n > 0:
            if self.interpolation == 'hold' or t_target <= self._cmd_t:
                slope = 0.0
            else:
                slope = (theta1 - self._cmd_value) / (t_target - self._cmd_t)
            done, status = advance_segment(
                self.p, self.C, self._u, self._v, self._a, self._theta1, self._theta1_dot,
                self._t0, self._k, self.dt, n, self._cmd_t,
                self._cmd_value if slope != 0.0 else float(theta1), slope, t_target,
                float(theta1), self._stats, self._ctl)
            self._after_kernel(done, status,
                               self._segment_value(done, theta1, slope, t_target), slope)
        if t_target > self._cmd_t or n > 0:
            self._cmd_t = max(t_target, self._cmd_t)
            self._cmd_value = float(theta1)
        return max(n, 0)

    def resync(self, t: float) -> None:
        """Jump the simulated clock to ``t`` without integrating (dropped catch-up time)."""
        self._t0 = float(t) - self._k * self.dt
        self._cmd_t = min(self._cmd_t, self.t)

    def _segment_value(self, done: int, theta1: float, slope: float,
                       t_target: float) -> float:
        """theta1 at the last completed grid point of an advance_segment call."""
        grid = self._t0 + float(self._k + done) * self.dt
        if slope == 0.0 or grid >= t_target:
            return float(theta1)
        return self._cmd_value + slope * (grid - self._cmd_t)

    def _run_kernel(self, th, td, stride, ru, rv, ra, raux) -> None:
        done, status = advance(self.p, self.C, self._u, self._v, self._a, th, td, self.dt,
                               stride, ru, rv, ra, raux, self._stats, self._ctl)
        self._after_kernel(done, status, float(th[done]), float(td[done]))

    def _after_kernel(self, done: int, status: int, theta1_last: float,
                      theta1_dot_last: float) -> None:
        self._k += done
        if done > 0:
            self._theta1, self._theta1_dot = theta1_last, theta1_dot_last
        if status != STATUS_OK:
            what = 'non-finite state or command' if status == STATUS_NONFINITE else \
                'Newton did not converge at the finest subdivision'
            raise SimulationError(f'integration stopped at t = {self.t:.9g} s: {what}')

    # ---- batch ---------------------------------------------------------------------------
    def run(self, profile: Profile, t_end: float, record_every: int = 1,
            chunk_steps: int = 1 << 18) -> Trajectory:
        """Integrate the profile from the current state to ``t_end`` and record every
        ``record_every`` steps (row 0 = current state)."""
        n_total = int(math.floor((t_end - self.t) / self.dt + 1e-9))
        if n_total < 0:
            raise ValueError(f't_end {t_end} is before the current time {self.t}')
        stride = max(1, int(record_every))
        chunk = max(stride, (chunk_steps // stride) * stride)
        n_rec = n_total // stride
        t_rec = np.empty(n_rec + 1)
        th_rec, td_rec = np.empty(n_rec + 1), np.empty(n_rec + 1)
        u_rec, v_rec, a_rec = (np.empty((n_rec + 1, 3)) for _ in range(3))
        aux_rec = np.empty((n_rec + 1, N_AUX))
        t_rec[0], th_rec[0], td_rec[0] = self.t, self._theta1, self._theta1_dot
        u_rec[0], v_rec[0], a_rec[0] = self._u, self._v, self._a
        generalized_forces(self.p, self._u, self._v, self._theta1, np.zeros(3),
                           np.zeros((3, 3)), np.zeros((3, 3)), aux_rec[0])
        row = 1
        done_total = 0
        while done_total < n_total:
            n = min(chunk, n_total - done_total)
            ks = self._k + np.arange(1, n + 1)
            grid = self._t0 + ks * self.dt
            th = np.concatenate(([self._theta1], profile.theta1(grid)))
            td = np.concatenate(([self._theta1_dot], profile.theta1_dot(grid)))
            m = n // stride
            sl = slice(row, row + m)
            self._run_kernel(th, td, stride, u_rec[sl], v_rec[sl], a_rec[sl], aux_rec[sl])
            idx = np.arange(1, m + 1) * stride
            t_rec[sl], th_rec[sl], td_rec[sl] = grid[idx - 1], th[idx], td[idx]
            row += m
            done_total += n
        self._cmd_t, self._cmd_value = self.t, self._theta1
        return Trajectory(t=t_rec[:row], theta1=th_rec[:row], theta1_dot=td_rec[:row],
                          theta=u_rec[:row], omega=v_rec[:row], alpha=a_rec[:row],
                          aux=aux_rec[:row], output_ratio=float(self.p[P_RIGID3]),
                          profile=profile.describe(), stats=self.stats)


def simulate(config: Config, profile: Profile | None = None, t_end: float | None = None,
             record_every: int = 1, theta1_initial: float | None = None) -> Trajectory:
    """Batch run from rest: the config's input profile (or ``profile``) to ``t_end``."""
    profile = profile if profile is not None else make_profile(config.input)
    t_end = config.input.end_time if t_end is None else t_end
    th0 = float(profile.theta1(np.array([0.0]))[0]) if theta1_initial is None else \
        theta1_initial
    sim = Simulator(config, theta1=th0)
    return sim.run(profile, t_end, record_every)
