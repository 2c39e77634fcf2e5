# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""This module holds the stamped path of the real-time pipeline (:class:`StampedPath`):
stamped references (``push``), the stale hold (``hold``) and its retraction by a late
sample, and the resync of a confirmed jump or restart of the stamps."""

from __future__ import annotations

from collections.abc import Callable

from .admission import Admission, Candidate, JumpConfirmation
from .outputs import Output, Reject
from .sample_path import SamplePath

__all__ = ['StampedPath', 'RESTART_MIN_BACK_NS']

RESTART_MIN_BACK_NS = 100_000_000  # a stamp this much older may start a new timeline

#: restart(out, kind, message, drop): the pipeline starts afresh (on another input)
Restart = Callable[[Output, str, str, bool], None]


class StampedPath:
    """``push`` and ``hold`` of :class:`~.predictor.RealtimePredictor` (the rules: the
    package's docstring), on the shared ``samples``; ``admission``: the input checks;
    ``confirm_samples``: agreeing candidates that confirm a resync; ``stale_margin_ns``:
    lateness allowed before a hold; ``restart``: the pipeline's restart (a stamped sample
    after Float64 commands)."""

    def __init__(self, samples: SamplePath, admission: Admission, confirm_samples: int,
                 stale_margin_ns: int, restart: Restart) -> None:
        self.samples = samples
        self.admission = admission
        self.chain = JumpConfirmation(confirm_samples, 0.0)     # resync candidates
        self.stale_margin_ns = stale_margin_ns
        self._restart = restart

    def push(self, stamp_ns: int, theta1_ref: float, now_ns: int | None, out: Output
             ) -> None:
        samples, adm = self.samples, self.admission
        reason = adm.value_reason(theta1_ref)
        if reason is None:
            reason = adm.stamp_reason(stamp_ns, now_ns)
        if reason is None and samples.state.mode == 'command':   # the stamped stream takes over
            self._restart(out, 'input_changed', 'stamped references after Float64 '
                          'commands: the pipeline restarts on the stamped stream', False)
        st = samples.state
        if reason is None and st.started:
            late = samples.saved is not None and st.last_real_ns < stamp_ns <= st.last_ns
            reason = adm.jump_reason(theta1_ref, st.last_real_ref)
            if reason is None and late:
                # a late sample (a stalled transport, not a paused servo): the package doc
                samples.restore()
                samples.counters['stale_retractions'] += 1
                samples.event(out, 'stale_retracted', 'a late sample: stale hold retracted')
                st = samples.state
            reason = adm.order_reason(stamp_ns, st.last_ns) or reason
        arrival_ns = stamp_ns if now_ns is None else now_ns
        if reason is not None:
            restart = reason is Reject.OUT_OF_ORDER and \
                st.last_ns - stamp_ns > RESTART_MIN_BACK_NS    # not a late packet
            if reason is Reject.JUMP or restart:
                # a resync candidate: counted when its fate is known (accepted by a
                # confirmed resync, or rejected when the chain breaks)
                out.rejected = reason
                confirmed, broken = self.chain.offer(theta1_ref, reason, stamp_ns)
                self.count_rejected(broken)
                if confirmed:
                    out.rejected = None
                    self._resync(out)      # confirmed: the candidates are accepted
                    samples.state.last_arrival_ns = arrival_ns
            else:
                samples.reject(out, reason)
            out.stale = samples.state.stale
            return
        self.drop_candidates()
        samples.accept(stamp_ns, theta1_ref, out, predict=True)
        samples.saved = None
        st.last_arrival_ns = arrival_ns
        out.stale = st.stale

    def hold(self, now_ns: int, out: Output) -> None:
        samples = self.samples
        st = samples.state
        if st.started and st.mode == 'stamped':
            stream_ns = now_ns - max(0, st.last_arrival_ns - st.last_real_ns)   # its time
            if stream_ns - st.last_real_ns > st.gap_ns + self.stale_margin_ns:
                if not st.stale:        # a late sample may retract it: the stream saved
                    samples.save()
                samples.go_stale(stream_ns, out)
                samples.hold_to(stream_ns, out)
        out.stale = samples.state.stale

    # ---- resync candidates ---------------------------------------------------------------
    def count_rejected(self, candidates: list[Candidate]) -> None:
        """Candidates whose chain broke: rejected, each under its own reason."""
        c = self.samples.counters
        for cand in candidates:
            c['rejected_samples'] += 1
            c['rejected_' + cand.reason.value] += 1

    def drop_candidates(self) -> None:
        self.count_rejected(self.chain.clear())

    def _resync(self, out: Output) -> None:
        samples = self.samples
        chain = self.chain.clear()
        st = samples.state
        old_ns, old_ref = st.last_real_ns, st.last_real_ref
        first = chain[0]
        samples.counters['resyncs'] += 1
        samples.event(out, 'resync', f'reference moved from {old_ref!r} rad at {old_ns} ns '
                      f'to {first.value!r} rad at {first.stamp_ns} ns, confirmed by '
                      f'{len(chain)} samples: the simulation restarts at rest there')
        if st.started:
            samples.release(None, out, predict=True)
        samples.init_state()
        samples.state.mode = st.mode
        for cand in chain:
            assert cand.stamp_ns is not None       # stamped candidates
            samples.accept(cand.stamp_ns, cand.value, out, predict=True)
