# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""What a run of the drive yields: :class:`SimState` (one instant) and :class:`Trajectory`
(the time series of a run, its error columns and energy), written to CSV by
:class:`TrajectoryCsvWriter` (streamed, chunk by chunk) with its size estimates, and the
ring-down metric of a run.  The runs themselves: :mod:`worm_gear_sim.dynamics.simulation`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

import numpy as np

from ..records import write_csv_header
from ..schema.parameters import Parameters
from .equations import energy_series
from .layout import AUX_CGKG, AUX_CWKW, AUX_FX, AUX_FY, AUX_MU, AUX_Q, AUX_VS, AUX_WN, N_AUX
from .model import DriveModel

__all__ = ['SimState', 'Trajectory', 'TrajectoryCsvWriter', 'CSV_FORMAT', 'ROW_BYTES',
           'csv_bytes_estimate', 'ring_down']


@dataclass(frozen=True)
class SimState:
    """Snapshot of the drive at time t (angles rad, rates rad/s, accelerations rad/s^2)."""

    t: float
    theta1: float
    theta1_dot: float
    theta: np.ndarray     # (theta2, theta3, theta4)
    omega: np.ndarray
    alpha: np.ndarray


@dataclass
class Trajectory:
    """Time series of a run; row 0 is the initial state."""

    t: np.ndarray
    theta1: np.ndarray
    theta1_dot: np.ndarray
    theta: np.ndarray        # (n, 3): theta2, theta3, theta4
    omega: np.ndarray
    alpha: np.ndarray
    aux: np.ndarray          # (n, N_AUX): W_n, mu, cwkw, cgkg, v_s, F_X, F_Y, q
    output_per_input: float      # l_w / r_g: rigid theta4 per theta1
    profile: str = ''
    stats: dict = field(default_factory=dict)

    theta2 = property(lambda self: self.theta[:, 0])
    theta3 = property(lambda self: self.theta[:, 1])
    theta4 = property(lambda self: self.theta[:, 2])
    normal_force = property(lambda self: self.aux[:, AUX_WN])
    friction_coefficient = property(lambda self: self.aux[:, AUX_MU])
    sliding_velocity = property(lambda self: self.aux[:, AUX_VS])

    @property
    def worm_error(self) -> np.ndarray:
        """theta2 - theta1 [rad]: worm body behind/ahead of the command."""
        return self.theta[:, 0] - self.theta1

    @property
    def output_error(self) -> np.ndarray:
        """theta4 - theta1 l_w / r_g [rad]: antenna positioning error."""
        return self.theta[:, 2] - self.theta1 * self.output_per_input

    def energy(self, model: DriveModel | Parameters) -> np.ndarray:
        """Kinetic + shaft torsion + mesh energy 0.5 k_Y q^2 [J] at every row (``model``:
        the run's :class:`DriveModel` or Config)."""
        return energy_series(DriveModel.of(model).p, np.ascontiguousarray(self.theta),
                             np.ascontiguousarray(self.omega), np.ascontiguousarray(self.theta1))

    def columns(self) -> dict[str, np.ndarray]:
        a = self.aux
        return {
            't': self.t, 'theta1': self.theta1, 'theta1_dot': self.theta1_dot,
            'theta2': self.theta[:, 0], 'theta3': self.theta[:, 1], 'theta4': self.theta[:, 2],
            'omega2': self.omega[:, 0], 'omega3': self.omega[:, 1], 'omega4': self.omega[:, 2],
            'alpha2': self.alpha[:, 0], 'alpha3': self.alpha[:, 1], 'alpha4': self.alpha[:, 2],
            'normal_force': a[:, AUX_WN], 'mu': a[:, AUX_MU], 'sliding_velocity': a[:, AUX_VS],
            'worm_tooth_stiffness': a[:, AUX_CWKW], 'gear_tooth_stiffness': a[:, AUX_CGKG],
            'force_x': a[:, AUX_FX], 'force_y': a[:, AUX_FY], 'mesh_deflection': a[:, AUX_Q],
            'worm_error': self.worm_error, 'output_error': self.output_error,
        }

    def to_csv(self, path: str | Path, header_comment: str = '') -> None:
        """Write all columns (SI units, rad) with a commented header."""
        with TrajectoryCsvWriter(path, header_comment) as w:
            w.write(self)

    def rows(self, index: np.ndarray | slice) -> Trajectory:
        """The selected rows as a Trajectory (same profile, ratio and stats)."""
        return Trajectory(t=self.t[index], theta1=self.theta1[index],
                          theta1_dot=self.theta1_dot[index], theta=self.theta[index],
                          omega=self.omega[index], alpha=self.alpha[index],
                          aux=self.aux[index], output_per_input=self.output_per_input,
                          profile=self.profile, stats=self.stats)

    @staticmethod
    def concatenate(parts: list[Trajectory]) -> Trajectory:
        """Chunks of one run (e.g. from :meth:`Simulator.iter_run`) joined in order."""
        if not parts:
            raise ValueError('no trajectory parts to concatenate')
        last = parts[-1]

        def cat(name: str) -> np.ndarray:
            return np.concatenate([getattr(t, name) for t in parts])
        return Trajectory(t=cat('t'), theta1=cat('theta1'), theta1_dot=cat('theta1_dot'),
                          theta=cat('theta'), omega=cat('omega'), alpha=cat('alpha'),
                          aux=cat('aux'), output_per_input=last.output_per_input,
                          profile=last.profile, stats=last.stats)


#: CSV number format: t to 1 ns whatever the duration; every other column to 12
#: significant digits (relative 5e-12: 0.1 rad to 5e-13 rad, 56 rad to 3e-10 rad)
CSV_FORMAT = ['%.9f', '%.12g']


class TrajectoryCsvWriter:
    """Streaming CSV writer of Trajectory rows (chunks of one run in order): the commented
    header and the column line once, then rows as they come.  ``Trajectory.to_csv`` and
    :func:`simulate_to_csv` use it, so a streamed file equals an in-memory one."""

    def __init__(self, path: str | Path, header_comment: str = ''):
        self.path = Path(path)
        self.header_comment = header_comment
        self.rows_written = 0
        self._fh: TextIO | None = None

    def write(self, traj: Trajectory) -> None:
        cols = traj.columns()
        if self._fh is None:
            units = {'t': 's', 'normal_force': 'N', 'force_x': 'N', 'force_y': 'N',
                     'mu': '1', 'sliding_velocity': 'm/s', 'worm_tooth_stiffness': 'N/m',
                     'gear_tooth_stiffness': 'N/m', 'mesh_deflection': 'm'}
            names = [f'{k}[{_csv_unit(k, units)}]' for k in cols]
            self._fh = open(self.path, 'w')
            write_csv_header(self._fh, names, f'worm_gear_sim; profile: {traj.profile}\n'
                             + self.header_comment)
        data = np.column_stack(list(cols.values()))
        np.savetxt(self._fh, data, delimiter=',', fmt=CSV_FORMAT[:1] + CSV_FORMAT[1:] *
                   (data.shape[1] - 1))
        self.rows_written += len(traj.t)

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def __enter__(self) -> TrajectoryCsvWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _csv_unit(name: str, units: dict[str, str]) -> str:
    if name in units:
        return units[name]
    if name == 'theta1_dot' or name.startswith('omega'):
        return 'rad/s'
    if name.startswith('alpha'):
        return 'rad/s^2'
    return 'rad'


#: Bytes per recorded row of a Trajectory (t, theta1, theta1_dot, 3 x theta/omega/alpha,
#: N_AUX mesh quantities; float64).
ROW_BYTES = 8 * (3 + 9 + N_AUX)


def csv_bytes_estimate(rows: int) -> float:
    """Approximate size [bytes] of ``rows`` CSV rows of a Trajectory (22 columns of up to 18
    characters each with '%.12g')."""
    return rows * 22 * 18.0

def ring_down(traj: Trajectory, t_move: float, theta4_eq: float, horizon: float = 0.5,
              window: float = 0.1) -> float:
    """Fraction of the antenna's oscillation lost over ``horizon`` after the move ends at
    ``t_move``: 1 - max|theta4 - eq| over the last ``window`` / max over the first
    ``window`` of [t_move, t_move + horizon]."""
    t = traj.t
    d4 = np.abs(traj.theta4 - theta4_eq)
    first = (t >= t_move - 1e-12) & (t < t_move + window)
    last = (t > t_move + horizon - window) & (t <= t_move + horizon + 1e-12)
    if not first.any() or not last.any() or t[-1] < t_move + horizon - 1e-9:
        raise ValueError(f'the run must cover the move end ({t_move:g} s) plus {horizon:g} s')
    return 1.0 - float(d4[last].max() / d4[first].max())
