# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Which measured outputs a fit can use at their sampling: an output whose elastic motion
lies largely above its Nyquist frequency is named and left out of the fit instead of
sinking it (:data:`ALIASED_SHARE`).  The rule: docs/identification.md ("Records").
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..config.usable import Config
from ..dynamics.modal import modes
from ..dynamics.model import DriveModel
from ..dynamics.stepping import SimulationError
from ..records import Record
from .data import FIT_EVERY, MAX_FIT_SAMPLES, OUTPUTS, motion_times, predict, rigid_motion

__all__ = ['ALIASED_SHARE', 'DENSE_SPAN', 'OutputSampling', 'sampling_check',
           'sampling_advice']

#: Share of an output's elastic motion (power) above Nyquist beyond which it is not
#: observable at that sampling.
ALIASED_SHARE = 0.10
#: Seconds of a record simulated at every step for the check (from its start; the move and
#: its ringing are what matter).
DENSE_SPAN = 0.3
#: Sample rate advised: this many samples per period of the highest mode that moves an
#: output (Nyquist is 2; 2.5 leaves room for an anti-aliasing filter's roll-off).
ADVISED_SAMPLES_PER_PERIOD = 2.5
#: A mode "moves" an output when the output's entry of the mode shape is at least this share
#: of the shape's largest entry.
SHAPE_SHARE = 0.05


@dataclass
class OutputSampling:
    """The sampling verdict of one output over the records that measure it."""

    output: str
    sample_rate_hz: float             # the lowest over the records measuring it
    share_above_nyquist: float        # the largest over those records (0..1)
    mode_hz: float | None             # the strongest model mode above Nyquist, if any
    record: str                       # the record of the worst share
    observable: bool
    fit_every: int = 1                # that record decimated for the fit: every k-th sample

    def describe(self) -> str:
        cut = (f' (the fit keeps every {self.fit_every}th sample of {self.record}, recorded '
               f'at {self.sample_rate_hz * self.fit_every:.6g} Hz: at most {MAX_FIT_SAMPLES} '
               'samples per record; fit a shorter record, or several)'
               if self.fit_every > 1 else '')
        if self.observable:
            return (f'{self.output}: sampled at {self.sample_rate_hz:.6g} Hz, '
                    f'{100 * self.share_above_nyquist:.1f} % of its motion above '
                    f'Nyquist{cut}')
        mode = f'its {self.mode_hz:.0f} Hz mode' if self.mode_hz else 'its modes'
        need = (f'; sample at >= {ADVISED_SAMPLES_PER_PERIOD * self.mode_hz:.0f} Hz to use it'
                if self.mode_hz else '')
        return (f'{self.output}: not observable at this sampling: {self.record} samples it at '
                f'{self.sample_rate_hz:.6g} Hz (Nyquist {self.sample_rate_hz / 2:.6g} Hz) and '
                f'{100 * self.share_above_nyquist:.0f} % of its motion is in {mode} above '
                f'that{need}{cut}')


def _sample_rate(t: np.ndarray) -> float:
    dt = float(np.median(np.diff(t))) if t.size > 1 else math.inf
    return 1.0 / dt if dt > 0 else math.inf


def _dense(model: DriveModel, rec: Record) -> tuple[np.ndarray, dict[str, np.ndarray]] | None:
    """The model's outputs at every step over the record's first DENSE_SPAN seconds."""
    dt = model.config.integrator.time_step
    t0 = float(rec.t[0])
    t_end = min(float(rec.t[-1]), t0 + max(DENSE_SPAN, motion_times(rec.t, rec.theta1)[0]
                                            - t0 + 0.5 * DENSE_SPAN))
    n = int(math.floor((t_end - t0) / dt + 1e-9))
    if n < 16:
        return None
    t = t0 + np.arange(n + 1) * dt
    th1 = np.interp(t, rec.t, rec.theta1)
    load = None if rec.load_torque is None else np.interp(t, rec.t, rec.load_torque)
    dense = Record(name=rec.name, t=t, theta1=th1, measured={'theta4': th1}, load_torque=load)
    try:
        return th1, predict(model, dense)
    except (SimulationError, ValueError):
        return None


def _share_above(got: tuple[np.ndarray, dict[str, np.ndarray]], o: str, rigid: float,
                 dt: float, nyq: float, above: list[tuple[float, float]]
                 ) -> tuple[float, float | None]:
    """(share of the elastic motion's power above nyq, the model mode nearest the spectral
    peak above nyq)."""
    th1, pred = got
    y = pred[o] - rigid * th1
    y = y - y.mean()
    spec = np.abs(np.fft.rfft(y)) ** 2
    f = np.fft.rfftfreq(y.size, dt)
    total = float(spec[1:].sum())
    if not total > 0:
        return 0.0, None
    hi = f > nyq
    share = float(spec[hi].sum()) / total
    peak = float(f[hi][np.argmax(spec[hi])]) if hi.any() else math.nan
    if not math.isfinite(peak):
        return share, max(above, key=lambda a: a[1])[0]
    return share, min((fm for fm, _ in above), key=lambda fm: abs(fm - peak))


def sampling_check(base: DriveModel | Config, records: Sequence[Record]
                   ) -> dict[str, OutputSampling]:
    """:class:`OutputSampling` of every measured output (module docstring)."""
    model = DriveModel.of(base)
    md = modes(model)
    rigid = rigid_motion(model)
    dt = model.config.integrator.time_step
    out: dict[str, OutputSampling] = {}
    dense_cache: dict[int, tuple[np.ndarray, dict[str, np.ndarray]] | None] = {}
    for o in OUTPUTS:
        j = OUTPUTS.index(o)
        cands: list[OutputSampling] = []
        for i, r in enumerate(records):
            if o not in r.measured:
                continue
            fs = _sample_rate(np.asarray(r.t, float))
            nyq = 0.5 * fs
            above = [(f, abs(md.shapes[j, k]) / max(np.max(np.abs(md.shapes[:, k])), 1e-300))
                     for k, f in enumerate(md.frequencies_hz) if f > nyq]
            above = [(f, s) for f, s in above if s >= SHAPE_SHARE]
            share, mode_hz = 0.0, None
            if above:
                if i not in dense_cache:
                    dense_cache[i] = _dense(model, r)
                got = dense_cache[i]
                if got is not None:
                    share, mode_hz = _share_above(got, o, rigid[j], dt, nyq, above)
            cands.append(OutputSampling(o, fs, share, mode_hz, r.name, share <= ALIASED_SHARE,
                                        int(r.source.get(FIT_EVERY, 1))))
        if cands:   # the worst record decides: not observable first, then the largest share
            out[o] = max(cands, key=lambda c: (not c.observable, c.share_above_nyquist))
    return out


def sampling_advice(base: DriveModel | Config) -> dict[str, float]:
    """Sample rate [Hz] each output needs so that every mode that moves it (shape entry
    >= SHAPE_SHARE of the mode's largest) lies below Nyquist with room for the
    anti-aliasing filter: ADVISED_SAMPLES_PER_PERIOD x the highest such mode."""
    md = modes(DriveModel.of(base))
    advice = {}
    for j, o in enumerate(OUTPUTS):
        fs = [f for k, f in enumerate(md.frequencies_hz)
              if abs(md.shapes[j, k]) >= SHAPE_SHARE * np.max(np.abs(md.shapes[:, k]))]
        advice[o] = ADVISED_SAMPLES_PER_PERIOD * max(fs) if fs else 0.0
    return advice
