# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The dominant frequency of a sampled signal (the ringing a record shows)."""

from __future__ import annotations

import math

import numpy as np

__all__ = ['dominant_frequency']


def dominant_frequency(t: np.ndarray, y: np.ndarray, f_min: float = 1.0) -> float:
    """Frequency [Hz] of the largest spectral peak of y - mean (Hann window, zero
    padding x2, parabolic interpolation of the log magnitude). NaN when the series is too
    short or flat."""
    n = y.size
    if n < 16:
        return math.nan
    dt = float(t[1] - t[0])
    yy = (y - y.mean()) * np.hanning(n)
    if not np.any(yy):
        return math.nan
    nfft = 1 << int(math.ceil(math.log2(2 * n)))
    mag = np.abs(np.fft.rfft(yy, nfft))
    freqs = np.fft.rfftfreq(nfft, dt)
    mag[freqs < f_min] = 0.0
    k = int(np.argmax(mag))
    if 0 < k < mag.size - 1 and mag[k - 1] > 0 and mag[k + 1] > 0:
        a, b, c = np.log(mag[k - 1]), np.log(mag[k]), np.log(mag[k + 1])
        den = a - 2 * b + c
        off = 0.5 * (a - c) / den if den != 0 else 0.0
        return float((k + off) * (freqs[1] - freqs[0]))
    return float(freqs[k])
