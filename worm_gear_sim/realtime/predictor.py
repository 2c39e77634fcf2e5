# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The real-time pipeline's state machine, :class:`RealtimePredictor`: the stamped path
(``push``, ``hold``), the Float64 path (``push_command``, ``tick``), the resync policy, and
the sample path through the compensator; the input checks and the confirmation of a jump
are :mod:`.admission`, the simulator side is :class:`~.drive.SimulatedDrive`.  The rules
are written out in the package's docstring (:mod:`worm_gear_sim.realtime`)."""

from __future__ import annotations

import collections
import copy
import math

from ..compensation import Compensator
from ..dynamics.model import DriveModel
from ..dynamics.simulation import Simulator
from ..params import Config
from ..schema import LOAD_LIMIT
from .admission import Admission, Candidate, JumpConfirmation
from .blend import BlendedCompensator, unwrap
from .command_timing import CommandQueue, StreamClock
from .drive import SimulatedDrive
from .outputs import COUNTER_NAMES, Correction, Event, Output, Prepared, Reject

__all__ = ['RealtimePredictor', 'STALE_PERIODS', 'STALE_MAX_INTERVAL', 'CONFIRM_SAMPLES']

STALE_PERIODS = 3.5          # tick periods without a sample: the reference rests
STALE_MAX_INTERVAL = 0.05    # s: sample intervals longer than this are pauses, not a rate
CONFIRM_SAMPLES = 3          # agreeing candidates that confirm a jump or a new timeline
RESTART_MIN_BACK_NS = 100_000_000  # a stamp this much older may start a new timeline
CLOCK_TOLERANCE_NS = 1_000_000  # now_ns may step back this much without a restart
INFO_EVENTS = ('started', 'stream_resumed')
RETRACTED_COUNTS = ('overruns', 'dropped_time_ns', 'rest_samples')   # a stale hold's
LOAD_PENDING = 1000     # load samples kept from before the first reference (10 s at 100 Hz)


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
        self._explicit_base = None if base_ns is None else int(base_ns)
        self.sim_time = bool(sim_time)
        self.max_stamp_age_ns = int(round(max_stamp_age * 1e9))
        self.max_stamp_lead_ns = int(round(max_stamp_lead * 1e9))
        self.stale_margin_ns = int(round(stale_margin * 1e9))
        self.confirm_samples = int(confirm_samples)
        self.compensation_error = ''
        self.last_error = ''
        self._comp: Compensator | BlendedCompensator | None = None
        model = DriveModel.of(model)
        self.sim: Simulator | None = Simulator(model, 0.0, 0.0) if simulate else None
        if self.sim is not None:                      # compile / load the kernel now
            self.sim.advance_to(10 * self.sim.dt, 0.0)
            self.sim.reset(0.0, 0.0)
        self._drive = SimulatedDrive(self.sim, self.counters, self._event)
        self._queue = CommandQueue()
        self._admission = Admission(0.0, 0.0, self.max_stamp_age_ns, 0)
        self._chain = JumpConfirmation(self.confirm_samples, 0.0)      # stamped candidates
        self._cmd_chain = JumpConfirmation(self.confirm_samples, 0.0)  # Float64 candidates
        self._set_config(self._design(model))
        self._stream = StreamClock(float(self._period_ns))
        self._last_now_ns: dict[str, int] = {}    # per clock: 'stamped' | 'command'
        self._last_tick_ns = 0
        self._cmd: float | None = None             # last accepted Float64 command
        self._init_state()

    # ---- configuration -----------------------------------------------------------------
    def _design(self, model: DriveModel) -> Prepared:
        if not self.compensate:
            return Prepared(model, None)
        try:
            return Prepared(model, Compensator(model))
        except Exception as exc:  # noqa: BLE001 - run uncompensated, say why
            return Prepared(model, None, f'{type(exc).__name__}: {exc}')

    def _set_config(self, prepared: Prepared) -> None:
        self.model = prepared.model
        self.config = config = prepared.model.config
        node = config.node
        self.apply_compensation = node.compensation_applied if self._apply_arg is None \
            else bool(self._apply_arg)
        drive = self._drive
        drive.apply_compensation = self.apply_compensation
        drive.max_catch_up = node.max_catch_up
        drive.output_per_input = self.model.output_per_input
        self._period_ns = int(round(1e9 / node.publish_rate_hz))
        self._gap0_ns = int(round(STALE_PERIODS * self._period_ns))
        comp = prepared.compensator
        if comp is not None and self._comp is not None:
            comp.copy_history(self._comp)
        self._comp = comp
        self.compensation_error = prepared.error
        self.preview_ns = int(round(config.compensation.preview_time * 1e9))
        adm = self._admission
        adm.lead_ns = self.max_stamp_lead_ns + self.preview_ns
        adm.max_jump = self._chain.max_jump = self._cmd_chain.max_jump = node.max_command_jump
        adm.max_abs = node.max_command_abs
        span = 0.0 if comp is None else comp.filter.lag_span + comp.preview
        self._rest_count = int(math.ceil(span * 1e9 / self._period_ns)) + 2
        if self.sim is not None:
            self.sim.interpolation = node.command_interpolation

    def prepare(self, config: DriveModel | Config, trial: Simulator | None = None
                ) -> Prepared:
        """Design for ``config`` off the real-time path (its model, the compensator design,
        a trial of the simulator's parameters on ``trial``, default a
        :meth:`~worm_gear_sim.dynamics.stepping.Stepper.trial_copy` of the simulator taken
        now; it only reads the pipeline, so another thread may run it while samples flow).
        Raises ValueError (ConfigError) if the simulator cannot take it (time step changed,
        non-finite acceleration).  Every other method belongs to the executor's thread."""
        model = DriveModel.of(config)
        if self.sim is not None:
            (self.sim.trial_copy() if trial is None else trial).reconfigure(model)
        return self._design(model)

    def reconfigure(self, new: DriveModel | Config | Prepared, blend: float = 0.0) -> None:
        """Swap in a validated configuration (or what :meth:`prepare` made of one),
        keeping time, state, reference history and pending corrections; ``blend`` > 0: the
        correction hands over to the new compensator over that long [s] (:mod:`.blend`).
        On ValueError nothing changed."""
        prepared = new if isinstance(new, Prepared) else self.prepare(new)
        if self.sim is not None:
            self.sim.reconfigure(prepared.model)
        old = self._comp
        self._set_config(prepared)
        if blend > 0.0 and old is not None and prepared.compensator is not None:
            self._comp = BlendedCompensator(old, prepared.compensator, blend)
        self._before_stale: dict | None = None   # no retraction to the old set
        if self._stream.period0 != float(self._period_ns):  # pragma: no cover - read-only
            self._stream = StreamClock(float(self._period_ns))
        self.counters['reconfigurations'] += 1

    def reset(self) -> None:
        """Forget the stream (the next accepted sample or tick starts afresh at rest);
        the counters are kept."""
        self._init_state()
        self._queue.clear()
        self._stream.reset()
        self._cmd = None
        self._cmd_chain.clear()
        self._last_now_ns = {}

    def _init_state(self) -> None:
        self._drop_candidates()
        self._started = False
        self._mode = ''                          # 'stamped' | 'command' once started
        self._base: int | None = self._explicit_base
        self._last_ns = 0                        # last sample fed (real or rest) [ns]
        self._last_real_ns = 0                   # last accepted sample [ns]
        self._last_real_ref = 0.0                # its theta1_ref [rad]
        self._last_arrival_ns = 0                # caller's clock at that sample [ns]
        self._gap_ns = self._gap0_ns             # G at the last accepted sample
        self._rest_k = 0                         # rest samples inserted after it
        self._pending: collections.deque = collections.deque()   # (ns, theta1_ref, real)
        self._stale = False
        self._before_stale = None          # the state a stale hold retracts to
        self._delta = 0.0                        # last correction [rad]
        self._last_load_ns: int | None = None    # last accepted load sample [ns]
        # load samples before the start: (stamp [ns], N m), the newest LOAD_PENDING
        self._load_pending: collections.deque = collections.deque(maxlen=LOAD_PENDING)
        self._drive.clear()

    # ---- properties --------------------------------------------------------------------
    @property
    def started(self) -> bool:
        return self._started

    @property
    def stale(self) -> bool:
        return self._stale

    @property
    def base_ns(self) -> int | None:
        """The time origin: stamp_ns maps to (stamp_ns - base_ns) * 1e-9 s."""
        return self._base

    @property
    def last_delta(self) -> float:
        """The newest correction computed [rad]."""
        return self._delta

    @property
    def last_stamp_ns(self) -> int:
        """Stamp of the last accepted sample (0 before the first)."""
        return self._last_real_ns

    @property
    def stream_lag_ns(self) -> int:
        """How much the last sample's arrival [caller's clock] lagged its stamp, or 0."""
        return max(0, self._last_arrival_ns - self._last_real_ns)

    @property
    def stale_after_ns(self) -> int:
        """G: a stamp gap longer than this is a pause (module doc)."""
        return self._gap_ns

    @property
    def pending(self) -> int:
        """Samples whose correction waits for the preview."""
        return len(self._pending)

    @property
    def queued_commands(self) -> int:
        """Float64 commands waiting for a tick."""
        return len(self._queue)

    @property
    def compensator(self) -> Compensator | None:
        return unwrap(self._comp)

    @property
    def stream_clock(self) -> StreamClock:
        return self._stream

    # ---- the stamped path --------------------------------------------------------------
    def push(self, stamp_ns: int, theta1_ref: float, *, now_ns: int | None = None) -> Output:
        """A stamped reference sample (see the module doc for the rules).  ``now_ns``: the
        caller's clock at reception (same clock as the stamps); None skips the stamp
        window and the clock-restart check (offline)."""
        out = Output()
        self.counters['samples_received'] += 1
        stamp_ns = int(stamp_ns)
        theta1_ref = float(theta1_ref)
        if now_ns is not None:
            now_ns = int(now_ns)
            self._check_clock(now_ns, out, 'stamped')
        adm = self._admission
        reason = adm.value_reason(theta1_ref)
        if reason is None:
            reason = adm.stamp_reason(stamp_ns, now_ns)
        if reason is None and self._mode == 'command':   # the stamped stream takes over
            self._restart(out, 'input_changed', 'stamped references after Float64 '
                          'commands: the pipeline restarts on the stamped stream', drop=False)
        if reason is None and self._started:
            late = self._before_stale is not None and \
                self._last_real_ns < stamp_ns <= self._last_ns
            reason = adm.jump_reason(theta1_ref, self._last_real_ref)
            if reason is None and late:
                # a late sample (a stalled transport, not a paused servo): module doc
                vars(self).update(self._before_stale or {})     # and the counts of
                self.counters.update(self._before_stale_counts)  # what it retracts
                self.counters['stale_retractions'] += 1
                self._event(out, 'stale_retracted', 'a late sample: stale hold retracted')
            reason = adm.order_reason(stamp_ns, self._last_ns) or reason
        arrival_ns = stamp_ns if now_ns is None else now_ns
        if reason is not None:
            restart = reason is Reject.OUT_OF_ORDER and \
                self._last_ns - stamp_ns > RESTART_MIN_BACK_NS    # not a late packet
            if reason is Reject.JUMP or restart:
                # a resync candidate: counted when its fate is known (accepted by a
                # confirmed resync, or rejected when the chain breaks)
                out.rejected = reason
                confirmed, broken = self._chain.offer(theta1_ref, reason, stamp_ns)
                self._count_rejected(broken)
                if confirmed:
                    out.rejected = None
                    self._resync(out)      # confirmed: the candidates are accepted
                    self._last_arrival_ns = arrival_ns
            else:
                self._reject(out, reason)
            out.stale = self._stale
            return out
        self._drop_candidates()
        self._accept(stamp_ns, theta1_ref, out, predict=True)
        self._before_stale = None
        self._last_arrival_ns = arrival_ns
        out.stale = self._stale
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
            reason = adm.order_reason(stamp_ns, self._last_load_ns)
        if reason is not None:
            c['rejected_load_samples'] += 1
            c['rejected_load_' + reason.value] += 1
            return reason
        self._last_load_ns = stamp_ns
        self._before_stale = None          # a retraction would lose it
        c['load_samples_accepted'] += 1
        if self.sim is None:
            return None
        if not self._started:               # applied when the simulation starts
            self._load_pending.append((stamp_ns, torque))
            return None
        if not self.sim.push_load(self._time(stamp_ns), torque):
            c['late_load_samples'] += 1
        return None

    @property
    def load_torque(self) -> float:
        """The load torque on the simulated antenna now [N m]."""
        if self.sim is None:
            return float(self.config.load.output_torque)
        return self.sim.load_torque

    def hold(self, now_ns: int) -> Output:
        """Stamped path, from a slow timer: if the stream is stale (no sample has arrived
        for G + ``stale_margin``, and the stream's time, ``now_ns - stream_lag_ns``, passed its
        last stamp by as much: a lagging stream is stale only when samples stop), insert the
        rest samples due, release the corrections waiting for them, advance the simulator
        holding the last command up to the stream's time and return that held prediction."""
        out = Output()
        now_ns = int(now_ns)
        self._check_clock(now_ns, out, 'stamped')
        if not self._started or self._mode != 'stamped':
            out.stale = self._stale
            return out
        stream_ns = now_ns - self.stream_lag_ns    # the stream's time now
        if stream_ns - self._last_real_ns > self._gap_ns + self.stale_margin_ns:
            if not self._stale:     # a late sample may retract it: the state copied
                self._before_stale_counts = {k: self.counters[k] for k in RETRACTED_COUNTS}
                keep = {id(x): x for x in (self, self.counters, self.model, self.config)}
                self._before_stale = copy.deepcopy(
                    {k: v for k, v in vars(self).items() if k != 'counters'}, keep)
            self._go_stale(stream_ns, out)
            self._hold_to(stream_ns, out)
        out.stale = self._stale
        return out

    def finish(self) -> Output:
        """End of a finite stream (offline): the reference rests from its last sample;
        every pending correction is released (as ``hold`` would, much later)."""
        out = Output()
        if self._started:
            self._insert_rest(None, out, predict=False)
            self._release(None, out, predict=False)
        return out

    # ---- the Float64 path --------------------------------------------------------------
    def push_command(self, receive_ns: int, theta1_ref: float) -> Output:
        """An unstamped command received at ``receive_ns`` (the node's clock: monotonic,
        or /clock with ``sim_time``).  Validated at once (value rules of ``push``; a jump
        is confirmed by ``confirm_samples`` agreeing commands, then the next tick restarts
        at rest at the new level); queued until ``tick``."""
        out = Output()
        c = self.counters
        c['commands_received'] += 1
        theta1_ref = float(theta1_ref)
        reason = self._admission.value_reason(theta1_ref)
        if reason is None:
            reason = self._admission.jump_reason(theta1_ref, self._cmd)
        if reason is None:
            self._cmd_chain.clear()
            self._accept_command(receive_ns, theta1_ref, out)
            return out
        confirmed = False
        if reason is Reject.JUMP:   # each candidate is counted rejected when it comes
            confirmed, _ = self._cmd_chain.offer(theta1_ref, reason)
        if not confirmed:
            self._reject(out, reason)
            return out
        self._event(out, 'resync', f'worm_angle_command jumped from {self._cmd!r} to '
                    f'{theta1_ref!r} rad, confirmed by {len(self._cmd_chain)} commands: the '
                    'simulation restarts at rest at the new level')
        c['resyncs'] += 1
        if self._started:
            self._release(None, out, predict=False)
        self._init_state()
        self._queue.clear()
        self._cmd_chain.clear()
        self._accept_command(receive_ns, theta1_ref, out)
        return out

    def _accept_command(self, receive_ns: int, theta1_ref: float, out: Output) -> None:
        c = self.counters
        self._cmd = theta1_ref
        out.accepted = True
        receive_ns = int(receive_ns)
        if self.sim_time:
            self._queue.push('sim', receive_ns, theta1_ref)
        else:
            timing = self.config.node.command_timing
            if timing == 'reception':
                self._queue.push('wall', receive_ns, theta1_ref)
            elif timing == 'stream':
                self._queue.push('wall', self._stream(receive_ns), theta1_ref)
                c['stream_relocks'] = self._stream.relocks
                c['stream_outliers'] = self._stream.outliers
            else:                   # 'tick': no time of its own, restamped to the next tick
                self._queue.push('wall', self._last_tick_ns, theta1_ref)

    def tick(self, now_ns: int) -> Output:
        """Float64 path, at ``node.publish_rate_hz``: the queued commands become samples
        (``node.command_timing``), the simulator holds the last command up to ``now_ns``
        (or to the last corrected sample when the applied compensation waits for a
        preview) and one prediction of that instant is returned.  Nothing before the first
        command."""
        out = Output()
        now_ns = int(now_ns)
        self._check_clock(now_ns, out, 'command')
        if self._mode == 'stamped':
            if not len(self._queue):
                return out                   # the stamped stream is in use: nothing to do
            self._restart(out, 'input_changed', 'Float64 commands after stamped '
                          'references: the pipeline restarts on the commands', drop=False)
        c = self.counters
        base = 'sim' if self.sim_time else 'wall'
        if not self._started:
            if self._cmd is None:
                return out
            q = self._queue
            q.merged += max(q.clear() - 1, 0)
            self._mode = 'command'
            self._last_tick_ns = now_ns
            self._accept(now_ns, self._cmd, out, predict=False)
            c['commands_used'] += 1
        else:
            if now_ns <= self._last_tick_ns:
                out.stale = self._stale
                return out                       # no time has passed
            restamp = self.sim_time or self.config.node.command_timing == 'tick'
            samples = self._queue.take(base, self._last_tick_ns, now_ns, restamp=restamp)
            c['commands_used'] += len(samples)
            for ns, v in samples:
                if ns <= self._last_ns:          # same time or earlier: replaces the value
                    c['merged_samples'] += 1
                    ns = self._last_ns
                self._accept(ns, v, out, predict=False, merge=True)
            self._last_tick_ns = now_ns
            if now_ns - self._last_real_ns > self._gap_ns:
                self._go_stale(now_ns, out)
        q = self._queue
        c['commands_dropped'], c['commands_restamped'] = q.dropped, q.restamped
        c['commands_merged'] = q.merged + c['merged_samples']
        self._hold_to(now_ns, out)
        out.stale = self._stale
        return out

    # ---- internals: rejection and resync -----------------------------------------------
    def _reject(self, out: Output, reason: Reject) -> None:
        out.rejected = reason
        self.counters['rejected_samples'] += 1
        self.counters['rejected_' + reason.value] += 1

    def _check_clock(self, now_ns: int, out: Output, path: str) -> bool:
        """A caller clock that went backwards beyond the tolerance restarts the pipeline.
        Each input path has its own clock (``path``: 'stamped' for ``push``/``hold``,
        'command' for ``tick``): the node reads ROS time for one and the monotonic clock
        for the other, so switching paths is not a clock going back."""
        clocks = self._last_now_ns
        last = clocks.get(path)
        clocks[path] = now_ns if last is None else max(now_ns, last)
        if last is not None and now_ns < last - CLOCK_TOLERANCE_NS:
            clocks[path] = now_ns
            self.counters['clock_restarts'] += 1
            self._restart(out, 'clock_restart', f'clock went backwards by '
                          f'{(last - now_ns) * 1e-9:.6g} s: the pipeline restarts')
            return True
        return False

    def _count_rejected(self, candidates: list[Candidate]) -> None:
        """Candidates whose chain broke: rejected, each under its own reason."""
        c = self.counters
        for cand in candidates:
            c['rejected_samples'] += 1
            c['rejected_' + cand.reason.value] += 1

    def _drop_candidates(self) -> None:
        self._count_rejected(self._chain.clear())

    @property
    def resync_candidates(self) -> int:
        """Rejected-looking samples kept as resync candidates, not yet counted: each
        ends accepted (a confirmed resync) or rejected (the chain breaks)."""
        return len(self._chain)

    def _resync(self, out: Output) -> None:
        chain = self._chain.clear()
        old_ns, old_ref = self._last_real_ns, self._last_real_ref
        first = chain[0]
        self.counters['resyncs'] += 1
        self._event(out, 'resync', f'reference moved from {old_ref!r} rad at {old_ns} ns to '
                    f'{first.value!r} rad at {first.stamp_ns} ns, confirmed by {len(chain)} '
                    'samples: the simulation restarts at rest there')
        if self._started:
            self._release(None, out, predict=True)
        mode = self._mode
        self._init_state()
        self._mode = mode
        for cand in chain:
            assert cand.stamp_ns is not None       # stamped candidates
            self._accept(cand.stamp_ns, cand.value, out, predict=True)

    def _restart(self, out: Output, kind: str, message: str, drop: bool = True) -> None:
        if kind == 'input_changed':
            self.counters['input_switches'] += 1
        if self._started:
            if drop:
                self.counters['corrections_dropped'] += sum(
                    1 for p in self._pending if p[2])
            else:
                self._release(None, out, predict=False)
        self._event(out, kind, message)
        self._init_state()
        self._queue.clear()
        self._stream.reset()

    def _event(self, out: Output, kind: str, message: str) -> None:
        level = 'info' if kind in INFO_EVENTS else 'warn'
        out.events.append(Event(kind, message, level))
        if level == 'warn':
            self.last_error = message

    # ---- internals: the sample path ----------------------------------------------------
    def _accept(self, ns: int, theta1_ref: float, out: Output, predict: bool,
                merge: bool = False) -> None:
        c = self.counters
        if not self._started:
            self._start(ns, theta1_ref, predict)
            self._event(out, 'started', f'first reference sample {theta1_ref:.9g} rad: '
                        'simulation started at rest')
        elif ns - self._last_real_ns > self._gap_ns:     # a pause: the reference rested
            self._insert_rest(ns, out, predict)
        if self._stale:
            self._stale = False
            self._event(out, 'stream_resumed', 'reference stream resumed')
        if not merge or ns > self._last_real_ns:
            if self._last_real_ns and ns > self._last_real_ns:
                self._gap_ns = max(self._gap0_ns, 2 * min(ns - self._last_real_ns,
                                                          int(STALE_MAX_INTERVAL * 1e9)))
            self._rest_k = 0
        self._last_real_ns, self._last_real_ref = ns, theta1_ref
        c['samples_accepted'] += 1
        out.accepted = True
        self._feed(ns, theta1_ref, True, out, predict)

    def _start(self, ns: int, theta1_ref: float, predict: bool) -> None:
        if self._base is None:
            self._base = ns
        t = (ns - self._base) * 1e-9
        comp = self._comp
        d = 0.0
        if comp is not None:
            try:
                comp.reset(theta1_ref, t)
                d = comp.evaluate(t)      # the rest correction (static wind-up)
            except Exception as exc:  # noqa: BLE001 - a compensator bug must not stop us
                self._compensation_failed(exc, Output())
        self._delta = d
        pending = self._load_pending
        if pending and self.sim is not None:
            # the load at the start (the last sample stamped at or before it, else the
            # first): the drive starts at rest under it; the later ones follow in order
            before = [v for ns_l, v in pending if ns_l <= ns]
            self.sim.hold_load(before[-1] if before else pending[0][1])
        elif self.sim is not None and self.counters['load_samples_accepted']:
            # a restart: the samples of the previous time origin are dropped, their
            # latest value holds
            self.sim.hold_load(self.sim.load_torque)
        self._drive.start(theta1_ref + d if self.apply_compensation else theta1_ref,
                          theta1_ref, t)
        if pending and self.sim is not None:
            for ns_l, v in pending:
                if ns_l > ns:
                    self.sim.push_load(self._time(ns_l), v)
            pending.clear()
        self._started = True
        self._last_ns = ns
        if not self._mode:
            self._mode = 'stamped' if predict else 'command'

    def _insert_rest(self, until_ns: int | None, out: Output, predict: bool) -> None:
        """Rest samples (the last value) at last + G + k period, k < K, before
        ``until_ns`` (None: all), as the module doc says."""
        base = self._last_real_ns + self._gap_ns
        theta1_ref = self._last_real_ref
        while self._rest_k < self._rest_count:
            r = base + self._rest_k * self._period_ns
            if until_ns is not None and r >= until_ns:
                break
            self._rest_k += 1
            if r <= self._last_ns:
                continue
            self.counters['rest_samples'] += 1
            self._feed(r, theta1_ref, False, out, predict)

    def _feed(self, ns: int, theta1_ref: float, real: bool, out: Output, predict: bool
              ) -> None:
        """One sample into the compensator and (unless the compensation is applied) the
        simulator; release the corrections that became ready."""
        t = self._time(ns)
        comp = self._comp
        if comp is not None:
            try:
                comp.add_sample(t, theta1_ref)
            except Exception as exc:  # noqa: BLE001
                self._compensation_failed(exc, out)
            p = self._pending
            if p and p[-1][0] == ns:             # a merge: the same time, a new value
                p[-1] = (ns, theta1_ref, p[-1][2] or real)
            else:
                p.append((ns, theta1_ref, real))
        self._last_ns = ns
        if comp is None or not self.apply_compensation:
            self._drive.drive(ns, t, theta1_ref, theta1_ref, out, predict)
        if comp is not None:
            self._release(ns, out, predict)
            try:
                comp.trim(self._time(self._pending[0][0]) if self._pending else t)
            except Exception as exc:  # noqa: BLE001  # pragma: no cover
                self._compensation_failed(exc, out)

    def _release(self, newest_ns: int | None, out: Output, predict: bool) -> None:
        """Corrections whose preview has arrived (all with ``newest_ns`` None)."""
        p = self._pending
        comp = self._comp
        if comp is None:
            return
        P = self.preview_ns
        while p and (newest_ns is None or p[0][0] + P <= newest_ns):
            ns, theta1_ref, real = p.popleft()
            t = self._time(ns)
            try:
                d = float(comp.evaluate(t))
                if not math.isfinite(d):
                    raise ValueError(f'non-finite correction {d!r}')
            except Exception as exc:  # noqa: BLE001
                self._compensation_failed(exc, out)
                d = self._delta
            self._delta = d
            if real:
                out.corrections.append(Correction(ns, theta1_ref, d))
                self.counters['corrections'] += 1
            if self.apply_compensation:
                self._drive.drive(ns, t, theta1_ref + d, theta1_ref, out, predict)

    def _compensation_failed(self, exc: Exception, out: Output) -> None:
        self.counters['compensation_errors'] += 1
        self._event(out, 'compensation_error', f'feed-forward failed ({type(exc).__name__}: '
                    f'{exc}); keeping the last correction {self._delta:.3g} rad')

    # ---- internals: the simulator ------------------------------------------------------

    def _hold_to(self, ns: int, out: Output) -> None:
        """Hold the last command up to ``ns`` (not past a sample whose applied
        correction is still pending) and predict there."""
        if self.sim is None or not self._started:
            return
        if self.apply_compensation and self._pending:
            ns = min(ns, self._pending[0][0])
        self._drive.hold_to(ns, self._time(ns), self._stale, out)

    def _go_stale(self, now_ns: int, out: Output) -> None:
        if not self._stale:
            self._stale = True
            self.counters['stale_events'] += 1
            self._event(out, 'stream_stale', 'no reference sample for '
                        f'{(now_ns - self._last_real_ns) * 1e-9:.4g} s: the reference rests '
                        'at its last value; holding the prediction')
        self._insert_rest(now_ns + 1, out, predict=False)
        if self._rest_k >= self._rest_count:
            self._release(None, out, predict=False)

    def _time(self, ns: int) -> float:
        """Seconds since the time origin (the module doc's Time)."""
        base = self._base
        assert base is not None, 'no time origin before the first sample'
        return (ns - base) * 1e-9
