# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A tracking pass over the pedestal with live adaptation on every axis: the offline twin
of ``worm_gear_sim_pedestal`` with adaptation on (``worm-gear-sim pass --adapt``).

Each axis streams its share of the pass (:func:`pass_reference`) through its own
single-axis twin against its own plant; per axis the pointing error uncompensated,
``nominal`` and ``adapted``.  docs/pedestal.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config.files import parse_set
from ..config.pedestal import Drive, load_pedestal
from ..config.usable import Config
from ..dynamics.model import DriveModel
from ..schema.validation import ConfigError
from .adaptation_twin import BASE_NS, Reference, TwinRun, run_twin
from .tracking_pass import satellite_pass

__all__ = ['AxisPass', 'pass_reference', 'run_adaptive_pass', 'rms_over', 'tail_table',
           'pedestal_plants', 'AXES', 'TAIL_S']

#: What the first and the second drive of the pedestal turn.
AXES = ('azimuth', 'elevation')
#: The pass's last seconds the figures are taken over.
TAIL_S = 10.0


def pass_reference(axis: int, duration: float, max_elevation: float = math.radians(85.0),
                   altitude: float = 500e3) -> Reference:
    """The worm input angle of axis ``axis`` (0 azimuth, 1 elevation) of a pass of
    ``duration`` s centred on culmination, as a :data:`~worm_gear_sim.studies.adaptation_twin.
    Reference`: on the grid of the start set's ``node.publish_rate_hz`` from the pass's
    start, as long as the twin asks (it runs a few samples past ``duration``)."""
    if axis not in (0, 1):
        raise ValueError(f'axis {axis!r}: 0 (azimuth) or 1 (elevation)')

    def reference(cfg: Config, length: float) -> tuple[np.ndarray, np.ndarray]:
        dt = 1.0 / cfg.node.publish_rate_hz
        t = np.arange(int(math.ceil(length / dt - 1e-9)) + 1) * dt
        az, el = satellite_pass(t - duration / 2, altitude, max_elevation)
        angle = az - az[0] if axis == 0 else el
        return t, angle / DriveModel(cfg).output_per_input

    return reference


def pedestal_plants(drives: Sequence[Drive], plant_file: str | Path | None = None,
                    sets: Sequence[str] = ()) -> dict[str, Config]:
    """The drives' stand-ins (drive name -> set): the drive of the same name in the
    pedestal file ``plant_file`` (every drive must be there), or the drive's own set; then
    ``sets``, ``DRIVE.KEY=VALUE`` items (``azimuth.mesh.backlash=5.8e-4``).  ConfigError
    naming the problem."""
    names = [d.name for d in drives]
    if plant_file is not None:
        given = {p.name: p.config for p in load_pedestal(plant_file)}
        missing = [n for n in names if n not in given]
        if missing:
            raise ConfigError('pedestal.drives', f'{plant_file}: no plant for drive(s) '
                              f'{", ".join(missing)}')
        plants = {n: given[n] for n in names}
    else:
        plants = {d.name: d.config for d in drives}
    overrides: dict[str, list[str]] = {}
    for item in sets:
        name, dot, rest = item.partition('.')
        if not dot or name not in plants:
            raise ConfigError('', f'{item!r}: expected DRIVE.KEY=VALUE with DRIVE one of '
                              f'{", ".join(names)}')
        overrides.setdefault(name, []).append(rest)
    for name, items in overrides.items():
        try:
            plants[name] = plants[name].replace(parse_set(items))
        except ConfigError as exc:
            raise ConfigError(exc.key, f'plant of drive {name!r}: {exc.reason}') from None
    return plants


def rms_over(t: np.ndarray, e: np.ndarray, start: float, end: float = math.inf) -> float:
    """RMS of ``e`` over start <= t < end (nan when no sample falls there)."""
    m = (t >= start) & (t < end)
    return float(np.sqrt(np.mean(e[m] ** 2))) if np.any(m) else math.nan


@dataclass
class AxisPass:
    """One axis of the pass: the drive's ``name`` and worm input ``joint``; per sample the
    time ``t`` [s] and ``theta1_ref`` [rad]; the pointing errors [rad] ``uncompensated``,
    ``nominal`` (nan when not run) and ``adapted``; ``run``: the adapting twin's record
    (steps, values in use, counters)."""

    name: str
    joint: str
    t: np.ndarray
    theta1_ref: np.ndarray
    uncompensated: np.ndarray
    nominal: np.ndarray
    adapted: np.ndarray
    run: TwinRun

    def tail(self, seconds: float = TAIL_S) -> dict[str, float]:
        """RMS [rad] of the three errors over the last ``seconds`` and the ratios of
        uncompensated to each."""
        start = float(self.t[-1]) - seconds
        u, n, a = (rms_over(self.t, e, start) for e in
                   (self.uncompensated, self.nominal, self.adapted))
        return {'uncompensated': u, 'nominal': n, 'adapted': a,
                'nominal_ratio': u / n if n > 0 else math.inf,
                'adapted_ratio': u / a if a > 0 else math.inf}


def run_adaptive_pass(drives: Sequence[Drive], plants: Mapping[str, Config], duration: float,
                      *, max_elevation: float = math.radians(85.0), altitude: float = 500e3,
                      noise: float = 1e-6, encoder_bits: int = 20, seed: int = 0,
                      nominal: bool = True, base_ns: int = BASE_NS,
                      on_axis: Callable[[str], None] | None = None) -> list[AxisPass]:
    """The pass of ``duration`` s (module docstring) over the first two ``drives`` (azimuth,
    elevation), each starting from its own set with adaptation on, against
    ``plants[drive.name]`` (missing: the drive's own set); the encoder of axis k has the
    seed ``seed + k``.  ``nominal`` False: the nominal feed-forward is not run (its errors
    nan).  ``on_axis(name)`` is called before each axis."""
    if len(drives) < 2:
        raise ValueError(f'a pass needs two drives (azimuth, elevation); {len(drives)} given')
    out = []
    for k, d in enumerate(drives[:2]):
        if on_axis is not None:
            on_axis(d.name)
        plant = plants.get(d.name, d.config)
        ref = pass_reference(k, duration, max_elevation, altitude)
        runs = [run_twin(plant, d.config, ref, duration, noise=noise,
                         encoder_bits=encoder_bits, seed=seed + k, base_ns=base_ns,
                         adapt=adapt) for adapt in ((True, False) if nominal else (True,))]
        run = runs[0]
        nom = runs[1].error_compensated if nominal else np.full(run.t.size, np.nan)
        out.append(AxisPass(d.name, d.joint, run.t, run.theta1_ref, run.error_uncompensated,
                            nom, run.error_compensated, run))
    return out


def tail_table(axes: Sequence[AxisPass], seconds: float = TAIL_S
               ) -> list[dict[str, float | str]]:
    """Per axis: the pointing error's RMS [urad] over the last ``seconds`` uncompensated,
    with the nominal feed-forward and with the adapting one, and the ratios."""
    rows: list[dict[str, float | str]] = []
    for ax in axes:
        f = ax.tail(seconds)
        rows.append({'axis': ax.name, 'rms_uncompensated_urad': f['uncompensated'] * 1e6,
                     'rms_nominal_urad': f['nominal'] * 1e6,
                     'rms_adapted_urad': f['adapted'] * 1e6,
                     'nominal_ratio': f['nominal_ratio'], 'adapted_ratio': f['adapted_ratio']})
    return rows
