# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The offline twin of live adaptation (``worm-gear-sim adapt``).

A scenario's reference samples theta1_ref (at ``node.publish_rate_hz``) stream through the
node's real-time pipeline (:class:`~worm_gear_sim.realtime.predictor.RealtimePredictor`,
compensation applied to its simulated drive) and the node's adaptation loop
(:class:`~.live.LiveAdaptation`); each released compensated command theta1_ref + delta
drives a simulated plant (another parameter set: the real drive's stand-in, started at rest
under its load), whose antenna angle, quantised and noisy like an encoder, comes back as
the measured joint state stamped with the command's stamp.  The node does the same with a
real encoder, so the node's adaptation equals this for the same samples.

Scenarios (:func:`scenario`): ``sector`` (the antenna sweeps +-5 deg sinusoidally with a
4 s period, from rest at one edge), ``slew`` (worm slews at +-2 rad/s with reversals,
repeated back and forth), ``pass`` (the azimuth of an 85 deg satellite pass, the window
centred on culmination).  The reference is streamed ``compensation.preview_time`` ahead
(the centring preview when the start set has none: a planned scan is known a few ms ahead,
and the play is crossed well only with it, docs/compensation.md).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..compensation import centring_preview
from ..dynamics.model import DriveModel
from ..params import Config
from ..realtime.predictor import RealtimePredictor
from ..studies.mismatch import sector_scan, slew_reversals
from ..studies.tracking_pass import pass_window
from .live import LiveAdaptation
from .plant import EncoderPlant

__all__ = ['SCENARIOS', 'scenario', 'TwinRun', 'run_twin', 'BASE_NS', 'prepare_start',
           'plant_errors']

SCENARIOS = ('sector', 'slew', 'pass')
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


def run_twin(plant: Config, start: Config, name: str, duration: float, *,
             noise: float = 1e-6, encoder_bits: int = 20, seed: int = 0, adapt: bool = True,
             preview: float | None = None, base_ns: int = BASE_NS, hold: int = 0,
             plant_from_ns: int | None = None, handshake: int = 0, record: bool = False,
             on_sample: Callable[[float], None] | None = None) -> TwinRun:
    """Stream scenario ``name`` for ``duration`` s (module docstring): the plant driven by
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
    t, x = scenario(cfg, name, duration + ahead + 5.0 / cfg.node.publish_rate_hz)
    keep = t <= duration + 1e-12
    period_ns = int(round((t[1] - t[0]) * 1e9))
    first_ns = base_ns - int(hold) * period_ns
    plant_ns = first_ns if plant_from_ns is None else int(plant_from_ns)
    pred = RealtimePredictor(cfg, apply_compensation=True, base_ns=first_ns)
    names = cfg.node.joint_names[1:]
    live = LiveAdaptation(pred, names)
    drive = EncoderPlant(plant, float(x[0]), noise=noise, encoder_bits=encoder_bits, seed=seed)
    raw = EncoderPlant(plant, float(x[0]), noise=0.0, encoder_bits=0)   # the raw reference
    n_keep = int(np.count_nonzero(keep))
    theta4 = np.full(n_keep, np.nan)
    theta4_raw = np.full(n_keep, np.nan)
    index = {base_ns + int(round(tk * 1e9)): k for k, tk in enumerate(t[:n_keep])}
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
            for p in out.predictions:
                live.predicted(p.stamp_ns, p.theta)
            if out.predictions:
                before = live.counters['switches']
                run.messages += live.step(out.predictions[-1].stamp_ns)
                if live.counters['switches'] != before:
                    run.steps.append(((ns - base_ns) * 1e-9, live.adapter.applied_values()))
        got = []
        for c in out.corrections:
            if c.stamp_ns < plant_ns:
                continue
            tc = (c.stamp_ns - plant_ns) * 1e-9
            th4, meas = drive.command(tc, c.theta1_ref + c.delta)
            th4_raw = raw.command(tc, c.theta1_ref)[0]
            j = index.get(c.stamp_ns)
            if j is not None:
                theta4[j], theta4_raw[j] = th4, th4_raw
            got.append((c.stamp_ns, meas, c.delta))
            if adapt:
                live.measured(c.stamp_ns, names[2:], [meas])
        if record:
            run.record.append((ns, float(refs[k]), got))
        if on_sample is not None and k >= hold:
            on_sample(t[k - hold])
    run.error_uncompensated, run.error_compensated = plant_errors(
        plant, cfg, run.t, run.theta1_ref, theta4,
        None if np.isnan(theta4_raw).any() else theta4_raw)
    run.estimates = live.estimates()
    run.in_use = live.adapter.applied_values()
    run.crossings = list(live.adapter.crossings)
    run.counters = {**live.counters, **{f'predictor_{k}': v for k, v in
                                         pred.counters.items() if v}}
    return run
