# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The simulator side of the real-time pipeline: :class:`SimulatedDrive` advances the
:class:`~worm_gear_sim.dynamics.simulation.Simulator` with the applied command samples, never more
than ``node.max_catch_up`` seconds for one call (the rest is skipped: an overrun), keeps
the last good state after a simulation error, and returns :class:`Prediction` records.
The rules of when it is driven are the pipeline's (:mod:`.predictor`)."""

from __future__ import annotations

import copy
import math
from collections.abc import Callable

from ..dynamics.simulation import Simulator
from ..dynamics.stepping import SimulationError
from .outputs import Output, Prediction

__all__ = ['SimulatedDrive', 'HOLD_EPS']

HOLD_EPS = 0.5e-9            # s: 'hold' steps just after the sample time (stamps are whole ns)


class SimulatedDrive:
    """The simulated drive of one pipeline.  ``sim``: the simulator (None: corrections
    only, nothing is simulated); ``counters``: the pipeline's counters (``steps``,
    ``late_for_simulation``, ``overruns``, ``dropped_time_ns``, ``simulation_errors``,
    ``predictions`` are counted here); ``event(out, kind, message)``: the pipeline's event
    log.  ``apply_compensation``, ``max_catch_up`` [s] and ``output_per_input`` are set by
    the pipeline's configuration."""

    def __init__(self, sim: Simulator | None, counters: dict[str, int],
                 event: Callable[[Output, str, str], None]) -> None:
        self.sim = sim
        self.counters = counters
        self._event = event
        self.apply_compensation = False
        self.max_catch_up = math.inf
        self.output_per_input = 0.0
        self.clear()

    def clear(self) -> None:
        """Forget the stream: nothing driven yet."""
        self.drive_t = -math.inf        # last command time given to the simulator [s]
        self.t_start = math.nan         # time of the first sample [s]
        self.held = 0.0                 # command the simulator holds [rad]
        self.held_ref = 0.0             # reference of that command [rad]

    def __copy__(self) -> SimulatedDrive:
        """A copy that drives its own copy of the simulator (:meth:`Stepper.__copy__
        <worm_gear_sim.dynamics.stepping.Stepper.__copy__>`), counting into the same
        counters and event log."""
        new = object.__new__(SimulatedDrive)
        new.__dict__.update(self.__dict__)
        new.sim = copy.copy(self.sim)
        return new

    def restore(self, earlier: SimulatedDrive) -> None:
        """Go back to ``earlier``, a copy of this drive taken before (:func:`copy.copy`):
        its simulator's state and what it was driven with."""
        if self.sim is not None and earlier.sim is not None:
            self.sim.restore(earlier.sim)
        self.drive_t, self.t_start = earlier.drive_t, earlier.t_start
        self.held, self.held_ref = earlier.held, earlier.held_ref

    def start(self, cmd: float, ref: float, t: float, load: float | None = None) -> None:
        """The first sample: the drive starts at rest at command ``cmd`` at ``t``; ``load``
        [N m]: under that load torque, held from ``t`` (the load samples pushed before
        are dropped), None: the simulator's."""
        self.held, self.held_ref = cmd, ref
        if self.sim is not None:
            self.sim.reset(cmd, t, load_torque=load)
            if load is not None:
                self.sim.hold_load(load)
            self.drive_t = t
        self.t_start = t

    def drive(self, ns: int, t: float, cmd: float, ref: float, out: Output,
              predict: bool) -> None:
        """Advance the simulator to ``t`` with the command sample ``cmd`` (reference
        ``ref``); with ``predict`` a prediction stamped ``ns`` goes to ``out``."""
        sim = self.sim
        self.held, self.held_ref = cmd, ref
        if sim is None:
            return
        if t < self.drive_t:           # already integrated past it: applies from there
            self.counters['late_for_simulation'] += 1
            t = self.drive_t
        if t == self.t_start and sim.t == t:
            # the first sample's own command (e.g. its correction, once a preview allowed
            # it): the drive has not moved yet, so it starts at rest there
            try:
                sim.reset(cmd, t)
            except ValueError as exc:  # pragma: no cover - cmd is finite
                self._failed(sim, exc, t, out)
            if predict:
                out.predictions.append(self.prediction(ns, False))
            return
        self._catch_up(sim, t, out)
        try:
            if sim.interpolation == 'hold':   # the grid point at or after t takes cmd
                self.counters['steps'] += sim.advance_to(t - HOLD_EPS, None)
            self.counters['steps'] += sim.advance_to(t, cmd)
        except (SimulationError, ValueError) as exc:
            self._failed(sim, exc, t, out)
        self.drive_t = max(self.drive_t, t)
        if predict:
            out.predictions.append(self.prediction(ns, False))

    def hold_to(self, ns: int, t: float, held: bool, out: Output) -> None:
        """Hold the last command up to ``t`` and predict there (stamp ``ns``; ``held``:
        the prediction is a held one, the stream being stale)."""
        sim = self.sim
        if sim is None:
            return
        if t > self.drive_t:
            self._catch_up(sim, t, out)
            try:
                self.counters['steps'] += sim.advance_to(t, self.held)
            except (SimulationError, ValueError) as exc:
                self._failed(sim, exc, t, out)
            self.drive_t = t
        out.predictions.append(self.prediction(ns, held))

    def _catch_up(self, sim: Simulator, t: float, out: Output) -> None:
        behind = t - sim.t
        cap = self.max_catch_up
        if behind > cap:
            sim.resync(t - cap)
            c = self.counters
            c['overruns'] += 1
            c['dropped_time_ns'] += int(round((behind - cap) * 1e9))
            self._event(out, 'overrun', f'{behind:.4g} s behind: integrated the last {cap:g} s '
                        '(node.max_catch_up) and skipped the rest')

    def _failed(self, sim: Simulator, exc: Exception, t: float, out: Output) -> None:
        self.counters['simulation_errors'] += 1
        self._event(out, 'simulation_error', f'simulation error: {exc}; keeping the last good '
                    f'state (t = {sim.t:.6f} s) and continuing from t = {t:.6f} s')
        sim.resync(t)

    def prediction(self, ns: int, held: bool) -> Prediction:
        """The simulator's state as a prediction stamped ``ns``."""
        sim = self.sim
        assert sim is not None, 'a prediction needs the simulator'
        pos, vel, eff = sim.joint_state()
        th1, th2, th4 = pos[0], pos[1], pos[3]
        ref = self.held_ref if self.apply_compensation else th1
        self.counters['predictions'] += 1
        return Prediction(ns, th1, vel[0], pos[1:], vel[1:], eff, ref,
                          th4 - ref * self.output_per_input, th2 - th1, held)
