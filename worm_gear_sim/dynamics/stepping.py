# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The stepping integration of the drive: :class:`Stepper`, the Newmark integrator on a fixed
grid t = t0 + k dt for real time (:meth:`~Stepper.advance_to`) and batch
(:meth:`~Stepper.run`, :meth:`~Stepper.iter_run`), on the compiled kernel
(:func:`worm_gear_sim.dynamics.integrator.advance`; with ``integrator.method: adaptive`` the
variable step of :func:`worm_gear_sim.dynamics.adaptive.advance_adaptive`, whose steps end on
every tick and record point of the grid).  It runs whatever model it is given: proving a
parameter set usable is the job of :class:`worm_gear_sim.dynamics.simulation.Simulator` (the public
class: this plus the usable check and the diagnosis of a failed integration), whose check
runs a short trial on a :class:`Stepper` (:mod:`worm_gear_sim.dynamics.usability`).  What a run
yields (:class:`Trajectory`, :class:`SimState`, the CSV writer) is in
:mod:`worm_gear_sim.dynamics.trajectory`.  The real-time segment of :meth:`~Stepper.advance_to`
(the command on one interpolation segment, then the kernel) is compiled in
:mod:`worm_gear_sim.dynamics.segment`.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Iterator
from typing import Self

import numpy as np
from numpy.typing import ArrayLike

from ..schema.parameters import Parameters
from ..schema.sections import ANGLE_LIMIT, LOAD_LIMIT
from .adaptive import advance_adaptive
from .derived import Derived
from .equations import generalized_forces, mechanical_energy, mesh_forces_mu
from .integrator import (
    C_DA,
    C_FA,
    C_FW,
    C_MODE,
    C_MU,
    C_RHO,
    C_RHO2,
    C_RING,
    C_SINCE,
    N_CTL,
    N_STATS,
    S_ADAPTIVE_STEPS,
    S_CONTACT_EVENTS,
    S_EVALS,
    S_EVENTS,
    S_FAILED,
    S_LOGGED,
    S_MAX_SOLVES,
    S_REJECTED,
    S_SOLVES,
    S_STEPS,
    S_SUBDIV_EVENTS,
    S_SUBSTEPS,
    S_VERIFIED,
    STATUS_NONFINITE,
    STATUS_OK,
    advance,
    consistent_acceleration,
    record_aux,
)
from .integrator import (
    sliding_speed as record_aux_speed,
)
from .layout import AUX_FX, AUX_FY, N_AUX
from .live_load import NO_LOAD, LiveLoad
from .load import LoadSignal, load_grid
from .modal import (
    static_equilibrium,
    stepping_damping,
)
from .model import DriveModel, load_torque_of, with_load_torque
from .profiles import Profile
from .reseat import reseated
from .segment import advance_segment, advance_segment_adaptive
from .step_control import N_LOG, adaptive_parameters, step_log_of
from .trajectory import ROW_BYTES, SimState, Trajectory

__all__ = ['Stepper', 'SimulationError', 'RUN_MEMORY_LIMIT', 'RATE_LIMIT', 'TIME_LIMIT']


class SimulationError(RuntimeError):
    """The integrator could not advance (non-finite state or Newton failure)."""


#: Largest |rate| [rad/s] of an initial state (the worm at ~1e7 rpm).
RATE_LIMIT = 1e6
#: Largest |time| [s] (3e4 years): t0 + k dt keeps 1e-9 s of resolution up to ~1e7 s.
TIME_LIMIT = 1e12


def _finite_scalar(name: str, x: float, limit: float, unit: str) -> float:
    try:
        x = float(x)
    except (TypeError, ValueError):
        raise ValueError(f'{name} must be a number, got {x!r}') from None
    if not math.isfinite(x) or abs(x) > limit:
        raise ValueError(f'{name} = {x!r} {unit}: must be finite and within +-{limit:g} {unit}')
    return x


def _finite_vector(name: str, x: ArrayLike, limit: float, unit: str) -> np.ndarray:
    try:
        arr = np.array(x, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f'{name} must be 3 numbers (theta2, theta3, theta4), got {x!r}') \
            from None
    if arr.shape != (3,):
        raise ValueError(f'{name} must be 3 numbers (theta2, theta3, theta4), got {x!r}')
    if not (np.all(np.isfinite(arr)) and np.all(np.abs(arr) <= limit)):
        raise ValueError(f'{name} = {arr}: must be finite and within +-{limit:g} {unit}')
    return arr



#: advance_to integrates long spans in chunks of this many steps (1 MB of command samples).
ADVANCE_CHUNK = 1 << 16


class Stepper:
    """Stateful Newmark integrator of the worm-gear drive on a fixed grid t0 + k dt.

    Real time: call :meth:`advance_to` with the current time and the latest command; the
    command is a sample at that time and theta1 is interpolated from the previous sample
    (``interpolation='linear'``) or applied at once (``'hold'``).  Batch: :meth:`run`.

    ``model``: a :class:`DriveModel` (built once, shared with the compensator and the
    studies) or a Config (the stepper builds its model).  No usable check: use
    :class:`worm_gear_sim.dynamics.simulation.Simulator`, which adds it.
    """

    #: Default step limit of one :meth:`advance_to` call (1e8 steps: 400 s at the default
    #: 4 us, roughly half a minute of computation).
    max_advance_steps: int = 10 ** 8

    def __init__(self, model: DriveModel | Parameters, theta1: float = 0.0, t0: float = 0.0,
                 interpolation: str | None = None) -> None:
        config = model.config if isinstance(model, DriveModel) else model
        self._set_model(DriveModel.of(model))
        self.dt: float = config.integrator.time_step
        self.interpolation: str = interpolation or config.node.command_interpolation
        self._stats = np.zeros(N_STATS, dtype=np.int64)
        # Newton controller: contraction, steps since verify; friction mode and mu_eff; the
        # variable step's controller (integrator.method: adaptive)
        self._ctl = np.zeros(N_CTL)
        self._log = np.empty((0, N_LOG))    # the variable step's log (log_steps)
        self._load = LiveLoad()                 # push_load's samples
        self.reset(theta1, t0)

    # ---- state ---------------------------------------------------------------------------
    def reset(self, theta1: float = 0.0, t0: float = 0.0, theta: ArrayLike | None = None,
              omega: ArrayLike | None = None, *, load_torque: float | None = None) -> None:
        """Start at time t0 with command theta1; by default at rest in static equilibrium.
        ``load_torque`` [N m]: the load at t0 when a load signal drives the run (default:
        the load of :meth:`push_load`'s samples at t0 if any, which holds from t0 until
        the next later sample, else the model's constant ``load.output_torque``): the rest
        and the initial acceleration are taken under it.  Raises ValueError (state
        unchanged) for a non-finite or out-of-range input: angles beyond ANGLE_LIMIT, rates
        beyond RATE_LIMIT, or a state whose acceleration is not finite."""
        theta1 = _finite_scalar('reset: theta1', theta1, ANGLE_LIMIT, 'rad')
        t0 = _finite_scalar('reset: t0', t0, TIME_LIMIT, 's')
        p = self.p
        live = self._load.live
        if load_torque is None and live:   # pushed load samples: the load at t0 holds on
            load_torque = float(self._load.at(np.array([t0]))[0])
        if load_torque is not None:
            p = with_load_torque(p, _finite_scalar('reset: load_torque', load_torque,
                                                   LOAD_LIMIT, 'N m'))
        if theta is None:
            u = static_equilibrium(p, theta1)
        else:
            u = _finite_vector('reset: theta', theta, ANGLE_LIMIT, 'rad')
        v = np.zeros(3) if omega is None else _finite_vector('reset: omega', omega,
                                                             RATE_LIMIT, 'rad/s')
        a = np.zeros(3)
        consistent_acceleration(p, self.C, u, v, theta1, 0.0, a)
        if not (np.all(np.isfinite(u)) and np.all(np.abs(u) <= ANGLE_LIMIT)
                and np.all(np.isfinite(a))):
            raise ValueError(f'reset: the state at theta1 = {theta1:g} rad is not finite '
                             f'(theta = {u}, acceleration = {a})')
        self._t0 = t0
        self._k = 0
        self._u, self._v, self._a = u, v, a
        if live:     # the samples before t0 are done with; the later ones stay
            self._load.restart(t0, load_torque_of(p))
        self._theta1 = theta1
        self._theta1_dot = 0.0
        self._cmd_t = self._t0
        self._cmd_value = theta1
        self._ctl[:] = 0.0
        self._ctl[C_RHO] = self._ctl[C_RHO2] = 1.0
        self._ctl[C_MODE] = self._slip_mode()

    def __copy__(self) -> Self:
        """A copy that integrates on its own: its state, step-control and statistics
        arrays are its own (the model, and the load samples, which are replaced and never
        written into, are shared)."""
        new = object.__new__(type(self))
        new.__dict__.update(self.__dict__)
        new._u, new._v, new._a = self._u.copy(), self._v.copy(), self._a.copy()
        new._ctl, new._stats = self._ctl.copy(), self._stats.copy()
        new._log = self._log.copy()
        new._load = copy.copy(self._load)
        new.__dict__.pop('_aux_buf', None)
        return new

    def trial_copy(self) -> Self:
        """A copy for a trial of :meth:`reconfigure` (a set's check off the sample path):
        :func:`copy.copy`, so the trial never writes into this simulator."""
        return copy.copy(self)

    def restore(self, earlier: Stepper) -> None:
        """Go back to ``earlier``, a copy of this simulator taken before
        (:func:`copy.copy`): its time, state, command, step control, statistics, load
        samples and parameters."""
        self.__dict__.update(copy.copy(earlier).__dict__)

    def _set_model(self, model: DriveModel, C: np.ndarray | None = None) -> None:
        self.model = model
        self.config: Parameters = model.config
        self.p: np.ndarray = model.p          # the packed vector the kernels take
        self.C: np.ndarray = stepping_damping(model) if C is None else C
        self._ap: np.ndarray | None = adaptive_parameters(model) \
            if model.config.integrator.method == 'adaptive' else None

    @property
    def derived(self) -> Derived:
        """The model's derived quantities (inertias, stiffnesses, l_w, ratio)."""
        return self.model.derived

    def _check_time_step(self, model: DriveModel | Parameters) -> None:
        config = model.config if isinstance(model, DriveModel) else model
        if config.integrator.time_step != self.dt:
            raise ValueError('integrator.time_step cannot change on a running simulator')
        if config.integrator.method != self.config.integrator.method:
            raise ValueError('integrator.method cannot change on a running simulator')

    def reconfigure(self, model: DriveModel | Parameters, reseat: bool = False) -> None:
        """Swap in new (already validated) parameters, keeping time, state and command.
        The time step cannot change (it is read-only in the node).  ``reseat``: the
        deflections move by the change of the static equilibrium at the current command
        (:func:`~.reseat.reseated`: the forces kept, the velocities too), so that a large change (a
        load released) does not set the drive ringing: a drive without drag rings for ever."""
        self._check_time_step(model)
        model = DriveModel.of(model)
        C = stepping_damping(model)
        u = reseated(self.p, model.p, self._u, self._v, self._theta1) if reseat else self._u
        if not np.all(np.isfinite(u)):
            raise ValueError('the new parameters give a non-finite equilibrium')
        a = np.zeros(3)
        consistent_acceleration(model.p, C, u, self._v, self._theta1,
                                self._theta1_dot, a)
        if not np.all(np.isfinite(a)):
            raise ValueError('the new parameters give a non-finite acceleration')
        self._set_model(model, C)
        if reseat:
            self._u[:] = u
        self._a = a
        self._ctl[C_RHO], self._ctl[C_RHO2], self._ctl[C_SINCE] = 1.0, 1.0, 0.0
        self._ctl[C_DA:C_DA + 3] = 0.0       # no extrapolation across the change
        # the variable step: the acceleration is the new model's, at its inertias
        self._ctl[C_FW], self._ctl[C_FA], self._ctl[C_RING] = 0.0, 0.0, 0.0

    def _slip_mode(self) -> float:
        """Friction mode of the set-valued law at the current state: sign of the sliding
        speed, 0 (stuck) at rest."""
        v_s = record_aux_speed(self.p, self._v)
        return float(np.sign(v_s))

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
                'failed_steps': int(s[S_FAILED]), 'verified_steps': int(s[S_VERIFIED]),
                'contact_events': int(s[S_CONTACT_EVENTS]),
                'adaptive_steps': int(s[S_ADAPTIVE_STEPS]),
                'rejected_steps': int(s[S_REJECTED]), 'located_events': int(s[S_EVENTS])}

    def log_steps(self, capacity: int) -> None:
        """With the variable step: keep the next ``capacity`` accepted steps (time, size,
        friction mode, error, angles, event, evaluations) for :attr:`step_log`."""
        self._log = np.zeros((int(capacity), N_LOG))
        self._stats[S_LOGGED] = 0

    @property
    def step_log(self) -> dict[str, np.ndarray]:
        """The steps logged since :meth:`log_steps` (:func:`~worm_gear_sim.dynamics.adaptive.
        step_log_of`)."""
        return step_log_of(self._log, int(self._stats[S_LOGGED]))

    def forces(self) -> dict[str, float]:
        """Mesh quantities at the current state (W_n, mu, stiffnesses, F_X, F_Y, q); with
        the set-valued friction law mu is the coefficient of the last step (in stick the
        multiplier that holds the contact)."""
        Q, aux = np.zeros(3), np.zeros(N_AUX)
        generalized_forces(self.p, self._u, self._v, self._theta1, Q, np.zeros((3, 3)),
                           np.zeros((3, 3)), aux)
        if self.model.friction_is_set_valued:
            record_aux(self.p, self._u, self._v, self._theta1, self._ctl[C_MU], aux)
            u = self._u
            r = mesh_forces_mu(self.p, u[0], u[1], u[2], self._v[2], self._theta1,
                               self._ctl[C_MU])
            Q = np.array(r[:3])
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
        aux = self.__dict__.get('_aux_buf')
        if aux is None:
            aux = self._aux_buf = np.zeros(N_AUX)
        u, v, th1 = self._u, self._v, self._theta1
        # the mesh quantities as the integrator records them (with the set-valued law the
        # friction it solved for): one compiled call
        record_aux(self.p, u, v, th1, self._ctl[C_MU], aux)
        g, d = self.config.geometry, self.derived
        u2, u3, u4 = float(u[0]), float(u[1]), float(u[2])
        return ((th1, u2, u3, u4), (self._theta1_dot, float(v[0]), float(v[1]), float(v[2])),
                (d.K_w * (th1 - u2), g.worm_pitch_radius * float(aux[AUX_FX]),
                 g.gear_pitch_radius * float(aux[AUX_FY]), d.K_g * (u3 - u4)))

    def energy(self) -> float:
        return float(mechanical_energy(self.p, self._u, self._v, self._theta1))

    # ---- stepping --------------------------------------------------------------------------
    def advance_to(self, t_target: float, theta1: float | None = None, *,
                   max_steps: int | None = None) -> int:
        """Integrate whole steps up to ``t_target`` with ``theta1`` as the command sample at
        ``t_target`` (None: hold the last command).  Returns the number of steps taken;
        raises SimulationError (state unchanged past the last good step) on failure.

        Raises ValueError before integrating when ``t_target`` or ``theta1`` is not a finite
        number, |theta1| > ANGLE_LIMIT, or the span needs more than ``max_steps`` steps
        (default :attr:`max_advance_steps`, about a minute of computation): long offline runs
        belong to :meth:`run` / :meth:`iter_run`.  Memory is bounded (the span is integrated
        in chunks of ``ADVANCE_CHUNK`` steps)."""
        if theta1 is None:
            theta1 = self._cmd_value
        t_target = _finite_scalar('advance_to: t_target', t_target, TIME_LIMIT, 's')
        theta1 = _finite_scalar('advance_to: theta1', theta1, ANGLE_LIMIT, 'rad')
        n = int(math.floor((t_target - self.t) / self.dt + 1e-9))
        limit = self.max_advance_steps if max_steps is None else int(max_steps)
        if n > limit:
            raise ValueError(
                f'advance_to({t_target:g}): {n:.3g} steps of {self.dt:g} s from t = '
                f'{self.t:g} s exceed max_steps = {limit:.3g} (~{limit * 3e-7:.0f} s of '
                'computation); advance in smaller spans, pass max_steps=..., or use '
                'Simulator.run / iter_run for long offline runs')
        if n > 0:
            if self.interpolation == 'hold' or t_target <= self._cmd_t:
                slope = 0.0
            else:
                slope = (theta1 - self._cmd_value) / (t_target - self._cmd_t)
            left = n
            while left > 0:
                m = min(left, ADVANCE_CHUNK)
                args = (self._u, self._v, self._a, self._theta1, self._theta1_dot, self._t0,
                        self._k, self.dt, m, self._cmd_t,
                        self._cmd_value if slope != 0.0 else theta1, slope, t_target, theta1,
                        self._stats, self._ctl, self._load_on_grid(m))
                if self._ap is None:
                    done, status = advance_segment(self.p, self.C, *args)
                else:
                    done, status = advance_segment_adaptive(self.p, self._ap, self.C, *args,
                                                            self._log)
                self._after_kernel(done, status,
                                   self._segment_value(done, theta1, slope, t_target), slope)
                left -= m
            self._load.trim(self.t)
        if t_target > self._cmd_t or n > 0:
            self._cmd_t = max(t_target, self._cmd_t)
            self._cmd_value = theta1
        return max(n, 0)

    # ---- a load torque that arrives in real time ------------------------------------------
    def push_load(self, t: float, torque: float) -> bool:
        """A load torque sample [N m] at time ``t`` for :meth:`advance_to`: it applies from
        ``t`` until the next sample's time (zero-order hold: causal, so a live stream needs
        no look-ahead; ``SampledLoad(..., interpolation='hold')`` is its offline twin);
        before the first sample the load is the model's constant ``load.output_torque``.
        Times must increase (ValueError otherwise).  A sample at or before the simulator's
        time applies from its time on (returns False: it came late); True otherwise."""
        t = _finite_scalar('push_load: t', t, TIME_LIMIT, 's')
        torque = _finite_scalar('push_load: torque', torque, LOAD_LIMIT, 'N m')
        return self._load.push(t, torque, self.t, self.load_torque)

    def hold_load(self, torque: float) -> None:
        """The load torque [N m] from the simulator's time on, held (replaces every pushed
        sample)."""
        torque = _finite_scalar('hold_load: torque', torque, LOAD_LIMIT, 'N m')
        self._load.hold(torque, self.t)

    @property
    def load_torque(self) -> float:
        """The load torque on the antenna at the simulator's time [N m]."""
        if self._load.live:
            return float(self._load.at(np.array([self.t]))[0])
        return load_torque_of(self.p)

    def _load_on_grid(self, m: int) -> np.ndarray:
        """The pushed load at the next m + 1 grid points (NO_LOAD: none pushed)."""
        return self._load.on_grid(self._t0, self._k, m, self.dt)

    def resync(self, t: float) -> None:
        """Jump the simulated clock to ``t`` without integrating (dropped catch-up time)."""
        t = _finite_scalar('resync: t', t, TIME_LIMIT, 's')
        self._t0 = t - self._k * self.dt
        self._cmd_t = min(self._cmd_t, self.t)

    def _segment_value(self, done: int, theta1: float, slope: float,
                       t_target: float) -> float:
        """theta1 at the last completed grid point of an advance_segment call."""
        grid = self._t0 + float(self._k + done) * self.dt
        if slope == 0.0 or grid >= t_target:
            return float(theta1)
        return self._cmd_value + slope * (grid - self._cmd_t)

    def _run_kernel(self, th: np.ndarray, td: np.ndarray, stride: int, ru: np.ndarray,
                    rv: np.ndarray, ra: np.ndarray, raux: np.ndarray,
                    load: np.ndarray | None = None) -> None:
        load = NO_LOAD if load is None else load
        if self._ap is None:
            done, status = advance(self.p, self.C, self._u, self._v, self._a, th, td, self.dt,
                                   stride, ru, rv, ra, raux, self._stats, self._ctl, load)
        else:
            done, status = advance_adaptive(self.p, self._ap, self.C, self._u, self._v,
                                            self._a, th, td, self.dt, self.t, stride, ru, rv,
                                            ra, raux, self._stats, self._ctl, load, self._log)
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
            chunk_steps: int = 1 << 18, max_bytes: float | None = None,
            load: LoadSignal | None = None) -> Trajectory:
        """Integrate the profile from the current state to ``t_end`` and record every
        ``record_every`` steps (row 0 = current state), all in memory.  ``load``: a load
        torque signal on the antenna (:mod:`worm_gear_sim.dynamics.load`) in place of the model's
        constant ``load.output_torque``.

        Raises ValueError before integrating when the recorded rows would take more than
        ``max_bytes`` (default :data:`RUN_MEMORY_LIMIT`): stream long runs with
        :meth:`iter_run` / :func:`simulate_to_csv` (bounded memory), or record fewer rows."""
        n_total, stride = self._plan(t_end, record_every)
        n_rec = n_total // stride
        need = (n_rec + 1) * ROW_BYTES
        limit = RUN_MEMORY_LIMIT if max_bytes is None else max_bytes
        if need > limit:
            raise ValueError(
                f'recording {n_rec + 1:.4g} rows to t_end = {t_end:g} s (dt = {self.dt:g} s, '
                f'every {stride} step(s)) needs {need / 1e9:.3g} GB, above the limit '
                f'max_bytes = {limit / 1e9:.3g} GB: raise record_every, shorten t_end, pass '
                'max_bytes=..., or stream it (Simulator.iter_run, simulate_to_csv: bounded '
                'memory)')
        t_rec = np.empty(n_rec + 1)
        th_rec, td_rec = np.empty(n_rec + 1), np.empty(n_rec + 1)
        u_rec, v_rec, a_rec = (np.empty((n_rec + 1, 3)) for _ in range(3))
        aux_rec = np.empty((n_rec + 1, N_AUX))
        self._row0(t_rec, th_rec, td_rec, u_rec, v_rec, a_rec, aux_rec)
        row = 1
        for m, fill in self._chunks(profile, n_total, stride, chunk_steps, load):
            sl = slice(row, row + m)
            fill(t_rec[sl], th_rec[sl], td_rec[sl], u_rec[sl], v_rec[sl], a_rec[sl],
                 aux_rec[sl])
            row += m
        self._cmd_t, self._cmd_value = self.t, self._theta1
        return Trajectory(t=t_rec[:row], theta1=th_rec[:row], theta1_dot=td_rec[:row],
                          theta=u_rec[:row], omega=v_rec[:row], alpha=a_rec[:row],
                          aux=aux_rec[:row],
                          output_per_input=self.model.output_per_input,
                          profile=profile.describe(), stats=self.stats)

    def iter_run(self, profile: Profile, t_end: float, record_every: int = 1,
                 chunk_steps: int = 1 << 16,
                 load: LoadSignal | None = None) -> Iterator[Trajectory]:
        """:meth:`run` as a stream (``load`` as there): yields Trajectory chunks of at
        most ``chunk_steps // record_every`` rows (the first starts with the current
        state), so memory stays bounded whatever ``t_end`` is.  Concatenated, the chunks
        equal :meth:`run` bit for bit.  Stopping the iteration early leaves the simulator
        at the last chunk's end."""
        n_total, stride = self._plan(t_end, record_every)
        first = True
        desc, ratio = profile.describe(), self.model.output_per_input

        def make(rows: int) -> tuple[np.ndarray, ...]:
            return (np.empty(rows), np.empty(rows), np.empty(rows), np.empty((rows, 3)),
                    np.empty((rows, 3)), np.empty((rows, 3)), np.empty((rows, N_AUX)))

        def traj(arrs: tuple[np.ndarray, ...]) -> Trajectory:
            return Trajectory(t=arrs[0], theta1=arrs[1], theta1_dot=arrs[2], theta=arrs[3],
                              omega=arrs[4], alpha=arrs[5], aux=arrs[6], output_per_input=ratio,
                              profile=desc, stats=self.stats)

        for m, fill in self._chunks(profile, n_total, stride, chunk_steps, load):
            off = 1 if first else 0
            arrs = make(m + off)
            if first:
                self._row0(*arrs)
            fill(*(a[off:] for a in arrs))
            self._cmd_t, self._cmd_value = self.t, self._theta1
            first = False
            yield traj(arrs)
        if first:                      # nothing to integrate: the current state alone
            arrs = make(1)
            self._row0(*arrs)
            yield traj(arrs)

    def _plan(self, t_end: float, record_every: int) -> tuple[int, int]:
        t_end = _finite_scalar('t_end', t_end, TIME_LIMIT, 's')
        n_total = int(math.floor((t_end - self.t) / self.dt + 1e-9))
        if n_total < 0:
            raise ValueError(f't_end {t_end} is before the current time {self.t}')
        stride = int(record_every)
        if stride < 1:
            raise ValueError(f'record_every must be >= 1, got {record_every!r}')
        return n_total, stride

    def _row0(self, t_rec: np.ndarray, th_rec: np.ndarray, td_rec: np.ndarray,
              u_rec: np.ndarray, v_rec: np.ndarray, a_rec: np.ndarray,
              aux_rec: np.ndarray) -> None:
        t_rec[0], th_rec[0], td_rec[0] = self.t, self._theta1, self._theta1_dot
        u_rec[0], v_rec[0], a_rec[0] = self._u, self._v, self._a
        record_aux(self.p, self._u, self._v, self._theta1, self._ctl[C_MU], aux_rec[0])

    def _chunks(self, profile: Profile, n_total: int, stride: int, chunk_steps: int,
                load: LoadSignal | None = None) -> Iterator[tuple[int, Callable[..., None]]]:
        """Yield (rows, fill) per chunk of whole strides; ``fill(t, th, td, u, v, a, aux)``
        integrates the chunk writing its recorded rows into the given arrays."""
        chunk = max(stride, (int(chunk_steps) // stride) * stride)
        done_total = 0
        while done_total < n_total:
            n = min(chunk, n_total - done_total)
            m = n // stride

            def fill(t_rec: np.ndarray, th_rec: np.ndarray, td_rec: np.ndarray,
                     u_rec: np.ndarray, v_rec: np.ndarray, a_rec: np.ndarray,
                     aux_rec: np.ndarray, n: int = n, m: int = m) -> None:
                ks = self._k + np.arange(1, n + 1)
                grid = self._t0 + ks * self.dt
                th = np.concatenate(([self._theta1], profile.theta1(grid)))
                td = np.concatenate(([self._theta1_dot], profile.theta1_dot(grid)))
                self._run_kernel(th, td, stride, u_rec, v_rec, a_rec, aux_rec,
                                 load_grid(load, self.t, grid))
                idx = np.arange(1, m + 1) * stride
                t_rec[:], th_rec[:], td_rec[:] = grid[idx - 1], th[idx], td[idx]

            yield m, fill
            done_total += n


#: Default memory limit of an in-memory run (Simulator.run / simulate).
RUN_MEMORY_LIMIT = 2e9
