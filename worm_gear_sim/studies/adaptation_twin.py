# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The offline twin of live adaptation (``worm-gear-sim adapt``): :func:`run_twin`.

A scenario's references (:func:`scenario`: ``sector``, ``slew``, ``pass``) stream through
the node's pipeline and adaptation loop; the compensated commands drive a simulated plant
whose encoder comes back as the measured joint state.  The node does the same with a real
encoder, so its adaptation equals this for the same samples.  docs/adaptation.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..adaptation.live import LiveAdaptation
from ..adaptation.plant import EncoderPlant
from ..compensation.streaming import centring_preview
from ..config.usable import Config
from ..dynamics.model import DriveModel
from ..realtime.predictor import RealtimePredictor
from .mismatch import sector_scan, slew_reversals
from .tracking_pass import pass_window

__all__ = ['SCENARIOS', 'scenario', 'TwinRun', 'run_twin', 'BASE_NS', 'prepare_start',
           'plant_errors', 'Reference', 'reference_of']

SCENARIOS = ('sector', 'slew', 'pass')
#: A reference of one's own in place of a scenario: (the start set as run, length [s]) ->
#: (t, theta1_ref) on the grid of ``node.publish_rate_hz`` from t = 0, at least that long.
Reference = Callable[[Config, float], tuple[np.ndarray, np.ndarray]]
#: Stamp of t = 0 [ns] (stamps must be > 0).
BASE_NS = 1_000_000_000


def scenario(cfg: Config, name: str, duration: float) -> tuple[np.ndarray, np.ndarray]:
    """(t, theta1_ref) of scenario ``name`` over ``duration`` s at ``node.publish_rate_hz``
    (module docstring)."""
    if not (math.isfinite(duration) and duration > 0):
        raise ValueError(f'duration {duration!r}: must be > 0 s')
    dt = 1.0 / cfg.node.publish_rate_hz
    n = int(round(duration / dt)) + 1
    if name == 'sector':
        mv = sector_scan(cfg, periods=duration / 4.0 + 2 * dt)
        return mv.t[:n], mv.theta1[:n]
    if name == 'slew':
        mv = slew_reversals(cfg)
        x = mv.theta1 - mv.theta1[0]
        parts: list[np.ndarray] = []
        sign, end = 1.0, 0.0
        while sum(p.size for p in parts) < n:
            parts.append(end + sign * x[1:] if parts else x)
            end, sign = parts[-1][-1], -sign
        th = np.concatenate(parts)[:n]
        return np.arange(n) * dt, th
    if name == 'pass':
        t, az, _ = pass_window(duration, step=dt)
        return t[:n], (az[:n] - az[0]) / DriveModel(cfg).output_per_input
    raise ValueError(f'scenario {name!r}: one of {", ".join(SCENARIOS)}')


def reference_of(name: str | Reference) -> Reference:
    """The reference of a scenario's name (:func:`scenario`), or ``name`` itself when it
    is one already."""
    if callable(name):
        return name
    return lambda cfg, duration: scenario(cfg, name, duration)


@dataclass
class TwinRun:
    """The twin's record: per sample t, theta1_ref, antenna error uncompensated and with the
    adapting feed-forward [rad]; the steps applied (time, values), the final estimate, the
    counters and the drive's crossings the adapter measured (:attr:`.Adapter.crossings`)."""

    t: np.ndarray
    theta1_ref: np.ndarray
    error_uncompensated: np.ndarray
    error_compensated: np.ndarray
    steps: list[tuple[float, dict[str, Any]]] = field(default_factory=list)
    estimates: dict[str, Any] = field(default_factory=dict)
    in_use: dict[str, Any] = field(default_factory=dict)
    counters: dict[str, int] = field(default_factory=dict)
    messages: list[str] = field(default_factory=list)
    record: list[tuple[int, float, list[tuple[int, float, float]]]] = field(
        default_factory=list)
    crossings: list[tuple[float, float, float, float, str]] = field(default_factory=list)


def prepare_start(start: Config, preview: float | None = None) -> Config:
    """The start set as the twin runs it: adaptation on, the compensation applied to the
    prediction, ``preview`` (None: the start's, or the centring preview when it has none)."""
    p = start.compensation.preview_time if preview is None else float(preview)
    if preview is None and p == 0.0:
        p = centring_preview(start)
    return start.replace({'adaptation.enabled': True, 'node.compensation_applied': True,
                          'compensation.preview_time': p})


#: Where the twin's handshake stamps its samples, after the scenario's start [ns].
HANDSHAKE_AFTER_NS = 10_000_000_000


def _handshake(pred: RealtimePredictor, live: LiveAdaptation, drive: EncoderPlant,
               theta1: float, first_ns: int, period_ns: int, n: int) -> None:
    """``n`` samples of ``theta1`` from ``first_ns`` through the pipeline (clock ``now``
    = stamp - preview), the adaptation and ``drive`` (started at the first): the live
    harness's handshake before its clock goes back (:func:`run_twin`)."""
    ahead = int(pred.config.compensation.preview_time * 1e9)
    names = pred.config.node.joint_names[1:]
    for j in range(n):
        ns = first_ns + j * period_ns
        out = pred.push(ns, theta1, now_ns=ns - ahead)
        for p in out.predictions:
            live.predicted(p.stamp_ns, p.theta)
        if out.predictions:
            live.step(out.predictions[-1].stamp_ns)
        for c in out.corrections:
            _, meas = drive.command((c.stamp_ns - first_ns) * 1e-9, c.theta1_ref + c.delta)
            live.measured(c.stamp_ns, names[2:], [meas])


def plant_errors(plant: Config, start: Config, t: np.ndarray, theta1_ref: np.ndarray,
                 theta4: np.ndarray, theta4_raw: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(uncompensated, compensated) antenna error [rad] at the uniform times ``t``: the
    plant driven by the raw reference, and ``theta4`` (the plant driven by the adapting
    feed-forward) - theta1_ref l_w / r_g (the start set's ratio); nan where ``theta4`` is.
    ``theta4_raw``: the raw-driven plant's theta4 at ``t`` if the caller stepped it;
    otherwise stepped here as :class:`EncoderPlant` steps the plant (the same path as the
    compensated one, so a correction of zero gives the same error)."""
    if theta4_raw is None:
        raw = EncoderPlant(plant, float(theta1_ref[0]), noise=0.0, encoder_bits=0)
        theta4_raw = np.array([raw.command(float(tk), float(xk))[0]
                               for tk, xk in zip(t, theta1_ref)])
    unc = theta4_raw - theta1_ref * DriveModel(plant).output_per_input
    return unc, theta4 - theta1_ref * DriveModel(start).output_per_input


def run_twin(plant: Config, start: Config, name: str | Reference, duration: float, *,
             noise: float = 1e-6, encoder_bits: int = 20, seed: int = 0, adapt: bool = True,
             preview: float | None = None, base_ns: int = BASE_NS, hold: int = 0,
             plant_from_ns: int | None = None, handshake: int = 0, record: bool = False,
             on_sample: Callable[[float], None] | None = None) -> TwinRun:
    """Stream scenario ``name`` (or a :data:`Reference`) for ``duration`` s (module
    docstring): the plant driven by
    the adapting feed-forward (``adapt`` False: the feed-forward of the start set, never
    adapted), and by the raw reference for the uncompensated error.  ``noise``: encoder
    noise RMS [rad]; ``encoder_bits``: resolution 2 pi / 2^bits (0: none); ``base_ns``: the
    stamp of t = 0; ``hold``: this many samples of the first reference on the stream's grid
    before t = 0, the pipeline and the plant starting at the first of them (a start a few
    samples earlier: how much the adaptive path depends on its start; the live harness
    started so before its handshake ended in a restart); ``plant_from_ns``: the plant
    starts at this stamp instead, at rest at the first reference, and takes no earlier
    command; ``handshake``: this many samples of the
    first reference, answered by a plant, 10 s of stream time after the scenario's start,
    then the clock goes back to the scenario's start (the live harness's handshake): the
    pipeline, the adaptation and the plant restart, and the run is the plain one;
    ``record``: keep per pushed sample
    (stamp, theta1_ref, [(stamp, encoder theta4, delta) of each correction released]) in
    ``TwinRun.record`` (what a node would receive, in its order)."""
    cfg = prepare_start(start, preview)
    ahead = cfg.compensation.preview_time
    t, x = reference_of(name)(cfg, duration + ahead + 5.0 / cfg.node.publish_rate_hz)
    keep = t <= duration + 1e-12
    period_ns = int(round((t[1] - t[0]) * 1e9))
    first_ns = base_ns - int(hold) * period_ns
    pred = RealtimePredictor(cfg, apply_compensation=True, base_ns=first_ns)
    names = cfg.node.joint_names[1:]
    live = LiveAdaptation(pred, names)
    plants = _TwinPlants(
        drive=EncoderPlant(plant, float(x[0]), noise=noise, encoder_bits=encoder_bits,
                           seed=seed),
        raw=EncoderPlant(plant, float(x[0]), noise=0.0, encoder_bits=0),  # the raw reference
        plant_ns=first_ns if plant_from_ns is None else int(plant_from_ns),
        n_keep=int(np.count_nonzero(keep)), base_ns=base_ns, t=t)
    run = TwinRun(t[keep], x[keep], np.zeros(0), np.zeros(0))
    stamps = [first_ns + j * period_ns for j in range(int(hold))] + \
        [base_ns + int(round(tk * 1e9)) for tk in t]
    refs = np.concatenate([np.full(int(hold), x[0]), x])
    if handshake:
        _handshake(pred, live, EncoderPlant(plant, float(x[0]), noise=noise,
                                            encoder_bits=encoder_bits, seed=seed),
                   float(x[0]), first_ns + HANDSHAKE_AFTER_NS, period_ns, int(handshake))
    for k, ns in enumerate(stamps):
        # (after a handshake the first sample comes with the clock gone back: a restart)
        out = pred.push(ns, float(refs[k]),
                        now_ns=ns - int(ahead * 1e9) if handshake and k == 0 else None)
        if adapt:                   # as the node: predictions, the decision, then encoders
            _adapt(live, run, out, (ns - base_ns) * 1e-9)
        got = plants.drive_with(out.corrections, live if adapt else None, names[2:])
        if record:
            run.record.append((ns, float(refs[k]), got))
        if on_sample is not None and k >= hold:
            on_sample(t[k - hold])
    _finish(run, plant, cfg, plants, live, pred)
    return run


def _adapt(live: LiveAdaptation, run: TwinRun, out: Any, t: float) -> None:
    """The pipeline's predictions to the adaptation and its decision, as the node does;
    a switch of the set in use is noted in ``run.steps`` at ``t`` [s]."""
    for p in out.predictions:
        live.predicted(p.stamp_ns, p.theta)
    if out.predictions:
        before = live.counters['switches']
        run.messages += live.step(out.predictions[-1].stamp_ns)
        if live.counters['switches'] != before:
            run.steps.append((t, live.adapter.applied_values()))


@dataclass
class _TwinPlants:
    """The plant driven by the feed-forward (``drive``, with encoders) and by the raw
    reference (``raw``), from ``plant_ns``; their theta4 at the kept reference times."""

    drive: EncoderPlant
    raw: EncoderPlant
    plant_ns: int
    n_keep: int
    base_ns: int
    t: np.ndarray
    theta4: np.ndarray = field(init=False)
    theta4_raw: np.ndarray = field(init=False)
    index: dict[int, int] = field(init=False)

    def __post_init__(self) -> None:
        self.theta4 = np.full(self.n_keep, np.nan)
        self.theta4_raw = np.full(self.n_keep, np.nan)
        self.index = {self.base_ns + int(round(tk * 1e9)): k
                      for k, tk in enumerate(self.t[:self.n_keep])}

    def drive_with(self, corrections: Any, live: LiveAdaptation | None,
                   encoder_names: Any) -> list[tuple[int, float, float]]:
        """Each correction released commands both plants; the encoder reading goes to
        ``live`` (None: not adapting).  Returns (stamp, encoder theta4, delta) of each."""
        got = []
        for c in corrections:
            if c.stamp_ns < self.plant_ns:
                continue
            tc = (c.stamp_ns - self.plant_ns) * 1e-9
            th4, meas = self.drive.command(tc, c.theta1_ref + c.delta)
            th4_raw = self.raw.command(tc, c.theta1_ref)[0]
            j = self.index.get(c.stamp_ns)
            if j is not None:
                self.theta4[j], self.theta4_raw[j] = th4, th4_raw
            got.append((c.stamp_ns, meas, c.delta))
            if live is not None:
                live.measured(c.stamp_ns, encoder_names, [meas])
        return got


def _finish(run: TwinRun, plant: Config, cfg: Config, plants: _TwinPlants,
            live: LiveAdaptation, pred: RealtimePredictor) -> None:
    """The run's errors, the adaptation's estimates and the counters into ``run``."""
    theta4, theta4_raw = plants.theta4, plants.theta4_raw
    run.error_uncompensated, run.error_compensated = plant_errors(
        plant, cfg, run.t, run.theta1_ref, theta4,
        None if np.isnan(theta4_raw).any() else theta4_raw)
    run.estimates = live.estimates()
    run.in_use = live.adapter.applied_values()
    run.crossings = list(live.adapter.crossings)
    run.counters = {**live.counters, **{f'predictor_{k}': v for k, v in
                                         pred.counters.items() if v}}
