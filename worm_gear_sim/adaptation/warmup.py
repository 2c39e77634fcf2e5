# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Every compiled kernel a configuration uses, compiled or loaded before the node is ready:
:func:`warm_up`.

It runs each path the node runs (the pipeline's stamped and unstamped paths, a stale hold,
a reconfiguration blended in, the model check and, with ``adaptation.enabled``, the
adaptation's samples) on throwaway objects built from the node's configuration, so that no
kernel compiles after "ready".  Figures: docs/performance.md.
"""

from __future__ import annotations

import gc
import math
import time
import warnings
from dataclasses import dataclass

import numpy as np

from .._support.kernel_cache import take_note
from ..config.usable import Config
from ..realtime.model_check import ModelCheck
from ..realtime.predictor import RealtimePredictor
from . import per_sample
from .live import LiveAdaptation

__all__ = ['warm_up', 'Warmed', 'WARM_PLAY', 'WARM_HARMONICS']

#: The play [rad] of the model the pipeline's reconfiguration is warmed with (the
#: compensator's backlash inverse and the play-free model of its modes) ...
WARM_PLAY = 2e-4
#: and its worm error harmonics [rad] (the modes about a rest point with periodic error)
WARM_HARMONICS = [1e-6, 1e-6]
_BASE_NS = 1_000_000_000


@dataclass(frozen=True)
class Warmed:
    """What :func:`warm_up` did: the seconds it took, and the one line that says where the
    kernels are cached when it is not the package's folder (said once per process, else
    '': :func:`~.kernel_cache.take_note`)."""

    seconds: float
    note: str = ''


def warm_up(cfg: Config, adaptation: bool = True) -> Warmed:
    """Compile or load every kernel ``cfg``'s node runs (module docstring); ``adaptation``
    False: a node without live adaptation (its kernels are not needed)."""
    t0 = time.perf_counter()
    with warnings.catch_warnings():        # a throwaway's notes: the node logs its own
        warnings.simplefilter('ignore')
        _pipeline(cfg)
        if adaptation and cfg.adaptation.enabled:
            _adaptation(cfg)
    gc.collect()      # the garbage of compiling (the node's process then freezes its heap)
    return Warmed(time.perf_counter() - t0, take_note())


def _samples(cfg: Config, n: int) -> list[tuple[int, float]]:
    """n stamped samples of a slow ramp at the node's rate."""
    period_ns = int(round(1e9 / cfg.node.publish_rate_hz))
    return [(_BASE_NS + k * period_ns, 1e-3 * k) for k in range(n)]


def _pipeline(cfg: Config) -> None:
    pred = RealtimePredictor(cfg, base_ns=_BASE_NS)
    names = cfg.node.joint_names
    check = ModelCheck(names[1:], cfg.node.residual_window, cfg.node.residual_warn_rms)
    samples = _samples(cfg, 40)
    for k, (ns, x) in enumerate(samples):
        if k == 5:
            pred.push_load(ns, 0.1, now_ns=ns)
        out = pred.push(ns, x, now_ns=ns)
        for p in out.predictions:
            check.predicted_ns(p.stamp_ns, p.theta)
            check.measured_message_ns(p.stamp_ns, list(names[1:]), list(p.theta))
    pred.hold(samples[-1][0] + 10 ** 9)     # a paused stream: the held output
    # a step's swap (prepared, blended in) to a model with play, and samples through it
    pred = RealtimePredictor(cfg, base_ns=_BASE_NS)
    played = cfg.replace({'mesh.backlash': max(cfg.mesh.backlash, WARM_PLAY),
                          'mesh.worm_error_harmonics': WARM_HARMONICS})
    for k, (ns, x) in enumerate(samples):
        if k == 20:
            pred.reconfigure(pred.prepare(played), blend=0.005)
        pred.push(ns, x, now_ns=ns)
    cmd = RealtimePredictor(cfg)            # the unstamped path
    period_ns = int(round(1e9 / cfg.node.publish_rate_hz))
    for k in range(1, 20):
        cmd.push_command(k * period_ns, 1e-3 * k)
        cmd.tick(k * period_ns + period_ns // 2)


def _adaptation(cfg: Config) -> None:
    cfg = cfg.replace({'node.compensation_applied': True})
    pred = RealtimePredictor(cfg, apply_compensation=True, base_ns=_BASE_NS)
    live = LiveAdaptation(pred, cfg.node.joint_names[1:])
    antenna = [cfg.node.joint_names[3]]
    rate = cfg.node.publish_rate_hz
    n = int(math.ceil((cfg.adaptation.sample_delay + 0.05) * rate)) + 10
    last = (0.0, 0.0, 0.0)
    for ns, x in _samples(cfg, n):
        out = pred.push(ns, x)
        for p in out.predictions:
            live.predicted(p.stamp_ns, p.theta)
            last = p.theta
        if out.predictions:
            live.step(out.predictions[-1].stamp_ns)
        for c in out.corrections:
            live.measured(c.stamp_ns, antenna, [last[2] + 1e-6])
    # the kernels rarer samples reach, with the arguments the estimator gives them
    ad = live.adapter
    t = float(ad._last_t) if math.isfinite(ad._last_t) else 0.0
    th2, th3, th4 = (float(v) for v in last)
    per_sample.sample_tail(ad._st, ad.theta, ad.P, ad._std2, ad._phi, ad.applied_x, ad._R,
                           ad._sc, ad._lay, t, th4 + 1e-6, th2, th3, th4)
    ad._timing._next_look = -math.inf     # the step detector's look, due now
    ad._step_update(t, 0.0)
    phi = np.zeros(ad.layout.n)
    phi[0] = 1.0
    per_sample._kalman_step(ad.theta, ad.P, np.zeros(ad.layout.n), ad._std ** 2, phi,
                            abs(1e-6), 1e-14, 4.0)
    per_sample.window_norm(ad._R, ad.theta)   # the window's residuals (diagnostics)
