# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Records for identification: their checks, the model's prediction of a record, synthetic
records of the model, and the dominant frequencies of the measured motion.

A *record* (:class:`~worm_gear_sim.records.Record`) is one measured run of the drive: sample
times ``t`` [s], the commanded worm angle ``theta1`` [rad] at those times and at least one
measured angle ``theta2``/``theta3``/``theta4`` [rad].  The model predicts a record by
starting at rest in static equilibrium at ``theta1[0]`` and integrating the command
interpolated linearly between the samples
(:class:`~worm_gear_sim.dynamics.profiles.SampledProfile`), exactly as ``simulate --csv``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..config.usable import Config
from ..dynamics.load import LoadSignal, SampledLoad
from ..dynamics.model import DriveModel
from ..dynamics.profiles import Profile, SampledProfile, motion_span
from ..dynamics.simulation import Simulator
from ..dynamics.spectrum import dominant_frequency
from ..records import Record

__all__ = ['OUTPUTS', 'MIN_SAMPLES', 'MAX_FIT_SAMPLES', 'MAX_RECORD_ANGLE', 'FIT_EVERY',
           'RECORDED_SAMPLES', 'decimation', 'IdentificationError', 'record_name', 'check_record',
           'normalised', 'motion_times', 'rigid_motion', 'predict', 'record_from_model',
           'measured_frequencies']

OUTPUTS: tuple[str, ...] = ('theta2', 'theta3', 'theta4')
MIN_SAMPLES = 20
#: Samples per record a fit uses at most (a longer record keeps every k-th sample).
MAX_FIT_SAMPLES = 200_000
#: The key of a normalised record's ``source`` holding its decimation stride (if > 1).
FIT_EVERY = 'fit_every'
RECORDED_SAMPLES = 'recorded_samples'
#: Largest angle a record may hold [rad] (theta1 and the measured outputs): 1.6e5 turns;
#: beyond it a value is a unit or parsing error, and squares of it overflow the fit.
MAX_RECORD_ANGLE = 1e6


class IdentificationError(ValueError):
    """Bad records, bad fit keys or a failed fit: one line naming the cause."""


def record_name(rec: Record, index: int | None = None) -> str:
    """The record's name, else 'record N' (N = index + 1)."""
    if rec.name:
        return rec.name
    return f'record {index + 1}' if index is not None else 'record'


def check_record(rec: Record, index: int | None = None) -> None:
    """Raise IdentificationError unless the record is usable: 1-D finite arrays of equal length,
    strictly increasing times, at least MIN_SAMPLES samples, at least one measured output among
    theta2/theta3/theta4 (any other name is refused), angles within MAX_RECORD_ANGLE, and
    no measured output constant over a record whose command moves (nothing to fit)."""
    nm = record_name(rec, index)
    t = np.asarray(rec.t, float)
    th1 = np.asarray(rec.theta1, float)
    if t.ndim != 1 or th1.shape != t.shape:
        raise IdentificationError(f'{nm}: t and theta1 must be 1-D series of equal length')
    if t.size < MIN_SAMPLES:
        raise IdentificationError(f'{nm}: too short ({t.size} samples, need >= {MIN_SAMPLES})')
    for label, arr in (('t', t), ('theta1', th1)):
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            raise IdentificationError(f'{nm}: {label} is not finite at sample {bad[0]}')
    dt = np.diff(t)
    if np.any(dt <= 0):
        k = int(np.flatnonzero(dt <= 0)[0])
        what = 'duplicated' if dt[k] == 0 else 'decreasing'
        raise IdentificationError(f'{nm}: {what} time at sample {k + 1} (t = {t[k + 1]:.9g} s);'
                                  ' times must increase strictly')
    if not rec.measured:
        raise IdentificationError(f'{nm}: no measured output (need one of '
                                  f'{", ".join(OUTPUTS)})')
    for key, arr in rec.measured.items():
        if key not in OUTPUTS:
            raise IdentificationError(f'{nm}: unknown measured output {key!r} (known: '
                                      f'{", ".join(OUTPUTS)})')
        a = np.asarray(arr, float)
        if a.shape != t.shape:
            raise IdentificationError(f'{nm}: {key} has {a.size} samples, t has {t.size}')
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            raise IdentificationError(f'{nm}: {key} is not finite at sample {bad[0]}')
        if float(np.ptp(a)) == 0.0 and float(np.ptp(th1)) > 0.0:
            raise IdentificationError(f'{nm}: {key} is constant ({float(a[0]):.6g} rad at '
                                      f'every sample) while theta1 moves: no measured motion '
                                      'to fit')
    for key, arr in (('theta1', th1), *rec.measured.items()):
        big = np.flatnonzero(np.abs(np.asarray(arr, float)) > MAX_RECORD_ANGLE)
        if big.size:
            raise IdentificationError(
                f'{nm}: {key} = {float(np.asarray(arr)[big[0]]):.6g} rad at sample {big[0]}, '
                f'beyond {MAX_RECORD_ANGLE:g} rad (a unit or parsing error?)')


def decimation(n: int) -> int:
    """The stride that brings ``n`` samples to at most MAX_FIT_SAMPLES (1: none)."""
    return max(1, -(-n // MAX_FIT_SAMPLES))


def normalised(rec: Record, index: int) -> Record:
    """A checked copy with contiguous float arrays and a name (``record N`` if it had none).
    A record of more than MAX_FIT_SAMPLES samples keeps every k-th (:func:`decimation`):
    the residuals compare the model with the record at its sample instants, so fewer
    instants bound the memory and the cost per evaluation without biasing the fit (the
    noise level is estimated on the samples kept)."""
    check_record(rec, index)
    k = decimation(len(rec.t))
    source = dict(rec.source)
    if k > 1:
        source[FIT_EVERY] = k           # said by the sampling verdict and the report
        source[RECORDED_SAMPLES] = len(rec.t)
    return Record(name=record_name(rec, index), t=np.ascontiguousarray(rec.t[::k], float),
                  theta1=np.ascontiguousarray(rec.theta1[::k], float),
                  measured={o: np.ascontiguousarray(v[::k], float)
                            for o, v in rec.measured.items()},
                  t0_ns=rec.t0_ns,
                  load_torque=None if rec.load_torque is None else
                  np.ascontiguousarray(rec.load_torque[::k], float), source=source)


def motion_times(t: np.ndarray, th1: np.ndarray) -> tuple[float, float]:
    """First and last time at which the command changes (relative tolerance 1e-9 of its range
    or 1e-12 rad)."""
    span = motion_span(t, th1, tol=max(1e-12, 1e-9 * float(np.ptp(th1))))
    return (float(t[0]), float(t[0])) if span is None else span


def rigid_motion(model: DriveModel | Config) -> np.ndarray:
    """(theta2, theta3, theta4) of the undeformed drive per unit theta1."""
    return DriveModel.of(model).rigid_motion


def predict(model: DriveModel | Config, rec: Record, t_end: float | None = None,
            memo: dict[float | None, Any] | None = None) -> dict[str, np.ndarray]:
    """The model's theta2, theta3, theta4 at the record's sample times up to ``t_end``.

    Starts at rest in static equilibrium at theta1[0] (under the record's load torque at
    t[0] when it has one), command (and load) interpolated linearly between the samples.
    ``memo``: a dict the caller keeps for this record (a fit's evaluations): the command of
    each ``t_end`` and its values on the integrator's grid are kept in it (the same numbers).
    Raises SimulationError if the integration fails."""
    t = np.asarray(rec.t, float)
    th1 = np.asarray(rec.theta1, float)
    load = None if rec.load_torque is None else SampledLoad(t, rec.load_torque)
    if t_end is not None:
        n = int(np.searchsorted(t, t_end, side='right'))
        t, th1 = t[:max(n, 2)], th1[:max(n, 2)]
    model = DriveModel.of(model)
    dt = model.config.integrator.time_step
    steps = (t - t[0]) / dt
    ks = np.rint(steps)
    sim = Simulator(model, theta1=float(th1[0]), t0=float(t[0]), interpolation='linear')
    if load is not None:
        sim.reset(float(th1[0]), float(t[0]), load_torque=float(load.values[0]))
    prof = None if memo is None else memo.get(t_end)
    if prof is None:
        prof = SampledProfile(t, th1, 'linear', remember=memo is not None)
        if memo is not None:
            memo[t_end] = prof
    if np.all(np.abs(steps - ks) < 1e-6):
        k = ks.astype(np.int64)
        stride = int(np.gcd.reduce(np.diff(k))) if k.size > 1 else 1
        stride = max(stride, 1)
        traj = sim.run(prof, t[0] + (k[-1] + 0.5) * dt, record_every=stride, load=load)
        rows = k // stride
        th = traj.theta[rows]
    else:   # samples off the step grid: record 8 times per sample interval (memory
        # bounded by the samples, not the steps), interpolate linearly between
        every = max(1, int(np.min(np.diff(t)) / dt) // 8) if t.size > 1 else 1
        traj = sim.run(prof, float(t[-1]) + every * dt, record_every=every, load=load)
        th = np.column_stack([np.interp(t, traj.t, traj.theta[:, j]) for j in range(3)])
    return {name: th[:, j] for j, name in enumerate(OUTPUTS)}


def record_from_model(cfg: DriveModel | Config, profile: Profile, t_end: float,
                      sample_rate: float = 1e4, outputs: Sequence[str] = ('theta4',),
                      noise_rad: float = 0.0, resolution_rad: float = 0.0, seed: int = 0,
                      name: str = '', load: LoadSignal | None = None) -> Record:
    """A synthetic record of the model (for tests, benchmarks and trying the fit): the profile
    sampled at ``sample_rate`` from 0 to ``t_end``, each output plus Gaussian noise
    ``noise_rad`` (RMS) and quantised to ``resolution_rad`` (an encoder's step; 0: none).
    ``load``: a load torque signal, sampled into the record's ``load_torque`` and applied
    (linear between the samples, as :func:`predict` applies a record's load)."""
    n = int(math.floor(t_end * sample_rate + 1e-9)) + 1
    t = np.arange(n) / sample_rate
    th1 = np.asarray(profile.theta1(t), float)
    tl = None if load is None else np.asarray(load.torque(t), float)
    pred = predict(cfg, Record(name=name, t=t, theta1=th1, measured={'theta4': th1},
                               load_torque=tl))
    rng = np.random.default_rng(seed)
    meas = {}
    for o in outputs:
        y = pred[o] + noise_rad * rng.standard_normal(n)
        if resolution_rad > 0:
            y = np.round(y / resolution_rad) * resolution_rad
        meas[o] = y
    return Record(name=name, t=t, theta1=th1, measured=meas, load_torque=tl)


def measured_frequencies(base: DriveModel | Config, records: Sequence[Record]
                         ) -> list[tuple[float, str, float, float]]:
    """(frequency [Hz], output, amplitude [rad], sample rate [Hz]) of the dominant
    oscillation of each measured output of each record: FFT of the measured angle minus the
    rigid motion after the command stops (after it starts if the rest is shorter than 16
    samples), resampled uniformly."""
    rigid = rigid_motion(base)
    out = []
    for r in records:
        t, th1 = np.asarray(r.t, float), np.asarray(r.theta1, float)
        t_start, t_stop = motion_times(t, th1)
        for o, meas in r.measured.items():
            y = np.asarray(meas, float) - rigid[OUTPUTS.index(o)] * th1
            for t_from in (t_stop, t_start):
                sel = t >= t_from
                if np.count_nonzero(sel) >= 16:
                    break
            ts, ys = t[sel], y[sel]
            if ts.size < 16:
                continue
            tu = np.linspace(ts[0], ts[-1], ts.size)
            yu = np.interp(tu, ts, ys)
            f = dominant_frequency(tu, yu, f_min=2.0 / max(ts[-1] - ts[0], 1e-9))
            if math.isfinite(f) and f > 0:
                fs = (ts.size - 1) / (ts[-1] - ts[0])
                out.append((f, o, 0.5 * float(np.ptp(ys)), float(fs)))
    return out
