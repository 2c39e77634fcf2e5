# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""What the feed-forward gains on a drive with play, known or not (``worm-gear-sim sweep
crossing`` and ``sweep mismatch``).

Moves :func:`sector_scan` and :func:`slew_reversals`; :func:`benefit` compensates a move
on the known-trajectory path and measures the improvement; the studies
:func:`crossing_rows`, :func:`mismatch_rows`, :func:`random_drives` and
:func:`calibration_rows`.  docs/compensation.md.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..compensation.play_crossing import soft_feedforward_series
from ..config.usable import Config
from ..dynamics.model import DriveModel
from ..joint_trajectory.compensate import antenna_error, trajectory_feedforward, trajectory_model
from ..parallel.threads import map_like_serial
from ..realtime import feedforward_series
from .backlash_reversal import ARCMIN
from .compensation_eval import _piecewise_accel_profile

__all__ = ['Move', 'sector_scan', 'slew_reversals', 'benefit', 'MOVES', 'crossing_rows',
           'CROSSING_COLUMNS', 'MISMATCH_AXES', 'mismatched', 'mismatch_rows',
           'MISMATCH_COLUMNS', 'DriveRanges', 'random_drives', 'calibration_rows',
           'CALIBRATION_COLUMNS', 'CALIBRATION_KEYS', 'CALIBRATION_LIMITS', 'summary']


@dataclass(frozen=True)
class Move:
    """A known trajectory of the worm input: samples ``t`` [s], ``theta1`` [rad]."""

    name: str
    t: np.ndarray
    theta1: np.ndarray
    description: str


def _period(cfg: Config) -> float:
    return 1.0 / cfg.node.publish_rate_hz


def sector_scan(cfg: Config, amplitude_deg: float = 5.0, period: float = 4.0,
                periods: float = 1.0, rest: float = 0.0) -> Move:
    """The antenna sweeps ±``amplitude_deg`` sinusoidally with ``period`` [s], from rest at
    the lower edge, for ``periods`` periods, after ``rest`` [s] at rest there (module
    docstring)."""
    dt = _period(cfg)
    ratio = 1.0 / DriveModel(cfg).output_per_input
    n = int(round((periods * period + rest) / dt))
    t = np.arange(n + 1) * dt
    y = -math.radians(amplitude_deg) * np.cos(2.0 * math.pi * np.maximum(t - rest, 0.0)
                                              / period)
    return Move('sector', t, y * ratio,
                f'sector scan ±{amplitude_deg:g}° at the antenna, {period:g} s period')


def slew_reversals(cfg: Config, rate: float = 2.0, accel: float = 50.0, cruise: float = 0.3,
                   hold: float = 0.3, start: float = 0.01) -> Move:
    """The worm slews at +``rate`` [rad/s], reverses at ``accel`` [rad/s^2] to -rate,
    cruises, reverses again to +rate, cruises and stops; then ``hold`` s at rest."""
    ramp = rate / accel
    segs = [(ramp, accel), (cruise, 0.0), (2 * ramp, -accel), (cruise, 0.0),
            (2 * ramp, accel), (cruise, 0.0), (ramp, -accel)]
    total = start + 6 * ramp + 3 * cruise + hold
    t, th, _ = _piecewise_accel_profile(start, segs, _period(cfg), total)
    return Move('slew', t, th, f'worm slew reversals ±{rate:g} rad/s at {accel:g} rad/s^2')


#: the moves of the studies by name
MOVES: dict[str, Callable[[Config], Move]] = {'sector': sector_scan, 'slew': slew_reversals}


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e ** 2)))


def benefit(plant: Config, model: Config | None, move: Move,
            raw_rms: float | None = None, how: str = 'trajectory') -> dict[str, float]:
    """Antenna error RMS [rad] of ``plant`` on ``move``, raw and compensated with a
    feed-forward designed on ``model`` (None: the plant's own values); ``how``:
    ``trajectory`` (the known-trajectory path: centring preview, crossings planned on the
    whole path), ``stream`` (centring preview, the streaming compensator as configured:
    by default its soft crossing, predicted from the demand's trend), ``step`` (centring
    preview, the play crossed in one command period: the soft crossing off) or ``causal``
    (the streaming compensator as configured: a live stream without preview).  ``raw_rms``: the
    uncompensated RMS if already known."""
    m = DriveModel(plant if model is None else model)
    t, x = move.t, move.theta1
    if how == 'trajectory':
        delta = trajectory_feedforward(trajectory_model(m), t, x)
    elif how == 'stream':
        delta = feedforward_series(trajectory_model(m), t, x)
    elif how == 'step':
        step = trajectory_model(m).config
        delta = feedforward_series(DriveModel(dataclasses.replace(
            step, compensation=dataclasses.replace(step.compensation, soft_crossing=False))),
            t, x)
    elif how == 'causal':
        delta = feedforward_series(m, t, x)
    else:
        raise ValueError(f'how = {how!r}: trajectory, stream, step or causal')
    off = _rms(antenna_error(plant, t, x, x)) if raw_rms is None else raw_rms
    on = _rms(antenna_error(plant, t, x + delta, x))
    return {'raw_rms': off, 'compensated_rms': on, 'improvement': off / on}


# ---- perfect knowledge: the soft crossing on a grid ----------------------------------------
CROSSING_COLUMNS = ['study', 'play_arcmin', 'load_torque', 'drag', 'damping', 'raw_rms',
                    'causal_rms', 'step_rms', 'stream_rms', 'soft_rms', 'causal_x', 'step_x',
                    'stream_x', 'soft_x', 'crossings', 'crossing_ms']
CROSSING_PLAYS = (0.5, 1.0, 2.0, 5.0)
CROSSING_LOADS = (0.0, 0.5, 1.0, 2.0, 5.0)
CROSSING_DRAGS = (0.0, 10.0, 50.0)


def crossing_rows(base: Config, plays: Sequence[float] = CROSSING_PLAYS,
                  loads: Sequence[float] = CROSSING_LOADS,
                  drags: Sequence[float] = CROSSING_DRAGS, damping: float = 0.0,
                  rest: float = 0.0,
                  progress: Callable[[dict], None] | None = None,
                  workers: int | None = None) -> list[dict]:
    """The sector scan (after ``rest`` s at rest) with perfect knowledge on every (play,
    load, drag) case: raw, causal, step crossing and soft crossing (module docstring).  The
    cases run on ``workers`` threads (:func:`~worm_gear_sim.parallel.threads.map_like_serial`;
    1: in order in this thread), the same rows either way; ``progress`` sees each row as it
    is done (on threads, in the order they finish)."""
    cases = [(play, load, drag) for play in plays for load in loads for drag in drags]
    return map_like_serial(lambda c: _crossing_case(base, *c, damping, rest), cases,
                           workers=workers,
                           on_result=None if progress is None else lambda _, r: progress(r))


def _crossing_case(base: Config, play: float, load: float, drag: float, damping: float,
                   rest: float) -> dict:
    plant = base.replace({'mesh.backlash': play * ARCMIN, 'load.output_torque': load,
                          'load.output_viscous_coefficient': drag,
                          'damping.modal_damping_ratios': [damping] * 3})
    move = sector_scan(plant, rest=rest)
    raw = _rms(antenna_error(plant, move.t, move.theta1, move.theta1))
    r = {'study': 'crossing', 'play_arcmin': play, 'load_torque': load, 'drag': drag,
         'damping': damping, 'raw_rms': raw}
    for how, key in (('causal', 'causal'), ('step', 'step'), ('stream', 'stream'),
                     ('trajectory', 'soft')):
        b = benefit(plant, None, move, raw, how)
        r[f'{key}_rms'] = b['compensated_rms']
        r[f'{key}_x'] = b['improvement']
    _, plans = soft_feedforward_series(trajectory_model(DriveModel(plant)), move.t,
                                       move.theta1)
    r['crossings'] = len(plans)
    r['crossing_ms'] = ' '.join(f'{1e3 * (p.end - p.start):.3g}' for p in plans)
    return r


# ---- one model error at a time -------------------------------------------------------------
#: the model's errors against the drive: name -> keys scaled together
MISMATCH_AXES: dict[str, tuple[str, ...]] = {
    'play': ('mesh.backlash',),
    'load': ('load.output_torque', 'load.output_viscous_coefficient'),
    'teeth': ('mesh.worm_tooth_stiffness_multiplier', 'mesh.gear_tooth_stiffness_multiplier'),
    'bearings': ('shafts.worm_bearing_axial_stiffness', 'shafts.gear_bearing_axial_stiffness'),
}
MISMATCH_ERRORS = (-0.3, -0.2, -0.1, 0.0, 0.1, 0.2, 0.3)
#: the drive of the one-axis study (with the base config)
MISMATCH_DRIVE: dict[str, Any] = {'mesh.backlash': 2.0 * ARCMIN, 'load.output_torque': 1.0,
                                  'load.output_viscous_coefficient': 20.0}
MISMATCH_COLUMNS = ['study', 'move', 'axis', 'error', 'raw_rms', 'compensated_rms',
                    'improvement']


def mismatched(drive: Config, axis: str, error: float) -> Config:
    """The model of ``drive`` with the keys of ``axis`` (MISMATCH_AXES) off by ``error``
    (a share: +0.1 = 10 % too large)."""
    if axis not in MISMATCH_AXES:
        raise ValueError(f'mismatch axis {axis!r}: one of {", ".join(MISMATCH_AXES)}')
    flat = drive.to_flat_dict()
    return drive.replace({k: flat[k] * (1.0 + error) for k in MISMATCH_AXES[axis]})


def mismatch_rows(drive: Config, axes: Sequence[str] = tuple(MISMATCH_AXES),
                  errors: Sequence[float] = MISMATCH_ERRORS,
                  moves: Sequence[str] = tuple(MOVES),
                  progress: Callable[[dict], None] | None = None,
                  workers: int | None = None) -> list[dict]:
    """The benefit on ``drive`` of a model off by each error, one axis at a time; the runs
    on ``workers`` threads as in :func:`crossing_rows`."""
    mvs = {mv: MOVES[mv](drive) for mv in moves}
    raws = map_like_serial(lambda mv: _rms(antenna_error(drive, mvs[mv].t, mvs[mv].theta1,
                                                          mvs[mv].theta1)),
                           list(mvs), workers=workers)
    raw = dict(zip(mvs, raws))
    cases = [(mv, axis, err) for mv in moves for axis in axes for err in errors]

    def one(case: tuple[str, str, float]) -> dict:
        mv, axis, err = case
        b = benefit(drive, mismatched(drive, axis, err), mvs[mv], raw[mv])
        return {'study': 'mismatch', 'move': mv, 'axis': axis, 'error': err, **b}

    return map_like_serial(one, cases, workers=workers,
                           on_result=None if progress is None else lambda _, r: progress(r))


# ---- calibrate, then compensate, on random drives ------------------------------------------
@dataclass(frozen=True)
class DriveRanges:
    """Ranges of the random drives: play [arcmin], load torque [N m], drag [N m s/rad],
    teeth and bearing stiffness factors (both multipliers / both bearings together)."""

    play_arcmin: tuple[float, float] = (0.5, 5.0)
    load_torque: tuple[float, float] = (0.0, 5.0)
    drag: tuple[float, float] = (0.0, 100.0)
    teeth: tuple[float, float] = (0.7, 1.3)
    bearings: tuple[float, float] = (0.7, 1.3)


def random_drives(base: Config, n: int, seed: int = 0,
                  ranges: DriveRanges = DriveRanges()) -> list[tuple[dict, Config]]:
    """``n`` drives drawn uniformly in ``ranges`` (seeded): (their values, config)."""
    rng = np.random.default_rng(seed)
    flat = base.to_flat_dict()
    out = []
    for _ in range(int(n)):
        v = {'play_arcmin': rng.uniform(*ranges.play_arcmin),
             'load_torque': rng.uniform(*ranges.load_torque),
             'drag': rng.uniform(*ranges.drag), 'teeth': rng.uniform(*ranges.teeth),
             'bearings': rng.uniform(*ranges.bearings)}
        over: dict[str, Any] = {'mesh.backlash': v['play_arcmin'] * ARCMIN,
                                'load.output_torque': v['load_torque'],
                                'load.output_viscous_coefficient': v['drag']}
        for k in MISMATCH_AXES['teeth']:
            over[k] = flat[k] * v['teeth']
        for k in MISMATCH_AXES['bearings']:
            over[k] = flat[k] * v['bearings']
        out.append((v, base.replace(over)))
    return out


#: the keys calibrated (play, load torque and drag, teeth)
CALIBRATION_KEYS = ('mesh.backlash', 'load.output_torque', 'load.output_viscous_coefficient',
                    'mesh.gear_tooth_stiffness_multiplier')
#: the calibration's limits: worm travel [rad], rate [rad/s], accel [rad/s^2], duration [s]
CALIBRATION_LIMITS = (0.5, 6.0, 1500.0, 2.0)
CALIBRATION_COLUMNS = ['study', 'drive', 'play_arcmin', 'load_torque', 'drag', 'teeth',
                       'bearings', 'accepted', 'fit_play_arcmin', 'fit_load_torque',
                       'fit_drag', 'fit_teeth', 'calibration_s', 'sector_raw_rms',
                       'sector_nominal_x', 'sector_x', 'slew_raw_rms', 'slew_nominal_x',
                       'slew_x', 'reasons']


def calibration_rows(base: Config, n: int, seed: int = 0,
                     ranges: DriveRanges = DriveRanges(),
                     keys: Sequence[str] = CALIBRATION_KEYS,
                     limits: Sequence[float] = CALIBRATION_LIMITS,
                     noise_rad: float = 1e-6, encoder_bits: int = 20,
                     sample_rate: float = 1e4, options: Any = None,
                     moves: Sequence[str] = tuple(MOVES),
                     progress: Callable[[dict], None] | None = None) -> list[dict]:
    """Calibrate ``keys`` of ``base`` on each random drive (its records simulated, with
    noise and encoder steps), then compensate both moves with the calibrated model
    (accepted or not: the row says which) and with ``base`` (the nominal model).
    ``options``: the fit's :class:`~worm_gear_sim.identification.FitOptions` (None: its
    defaults, a Dask cluster of one process per core: call from a ``__main__`` guard)."""
    from ..identification.calibrate import calibrate, plant_runner
    from ..identification.excitation import Limits
    rows = []
    res_rad = 2.0 * math.pi / 2 ** encoder_bits if encoder_bits > 0 else 0.0
    for k, (v, drive) in enumerate(random_drives(base, n, seed, ranges)):
        t0 = time.perf_counter()
        run = plant_runner(drive, sample_rate, ('theta4',), noise_rad, res_rad, seed + k)
        reasons = ''
        try:
            cal = calibrate(base, list(keys), Limits(*limits), run, options=options)
            fitted: Config | None = cal.config
            accepted = bool(cal.accepted)
            reasons = '; '.join(cal.reasons)
        except Exception as exc:  # noqa: BLE001 - a failed calibration is a result
            fitted, accepted, reasons = None, False, f'{type(exc).__name__}: {exc}'
        wall = time.perf_counter() - t0
        row: dict[str, Any] = {'study': 'calibration', 'drive': k, **v, 'accepted': accepted,
                               'calibration_s': wall, 'reasons': reasons}
        if fitted is not None:
            row.update({'fit_play_arcmin': fitted.mesh.backlash / ARCMIN,
                        'fit_load_torque': fitted.load.output_torque,
                        'fit_drag': fitted.load.output_viscous_coefficient,
                        'fit_teeth': fitted.mesh.gear_tooth_stiffness_multiplier})
        for mv in moves:
            move = MOVES[mv](drive)
            raw = _rms(antenna_error(drive, move.t, move.theta1, move.theta1))
            row[f'{mv}_raw_rms'] = raw
            row[f'{mv}_nominal_x'] = benefit(drive, base, move, raw)['improvement']
            row[f'{mv}_x'] = benefit(drive, fitted, move, raw)['improvement'] \
                if fitted is not None else math.nan
        rows.append(row)
        if progress is not None:
            progress(row)
    return rows


def summary(rows: Sequence[Mapping[str, Any]], column: str) -> dict[str, float]:
    """min / median / max of a column over rows (nan ignored)."""
    v = np.array([float(r[column]) for r in rows if r.get(column) is not None], float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return {'min': math.nan, 'median': math.nan, 'max': math.nan}
    return {'min': float(v.min()), 'median': float(np.median(v)), 'max': float(v.max())}
