# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The drive's stand-in for adaptation runs (pure core, no rclpy): a simulated plant driven
by the compensated command, read by an encoder.

:class:`EncoderPlant` is one source for the offline twin (:mod:`.twin`) and the live plant
node (:mod:`worm_gear_sim.ros.plant`): a :class:`~worm_gear_sim.dynamics.
simulation.Simulator` of the plant's parameter set, started at rest under its load at the
first reference theta1_ref(0), stepped to each command's instant with that command held
(the servo's command theta1_ref + delta), and its antenna angle theta4 read with encoder
noise (Gaussian, RMS ``noise``) and steps (resolution 2 pi / 2^bits), one noise draw per
command in command order (so the twin and the node, given the same commands, read the same
encoder).
"""

from __future__ import annotations

import math

import numpy as np

from ..config.usable import Config
from ..dynamics.simulation import Simulator

__all__ = ['EncoderPlant', 'encoder_resolution']


def encoder_resolution(bits: int) -> float:
    """Encoder step 2 pi / 2^bits [rad] (0 bits: no quantisation, 0.0)."""
    if not (isinstance(bits, int) and 0 <= bits <= 64):
        raise ValueError(f'encoder_bits {bits!r}: an integer in 0..64')
    return 2.0 * math.pi / 2 ** bits if bits > 0 else 0.0


class EncoderPlant:
    """The plant (module docstring).  ``theta1``: the first reference [rad] (the plant
    starts there at rest under its load, at t = 0); ``noise``: encoder noise RMS [rad];
    ``encoder_bits``: resolution 2 pi / 2^bits (0: none); ``seed``: the noise's seed."""

    def __init__(self, plant: Config, theta1: float, *, noise: float = 1e-6,
                 encoder_bits: int = 20, seed: int = 0) -> None:
        if not (math.isfinite(noise) and noise >= 0.0):
            raise ValueError(f'noise {noise!r}: must be >= 0 rad')
        self.sim = Simulator(plant, theta1=float(theta1))
        self.noise = float(noise)
        self.resolution = encoder_resolution(encoder_bits)
        self._rng = np.random.default_rng(seed)

    @property
    def t(self) -> float:
        """The plant's time [s] (0 at the first reference)."""
        return float(self.sim.t)

    def command(self, t: float, theta1: float) -> tuple[float, float]:
        """Step the plant to ``t`` [s] with the command ``theta1`` held over the interval (a
        command at or before the plant's time only reads it); returns (theta4, the encoder's
        reading of it) [rad]."""
        if t > self.sim.t:
            self.sim.advance_to(t, theta1)
        theta4 = float(self.sim.joint_state()[0][3])
        meas = theta4 + (self.noise * self._rng.standard_normal() if self.noise > 0 else 0.0)
        if self.resolution > 0:
            meas = round(meas / self.resolution) * self.resolution
        return theta4, meas
