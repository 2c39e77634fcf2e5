# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The offline twin of the real-time pipeline: :func:`feedforward_series` feeds a whole
sampled reference through :class:`~.predictor.RealtimePredictor` (corrections only), so
live and offline corrections are one code path."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ..config.usable import Config
from ..dynamics.model import DriveModel
from .predictor import RealtimePredictor

__all__ = ['feedforward_series']


def feedforward_series(model: DriveModel | Config, times: ArrayLike,
                       theta1_ref: ArrayLike) -> np.ndarray:
    """The offline twin of the live pipeline: the correction for each sample of a sampled
    reference, exactly as :class:`~.predictor.RealtimePredictor` (the node's
    pipeline) computes it from the same (time, value) pairs, whatever their arrival.

    ``times``: strictly increasing, float seconds or integer nanoseconds (an integer
    array, e.g. ROS stamps: keep them integer, a float of epoch seconds has only ~0.2 us
    of resolution); only differences matter.  The reference is taken to rest at its first
    value before the first sample and at its last value after the last one.  With
    ``compensation.preview_time`` P the correction for sample t uses the samples up to
    t + P (past the end: the rest).  A sample the pipeline would reject (non-finite,
    ``node.max_command_abs``, a jump of more than ``node.max_command_jump``) raises
    ValueError naming it."""
    x = np.asarray(theta1_ref, float)
    t_in = np.asarray(times)
    if t_in.ndim != 1 or x.shape != t_in.shape or t_in.size == 0:
        raise ValueError('times and theta1_ref must be equal-length 1-D arrays')
    if np.issubdtype(t_in.dtype, np.integer):
        rel = t_in.astype(np.int64) - np.int64(t_in[0])
    else:
        t = t_in.astype(float)
        if not np.all(np.isfinite(t)):
            raise ValueError('times must be finite')
        rel = np.round((t - t[0]) * 1e9).astype(np.int64)
    if rel.size > 1 and not np.all(np.diff(rel) > 0):
        i = int(np.argmax(np.diff(rel) <= 0)) + 1
        raise ValueError(f'times must be strictly increasing (to the nanosecond): sample {i}')
    origin = 1_000_000_000                     # stamps must be > 0: any origin will do
    p = RealtimePredictor(model, simulate=False, base_ns=origin)
    out = np.empty(x.size)
    k = 0
    for i in range(x.size):
        o = p.push(origin + int(rel[i]), float(x[i]))
        if o.rejected is not None:
            raise ValueError(f'sample {i} (theta1_ref = {float(x[i])!r}) rejected: '
                             f'{o.rejected.value}')
        for c in o.corrections:
            out[k] = c.delta
            k += 1
    for c in p.finish().corrections:
        out[k] = c.delta
        k += 1
    return out
