# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The adaptation loop the node and the offline twin share (pure core, no rclpy):
:class:`LiveAdaptation`.

Beside a ``RealtimePredictor``, it takes every prediction (:meth:`~LiveAdaptation.predicted`)
and every encoder message (:meth:`~LiveAdaptation.measured`), and at each :meth:`step` lets
the samples enter the estimate and the adapter decide.  A sample enters at a step fixed by
its stamp (``adaptation.sample_delay``) and a decided step is swapped in at a fixed stamp
(:data:`APPLY_LEAD` later; :func:`in_slices` prepares it in slices), so the node equals the
twin while ``late_samples`` and ``late_steps`` are 0.  docs/adaptation.md.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from collections.abc import Callable, Collection, Mapping, Sequence
from concurrent.futures import Executor, Future
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._support.stepwise import SLICE_BUDGET, Steps, Stepwise, run_steps
from ..config.usable import Config, config_from_mapping
from ..realtime.encoder_admission import ENCODER_REASONS, EncoderAdmission
from ..realtime.predictor import Prepared, RealtimePredictor
from ..realtime.preparation import prepare_steps
from ..realtime.switch_interval import short_switch_interval
from ..schema.parameters import Parameters
from .estimator import Adapter
from .learnt import carried_adapter, carried_values, carry_notes, format_value, touches_estimator
from .plausibility import estimate_problem

__all__ = ['LiveAdaptation', 'REJECT_REASONS', 'APPLY_LEAD', 'Submit', 'run_now',
           'in_worker', 'in_slices', 'swap_back']

#: A step's correction is blended in over this many periods of the antenna mode of the
#: model it brings (at most one ``adaptation.step_interval``): a drive without drag rings
#: for ever after a step of the command (:mod:`~worm_gear_sim.compensation.blend`).
BLEND_PERIODS = 5.0
#: A step decided at the prediction stamped t is applied at the first prediction stamped
#: >= t + APPLY_LEAD [s] (module docstring): time for the worker to prepare it (5-15 ms
#: measured under load) with margin; small against the hold-offs of the estimate (0.15 s).
APPLY_LEAD = 0.05
#: Runs a preparation (a function that returns its steps, :mod:`worm_gear_sim._support.stepwise`):
#: returns a future-like object (``done()``, ``result()``; ``advance()`` when it runs in
#: slices on the caller's thread).
Submit = Callable[[Callable[[], Steps[Any]]], Any]
#: The interpreter's switch interval while a preparation runs in a worker thread [s]: the
#: sample thread waits at most about this long for the GIL (Python's default, 5 ms, made a
#: sample wait up to 5-7 ms while the worker prepared: measured, bench_adaptation.py).

#: Reasons an encoder sample is rejected (counted under ``rejected_<reason>``).
REJECT_REASONS = ('other_joint', *ENCODER_REASONS)


class LiveAdaptation:
    """Adapt ``predictor``'s model from encoder samples (module docstring).

    ``joint_names``: the names of theta2, theta3, theta4 in the encoder messages
    (``node.joint_names[1:]``); ``history``: predictions kept for interpolation;
    ``submit``: runs a step's preparation (default :func:`run_now`, at once: the twin; the
    node passes a worker thread's ``submit``)."""

    def __init__(self, predictor: RealtimePredictor, joint_names: Sequence[str],
                 history: int = 512, submit: Submit | None = None) -> None:
        if len(joint_names) != 3:
            raise ValueError('joint_names: the names of theta2, theta3 and theta4')
        self.predictor = predictor
        #: the operator's set (the nominal one): the model in use is it with the adapted
        #: values on top (:mod:`.learnt`)
        self.declared = _as_config(predictor.config)
        self.joint_names = tuple(joint_names)
        self.history = _Predictions(history)
        self.adapter = Adapter(predictor.model, predictor.config.adaptation)
        self.counters: dict[str, int] = {'samples': 0, 'used': 0, 'rejected': 0,
                                         'switches': 0, 'refusals': 0, 'late_steps': 0,
                                         'late_samples': 0, 'restarts': 0, 'resets': 0,
                                         'parameter_sets': 0}
        self.counters.update({f'rejected_{r}': 0 for r in REJECT_REASONS})
        self.last_refusal = ''
        self.last_note = ''
        self._base_ns: int | None = None
        node = predictor.config.node
        self.admission = EncoderAdmission(
            self.joint_names, (2,), 'other_joint', max_residual=node.residual_plausible_max,
            period=int(round(1e9 / node.publish_rate_hz)))
        self._submit = submit or run_now
        self._lead_ns = int(round(APPLY_LEAD * 1e9))
        self._delay_ns = int(round(predictor.config.adaptation.sample_delay * 1e9))
        #: samples waiting for their entry: (entry stamp [ns], t, measured theta4,
        #: predicted theta2, theta3, theta4), in stamp order
        self.waiting: deque[tuple[int, float, float, float, float, float]] = deque()
        self._step_ns = -1                    # the stamp of the last step
        self.pending: _Pending | None = None
        self._pipeline_counters = predictor.counters
        self._starts = _pipeline_starts(predictor.counters)
        self._retractions = predictor.counters['stale_retractions']
        self._pred_ns = 0                     # the stamp of the last prediction

    def _restart(self) -> None:
        """The pipeline restarted (a clock restart, a resync, a change of input: its
        simulator starts again at rest and its stamps may start over): the stored
        predictions, the samples waiting and a step being prepared belong to the old stream.
        The adaptation starts afresh from the model in use, as a node started from it would
        (its estimate at the prior, its nominal set the model in use); the counters go on
        (``restarts`` counts these)."""
        self.history = _Predictions(self.history.capacity)
        self.adapter = Adapter(self.predictor.model, self.predictor.config.adaptation)
        self.waiting.clear()
        self.pending = None
        self._base_ns = None
        self.admission.reset()
        self._step_ns = -1
        self.last_note = ''
        self.counters['restarts'] += 1

    # ---- inputs ------------------------------------------------------------------------
    def predicted(self, stamp_ns: int, theta: Sequence[float]) -> None:
        """A prediction of the drive (theta2, theta3, theta4) at ``stamp_ns``; the first
        after a restart of the pipeline restarts the adaptation (:meth:`_restart`)."""
        stamp_ns = int(stamp_ns)
        counters = self._pipeline_counters
        starts = _pipeline_starts(counters)
        retractions = counters['stale_retractions']
        if starts == self._starts and retractions != self._retractions:
            # a stale hold retracted by a late sample (the same stream, taken as if in
            # time): its held predictions are dropped, the estimate goes on
            self._retractions = retractions
            if self._base_ns is not None and stamp_ns <= self._pred_ns:
                self.history.truncate(self._seconds(stamp_ns))
                self._step_ns = min(self._step_ns, stamp_ns)
                self._pred_ns = stamp_ns
        if starts != self._starts or stamp_ns < self._pred_ns:
            # (a prediction going back: the new stream's, after the old stream's last ones
            # released at a resync)
            self._starts = starts
            self._retractions = retractions
            self._restart()
        self._pred_ns = stamp_ns
        if self._base_ns is None:
            self._base_ns = stamp_ns
        self.history.push(self._seconds(stamp_ns), theta)

    def _seconds(self, stamp_ns: int) -> float:
        assert self._base_ns is not None
        return (int(stamp_ns) - self._base_ns) * 1e-9

    def _prediction(self, stamp_ns: int) -> tuple[float, float, float] | None:
        """The stored prediction at ``stamp_ns`` (None outside them)."""
        if self._base_ns is None:
            return None
        return self.history.at(self._seconds(stamp_ns))

    def _reject(self, reason: str) -> str:
        self.counters['rejected'] += 1
        self.counters[f'rejected_{reason}'] += 1
        return reason

    def measured(self, stamp_ns: int, names: Sequence[str], positions: Sequence[float]
                 ) -> str | None:
        """An encoder message; returns None (used or waiting) or the rejection reason."""
        self.counters['samples'] += 1
        try:
            stamp_ns = int(stamp_ns)
        except (TypeError, ValueError, OverflowError):
            return self._reject('non_finite')
        if stamp_ns <= 0:
            return self._reject('non_finite')
        got = self.admission.admit(stamp_ns, names, positions, self._prediction)
        if isinstance(got, str):
            return self._reject(got)
        meas = got[1][0]
        theta2, theta3, theta4 = got[2]
        t = self._seconds(stamp_ns)
        entry = stamp_ns + self._delay_ns
        if entry > self._step_ns:
            self.waiting.append((entry, t, meas, theta2, theta3, theta4))
        else:       # its entry step has passed: at once (none waits: the older, stamped
            self.counters['late_samples'] += 1      # before it, entered at that step)
            if self.adapter.update(t, meas, theta2, theta3, theta4):
                self.counters['used'] += 1
        return None

    # ---- switching ---------------------------------------------------------------------
    def step(self, stamp_ns: int) -> list[str]:
        """At the prediction stamped ``stamp_ns``: swap in a prepared step whose stamp has
        come, or take the adapter's next decision and start preparing it (module
        docstring); the new messages to log (a note of an accepted set, a refusal's reason
        the first time it comes)."""
        if self._base_ns is None:
            return []
        stamp_ns = int(stamp_ns)
        self._step_ns = stamp_ns
        waiting = self.waiting
        if waiting and waiting[0][0] <= stamp_ns:      # (inline: once per sample)
            update = self.adapter.update
            used = 0
            while waiting and waiting[0][0] <= stamp_ns:
                _, t, meas, theta2, theta3, theta4 = waiting.popleft()
                used += update(t, meas, theta2, theta3, theta4)
            self.counters['used'] += used
        if self.pending is not None:
            return self._apply_due(stamp_ns)
        # the adapter decides on the samples' clock, D behind the predictions: at the stamp
        # t + D it has the samples up to t, as the twin had at t before the delay
        t_samples = self._seconds(stamp_ns - self._delay_ns)
        if t_samples < 0.0:
            return []
        ad = self.adapter
        refusals = ad.refusals
        d = ad.poll(t_samples)
        msgs: list[str] = []
        if d.note and d.note != self.last_note:
            self.last_note = d.note
            msgs.append(d.note)
        if ad.refusals != refusals:
            msgs += self._refused(ad.last_refusal, counted=True)
        if d.step is None or d.overrides is None:
            return msgs
        pred, overrides = self.predictor, d.overrides
        base = pred.config
        # the simulator's state now, whenever the worker runs: the same result as the twin
        trial = None if pred.sim is None else pred.sim.trial_copy()

        def prepare() -> Steps[tuple[Prepared, float]]:
            cfg = yield from _as_config(base).replace_steps(overrides)
            yield
            new = yield from prepare_steps(pred, cfg, trial)
            return new, blend_time(new.compensator, base.adaptation.step_interval)

        self.pending = _Pending(d.step, int(stamp_ns) + self._lead_ns, self._submit(prepare),
                                base)
        return msgs

    def _apply_due(self, stamp_ns: int) -> list[str]:
        """The pending step, swapped in if its stamp has come and it is prepared; not
        prepared: moved to the next fixed stamp and counted."""
        p = self.pending
        assert p is not None
        advance = getattr(p.future, 'advance', None)
        if advance is not None:               # in slices (in_slices): one, on this thread
            advance()
        if stamp_ns < p.apply_ns or self.predictor.stale:
            # (held as stale: the step waits for the stream.  Swapped in on a held
            # prediction, it would end the hold's retraction: the late samples of a stalled
            # transport would be rejected as out of order, never answered)
            return []
        if not p.future.done():
            self.counters['late_steps'] += 1
            while p.apply_ns <= stamp_ns:
                p.apply_ns += self._lead_ns
            return []
        self.pending = None
        ad, pred = self.adapter, self.predictor
        if pred.config is not p.base:   # replaced from outside meanwhile: not this step
            return []
        try:
            prepared, blend = p.future.result()
            pred.reconfigure(prepared, blend=blend)
        except (ValueError, ArithmeticError) as exc:   # ConfigError is a ValueError
            ad.refused(f'{type(exc).__name__}: {exc}')
            return self._refused(ad.last_refusal, counted=True)
        ad.applied(p.step, pred.model, at=self._seconds(stamp_ns))
        self.counters['switches'] += 1
        return []

    def _refused(self, reason: str, counted: bool) -> list[str]:
        self.counters['refusals'] += 1
        new = reason != self.last_refusal
        self.last_refusal = reason
        return [f'adapted set not applied, keeping the last good model: {reason}'] if new \
            else []

    # ---- what an operator does (:mod:`.learnt`) -----------------------------------------
    def carried_values(self, declared: Config, names: Collection[str]) -> dict[str, Any]:
        """The adapted values in use that the operator's new set ``declared`` (a set of the
        parameters ``names``) keeps: the pipeline is to run ``declared.replace(...)`` of
        them (:func:`~.learnt.carried_values`)."""
        return carried_values(self.adapter, declared, names)

    def carry_over(self, declared: Config, names: Collection[str]) -> list[str]:
        """The pipeline runs the operator's new set ``declared`` with
        :meth:`carried_values` on top (swapped in by the caller): the adapter carries over
        what was learnt (:mod:`.learnt`; a step being prepared is dropped, and, where the
        estimator's inputs changed, the samples waiting: the replaced model predicted
        them).  Returns the lines to log (what was restarted or dropped)."""
        old = self.adapter
        in_use = old.applied_values()
        touched = touches_estimator(self.declared, declared, names) or not np.array_equal(
            old.layout.pack(self.predictor.config), old.applied_x)
        self.declared = declared
        self._delay_ns = int(round(declared.adaptation.sample_delay * 1e9))
        self.counters['parameter_sets'] += 1
        self.pending = None
        if not touched:
            return []
        self.waiting.clear()
        self.adapter = carried_adapter(old, self.predictor.model, declared, names)
        return carry_notes(old, in_use, self.adapter, names)

    def forget(self) -> str:
        """The explicit forgetting, once the pipeline runs the operator's set again
        (swapped in by the caller): the estimate restarts from the prior about it, nothing
        decided or waiting is kept; counted (``resets``).  Returns the line to log."""
        dropped = ', '.join(f'{k} {format_value(v)}'
                            for k, v in self.adapter.applied_values().items())
        self.adapter = Adapter(self.predictor.model, self.declared.adaptation)
        self.adapter.nominal_x = self.adapter.layout.pack(self.declared)
        self.pending = None
        self.waiting.clear()
        self.last_refusal = self.last_note = ''
        self.counters['resets'] += 1
        return (f'adaptation reset ({self.counters["resets"]} so far): the model in use is the '
                f'declared set again, the estimate restarts from the prior (was in use: '
                f'{dropped})')

    def reconfigure(self, overrides: Mapping[str, Any]) -> list[str]:
        """A parameter set of the operator applied at once (the node prepares the pipeline
        in a worker instead, then :meth:`carry_over`): the operator's set becomes
        ``declared.replace(overrides)``, the pipeline runs it with what was learnt on top.
        ConfigError (nothing changed) if either is not a usable set."""
        declared = self.declared.replace(overrides)
        carried = self.carried_values(declared, overrides.keys())
        self.predictor.reconfigure(declared.replace(carried) if carried else declared)
        return self.carry_over(declared, overrides.keys())

    def reset(self) -> str:
        """:meth:`forget`, the pipeline returned to the operator's set at once
        (:func:`swap_back`)."""
        swap_back(self.predictor, self.predictor.prepare(self.declared))
        return self.forget()

    # ---- read-out ----------------------------------------------------------------------
    def estimates(self) -> dict[str, Any]:
        return self.adapter.estimates()

    def plausibility(self) -> tuple[bool, str]:
        """(whether the estimate is plausible, why not: '' when it is):
        :func:`~.plausibility.estimate_problem`.  An implausible estimate is never applied."""
        why = estimate_problem(self.adapter)
        return not why, why

    def status(self) -> tuple[str, str, dict[str, str]]:
        """(level OK/WARN, message, key values) for /diagnostics."""
        ad = self.adapter
        rms = ad.window_rms()
        values = {k: ('n/a' if not math.isfinite(v) else f'{v:.3e}')
                  for k, v in (('residual_rms_estimate [rad]', rms['estimate']),
                               ('residual_rms_in_use [rad]', rms['applied']),
                               ('residual_rms_nominal [rad]', rms['nominal']))}
        values.update({k: str(v) for k, v in self.counters.items()})
        plausible, why = self.plausibility()
        values['estimate plausible'] = 'yes' if plausible else f'no: {why}'
        for k, v in ad.estimates().items():
            values[f'estimate {k}'] = format_value(v)
        for k, v in ad.applied_values().items():
            values[f'in use {k}'] = format_value(v)
        if self.last_refusal:
            values['last_refusal'] = self.last_refusal
        if self.counters['used'] == 0:
            return 'OK', 'adaptation on: waiting for measured joint states', values
        level = 'WARN' if self.last_refusal and ad.target is None and \
            self.counters['refusals'] and not self.counters['switches'] else 'OK'
        msg = (f'adaptation on: {self.counters["switches"]} steps applied, '
               f'{self.counters["refusals"]} refused')
        return level, msg, values

    def params_config(self) -> Config:
        """The model in use (with the adapted values) as a Config to start from."""
        return _as_config(self.predictor.config)


@dataclass
class _Pending:
    """A step being prepared: its state vector, the stamp it is due [ns], the preparation
    (future-like) and the config it was designed from."""

    step: np.ndarray
    apply_ns: int
    future: Any
    base: Parameters


def _pipeline_starts(c: dict[str, int]) -> int:
    """How often the pipeline's simulator restarted, from its counters (clock restarts,
    resyncs, input switches)."""
    return c['clock_restarts'] + c['resyncs'] + c['input_switches']


def blend_time(compensator: Any, most: float) -> float:
    """How long a step's correction is blended in [s]: BLEND_PERIODS periods of the antenna
    mode the new compensator was designed for (``mode_frequency_hz``: teeth in contact), at
    most ``most``; no compensator: ``most`` (nothing is blended then)."""
    f0 = float(getattr(compensator, 'mode_frequency_hz', 0.0))
    return min(BLEND_PERIODS / f0, most) if f0 > 0.0 and math.isfinite(f0) else most


def swap_back(predictor: RealtimePredictor, prepared: Prepared) -> None:
    """Swap the operator's set ``prepared`` back in (a reset) as gently as a step: the
    simulated drive reseated (its forces kept: the load and drag released would set it
    ringing) and the correction blended (:func:`blend_time`).  A drive without drag rings
    for ever after a jolt; its estimate, at neither load nor drag, takes its flank from
    that ringing and uses no sample."""
    blend = blend_time(prepared.compensator, prepared.config.adaptation.step_interval)
    predictor.reconfigure(prepared, blend=blend, reseat=True)


def run_now(prepare: Callable[[], Steps[Any]]) -> Future:
    """A :data:`Submit` that prepares at once (the twin): a done future (its result, or the
    exception the preparation raised)."""
    fut: Future = Future()
    try:
        fut.set_result(run_steps(prepare()))
    except Exception as exc:  # noqa: BLE001 - re-raised by result() where it is applied
        fut.set_exception(exc)
    return fut


def in_worker(pool: Executor) -> Submit:
    """A :data:`Submit` that runs each preparation in ``pool`` (a worker thread) with the
    switch interval lowered while it runs (:func:`~worm_gear_sim.realtime.switch_interval.
    short_switch_interval`, shared with the trajectory worker)."""
    def run(prepare: Callable[[], Steps[Any]]) -> Any:
        with short_switch_interval():
            return run_steps(prepare())

    return lambda prepare: pool.submit(run, prepare)


def in_slices(budget: float = SLICE_BUDGET) -> Submit:
    """A :data:`Submit` that runs each preparation on the caller's thread, a slice of about
    ``budget`` [s] at each :meth:`LiveAdaptation.step` while it is pending (the node: after
    each sample's answers; no second thread competes with the sample path for the
    interpreter).  The result is the one :func:`run_now` gives."""
    return lambda prepare: Stepwise(prepare(), budget)


def _as_config(p: Parameters) -> Config:
    return p if isinstance(p, Config) else config_from_mapping(p.to_nested_dict())


class _Predictions:
    """The last ``capacity`` predictions (t, (theta2, theta3, theta4)) in time order (up to
    twice as many kept between trims), interpolated linearly at a time inside their span.
    Python lists: the newest is appended and read back at its own stamp, the usual case,
    without numpy's per-call cost."""

    def __init__(self, capacity: int) -> None:
        self._t: list[float] = []
        self._x: list[tuple[float, float, float]] = []
        self._cap = capacity

    @property
    def capacity(self) -> int:
        return self._cap

    def push(self, t: float, theta: Sequence[float]) -> None:
        ts = self._t
        if ts and t <= ts[-1]:
            if t == ts[-1]:
                self._x[-1] = tuple(theta)    # type: ignore[assignment]
                return
            ts.clear()                        # the clock went back: start over
            self._x.clear()
        if len(ts) == 2 * self._cap:
            del ts[:self._cap]
            del self._x[:self._cap]
        ts.append(t)
        self._x.append(tuple(theta))          # type: ignore[arg-type]

    def truncate(self, t: float) -> None:
        """Drop the predictions at ``t`` and after (a stale hold's, retracted)."""
        k = bisect.bisect_left(self._t, t)
        del self._t[k:]
        del self._x[k:]

    def at(self, t: float) -> tuple[float, float, float] | None:
        ts = self._t
        if ts and t == ts[-1]:                # the usual case: the newest prediction's stamp
            return self._x[-1]
        n = len(ts)
        if not n or t > ts[-1] or t < ts[max(n - self._cap, 0)]:
            return None
        k = bisect.bisect_left(ts, t)
        if ts[k] == t:
            return self._x[k]
        w = (t - ts[k - 1]) / (ts[k] - ts[k - 1])
        x0, x1 = self._x[k - 1], self._x[k]
        return ((1.0 - w) * x0[0] + w * x1[0], (1.0 - w) * x0[1] + w * x1[1],
                (1.0 - w) * x0[2] + w * x1[2])
