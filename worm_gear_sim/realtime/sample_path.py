# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""This module holds the sample path both inputs of the real-time pipeline share
(:class:`SamplePath`): accepted samples, and the rest samples of a pause, through the
compensator and the simulated drive; the corrections released when their preview has come;
the stale stream; load samples; the stream's state and what a stale hold saves of it."""

from __future__ import annotations

import math

from ..compensation.blend import BlendedCompensator, settled, unwrap
from ..compensation.streaming import Compensator
from ..dynamics.simulation import Simulator
from .drive import SimulatedDrive
from .outputs import Correction, Event, Output, Prepared, Reject
from .stream_state import STALE_MAX_INTERVAL, STALE_PERIODS, SavedStream, StreamState

__all__ = ['SamplePath', 'INFO_EVENTS']

INFO_EVENTS = ('started', 'stream_resumed')
_MAX_INTERVAL_NS = int(STALE_MAX_INTERVAL * 1e9)


class SamplePath:
    """The samples' way through the compensator and the simulated drive, for both inputs
    (the rules: the package's docstring).  ``sim``: the simulator (None: corrections only);
    ``counters``: the pipeline's counters; ``base_ns``: a fixed time origin (None: each
    stream's first sample).  :meth:`configure` sets what the configuration decides;
    :attr:`state` is the stream's (a fresh one per stream), :attr:`saved` what a stale hold
    saved of it (:meth:`save`, :meth:`restore`)."""

    def __init__(self, sim: Simulator | None, counters: dict[str, int],
                 base_ns: int | None) -> None:
        self.sim = sim
        self.counters = counters
        self.base_ns = base_ns
        self.last_error = ''
        self.drive = SimulatedDrive(sim, counters, self.event)
        self.comp: Compensator | BlendedCompensator | None = None
        self.apply_compensation = False
        self.period_ns = self.gap0_ns = self.preview_ns = self.rest_count = 0
        self.saved: SavedStream | None = None
        self.state = StreamState(base_ns, 0)

    def configure(self, prepared: Prepared, apply_compensation: bool, blend: float = 0.0
                  ) -> None:
        """Take the configuration of ``prepared``; its compensator takes over the history
        of the one in charge (``blend`` > 0 [s]: it is handed over, :mod:`.blend`)."""
        node = prepared.model.config.node
        old, comp = self.comp, prepared.compensator
        if comp is not None and old is not None:
            comp.copy_history(unwrap(old))
        self.comp = comp
        if blend > 0.0 and old is not None and comp is not None:
            self.comp = BlendedCompensator(old, comp, blend)
        self.apply_compensation = self.drive.apply_compensation = apply_compensation
        self.drive.max_catch_up = node.max_catch_up
        self.drive.output_per_input = prepared.model.output_per_input
        self.period_ns = int(round(1e9 / node.publish_rate_hz))
        self.gap0_ns = int(round(STALE_PERIODS * self.period_ns))
        self.preview_ns = int(round(prepared.model.config.compensation.preview_time * 1e9))
        span = 0.0 if comp is None else comp.filter.lag_span + comp.preview
        self.rest_count = int(math.ceil(span * 1e9 / self.period_ns)) + 2
        if self.sim is not None:
            self.sim.interpolation = node.command_interpolation
        self.saved = None                  # no retraction to the former configuration

    def init_state(self) -> None:
        """A new stream: nothing accepted yet (the next sample starts at rest)."""
        self.state = StreamState(self.base_ns, self.gap0_ns)
        self.saved = None
        self.drive.clear()

    # ---- what a stale hold saves -------------------------------------------------------
    def save(self) -> None:
        """Keep the stream as it is now, for :meth:`restore`."""
        self.saved = SavedStream.of(self.state, self.comp, self.drive, self.counters)

    def restore(self) -> None:
        """Back to what :meth:`save` kept (the drive in place; the saved copies are used
        once)."""
        saved = self.saved
        assert saved is not None, 'nothing saved'
        self.saved = None
        self.state, self.comp = saved.state, saved.compensator
        self.drive.restore(saved.drive)
        self.counters.update(saved.counts)

    # ---- counting and the event log ----------------------------------------------------
    def event(self, out: Output, kind: str, message: str) -> None:
        level = 'info' if kind in INFO_EVENTS else 'warn'
        out.events.append(Event(kind, message, level))
        if level == 'warn':
            self.last_error = message

    def reject(self, out: Output, reason: Reject) -> None:
        out.rejected = reason
        self.counters['rejected_samples'] += 1
        self.counters['rejected_' + reason.value] += 1

    def time(self, ns: int) -> float:
        """Seconds since the time origin (the package docstring's Time)."""
        base = self.state.base_ns
        assert base is not None, 'no time origin before the first sample'
        return (ns - base) * 1e-9

    # ---- samples -----------------------------------------------------------------------
    def accept(self, ns: int, theta1_ref: float, out: Output, predict: bool,
               merge: bool = False) -> None:
        """An accepted sample at ``ns`` (a pause before it rests the reference first);
        ``predict``: predictions at the samples' stamps go to ``out``; ``merge``: a sample
        not after the last replaces its value."""
        st = self.state
        if not st.started:
            self._start(ns, theta1_ref, predict)
            self.event(out, 'started', f'first reference sample {theta1_ref:.9g} rad: '
                       'simulation started at rest')
        elif ns - st.last_real_ns > st.gap_ns:     # a pause: the reference rested
            self.insert_rest(ns, out, predict)
        if st.stale:
            st.stale = False
            self.event(out, 'stream_resumed', 'reference stream resumed')
        if not merge or ns > st.last_real_ns:
            if st.last_real_ns and ns > st.last_real_ns:
                st.gap_ns = max(self.gap0_ns, 2 * min(ns - st.last_real_ns, _MAX_INTERVAL_NS))
            st.rest_k = 0
        st.last_real_ns, st.last_real_ref = ns, theta1_ref
        self.counters['samples_accepted'] += 1
        out.accepted = True
        self._feed(ns, theta1_ref, True, out, predict)

    def _start(self, ns: int, theta1_ref: float, predict: bool) -> None:
        st = self.state
        if st.base_ns is None:
            st.base_ns = ns
        t = (ns - st.base_ns) * 1e-9
        comp = self.comp
        d = 0.0
        if comp is not None:
            try:
                comp.reset(theta1_ref, t)
                d = comp.evaluate(t)      # the rest correction (static wind-up)
            except Exception as exc:  # noqa: BLE001 - a compensator bug must not stop us
                self._compensation_failed(exc, Output())
            self.comp = settled(comp)     # a restart ends a blend
        st.delta = d
        sim = self.sim
        pending = st.load_pending
        load = None
        if pending and sim is not None:
            # the load at the start (the last sample stamped at or before it, else the
            # first): the drive starts at rest under it; the later ones follow in order
            before = [v for ns_l, v in pending if ns_l <= ns]
            load = before[-1] if before else pending[0][1]
        elif sim is not None and self.counters['load_samples_accepted']:
            # a restart: the samples of the previous time origin are dropped, their
            # latest value holds
            load = sim.load_torque
        self.drive.start(theta1_ref + d if self.apply_compensation else theta1_ref,
                         theta1_ref, t, load)
        if pending and sim is not None:
            for ns_l, v in pending:
                if ns_l > ns:
                    sim.push_load(self.time(ns_l), v)
            pending.clear()
        st.started = True
        st.last_ns = ns
        if not st.mode:
            st.mode = 'stamped' if predict else 'command'

    def insert_rest(self, until_ns: int | None, out: Output, predict: bool) -> None:
        """Rest samples (the last value) at last + G + k period, k < K, before
        ``until_ns`` (None: all), as the package docstring says."""
        st = self.state
        base = st.last_real_ns + st.gap_ns
        theta1_ref = st.last_real_ref
        while st.rest_k < self.rest_count:
            r = base + st.rest_k * self.period_ns
            if until_ns is not None and r >= until_ns:
                break
            st.rest_k += 1
            if r <= st.last_ns:
                continue
            self.counters['rest_samples'] += 1
            self._feed(r, theta1_ref, False, out, predict)

    def _feed(self, ns: int, theta1_ref: float, real: bool, out: Output, predict: bool
              ) -> None:
        """One sample into the compensator and (unless the compensation is applied) the
        simulator; release the corrections that became ready."""
        st = self.state
        t = self.time(ns)
        comp = self.comp
        if comp is not None:
            try:
                comp.add_sample(t, theta1_ref)
            except Exception as exc:  # noqa: BLE001
                self._compensation_failed(exc, out)
            p = st.pending
            if p and p[-1][0] == ns:             # a merge: the same time, a new value
                p[-1] = (ns, theta1_ref, p[-1][2] or real)
            else:
                p.append((ns, theta1_ref, real))
        st.last_ns = ns
        if comp is None or not self.apply_compensation:
            self.drive.drive(ns, t, theta1_ref, theta1_ref, out, predict)
        if comp is not None:
            self.release(ns, out, predict)
            try:
                comp.trim(self.time(st.pending[0][0]) if st.pending else t)
            except Exception as exc:  # noqa: BLE001  # pragma: no cover
                self._compensation_failed(exc, out)

    def release(self, newest_ns: int | None, out: Output, predict: bool) -> None:
        """Corrections whose preview has arrived (all with ``newest_ns`` None)."""
        comp = self.comp
        if comp is None:
            return
        st = self.state
        p = st.pending
        P = self.preview_ns
        while p and (newest_ns is None or p[0][0] + P <= newest_ns):
            ns, theta1_ref, real = p.popleft()
            t = self.time(ns)
            try:
                d = float(comp.evaluate(t))
                if not math.isfinite(d):
                    raise ValueError(f'non-finite correction {d!r}')
            except Exception as exc:  # noqa: BLE001
                self._compensation_failed(exc, out)
                d = st.delta
            st.delta = d
            if real:
                out.corrections.append(Correction(ns, theta1_ref, d))
                self.counters['corrections'] += 1
            if self.apply_compensation:
                self.drive.drive(ns, t, theta1_ref + d, theta1_ref, out, predict)
        self.comp = settled(comp)

    def _compensation_failed(self, exc: Exception, out: Output) -> None:
        self.counters['compensation_errors'] += 1
        self.event(out, 'compensation_error', f'feed-forward failed ({type(exc).__name__}: '
                   f'{exc}); keeping the last correction {self.state.delta:.3g} rad')

    def finish(self, out: Output) -> None:
        """End of a finite stream: the reference rests; every pending correction goes."""
        if self.state.started:
            self.insert_rest(None, out, predict=False)
            self.release(None, out, predict=False)

    # ---- the stale stream and the held prediction ----------------------------------------
    def go_stale(self, now_ns: int, out: Output) -> None:
        """No sample for G: the reference rests (rest samples due by ``now_ns``)."""
        st = self.state
        if not st.stale:
            st.stale = True
            self.counters['stale_events'] += 1
            self.event(out, 'stream_stale', 'no reference sample for '
                       f'{(now_ns - st.last_real_ns) * 1e-9:.4g} s: the reference rests '
                       'at its last value; holding the prediction')
        self.insert_rest(now_ns + 1, out, predict=False)
        if st.rest_k >= self.rest_count:
            self.release(None, out, predict=False)

    def hold_to(self, ns: int, out: Output) -> None:
        """Hold the last command up to ``ns`` (not past a sample whose applied
        correction is still pending) and predict there."""
        st = self.state
        if self.sim is None or not st.started:
            return
        if self.apply_compensation and st.pending:
            ns = min(ns, st.pending[0][0])
        self.drive.hold_to(ns, self.time(ns), st.stale, out)

    # ---- load samples --------------------------------------------------------------------
    def add_load(self, stamp_ns: int, torque: float) -> None:
        """An accepted load sample (checked by the caller): applied in stamp order, kept
        until the start before the first reference; a stale hold's retraction would lose
        it, so the hold stays."""
        st = self.state
        st.last_load_ns = stamp_ns
        self.saved = None
        c = self.counters
        c['load_samples_accepted'] += 1
        if self.sim is None:
            return
        if not st.started:               # applied when the simulation starts
            st.load_pending.append((stamp_ns, torque))
            return
        t = self.time(stamp_ns)
        if t <= self.sim.t:              # late (or stamped before the start): from now on
            self.sim.hold_load(torque)
            c['late_load_samples'] += 1
        else:
            self.sim.push_load(t, torque)
