# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Public simulation API: a stepping :class:`Simulator` for real time and a batch
:func:`simulate` / :func:`simulate_to_csv` for studies.  Both drive the same compiled kernel
(:func:`worm_gear_sim.dynamics.integrator.advance`) on the same grid t = t0 + k dt, through
:class:`~worm_gear_sim.dynamics.stepping.Stepper` (the integration itself); the :class:`Simulator`
adds what a caller with a parameter set needs: the set proven usable first
(:func:`~worm_gear_sim.dynamics.usability.check_usable`, whose trial runs a bare
:class:`~worm_gear_sim.dynamics.stepping.Stepper`), a warning for an under-resolved step, and the
likely cause of a failed integration in its :class:`SimulationError`.  What a run yields
(:class:`Trajectory`, :class:`SimState`, the CSV writer) is in
:mod:`worm_gear_sim.dynamics.trajectory`.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np

from ..schema.parameters import Parameters
from .load import ElasticLoadWarning, LoadSignal, elastic_load_warning
from .modal import StepResolutionWarning, step_resolution_warning
from .model import DriveModel
from .profiles import Profile, make_profile
from .stepping import SimulationError, Stepper
from .trajectory import (
    Trajectory,
    TrajectoryCsvWriter,
)
from .usability import check_usable, diagnose

__all__ = ['Simulator', 'simulate', 'simulate_to_csv', 'KEEP_ROWS', 'record_stride']


class Simulator(Stepper):
    """Stateful Newmark integrator of the worm-gear drive on a fixed grid t0 + k dt
    (:class:`~worm_gear_sim.dynamics.stepping.Stepper`: real time with :meth:`advance_to`, batch
    with :meth:`run` / :meth:`iter_run`) for a parameter set proven usable.

    ``model``: a :class:`DriveModel` (built once, shared with the compensator and the
    studies) or a Config (the simulator builds its model).  ``check``: prove the parameter
    set usable first (:func:`check_usable`, cached per Config; a :class:`ConfigError`
    naming the keys otherwise) and warn when the step does not resolve the highest mode.
    A failed integration's :class:`SimulationError` names its likely cause
    (:func:`~worm_gear_sim.dynamics.usability.diagnose`).
    """

    def __init__(self, model: DriveModel | Parameters, theta1: float = 0.0, t0: float = 0.0,
                 interpolation: str | None = None, *, check: bool = True) -> None:
        config = model.config if isinstance(model, DriveModel) else model
        if check:   # ConfigError naming the keys unless the set can be simulated
            check_usable(config)
        model = DriveModel.of(model)
        if check:   # allowed, but theta2 pointwise is not trustworthy (modal.STEPS_PER_PERIOD)
            msg = step_resolution_warning(model)
            if msg:
                warnings.warn(msg, StepResolutionWarning, stacklevel=2)
        super().__init__(model, theta1, t0, interpolation)

    def reconfigure(self, model: DriveModel | Parameters, reseat: bool = False) -> None:
        """Swap in new (already validated) parameters, keeping time, state and command
        (``reseat``: :meth:`.stepping.Stepper.reconfigure`).  The time step cannot
        change (it is read-only in the node); the set is proven usable first."""
        self._check_time_step(model)
        check_usable(model.config if isinstance(model, DriveModel) else model)
        super().reconfigure(model, reseat)

    def _after_kernel(self, done: int, status: int, theta1_last: float,
                      theta1_dot_last: float) -> None:
        try:
            super()._after_kernel(done, status, theta1_last, theta1_dot_last)
        except SimulationError as exc:
            hint = diagnose(self.config)
            if not hint:
                raise
            raise SimulationError(f'{exc}; {hint}') from None


#: Rows kept in memory by simulate_to_csv for plots and metrics (every k-th row).
KEEP_ROWS = 200_000


def record_stride(dt: float, record_dt: float | None = None, record_every: int = 1) -> int:
    """Integration steps per recorded row: ``record_every``, or with ``record_dt`` [s] the
    whole number of steps of ``dt`` nearest to it (at least 1: every step).  The one rule of
    :func:`simulate`, :func:`simulate_to_csv` and ``worm-gear-sim simulate --output-rate``."""
    if record_dt is None:
        return int(record_every)
    if not (math.isfinite(record_dt) and record_dt >= 0):
        raise ValueError(f'record_dt must be a time step >= 0 s, got {record_dt!r}')
    return max(1, int(round(record_dt / dt)))


def simulate(model: DriveModel | Parameters, profile: Profile | None = None,
             t_end: float | None = None, record_every: int = 1,
             theta1_initial: float | None = None,
             max_bytes: float | None = None, load: LoadSignal | None = None, *,
             record_dt: float | None = None) -> Trajectory:
    """Batch run of ``model`` (a :class:`DriveModel` or a Config) from rest: the config's
    input profile (or ``profile``) to ``t_end``, in memory (up-front ValueError beyond
    ``max_bytes``, see :meth:`Simulator.run`; long runs: :func:`simulate_to_csv`).  A row
    every ``record_every`` steps, or about every ``record_dt`` seconds
    (:func:`record_stride`).  ``load``: a load torque signal
    (:mod:`worm_gear_sim.dynamics.load`) in place of the constant ``load.output_torque``;
    the drive starts at rest under its value at t = 0."""
    config = model.config if isinstance(model, DriveModel) else model
    profile = profile if profile is not None else make_profile(config.input)
    t_end = config.input.end_time if t_end is None else t_end
    stride = record_stride(config.integrator.time_step, record_dt, record_every)
    sim = _at_rest(model, profile, theta1_initial, load)
    return sim.run(profile, t_end, stride, max_bytes=max_bytes, load=load)


def _at_rest(model: DriveModel | Parameters, profile: Profile, theta1_initial: float | None,
             load: LoadSignal | None) -> Simulator:
    """A simulator at rest at the profile's first command, under the load at t = 0."""
    th0 = float(profile.theta1(np.array([0.0]))[0]) if theta1_initial is None else \
        theta1_initial
    sim = Simulator(model, theta1=th0)
    if load is not None:
        sim.reset(th0, load_torque=float(load.torque(np.array([0.0]))[0]))
    msg = elastic_load_warning(sim.model, load)
    if msg:                 # allowed: the model integrates it, a real drive would yield
        warnings.warn(msg, ElasticLoadWarning, stacklevel=3)
    return sim


def simulate_to_csv(model: DriveModel | Parameters, path: str | Path,
                    profile: Profile | None = None, t_end: float | None = None,
                    record_every: int = 1, theta1_initial: float | None = None,
                    header_comment: str = '', keep_rows: int = KEEP_ROWS,
                    chunk_steps: int = 1 << 16, load: LoadSignal | None = None, *,
                    record_dt: float | None = None) -> Trajectory:
    """:func:`simulate` streamed to a CSV file in chunks: memory stays bounded whatever the
    duration.  Returns a thinned Trajectory (every k-th recorded row, at most about
    ``keep_rows`` rows, always the last) for plots and metrics; the file has every
    recorded row and equals ``simulate(...).to_csv(path)``.  The file grows by ~400 bytes
    per row: by default every step is a row (250 000 per simulated second at 4 us, ~100 MB);
    ``record_dt`` (e.g. 1e-3: a row per millisecond, 0.4 MB per simulated second) or
    ``record_every`` keep fewer (:func:`record_stride`)."""
    config = model.config if isinstance(model, DriveModel) else model
    profile = profile if profile is not None else make_profile(config.input)
    t_end = config.input.end_time if t_end is None else t_end
    sim = _at_rest(model, profile, theta1_initial, load)
    n_total, stride = sim._plan(t_end, record_stride(sim.dt, record_dt, record_every))
    n_rows = n_total // stride + 1
    keep = max(1, -(-n_rows // max(1, int(keep_rows))))     # ceil
    kept: list[Trajectory] = []
    row = 0
    last = None
    with TrajectoryCsvWriter(path, header_comment) as w:
        for part in sim.iter_run(profile, t_end, stride, chunk_steps, load=load):
            w.write(part)
            idx = np.arange(row, row + len(part.t))
            sel = (idx % keep) == 0
            if sel.any():
                kept.append(part.rows(sel))
            row += len(part.t)
            last = part
    if last is not None and (row - 1) % keep != 0:
        kept.append(last.rows(slice(-1, None)))
    out = Trajectory.concatenate(kept)
    out.stats = sim.stats
    return out
