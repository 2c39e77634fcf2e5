# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The compensator settings a calibration recommends, and the improvement they predict
(``worm-gear-sim calibrate``, ``worm_gear_sim_calibrate``).

The fitted model is the best knowledge of the drive: it stands for the drive and for the
compensator's model in the compensation evaluation of the studies (:func:`~.mismatch.
benefit` on the :func:`~.mismatch.sector_scan`, the streaming compensator as the node runs it
on a live stream, ``how='causal'``).  Candidates: the compensator as configured and, when
the fitted drive has play, the play crossed in one command period (``soft_crossing``
off) and no backlash inverse.  The recommendation is the candidate with the smallest
antenna error on the scan; compensation off when none beats the uncompensated command.
The prediction holds as far as the model does: the held-out move of the calibration says
how far (its RMS error against its amplitude)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..config.usable import Config
from ..joint_trajectory.compensate import antenna_error
from .mismatch import benefit, sector_scan

__all__ = ['Recommendation', 'recommend_compensator', 'calibration_recommendation',
           'COMPENSATOR_KEYS']

#: The settings a recommendation names (the compensation section's choices).
COMPENSATOR_KEYS = ('compensation.enabled', 'compensation.backlash_inverse',
                    'compensation.soft_crossing', 'compensation.lag_order',
                    'compensation.preview_time')


@dataclass(frozen=True)
class Recommendation:
    """The recommended settings (dotted compensation parameters), the antenna error RMS on
    the scan [rad] without and with them, and every candidate tried."""

    settings: dict[str, Any]
    raw_rms: float
    compensated_rms: float
    scan: str
    tried: list[dict[str, Any]] = field(default_factory=list)
    #: the settings that differ from the calibrated set's own (empty: as configured)
    changed: tuple[str, ...] = ()

    @property
    def improvement(self) -> float:
        """Uncompensated / compensated antenna error RMS on the scan."""
        return self.raw_rms / self.compensated_rms if self.compensated_rms > 0 else \
            float('inf')

    def lines(self) -> list[str]:
        """What the command line prints (µrad)."""
        flat = ', '.join(f'{k} = {_text(v)}' for k, v in self.settings.items())
        how = f'changed: {", ".join(self.changed)}' if self.changed else 'as configured'
        return [f'recommended compensator ({how}): {flat}',
                f'predicted on a {self.scan}: antenna error RMS '
                f'{self.raw_rms * 1e6:.4g} µrad uncompensated -> '
                f'{self.compensated_rms * 1e6:.4g} µrad with it '
                f'({self.improvement:.3g}x less; {len(self.tried)} setting(s) tried)']

    def to_dict(self) -> dict[str, Any]:
        return {'settings': self.settings, 'changed': list(self.changed),
                'raw_rms_rad': self.raw_rms,
                'compensated_rms_rad': self.compensated_rms, 'improvement': self.improvement,
                'scan': self.scan, 'tried': self.tried}


def _text(v: Any) -> str:
    return str(v).lower() if isinstance(v, bool) else f'{v:g}' if isinstance(v, float) \
        else str(v)


def _candidates(fitted: Config) -> list[dict[str, Any]]:
    flat = fitted.to_flat_dict()
    configured = {k: flat[k] for k in COMPENSATOR_KEYS}
    configured['compensation.enabled'] = True
    out = [configured]
    if fitted.mesh.backlash > 0:
        out.append({**configured, 'compensation.backlash_inverse': True,
                    'compensation.soft_crossing': not configured['compensation.soft_crossing']})
        out.append({**configured, 'compensation.backlash_inverse':
                    not configured['compensation.backlash_inverse']})
    unique: list[dict[str, Any]] = []
    for c in out:
        if c not in unique:
            unique.append(c)
    return unique


def recommend_compensator(fitted: Config) -> Recommendation:
    """The compensator settings for the drive ``fitted`` (a calibration's fitted set) and
    the improvement they predict on a sector scan (module docstring)."""
    move = sector_scan(fitted)
    raw = float(np.sqrt(np.mean(antenna_error(fitted, move.t, move.theta1, move.theta1) ** 2)))
    tried: list[dict[str, Any]] = []
    results: list[tuple[float, dict[str, Any]]] = []
    for candidate in _candidates(fitted):
        b = benefit(fitted.replace(candidate), None, move, raw, how='causal')
        tried.append({'settings': candidate, 'compensated_rms_rad': b['compensated_rms'],
                      'improvement': b['improvement']})
        results.append((float(b['compensated_rms']), candidate))
    rms, best = min(results, key=lambda r: r[0])
    settings: dict[str, Any] = dict(best)
    if not rms < raw:                                   # nothing beats no compensation
        settings, rms = {'compensation.enabled': False}, raw
    flat = fitted.to_flat_dict()
    return Recommendation(settings, raw, rms, move.description, tried,
                          tuple(k for k, v in settings.items() if flat[k] != v))


def calibration_recommendation(res: Any, stage: Any = None) -> Recommendation | None:
    """The compensator settings recommended for an accepted calibration (a
    :class:`~worm_gear_sim.identification.calibrate.CalibrationResult`) and the improvement
    they predict on a sector scan (:func:`recommend_compensator`); None when not accepted.
    ``stage``: the calibration's progress callback, told the stage's name."""
    if not res.accepted:
        return None
    if stage is not None:
        stage('predict a sector scan')
    return recommend_compensator(res.config)
