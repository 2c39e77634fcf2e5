# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""This module holds the Float64 command path of the real-time pipeline
(:class:`CommandPath`): unstamped commands validated and queued (``push_command``), turned
into samples and a prediction at each tick (``tick``)."""

from __future__ import annotations

from collections.abc import Callable

from .admission import Admission, JumpConfirmation
from .command_timing import CommandQueue, StreamClock
from .outputs import Output, Reject
from .sample_path import SamplePath
from .stamped_path import Restart

__all__ = ['CommandPath']


class CommandPath:
    """``push_command`` and ``tick`` of :class:`~.predictor.RealtimePredictor` (the rules:
    the package's docstring), on the shared ``samples``; ``admission``: the input checks;
    ``confirm_samples``: agreeing commands that confirm a jump; ``period_ns``: the tick
    period (the stream clock's first guess); ``sim_time``: reception times are /clock
    readings; ``restart``: the pipeline's restart (commands after stamped references);
    ``forget``: the pipeline forgets its stream (a confirmed jump)."""

    def __init__(self, samples: SamplePath, admission: Admission, confirm_samples: int,
                 period_ns: int, sim_time: bool, restart: Restart,
                 forget: Callable[[], None]) -> None:
        self.samples = samples
        self.admission = admission
        self.chain = JumpConfirmation(confirm_samples, 0.0)     # jump candidates
        self.queue = CommandQueue()
        self.stream = StreamClock(float(period_ns))
        self.sim_time = sim_time
        self.timing = 'tick'              # node.command_timing (the configuration's)
        self.cmd: float | None = None     # last accepted command
        self.last_tick_ns = 0
        self._restart = restart
        self._forget = forget

    def clear(self) -> None:
        """Forget the commands: the queue, the stream clock, the last command and the jump
        candidates."""
        self.queue.clear()
        self.stream.reset()
        self.cmd = None
        self.chain.clear()

    def push_command(self, receive_ns: int, theta1_ref: float, out: Output) -> None:
        samples = self.samples
        c = samples.counters
        c['commands_received'] += 1
        theta1_ref = float(theta1_ref)
        reason = self.admission.value_reason(theta1_ref)
        if reason is None:
            reason = self.admission.jump_reason(theta1_ref, self.cmd)
        if reason is None:
            self.chain.clear()
            self._accept(receive_ns, theta1_ref, out)
            return
        confirmed = False
        if reason is Reject.JUMP:   # each candidate is counted rejected when it comes
            confirmed, _ = self.chain.offer(theta1_ref, reason)
        if not confirmed:
            samples.reject(out, reason)
            return
        samples.event(out, 'resync', f'worm_angle_command jumped from {self.cmd!r} to '
                      f'{theta1_ref!r} rad, confirmed by {len(self.chain)} commands: the '
                      'simulation restarts at rest at the new level')
        c['resyncs'] += 1
        if samples.state.started:
            samples.release(None, out, predict=False)
        self._forget()
        self.queue.clear()
        self.chain.clear()
        self._accept(receive_ns, theta1_ref, out)

    def _accept(self, receive_ns: int, theta1_ref: float, out: Output) -> None:
        self.cmd = theta1_ref
        out.accepted = True
        receive_ns = int(receive_ns)
        if self.sim_time:
            self.queue.push('sim', receive_ns, theta1_ref)
        elif self.timing == 'reception':
            self.queue.push('wall', receive_ns, theta1_ref)
        elif self.timing == 'stream':
            self.queue.push('wall', self.stream(receive_ns), theta1_ref)
            c = self.samples.counters
            c['stream_relocks'] = self.stream.relocks
            c['stream_outliers'] = self.stream.outliers
        else:                   # 'tick': no time of its own, restamped to the next tick
            self.queue.push('wall', self.last_tick_ns, theta1_ref)

    def tick(self, now_ns: int, out: Output) -> None:
        samples = self.samples
        if samples.state.mode == 'stamped':
            if not len(self.queue):
                return                   # the stamped stream is in use: nothing to do
            self._restart(out, 'input_changed', 'Float64 commands after stamped '
                          'references: the pipeline restarts on the commands', False)
        c = samples.counters
        st = samples.state
        q = self.queue
        if not st.started:
            if self.cmd is None:
                return
            q.merged += max(q.clear() - 1, 0)
            st.mode = 'command'
            self.last_tick_ns = now_ns
            samples.accept(now_ns, self.cmd, out, predict=False)
            c['commands_used'] += 1
        else:
            if now_ns <= self.last_tick_ns:
                out.stale = st.stale
                return                       # no time has passed
            restamp = self.sim_time or self.timing == 'tick'
            taken = q.take('sim' if self.sim_time else 'wall', self.last_tick_ns, now_ns,
                           restamp=restamp)
            c['commands_used'] += len(taken)
            for ns, v in taken:
                if ns <= st.last_ns:          # same time or earlier: replaces the value
                    c['merged_samples'] += 1
                    ns = st.last_ns
                samples.accept(ns, v, out, predict=False, merge=True)
            self.last_tick_ns = now_ns
            if now_ns - st.last_real_ns > st.gap_ns:
                samples.go_stale(now_ns, out)
        c['commands_dropped'], c['commands_restamped'] = q.dropped, q.restamped
        c['commands_merged'] = q.merged + c['merged_samples']
        samples.hold_to(now_ns, out)
        out.stale = st.stale
