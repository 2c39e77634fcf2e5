# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""This module holds :class:`RealtimePredictor`, the real-time pipeline's public face: its
configuration (``prepare``, ``reconfigure``), the callers' clocks, the restart on a clock
going back or on another input, and the calls of the two input paths it owns
(:mod:`.stamped_path`, :mod:`.command_path`) on their shared :mod:`.sample_path`.  The rules
are written out in the package's docstring (:mod:`worm_gear_sim.realtime`)."""

from __future__ import annotations

from .._support.stepwise import run_steps
from ..compensation.blend import unwrap
from ..compensation.streaming import Compensator
from ..config.usable import Config
from ..dynamics.model import DriveModel
from ..dynamics.simulation import Simulator
from ..schema.sections import LOAD_LIMIT
from .admission import Admission
from .command_path import CommandPath
from .command_timing import CommandQueue, StreamClock
from .outputs import COUNTER_NAMES, Output, Prepared, Reject
from .preparation import design_steps, prepare_steps
from .sample_path import SamplePath
from .stamped_path import StampedPath

__all__ = ['RealtimePredictor', 'CONFIRM_SAMPLES']

CONFIRM_SAMPLES = 3          # agreeing candidates that confirm a jump or a new timeline
CLOCK_TOLERANCE_NS = 1_000_000  # now_ns may step back this much without a restart


class RealtimePredictor:
    """The real-time pipeline: samples in, corrections and predictions out (module doc).

    ``model``: a :class:`DriveModel` or a validated :class:`Config` (the plant model AND the
    compensator's nominal design; built once and shared by both). ``compensate``: compute
    corrections; ``apply_compensation``: drive the simulator with theta1_ref + delta (None:
    ``node.compensation_applied``); ``simulate``: run the simulator at all (False: corrections
    only, as ``feedforward_series``); ``base_ns``: the time origin (None: the first accepted
    stamp); ``sim_time``: the Float64 path's reception times are /clock readings;
    ``max_stamp_age`` / ``max_stamp_lead`` [s]: accepted stamp window around ``now_ns`` (lead:
    plus the preview time); ``stale_margin`` [s]: lateness allowed to samples before ``hold``
    declares the stream stale; ``confirm_samples``: agreeing candidates that confirm a jump or
    a restart."""

    def __init__(self, model: DriveModel | Config, *, compensate: bool = True,
                 apply_compensation: bool | None = None, simulate: bool = True,
                 base_ns: int | None = None, sim_time: bool = False,
                 max_stamp_age: float = 1.0, max_stamp_lead: float = 1.0,
                 stale_margin: float = 0.02, confirm_samples: int = CONFIRM_SAMPLES) -> None:
        if confirm_samples < 2:
            raise ValueError('confirm_samples must be >= 2')
        if not (max_stamp_age > 0.0 and max_stamp_lead > 0.0 and stale_margin >= 0.0):
            raise ValueError('max_stamp_age and max_stamp_lead must be > 0, stale_margin >= 0')
        self.counters: dict[str, int] = dict.fromkeys(COUNTER_NAMES, 0)
        self.compensate = bool(compensate)
        self._apply_arg = apply_compensation
        self.max_stamp_age_ns = int(round(max_stamp_age * 1e9))
        self.max_stamp_lead_ns = int(round(max_stamp_lead * 1e9))
        self.confirm_samples = int(confirm_samples)
        self.compensation_error = ''
        model = DriveModel.of(model)
        self.sim: Simulator | None = Simulator(model, 0.0, 0.0) if simulate else None
        if self.sim is not None:                      # compile / load the kernel now
            self.sim.advance_to(10 * self.sim.dt, 0.0)
            self.sim.reset(0.0, 0.0)
        self._admission = Admission(0.0, 0.0, self.max_stamp_age_ns, 0)
        self._samples = SamplePath(self.sim, self.counters,
                                   None if base_ns is None else int(base_ns))
        self._stamped = StampedPath(self._samples, self._admission, self.confirm_samples,
                                    int(round(stale_margin * 1e9)), self._restart)
        self._commands = CommandPath(self._samples, self._admission, self.confirm_samples,
                                     int(round(1e9 / model.config.node.publish_rate_hz)),
                                     bool(sim_time), self._restart, self._init_state)
        self._set_config(self._design(model))
        self._clocks: dict[str, int] = {}          # per clock: 'stamped' | 'command'
        self._init_state()

    # ---- configuration -----------------------------------------------------------------
    def _design(self, model: DriveModel) -> Prepared:
        return run_steps(design_steps(model, self.compensate))

    def _set_config(self, prepared: Prepared, blend: float = 0.0) -> None:
        self.model = prepared.model
        self.config = config = prepared.model.config
        node = config.node
        apply = node.compensation_applied if self._apply_arg is None else bool(self._apply_arg)
        self._samples.configure(prepared, apply, blend)
        self.compensation_error = prepared.error
        adm = self._admission
        adm.lead_ns = self.max_stamp_lead_ns + self._samples.preview_ns
        adm.max_jump = self._stamped.chain.max_jump = self._commands.chain.max_jump = \
            node.max_command_jump
        adm.max_abs = node.max_command_abs
        self._commands.timing = node.command_timing

    def prepare(self, config: DriveModel | Config, trial: Simulator | None = None
                ) -> Prepared:
        """Design for ``config`` off the real-time path (its model, the compensator design,
        a trial of the simulator's parameters on ``trial``, default a
        :meth:`~worm_gear_sim.dynamics.stepping.Stepper.trial_copy` of the simulator taken
        now; it only reads the pipeline, so another thread may run it while samples flow).
        Raises ValueError (ConfigError) if the simulator cannot take it (time step changed,
        non-finite acceleration).  Every other method belongs to the executor's thread.
        In steps: :func:`~.preparation.prepare_steps`."""
        return run_steps(prepare_steps(self, config, trial))

    def reconfigure(self, new: DriveModel | Config | Prepared, blend: float = 0.0,
                    reseat: bool = False) -> None:
        """Swap in a validated configuration (or what :meth:`prepare` made of one),
        keeping time, state, reference history and pending corrections; ``blend`` > 0: the
        correction hands over to the new compensator over that long [s] (:mod:`.blend`);
        ``reseat``: the simulated drive's deflections move to the new set's equilibrium
        (a return to the declared set: :meth:`~worm_gear_sim.dynamics.stepping.Stepper.
        reconfigure`).  On ValueError nothing changed."""
        prepared = new if isinstance(new, Prepared) else self.prepare(new)
        if self.sim is not None:
            self.sim.reconfigure(prepared.model, reseat)
        self._set_config(prepared, blend)      # no retraction to the old set
        period = float(self._samples.period_ns)
        if self._commands.stream.period0 != period:  # pragma: no cover - read-only
            self._commands.stream = StreamClock(period)
        self.counters['reconfigurations'] += 1

    def reset(self) -> None:
        """Forget the stream (the next accepted sample or tick starts afresh at rest);
        the counters are kept."""
        self._init_state()
        self._commands.clear()
        self._clocks = {}

    def _init_state(self) -> None:
        self._stamped.drop_candidates()
        self._samples.init_state()

    # ---- properties --------------------------------------------------------------------
    @property
    def started(self) -> bool:
        return self._samples.state.started

    @property
    def stale(self) -> bool:
        return self._samples.state.stale

    @property
    def base_ns(self) -> int | None:
        """The time origin: stamp_ns maps to (stamp_ns - base_ns) * 1e-9 s."""
        return self._samples.state.base_ns

    @property
    def last_delta(self) -> float:
        """The newest correction computed [rad]."""
        return self._samples.state.delta

    @property
    def last_stamp_ns(self) -> int:
        """Stamp of the last accepted sample (0 before the first)."""
        return self._samples.state.last_real_ns

    @property
    def stream_lag_ns(self) -> int:
        """How much the last sample's arrival [caller's clock] lagged its stamp, or 0."""
        st = self._samples.state
        return max(0, st.last_arrival_ns - st.last_real_ns)

    @property
    def stale_after_ns(self) -> int:
        """G: a stamp gap longer than this is a pause (module doc)."""
        return self._samples.state.gap_ns

    @property
    def stale_margin_ns(self) -> int:
        """Lateness allowed to samples before ``hold`` declares the stream stale [ns]."""
        return self._stamped.stale_margin_ns

    @property
    def pending(self) -> int:
        """Samples whose correction waits for the preview."""
        return len(self._samples.state.pending)

    @property
    def queued_commands(self) -> int:
        """Float64 commands waiting for a tick."""
        return len(self._commands.queue)

    @property
    def compensator(self) -> Compensator | None:
        return unwrap(self._samples.comp)

    @property
    def stream_clock(self) -> StreamClock:
        return self._commands.stream

    @property
    def resync_candidates(self) -> int:
        """Rejected-looking samples kept as resync candidates, not yet counted: each
        ends accepted (a confirmed resync) or rejected (the chain breaks)."""
        return len(self._stamped.chain)

    @property
    def apply_compensation(self) -> bool:
        """The simulator is driven with theta1_ref + delta."""
        return self._samples.apply_compensation

    @property
    def preview_ns(self) -> int:
        """``compensation.preview_time`` [ns]."""
        return self._samples.preview_ns

    @property
    def last_error(self) -> str:
        """The message of the last warning event ('' before the first)."""
        return self._samples.last_error

    @property
    def sim_time(self) -> bool:
        """The Float64 path's reception times are /clock readings (the node sets it)."""
        return self._commands.sim_time

    @sim_time.setter
    def sim_time(self, on: bool) -> None:
        self._commands.sim_time = bool(on)

    @property
    def _cmd(self) -> float | None:
        """The last accepted Float64 command (read by the node's tests)."""
        return self._commands.cmd

    @property
    def _queue(self) -> CommandQueue:
        """The queued Float64 commands (read by the node's tests)."""
        return self._commands.queue

    @property
    def load_torque(self) -> float:
        """The load torque on the simulated antenna now [N m]."""
        if self.sim is None:
            return float(self.config.load.output_torque)
        return self.sim.load_torque

    # ---- the stamped path --------------------------------------------------------------
    def push(self, stamp_ns: int, theta1_ref: float, *, now_ns: int | None = None) -> Output:
        """A stamped reference sample (see the module doc for the rules).  ``now_ns``: the
        caller's clock at reception (same clock as the stamps); None skips the stamp
        window and the clock-restart check (offline)."""
        out = Output()
        self.counters['samples_received'] += 1
        if now_ns is not None:
            now_ns = int(now_ns)
            self._check_clock(now_ns, out, 'stamped')
        self._stamped.push(int(stamp_ns), float(theta1_ref), now_ns, out)
        return out

    def push_load(self, stamp_ns: int, torque: float, *, now_ns: int | None = None
                  ) -> Reject | None:
        """A stamped load torque sample on the antenna [N m] (positive turning it back, the
        sign of ``load.output_torque``), applied to the simulated drive in stamp order with
        the references: linear between load samples, held after the last; before the first
        the constant ``load.output_torque``.  The rules of :meth:`push` for stamps and
        values (NaN, inf, beyond +-LOAD_LIMIT, zero or negative stamp, outside the stamp
        window of ``now_ns``, a duplicate or earlier stamp than the last load sample's):
        rejected, counted under ``rejected_load_<reason>``, nothing changed; returns the
        reason (None: accepted).  A sample stamped before the simulator's time applies from
        that time on (``late_load_samples``); one before the first reference is kept and
        applied when the simulation starts."""
        c = self.counters
        c['load_samples_received'] += 1
        stamp_ns = int(stamp_ns)
        torque = float(torque)
        adm = self._admission
        reason = adm.value_reason(torque, LOAD_LIMIT)
        if reason is None:
            reason = adm.stamp_reason(stamp_ns, None if now_ns is None else int(now_ns))
        if reason is None:
            reason = adm.order_reason(stamp_ns, self._samples.state.last_load_ns)
        if reason is not None:
            c['rejected_load_samples'] += 1
            c['rejected_load_' + reason.value] += 1
            return reason
        self._samples.add_load(stamp_ns, torque)
        return None

    def hold(self, now_ns: int) -> Output:
        """Stamped path, from a slow timer: if the stream is stale (no sample has arrived
        for G + ``stale_margin``, and the stream's time, ``now_ns - stream_lag_ns``, passed its
        last stamp by as much: a lagging stream is stale only when samples stop), insert the
        rest samples due, release the corrections waiting for them, advance the simulator
        holding the last command up to the stream's time and return that held prediction."""
        out = Output()
        now_ns = int(now_ns)
        self._check_clock(now_ns, out, 'stamped')
        self._stamped.hold(now_ns, out)
        return out

    def finish(self) -> Output:
        """End of a finite stream (offline): the reference rests from its last sample;
        every pending correction is released (as ``hold`` would, much later)."""
        out = Output()
        self._samples.finish(out)
        return out

    # ---- the Float64 path --------------------------------------------------------------
    def push_command(self, receive_ns: int, theta1_ref: float) -> Output:
        """An unstamped command received at ``receive_ns`` (the node's clock: monotonic,
        or /clock with ``sim_time``).  Validated at once (value rules of ``push``; a jump
        is confirmed by ``confirm_samples`` agreeing commands, then the next tick restarts
        at rest at the new level); queued until ``tick``."""
        out = Output()
        self._commands.push_command(receive_ns, theta1_ref, out)
        return out

    def tick(self, now_ns: int) -> Output:
        """Float64 path, at ``node.publish_rate_hz``: the queued commands become samples
        (``node.command_timing``), the simulator holds the last command up to ``now_ns``
        (or to the last corrected sample when the applied compensation waits for a
        preview) and one prediction of that instant is returned.  Nothing before the first
        command."""
        out = Output()
        now_ns = int(now_ns)
        self._check_clock(now_ns, out, 'command')
        self._commands.tick(now_ns, out)
        return out

    # ---- clocks and restarts -----------------------------------------------------------
    def _check_clock(self, now_ns: int, out: Output, path: str) -> bool:
        """A caller clock that went backwards beyond the tolerance restarts the pipeline.
        Each input path has its own clock (``path``: 'stamped' for ``push``/``hold``,
        'command' for ``tick``): the node reads ROS time for one and the monotonic clock
        for the other, so switching paths is not a clock going back.  A retracted stale
        hold leaves the clocks as they are."""
        clocks = self._clocks
        last = clocks.get(path)
        clocks[path] = now_ns if last is None else max(now_ns, last)
        if last is not None and now_ns < last - CLOCK_TOLERANCE_NS:
            clocks[path] = now_ns
            self.counters['clock_restarts'] += 1
            self._restart(out, 'clock_restart', f'clock went backwards by '
                          f'{(last - now_ns) * 1e-9:.6g} s: the pipeline restarts')
            return True
        return False

    def _restart(self, out: Output, kind: str, message: str, drop: bool = True) -> None:
        """Start afresh: the corrections waiting for a preview are dropped (``drop``) or
        released; the queued commands and the stream clock are forgotten."""
        if kind == 'input_changed':
            self.counters['input_switches'] += 1
        samples = self._samples
        if samples.state.started:
            if drop:
                self.counters['corrections_dropped'] += sum(
                    1 for p in samples.state.pending if p[2])
            else:
                samples.release(None, out, predict=False)
        samples.event(out, kind, message)
        self._init_state()
        self._commands.queue.clear()
        self._commands.stream.reset()
