# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Feed-forward compensation of the worm-gear drive's positioning error (pure core, no rclpy).

Given the servo's intended worm-angle command ``theta1_ref(t)``, streamed sample by sample,
:class:`Compensator` returns a correction ``delta`` so that, with ``theta1 = theta1_ref +
delta`` applied to the drive, the antenna angle ``theta4`` follows ``theta1_ref * l_w / r_g``.
This module contains :class:`Compensator` (designed from the NOMINAL model at construction
and :meth:`~Compensator.reconfigure`: the antenna mode, the reference filter of
:mod:`.filters`; run per sample: the filtered reference, the model inverse
:func:`worm_gear_sim.dynamics.inverse.inverse_theta1` and, with play, the flank it takes),
:func:`centring_preview` (the preview that centres the filter on the present) and
:func:`with_preview`.  The known trajectory's crossings of the play are planned in
:mod:`.play_crossing`.  How it works and what it achieves: docs/compensation.md.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from .._support.stepwise import Steps, run_steps
from ..config.usable import Config
from ..dynamics.modal import modes_steps
from ..dynamics.model import DriveModel, has_play, rest_flank
from ..schema.parameters import Parameters
from .filters import (
    _F_COEF,
    _F_LONG,
    _F_ON,
    _F_SHORT,
    _F_SOFT,
    _F_STATE,
    _F_TPREV,
    MIN_DEGREE,
    SOFT_PERIODS,
    SOFT_SHORTEST,
    SOFT_TOLERANCE,
    compensation_kernel,
    design_filter_steps,
    design_shaper,
)

__all__ = ['Compensator', 'centring_preview', 'with_preview']


# ---- the streaming compensator -------------------------------------------------------------
class Compensator:
    """Streaming feed-forward: ``update(t, theta1_ref)`` returns delta to ADD to theta1.

    Causal: a call uses only the samples passed so far.  With ``preview_time`` P > 0 the
    caller streams the reference P ahead: ``update(t, theta1_ref(t))`` returns the delta for
    time ``t - P`` (the reference there is :attr:`reference`).  Samples are joined by
    straight lines, as the simulator interpolates commands.  Construction and
    :meth:`reconfigure` do the design work (modes, shaper, quadrature weights); a call
    costs tens of microseconds.
    """

    def __init__(self, model: DriveModel | Config) -> None:
        run_steps(self._init_steps(model))

    @classmethod
    def design_steps(cls, model: DriveModel | Config) -> Steps[Compensator]:
        """``Compensator(model)`` cut into steps (:mod:`worm_gear_sim._support.stepwise`): the same
        object, its design a piece at a time."""
        self = cls.__new__(cls)
        yield from self._init_steps(model)
        return self

    def _init_steps(self, model: DriveModel | Config) -> Steps[None]:
        self._derivs = np.zeros(0)       # r, r', ... of the filtered reference (reset fills it)
        self._flank = np.zeros(12)       # the kernel's flank state (_F_*)
        yield from self._reconfigure_steps(model)
        self.reset(0.0, 0.0)

    # ---- design ----------------------------------------------------------------------------
    def reconfigure(self, model: DriveModel | Config) -> None:
        """Redesign from a (nominal) model or configuration; keeps the stored reference
        history."""
        run_steps(self._reconfigure_steps(model))

    def _reconfigure_steps(self, model: DriveModel | Config) -> Steps[None]:
        """:meth:`reconfigure` in steps (each ~0.1-0.4 ms on an idle core)."""
        model = DriveModel.of(model)
        config = model.config
        cs = config.compensation
        self.model = model
        self.config = config
        self.enabled = bool(cs.enabled)
        self.quasi_static = bool(cs.quasi_static)
        self.dynamic = bool(cs.model_inverse) and self.quasi_static
        self.preview = float(cs.preview_time)
        # the antenna mode with the teeth in contact (with play, the modes of the linearised
        # model are those of a free mesh: a rigid antenna and the gear alone)
        linear = DriveModel(dataclasses.replace(
            config, mesh=dataclasses.replace(config.mesh, backlash=0.0))) \
            if has_play(model.p) else model
        yield
        res = yield from modes_steps(linear)
        yield
        # the antenna mode: largest theta4 participation (mode 1 for the default drive)
        k = int(np.argmax(np.abs(res.shapes[2, :])))
        self.mode_frequency_hz = float(res.frequencies_hz[k] or res.undamped_hz[k])
        self.mode_damping_ratio = float(max(res.damping_ratios[k], 0.0))
        shaper = design_shaper(cs.shaper, self.mode_frequency_hz, self.mode_damping_ratio)
        # derivatives the inverse needs (r..r'' or r..r''''), plus the lead order: the
        # B-spline degree is the lowest that keeps them bounded (at least MIN_DEGREE)
        n_deriv = 5 if self.dynamic else (3 if self.quasi_static else 1)
        lag = int(cs.lag_order)
        degree = max(n_deriv - 1 + lag, MIN_DEGREE)
        # knots one command period apart (by default): the kernel's spectrum then has
        # (degree+1)-fold zeros at the command rate and its harmonics, so the correction,
        # sampled at that rate and joined by straight lines, does not alias into the
        # antenna mode (at f_rate - f_mode)
        width = float(cs.smoothing_time) or (degree + 1) / config.node.publish_rate_hz
        self.filter = yield from design_filter_steps(shaper, width / (degree + 1), degree, lag,
                                                     self.preview, n_deriv)
        yield
        self._tau = np.ascontiguousarray(self.filter.tau)
        W = self.filter.weights
        # the backlash inverse decides the flank from the lead-free (lag 0) r', r'': the
        # lead makes r'' overshoot at every rate change, which would flip the flank back
        # and forth (same knots, same nodes: the rows stack)
        self.backlash_inverse = bool(cs.backlash_inverse) and self.quasi_static \
            and has_play(model.p)
        if self.backlash_inverse:
            plain = yield from design_filter_steps(shaper, width / (degree + 1), degree, 0,
                                                   self.preview, 3)
            yield
            if not np.array_equal(plain.tau, self.filter.tau):  # pragma: no cover
                raise RuntimeError('backlash inverse: filter nodes differ')
            W = np.vstack((W, plain.weights[1:3]))
        self._W = np.ascontiguousarray(W)
        if self._derivs.size != W.shape[0]:
            self._derivs = np.zeros(W.shape[0])
        self._flank[_F_ON] = 1.0 if self.backlash_inverse else 0.0
        self._rest_flank = rest_flank(model.p) if self.backlash_inverse else 0.0
        self.soft_crossing = bool(cs.soft_crossing)
        self._flank[_F_LONG] = SOFT_PERIODS / self.mode_frequency_hz \
            if self.mode_frequency_hz > 0.0 else 0.0
        self._flank[_F_SHORT] = SOFT_SHORTEST / config.node.publish_rate_hz
        d = model.derived
        self._flank[_F_COEF] = 12.0 * (d.J_g + d.J_4) * SOFT_TOLERANCE * model.half_play
        self._n_deriv = n_deriv
        self._span = self.filter.lag_span + self.preview
        self._p, self._output_per_input = model.p, model.output_per_input   # per-sample use

    # ---- streaming -------------------------------------------------------------------------
    def reset(self, theta1_ref: float, t: float) -> None:
        """Forget the history: the reference has rested at ``theta1_ref`` until ``t``."""
        if not (math.isfinite(theta1_ref) and math.isfinite(t)):
            raise ValueError('reset: theta1_ref and t must be finite')
        self._ht = np.empty(64)          # history: times and values, [lo, hi) in use
        self._hx = np.empty(64)
        self._ht[0], self._hx[0] = float(t), float(theta1_ref)
        self._lo, self._hi = 0, 1
        self._last_delta = 0.0
        self._reference = float(theta1_ref)
        self._derivs = np.zeros(self._W.shape[0])
        self._derivs[0] = float(theta1_ref)
        self._flank[0] = self._rest_flank
        self._flank[_F_STATE] = 0.0
        self._flank[_F_TPREV] = -math.inf

    def update(self, t: float, theta1_ref: float) -> float:
        """Add the sample (t, theta1_ref) and return the correction delta [rad] for time
        t - preview_time.  Times must not decrease (an equal time replaces the sample)."""
        t = float(t)
        self.add_sample(t, theta1_ref)
        te = t - self.preview
        d = self.evaluate(te)
        self.trim(te)
        return d

    def add_sample(self, t: float, theta1_ref: float) -> None:
        """Append a sample to the history without evaluating (an equal time replaces the
        last sample; times must not decrease)."""
        t = float(t)
        x = float(theta1_ref)
        if not (math.isfinite(t) and math.isfinite(x)):
            raise ValueError('update: t and theta1_ref must be finite')
        hi = self._hi
        last = self._ht[hi - 1]
        if t < last:
            raise ValueError(f'update: time went backwards ({t!r} < {last!r})')
        if t == last:
            self._hx[hi - 1] = x
            return
        if hi == self._ht.size:          # full: compact, grow if still more than half used
            lo = self._lo
            n = hi - lo
            size = self._ht.size * 2 if n > self._ht.size // 2 else self._ht.size
            ht, hx = np.empty(size), np.empty(size)
            ht[:n], hx[:n] = self._ht[lo:hi], self._hx[lo:hi]
            self._ht, self._hx, self._lo, hi = ht, hx, 0, n
        self._ht[hi] = t
        self._hx[hi] = x
        self._hi = hi + 1

    def evaluate(self, te: float) -> float:
        """The correction for time ``te`` from the history so far (the reference at ``te``
        becomes :attr:`reference`); any ``te`` not before the last :meth:`trim`."""
        d, ref = compensation_kernel(float(te), self._tau, self._W, self._ht, self._hx,
                                     self._lo, self._hi, self._p, self._output_per_input,
                                     self.quasi_static, self.dynamic, self.enabled,
                                     self._derivs, self._flank)
        self._reference = ref
        self._last_delta = d
        return d

    def trim(self, te_min: float) -> None:
        """Forget the samples no evaluation at a time >= ``te_min`` needs (one before the
        filter window is kept for the interpolation)."""
        t_old = te_min - float(self._tau[-1])
        ht, lo, hi = self._ht, self._lo, self._hi
        while hi - lo > 2 and ht[lo + 1] <= t_old:
            lo += 1
        self._lo = lo

    def copy_history(self, other: Any) -> None:
        """Take over the reference history and last outputs of ``other`` (a redesign that
        keeps the stream; a Compensator, or a blend of two, whose new one's)."""
        self._ht, self._hx = other._ht.copy(), other._hx.copy()
        self._lo, self._hi = other._lo, other._hi
        self._last_delta, self._reference = other._last_delta, other._reference
        if self.backlash_inverse:    # the teeth stay where they are (none: the rest flank)
            self._flank[0] = other._flank[0] if other.backlash_inverse else self._rest_flank
            if other.backlash_inverse:          # and a crossing under way goes on
                self._flank[_F_STATE] = other._flank[_F_STATE]

    def __copy__(self) -> Compensator:
        """A copy that streams on its own: its history and kernel state are its own arrays
        (the design is shared)."""
        new = object.__new__(type(self))
        new.__dict__.update(self.__dict__)
        new._ht, new._hx = self._ht.copy(), self._hx.copy()
        new._derivs, new._flank = self._derivs.copy(), self._flank.copy()
        return new

    # ---- introspection ---------------------------------------------------------------------
    @property
    def reference(self) -> float:
        """theta1_ref at the time the last delta applies to (t - preview_time)."""
        return self._reference

    @property
    def delta(self) -> float:
        return self._last_delta

    @property
    def filtered_reference(self) -> np.ndarray:
        """Last filtered worm reference and its derivatives (r, r', r'' [, r''', r''''])."""
        return np.array(self._derivs[:self._n_deriv], float)

    @property
    def soft_crossing(self) -> bool:
        """Cross the play along a smooth step planned ahead (``compensation.soft_crossing``)
        rather than in one command period."""
        return bool(self._flank[_F_SOFT] > 0.0)

    @soft_crossing.setter
    def soft_crossing(self, on: bool) -> None:
        self._flank[_F_SOFT] = 1.0 if on else 0.0

    @property
    def flank(self) -> float:
        """The flank the backlash inverse has the worm on: +1 drive, -1 coast, 0 the centre
        of the play (always 0 without play or with ``compensation.backlash_inverse`` off)."""
        return float(self._flank[0])

    def describe(self) -> str:
        f = self.filter
        return (f'shaper {f.shaper.kind} at {self.mode_frequency_hz:.4g} Hz '
                f'(zeta {self.mode_damping_ratio:.3g}, {f.shaper.duration * 1e3:.3g} ms), '
                f'B-spline degree {f.degree} over {f.smoothing_time * 1e3:.3g} ms, '
                f'lead {f.lead[0]:.3g} s / '
                f'{f.lead[1]:.3g} s^2, preview {self.preview * 1e3:.3g} ms, '
                f'quasi_static {self.quasi_static}, model_inverse {self.dynamic}, '
                f'backlash_inverse {self.backlash_inverse}')


def centring_preview(model: DriveModel | Config) -> float:
    """The preview [s] that centres the reference filter's kernel on the present (its mean
    delay: 2.5 ms at a 1 kHz command rate).  With it the filtered reference is not late, so
    the backlash inverse changes flank when the move's torque changes sign rather than
    after (docs/compensation.md: 53-115x instead of 1.8-4x on fast reversals)."""
    config = DriveModel.of(model).config
    return float(Compensator(DriveModel(with_preview(config, 1.0))).filter.shift)


def with_preview(config: Parameters, preview: float) -> Parameters:
    """A copy of ``config`` (a Config stays a Config) with another
    ``compensation.preview_time`` [s]."""
    cs = dataclasses.replace(config.compensation, preview_time=float(preview))
    return dataclasses.replace(config, compensation=cs)
