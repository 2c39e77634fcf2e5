# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Calibration in one call: design an excitation within the user's limits, run it on the
drive, fit, validate on held-out moves, and say whether the result is accepted.

:func:`calibrate` runs the moves on a drive given as ``run(profile, t_end) -> Record``
(:func:`plant_runner` wraps a simulated one), fits with ``identify``, validates with
``prediction_errors`` and returns a :class:`CalibrationResult`; nothing is applied.  The
excitation and its design: docs/identification.md ("Calibrate in one command").
"""

from __future__ import annotations

import dataclasses
import math
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..config.usable import Config
from ..records import Record
from .data import IdentificationError, record_from_model
from .direct import LOAD, PLAY
from .excitation import Limits, Move, design_excitation, uses_sweeps
from .fit import FitOptions, identify, wind_up_only
from .report import FitResult, prediction_errors
from .unload import split_refit

__all__ = ['plant_runner', 'calibrate', 'CalibrationResult', 'excitation_series', 'ACCEPT_REL',
           'STAGES']

#: Accepted when every held-out move's theta4 RMS error is within this share of its
#: oscillation amplitude (and the fit itself is trustworthy).
ACCEPT_REL = 0.05


def excitation_series(moves: Sequence[Move], sample_rate: float) -> tuple[np.ndarray,
                                                                            np.ndarray]:
    """The moves one after the other as one command series (t [s], theta1 [rad]) sampled at
    ``sample_rate``: what a servo outside ROS streams (``calibrate --export-excitation``).
    Each move starts where the previous one ended, so ``step_back`` and the held-out move
    go back towards the start."""
    ts: list[np.ndarray] = []
    xs: list[np.ndarray] = []
    t0 = 0.0
    offset = 0.0
    for m in moves:
        n = int(math.floor(m.t_end * sample_rate + 1e-9)) + 1
        t = np.arange(n) / sample_rate
        x = m.profile.theta1(t)
        if xs:
            offset = xs[-1][-1] - x[0]
        ts.append(t0 + t)
        xs.append(x + offset)
        t0 += m.t_end + 1.0 / sample_rate
    return np.concatenate(ts), np.concatenate(xs)


def plant_runner(plant: Config, sample_rate: float, outputs: Sequence[str] = ('theta4',),
                 noise_rad: float = 0.0, resolution_rad: float = 0.0,
                 seed: int = 0) -> Callable[[Move], Record]:
    """A simulated drive standing in for the real one: each move is a record of ``plant``
    sampled at ``sample_rate`` with Gaussian noise and encoder steps."""
    def run(move: Move) -> Record:
        return record_from_model(plant, move.profile, move.t_end, sample_rate, outputs,
                                 noise_rad=noise_rad, resolution_rad=resolution_rad,
                                 seed=seed + zlib.crc32(move.name.encode()) % 1000,
                                 name=move.name)
    return run


@dataclass
class CalibrationResult:
    """What :func:`calibrate` did: the moves, the fit, the held-out errors and the verdict."""

    moves: list[Move]
    train: list[Record]
    held_out: list[Record]
    fit: FitResult
    validation_before: list[dict[str, Any]]
    validation_after: list[dict[str, Any]]
    accepted: bool
    reasons: list[str] = field(default_factory=list)     # why not accepted
    #: the 95 % bound on the held-out moves' theta4 RMS prediction error (.uncertainty)
    bounds: list[Any] = field(default_factory=list)

    @property
    def config(self) -> Config:
        return self.fit.config

    @property
    def not_seen(self) -> dict[str, str]:
        """Fitted keys the excitation could not show: key -> one line naming the move to
        record (:mod:`.visibility`)."""
        return self.fit.not_seen

    @property
    def seen(self) -> list[str]:
        """The fitted keys the excitation showed."""
        return [k for k in self.fit.keys if k not in self.fit.not_seen]

    def estimate(self, key: str) -> float:
        """The fitted value of ``key``."""
        return self.fit.values[self.fit.keys.index(key)]

    def worst_held_out(self, output: str = 'theta4') -> float:
        """The largest held-out RMS error of ``output`` as a share of its amplitude."""
        rel = [r[output]['rel'] for r in self.validation_after if output in r]
        return max(rel) if rel else math.nan


#: The stages :func:`calibrate` reports to its ``progress`` callback, besides one
#: ``record <move>`` per move (the refits only when they run).
STAGES = ('fit', 'validate', 'refit with every key free', 'refit with the unload dither',
          'prediction bound')


def calibrate(base: Config, keys: Sequence[str], limits: Limits,
              run: Callable[[Move], Record], *, options: FitOptions | None = None,
              outputs: Sequence[str] | None = None,
              accept_rel: float = ACCEPT_REL,
              progress: Callable[[str], None] | None = None) -> CalibrationResult:
    """Design the excitation, run it (``run(move) -> Record``), fit ``keys`` of ``base`` on
    the training moves, validate on the held-out ones; accepted when the fit is
    trustworthy and every held-out theta4 error is within ``accept_rel`` of its amplitude.
    ``progress(stage)`` is called as each stage starts (``record <move>``, then
    :data:`STAGES`).  Raises IdentificationError (nothing fitted) when the limits or the
    records are unusable: no motion measured, motion unrelated to the command, a record
    that stops."""
    moves = design_excitation(limits, keys, base)
    opt = options or FitOptions()
    stage = progress or (lambda _: None)
    if uses_sweeps(keys) and opt.n_starts is None:
        # the direct estimates and the play scan are the global stage: one local fit (from
        # the frequency start) suffices, and halves the time
        opt = dataclasses.replace(opt, n_starts=1)
    records = []
    for m in moves:
        stage(f'record {m.name}')
        rec = run(m)
        _check_followed(rec, m)
        records.append(rec)
    train = [r for r, m in zip(records, moves) if m.role == 'train']
    held = [r for r, m in zip(records, moves) if m.role == 'validate']
    stage('fit')
    res = identify(base, train, keys, options=opt, outputs=outputs)
    stage('validate')
    before = prediction_errors(base, held)
    after = prediction_errors(res.config, held)
    reasons = _reasons(res, after, accept_rel)
    if reasons and res.strategy.get('priors') and opt.priors is None:
        # the default prior (fit.PRIORS) is an assumption about the drive: refused with it,
        # the fit runs again with every key free, and the held-out moves judge that one
        stage('refit with every key free')
        free = identify(base, train, keys, options=dataclasses.replace(opt, priors={}),
                        outputs=outputs)
        after_free = prediction_errors(free.config, held)
        reasons_free = _reasons(free, after_free, accept_rel)
        if not reasons_free:
            held_keys = res.strategy['priors']
            res, after, reasons = free, after_free, reasons_free
            res.warnings.append('refused with the teeth prior; refitted with every key free '
                                '(the held-out moves chose between the two fits)')
            for k in held_keys:     # free now, but no better seen than with the prior
                wind_up_only(res, k, 'fitted free after the fit with its prior was refused')
    reserve = [r for r, m in zip(records, moves) if m.role == 'reserve']
    if reserve and PLAY in res.not_seen and LOAD in res.keys:
        # one flank in every sweep: the dither (.unload) tells the play from the load; its
        # fit is kept when it lifts the gear and the held-out moves accept it
        stage('refit with the unload dither')
        split = split_refit(base, train + reserve, keys, res, opt, outputs)
        after_split = prediction_errors(split.config, held)
        reasons_split = _reasons(split, after_split, accept_rel)
        if not reasons_split and PLAY not in split.not_seen:
            res, after, reasons = split, after_split, reasons_split
            train = train + reserve
            res.warnings.append('the sweeps held one flank: play and load told apart by the '
                                'unload_dither move (the gear lifts off its flank)')
        else:
            res.warnings.append('the unload_dither move did not tell the play from the load ('
                                + ('; '.join(reasons_split) or 'the gear does not lift off '
                                   'its flank in the fitted model') + ')')
    bounds = []
    if 'theta4' in res.output_verdicts and res.output_verdicts['theta4'] == 'matched':
        from .uncertainty import prediction_bound
        stage('prediction bound')
        bounds = [prediction_bound(res, train, h) for h in held]
    return CalibrationResult(moves, train, held, res, before, after, not reasons, reasons,
                             bounds)


def _reasons(res: FitResult, after: list[dict[str, Any]], accept_rel: float) -> list[str]:
    """Why a fit is not accepted: its problems and the held-out errors above accept_rel."""
    reasons = list(res.problems)
    for row in after:
        for o, e in row.items():
            if o == 'name' or o not in res.output_verdicts or \
                    res.output_verdicts[o] != 'matched':
                continue
            if not e['rel'] <= accept_rel:
                reasons.append(f'held-out {row["name"]}: {o} RMS {100 * e["rel"]:.2f} % of '
                               f'its amplitude (> {100 * accept_rel:g} %)')
    return reasons


def _check_followed(rec: Record, move: Move) -> None:
    """A servo that did not follow the excitation: records that stop early, no measured
    motion, or motion unrelated to the command (IdentificationError naming the move)."""
    if rec.t.size < 16 or rec.t[-1] - rec.t[0] < 0.9 * move.t_end:
        raise IdentificationError(f'{move.name}: the record stops after '
                                  f'{(rec.t[-1] - rec.t[0]) if rec.t.size else 0:.3g} s of '
                                  f'{move.t_end:.3g} s: the drive did not run the whole move')
    if not rec.measured:
        raise IdentificationError(f'{move.name}: no measured angle in the record')
    for o, y in rec.measured.items():
        if not float(np.ptp(y)) > 0:
            raise IdentificationError(f'{move.name}: {o} did not move (the drive did not '
                                      'follow the excitation)')
        if move.role == 'reserve':     # the dither: the antenna swings a quarter period
            continue                   # behind at its mode, uncorrelated by design
        c = np.corrcoef(rec.theta1, y)[0, 1] if np.ptp(rec.theta1) > 0 else math.nan
        if not c > 0.5:
            raise IdentificationError(f'{move.name}: {o} is unrelated to the command '
                                      f'(correlation {c:.2f}): the drive did not follow '
                                      'the excitation')
