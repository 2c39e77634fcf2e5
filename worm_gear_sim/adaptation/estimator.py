# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Online estimation of the drive's slowly changing parameters from the encoders, and the
rule that lets an adapted set replace the model in use.

This module contains :class:`Adapter`: a Kalman filter with random-walk parameters on the
residual theta4_meas - theta4_pred, linear in the periodic error's harmonics, the load
torque, the antenna drag and the play (their sensitivities at a fixed command; the play's
through the flank, the estimate's mean sign); the drive's flank changes, measured by
:mod:`.flank_timing`, as measurements of load, drag and play; and the switching rule
(:meth:`Adapter.poll`: the windowed residual of the estimate against the model in use and
the nominal set, then bounded steps towards the target, :mod:`.switching`).  Also
:func:`output_compliance`, the static wind-up behind the load's sensitivity.  The design
and its measurements: docs/adaptation.md.
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..config.usable import Config
from ..dynamics.inverse import inverse_theta1
from ..dynamics.model import DriveModel, with_load_torque
from . import per_sample as ps
from .flank_timing import STEP_GAP_WIDE, STEP_SIDE_WIDE, WINDOW, FlankTiming
from .history import EstimateHistory
from .layout import DRAG_KEY, LOAD_KEY, Layout
from .per_sample import _kalman_step, least_step, sample_head, sample_tail, window_norm
from .plausibility import values_problem
from .slots import Slot
from .switching import bounded_candidate, correction_bound, step_towards

__all__ = ['FLANK_HOLD_OFF', 'output_compliance', 'Adapter', 'Decision']

#: Samples this long after a change of the flank in contact are not used [s].
FLANK_HOLD_OFF = 0.15
#: Time constant of the low-pass on the antenna acceleration (flank decision) [s].
ACCEL_TIME_CONSTANT = 0.02
#: Innovations beyond this many predicted standard deviations are down-weighted (Huber).
HUBER_SIGMAS = 4.0
#: Timing uncertainty of a measured flank change [s] and a torque floor [N m]: the noise
#: of the flank-change measurement is SWITCH_TIME_SD |c alpha4| + SWITCH_TORQUE_SD.
SWITCH_TIME_SD = 2e-3
SWITCH_TORQUE_SD = 2e-3
#: Timing uncertainty of a flank change measured by the area formula [s] (neither the
#: float's onset nor the arch seen): the formula holds only when the model crosses first,
#: and off that case it was measured 12-330 ms off (benchmarks/bench_adaptation.py drives)
AREA_TIME_SD = 0.05
#: Timing uncertainty of a crossing the steep scale of the step detector found, as a share
#: of the time from the rise's extrapolated start to the step's middle (the start measured
#: 4-33 ms off on 11 drives drawn with drag, the rise 53-144 ms: bench_adaptation.py)
RISE_TIME_SHARE = 0.2
#: A step found on the detector's wide scale is the drive's crossing only where the
#: estimate's torque demand T + c omega4 + J alpha4 is within this many of its standard
#: deviations of zero (the drive crosses only there; a smooth residual not yet learnt can
#: look like a slow step: measured on a drive without drag that never crosses)
PLAUSIBLE_SIGMAS = 3.0
#: How many of the drive's measured crossings :attr:`Adapter.crossings` keeps
CROSSING_LOG = 4096
#: The step detector's widest window [s]
DETECT_SPAN = 2.0 * STEP_SIDE_WIDE + STEP_GAP_WIDE
#: A play smaller than this many measurement noises is not seen in a flank change.
MIN_PLAY_NOISES = 10.0
#: A flank change of the model this soon after a step applied is the step's [s].
STEP_FLIP_TIME = 0.005
#: How many of the latest steps' times an event's window is checked against.
STEP_TIMES = 8
#: A sample gap longer than this restarts the rate estimates [s].
MAX_GAP = 0.05


def output_compliance(model: DriveModel, phases: int = 8) -> tuple[float, float]:
    """Static wind-up of the chain at the antenna per N m of antenna torque, theta1 held
    [rad/(N m)], (sliding forwards, backwards): from the model's inverse (Eqs. 6-13), the
    mean over ``phases`` positions of one mesh cycle."""
    p = model.p
    ratio = model.output_per_input
    cycle = 2.0 * math.pi * ratio            # one worm turn at the antenna
    out = []
    for direction in (1.0, -1.0):
        vals = []
        for k in range(phases):
            y0 = cycle * k / phases
            a = inverse_theta1(with_load_torque(p, 0.0), y0, 1e-3 * direction, 0.0, 0.0,
                               0.0, False, 1.0)
            b = inverse_theta1(with_load_torque(p, 1.0), y0, 1e-3 * direction, 0.0, 0.0,
                               0.0, False, 1.0)
            vals.append((b - a) * ratio)
        out.append(float(np.mean(vals)))
    return out[0], out[1]


@dataclass
class Decision:
    """What :meth:`Adapter.poll` asks the caller to do: apply ``overrides`` (the next step,
    state vector ``step``) or nothing; ``note``: why (for the log, once per change)."""

    step: np.ndarray | None = None
    overrides: dict[str, Any] | None = None
    note: str = ''


#: "Nothing to do" (shared; never modified).
_NOTHING = Decision()


class Adapter:
    """The online estimator and the switching rule (module docstring).

    ``model``: the model in use at the start (nominal); ``settings``: the ``adaptation``
    section of a Config (keys, orders, memory, window, min_improvement, max_step,
    step_interval, measurement_noise).  Feed :meth:`update` in time order (the caller
    rejects bad samples); call :meth:`poll` now and then; tell it :meth:`applied` or
    :meth:`refused`; :meth:`rebase` after an outside change of the model."""

    # the per-sample scalars, in the array the compiled sample shares (:mod:`.per_sample`)
    _last_t, _th4, _w4, _a4, _rate = (Slot('_st', i) for i in (
        ps.S_LAST_T, ps.S_TH4, ps.S_W4, ps.S_A4, ps.S_RATE))
    _flank, _flank_t, _cross_t, _flank_m, _hold_until = (Slot('_st', i) for i in (
        ps.S_FLANK, ps.S_FLANK_T, ps.S_CROSS_T, ps.S_FLANK_M, ps.S_HOLD_UNTIL))
    _w_max, _a_max, _first_t = (Slot('_st', i) for i in (ps.S_W_MAX, ps.S_A_MAX, ps.S_FIRST_T))
    _rates, samples_used, samples_skipped = (Slot('_st', i, int) for i in (
        ps.S_RATES, ps.S_USED, ps.S_SKIPPED))
    _inertia, _load0, _drag0, _play0 = (Slot('_st', i) for i in (
        ps.S_INERTIA, ps.S_LOAD0, ps.S_DRAG0, ps.S_PLAY0))
    _model_flank_t, _applied_t = Slot('_st', ps.S_MODEL_FLANK_T), Slot('_st', ps.S_APPLIED_T)
    _applied_bound = Slot('_st', ps.S_APPLIED_BOUND)

    def __init__(self, model: DriveModel | Config, settings: Any) -> None:
        model = DriveModel.of(model)
        self.settings = settings
        self._st = np.zeros(ps.N_ST)
        self.layout = Layout.for_set(model.config, settings)
        n = self.layout.n
        self._std = self.layout.prior_std()
        self._std2 = self._std ** 2
        self.theta = np.zeros(n)
        self.P = np.zeros((n, n))
        self._phi = np.zeros(n)
        self._R = np.zeros((n + 2, n + 1))    # the window's factor (per_sample._window_step)
        self._sc = np.zeros(1)                # and its sum of weights
        self.samples_used = 0
        self.samples_skipped = 0
        self.flank_times = 0
        self.steps_seen = 0
        #: The drive's crossings measured, the latest CROSSING_LOG: (t_p [s], omega4, alpha4,
        #: time sd [s], how: 'step', 'wide step', 'onset', 'arch' or 'area'), for diagnostics
        self.crossings: collections.deque = collections.deque(maxlen=CROSSING_LOG)
        self.switches = 0
        self.refusals = 0
        self.last_refusal = ''
        self.target: np.ndarray | None = None
        self.rebase(model, nominal=True)

    # ---- the model in use ------------------------------------------------------------------
    def rebase(self, model: DriveModel | Config, nominal: bool = False) -> None:
        """The model in use changed from outside (or at the start, ``nominal``): its values
        become the applied set (and, ``nominal``, the prior mean and the nominal set); the
        estimate restarts there with the prior covariance, the window is emptied."""
        model = DriveModel.of(model)
        self.model = model
        self.applied_x = self.layout.pack(model.config)
        if nominal:
            self.nominal_x = self.applied_x.copy()
        self.theta[:] = self.applied_x
        self.P[:] = np.diag(self._std ** 2)
        self._R[:] = 0.0
        self._sc[:] = 0.0
        self.target = None
        self._compliance = output_compliance(model)
        d = model.derived
        self._inertia = d.J_g + d.J_4
        self._ratio = model.output_per_input
        flat = model.config.to_flat_dict()
        self._load0, self._drag0 = float(flat[LOAD_KEY]), float(flat[DRAG_KEY])
        self._last_t = math.nan
        self._th4 = self._w4 = self._a4 = 0.0
        self._rates = 0                   # samples since the rates restarted
        self._flank = self._flank_m = 0.0
        self._flank_t = -math.inf
        self._first_t = math.nan
        self._next_poll = -math.inf
        self._w_max = self._a_max = 0.0
        self._hold_until = -math.inf
        self._timing = FlankTiming()
        self._model_flank_t = -math.inf
        self._applied_t = -math.inf       # the last step applied (when its samples start)
        self._applied_bound = 0.0         # and the change of the correction it made [rad]
        self._recent_bounds: collections.deque = collections.deque()  # (t, bound) of steps
        self._step_times: collections.deque = collections.deque(maxlen=STEP_TIMES)
        self._cross_t = -math.inf         # the drive's last crossing, measured or estimated
        self._switches: collections.deque = collections.deque(maxlen=16)
        self._rate = 0.0
        self._history = EstimateHistory((self.theta, self.P, self._R, self._sc), DETECT_SPAN)
        self._prev_x = self.applied_x.copy()
        lay = self.layout
        parts = [[i for i in (lay.i_load, lay.i_drag) if i >= 0],
                 [i for i0, k in ((lay.worm0, lay.worm_orders), (lay.gear0, lay.gear_orders))
                  if i0 >= 0 for i in range(i0, i0 + 2 * k)],
                 [lay.i_play] if lay.i_play >= 0 else []]
        self._step_order = [np.array(p, np.int64) for p in parts if p]
        self._play0 = float(model.config.mesh.backlash)
        st, s, lay = self._st, self.settings, self.layout
        st[ps.S_C_POS], st[ps.S_C_NEG] = self._compliance
        st[ps.S_WINDOW], st[ps.S_MEMORY] = s.window, s.memory
        st[ps.S_NOISE], st[ps.S_NOISE2] = s.measurement_noise, s.measurement_noise ** 2
        st[ps.S_MAX_GAP], st[ps.S_ACCEL_TC] = MAX_GAP, ACCEL_TIME_CONSTANT
        st[ps.S_HOLD_OFF], st[ps.S_HUBER] = FLANK_HOLD_OFF, HUBER_SIGMAS
        self._lay = np.array([lay.i_load, lay.i_drag, lay.i_play, lay.worm0, lay.worm_orders,
                              lay.gear0, lay.gear_orders], np.int64)

    # ---- per sample ------------------------------------------------------------------------
    def update(self, t: float, theta4_meas: float, theta2: float, theta3: float,
               theta4_pred: float) -> bool:
        """One encoder sample at ``t`` [s] (measured theta4) with the prediction of that
        instant (theta2, theta3, theta4); True when it entered the estimate.  Compiled
        (:mod:`.per_sample`): the rates, the flanks, the record and the step detector's look
        in :func:`~.per_sample.sample_head`, the hold-offs and the filter in
        :func:`~.per_sample.sample_tail`; in between, only when the sample needs it, the
        flank-change events and a step found, here."""
        timing, hist = self._timing, self._history
        if t >= hist.next:
            hist.keep(t)
        model_flank_t = self._model_flank_t
        # (hist.theta, hist.P: the step detector's estimate, from before its window)
        args = (self._st, timing._ts, timing._a, self.theta, self.P, hist.theta, hist.P,
                self._std2, self._phi, self.applied_x, self._R, self._sc, self._lay,
                t, theta4_meas, theta2, theta3, theta4_pred)
        got = sample_head(*args)
        if got == ps.NEED_ROOM:                     # the record is full: room, then again
            timing.make_room(t)
            got = sample_head(*args)
        if got <= ps.USED:
            return got == ps.USED
        if got == ps.CROSSED:                       # the model crosses its play here
            if self._flipped_by_step(t, self._st.item(ps.X_OLD_FLANK_M)):
                self._model_flank_t = model_flank_t
                i_play = self.layout.i_play         # (its prediction moved by the play)
                self._applied_bound += self.applied_x[i_play] if i_play >= 0 else self._play0
            else:
                timing.model_flank_changed(t, self._st.item(ps.X_OLD_FLANK_M), self._flank_m)
        drag = self._st.item(ps.X_DRAG)             # the estimate's, before this sample
        self._flank_time_update(t, drag)
        self._step_update(t, drag)
        return sample_tail(self._st, self.theta, self.P, self._std2, self._phi,
                           self.applied_x, self._R, self._sc, self._lay, t,
                           theta4_meas, theta2, theta3, theta4_pred) == ps.USED

    def _step_update(self, t: float, drag: float) -> None:
        """A crossing of the drive's own, seen as a step of the residual while the model
        did not cross (:meth:`.flank_timing.FlankTiming.detect`): the torque measurement of
        :meth:`_flank_time_update` where the step's float starts and, with play adapted, the
        step's size as a measurement of the play (10 % uncertain)."""
        if not self._timing.due(t):
            return
        lay = self.layout
        theta_d, P_d = self._history.theta, self._history.P
        least = least_step(theta_d, P_d, self._lay, self._play0)
        # (a step applied to the model steps the residual too, by up to its bound)
        got = self._timing.detect(t, self.settings.measurement_noise, self._model_flank_t,
                                  least, theta_d, self.applied_x, P_d, self._lay,
                                  self._applied_t, self._applied_bound)
        if got is None:
            return
        t_p, w_p, a_p, step, wide, rise = got
        old = self._history.before(t_p)     # the estimate before the samples since t_p,
        theta, P = (self.theta, self.P) if old is None else old[:2]   # on the wrong flank
        if lay.i_drag >= 0:
            drag = theta[lay.i_drag]
        if wide and not self._may_cross(w_p, a_p, theta, P):
            return
        if old is not None:
            self._history.restore(old)
        self.steps_seen += 1
        # (a steep step's start is extrapolated from its rise: uncertain in proportion; a
        # wide step's onset as the area formula's crossing)
        self._torque_zero(t_p, w_p, a_p, drag,
                          AREA_TIME_SD if wide else max(SWITCH_TIME_SD, RISE_TIME_SHARE * rise),
                          'wide step' if wide else 'step')
        if lay.i_play >= 0:
            phi = np.zeros(lay.n)
            phi[lay.i_play] = 1.0
            sd = 0.1 * abs(step)
            _kalman_step(self.theta, self.P, np.zeros(lay.n), self._std ** 2, phi, abs(step),
                         sd * sd, HUBER_SIGMAS)
        self._hold_until = max(self._hold_until, t_p + FLANK_HOLD_OFF)

    def _demand_row(self, w_p: float, a_p: float) -> tuple[np.ndarray, float]:
        """The mesh torque demand T + c omega4 + J alpha4 at (w_p, a_p) as phi^T theta +
        known: the row of the estimated load and drag, and the rest (J alpha4, and the
        model's load and drag where they are not adapted)."""
        lay = self.layout
        phi = np.zeros(lay.n)
        known = self._inertia * a_p
        if lay.i_load >= 0:
            phi[lay.i_load] = 1.0
        else:
            known += self._load0
        if lay.i_drag >= 0:
            phi[lay.i_drag] = w_p
        else:
            known += self._drag0 * w_p
        return phi, known

    def _flipped_by_step(self, t: float, old: float) -> bool:
        """Whether the model's flank change at ``t`` from ``old`` is the set's (a step
        applied just now), not the motion's: the set before the step keeps the old flank
        at these rates."""
        if not t - self._applied_t <= STEP_FLIP_TIME:
            return False
        lay, x = self.layout, self._prev_x
        load = x[lay.i_load] if lay.i_load >= 0 else self._load0
        drag = x[lay.i_drag] if lay.i_drag >= 0 else self._drag0
        torque = self._inertia * self._a4 + drag * self._w4 + load
        return torque * old > 0.0

    def _may_cross(self, w_p: float, a_p: float, theta: np.ndarray | None = None,
                   P: np.ndarray | None = None) -> bool:
        """Whether the estimate's torque demand at (w_p, a_p) is within PLAUSIBLE_SIGMAS of
        its standard deviation (and the torque floor) of zero."""
        theta = self.theta if theta is None else theta
        P = self.P if P is None else P
        phi, known = self._demand_row(w_p, a_p)
        demand = known + float(phi @ theta)
        sd = math.sqrt(max(float(phi @ P @ phi), 0.0)) + SWITCH_TORQUE_SD
        return abs(demand) <= PLAUSIBLE_SIGMAS * sd

    def _torque_zero(self, t_p: float, w_p: float, a_p: float, drag: float,
                     time_sd: float = SWITCH_TIME_SD, how: str = 'step') -> None:
        """The drive's mesh torque was zero at t_p: T + c omega4 = -J alpha4 there
        (measured ``how``, its timing uncertain by ``time_sd``)."""
        lay = self.layout
        if lay.i_load < 0 and lay.i_drag < 0:
            return
        self.crossings.append((t_p, w_p, a_p, time_sd, how))
        self._switches.append((t_p, w_p, a_p))
        self._cross_t = max(self._cross_t, t_p)
        phi, known = self._demand_row(w_p, a_p)
        y = -known                          # the demand is zero: phi^T theta = -known
        sd = time_sd * abs(drag * a_p) + SWITCH_TORQUE_SD
        _kalman_step(self.theta, self.P, np.zeros(lay.n), self._std ** 2, phi, y, sd * sd,
                     HUBER_SIGMAS)
        self.flank_times += 1

    def _flank_time_update(self, t: float, drag: float) -> None:
        """The real drive's flank change as a measurement of (T, c) (:mod:`.flank_timing`):
        T + c omega4(t_p) = -J alpha4(t_p), its noise a timing error of SWITCH_TIME_SD
        (AREA_TIME_SD when the area formula measured it)."""
        lay = self.layout
        if lay.i_load < 0 and lay.i_drag < 0 or not self._timing.event_due(t):
            return
        # a step applied inside the event's window steps its residual: no measurement (any
        # step, not only the last: a step applied since, after the window, hid the one in it)
        if any(self._timing.event_spans(at) for at in self._step_times):
            self._timing.drop_event()
            return
        play = self.theta[lay.i_play] if lay.i_play >= 0 else self._play0
        model_play = self.applied_x[lay.i_play] if lay.i_play >= 0 else self._play0
        noise = self.settings.measurement_noise
        got = self._timing.ready(t, play, MIN_PLAY_NOISES * noise, model_play, noise,
                                 self._inertia / drag if drag > 0.0 else 0.0)
        if got is None:
            return
        t_p, w_p, a_p, how = got
        self._torque_zero(t_p, w_p, a_p, drag, AREA_TIME_SD if how == 'area' else SWITCH_TIME_SD,
                          how)

    # ---- switching -------------------------------------------------------------------------
    def window_rms(self) -> dict[str, float]:
        """Windowed RMS of the residual [rad] for the estimate, the model in use and the
        nominal set: the linearised residual of the samples used, plus the error of a
        mistimed crossing of the play at each measured flank change in the window."""
        w = self._sc.item(0)
        out = {}
        for name, x in (('estimate', self.theta), ('applied', self.applied_x),
                        ('nominal', self.nominal_x)):
            out[name] = math.hypot(window_norm(self._R, x), math.sqrt(self._crossing_ms(x))) \
                / math.sqrt(w) if w > 0.0 else math.nan
        return out

    def _crossing_ms(self, x: np.ndarray) -> float:
        """Sum of the squared error over the window's flank changes if the model ``x``
        decided them: the play b (the estimate's) for the time |tau_x(t_p)| / |c alpha4|
        its torque demand takes to reach zero after the drive's, per sample."""
        lay = self.layout
        if not self._switches or self._rate <= 0.0:
            return 0.0
        play = max(self.theta[lay.i_play] if lay.i_play >= 0 else self._play0, 0.0)
        load = x[lay.i_load] if lay.i_load >= 0 else self._load0
        drag = x[lay.i_drag] if lay.i_drag >= 0 else self._drag0
        total = 0.0
        for t_p, w_p, a_p in self._switches:
            weight = math.exp(-(self._last_t - t_p) / self.settings.window)
            tau = load + drag * w_p + self._inertia * a_p
            rate = abs(drag * a_p)
            late = min(abs(tau) / rate, WINDOW) if rate > 0.0 else WINDOW * (tau != 0.0)
            total += weight * play * play * late * self._rate
        return total

    def poll(self, t: float) -> Decision:
        """Every ``step_interval``: maybe take the estimate as the target (module
        docstring), then the next bounded step towards the target."""
        s = self.settings
        if t < self._next_poll:
            return _NOTHING
        self._next_poll = t + s.step_interval
        note = ''
        if not math.isnan(self._first_t) and t - self._first_t >= s.window:
            rms = self.window_rms()
            est, cur, nom = rms['estimate'], rms['applied'], rms['nominal']
            if est * est < (1.0 - s.min_improvement) * cur * cur and est <= nom:
                cand, why = self.bounded(self.theta)
                why = why or values_problem(self.model, self.layout.overrides(cand))
                if why:
                    self.refused(why)
                else:
                    self.target = cand
                    note = (f'adapted set accepted: windowed residual RMS {est:.3g} rad '
                            f'against {cur:.3g} rad (model in use), {nom:.3g} rad (nominal)')
        if self.target is None or np.array_equal(self.target, self.applied_x):
            return Decision(note=note)
        budget = s.max_step * self._ratio         # max_step at the worm -> antenna
        # the load and drag first (they decide when the model crosses its play), then the
        # harmonics, the play last: a straight line from a set that keeps one flank to one
        # that crosses passes through sets that hold the play on the wrong flank
        step = step_towards(self.target, self.applied_x, budget, self._step_order,
                            self._correction_bound)
        return Decision(step, self.layout.overrides(step), note)

    def bounded(self, x: np.ndarray) -> tuple[np.ndarray, str]:
        """The candidate of estimate ``x`` (:func:`~.switching.bounded_candidate`, with the
        estimate's covariance): a play or drag a little below zero taken as zero, one
        further below refused (the reason)."""
        return bounded_candidate(x, self.P, self.layout)

    def _correction_bound(self, delta: np.ndarray) -> float:
        """Bound of the change of the static antenna correction a parameter change makes
        [rad] (:func:`~.switching.correction_bound`)."""
        return correction_bound(delta, self.layout, self._compliance, self._w_max)

    def applied(self, step: np.ndarray, model: DriveModel, at: float | None = None) -> None:
        """The caller applied ``step`` (a Decision's) to the model in use; ``at``: the time
        of the first sample it predicts [s] (None: the last sample's)."""
        step = np.array(step, float)
        at = self._last_t if at is None else float(at)
        # the steps applied within the detector's widest window add up in its residual:
        # those within DETECT_SPAN of this one (a window holding this step holds no older
        # one).  Chaining each step's bound onto the previous one's whenever the two were
        # closer than DETECT_SPAN summed every step of a run of steps (one per
        # step_interval < DETECT_SPAN), so the detector went blind while the model moved
        recent = self._recent_bounds
        while recent and at - recent[0][0] >= DETECT_SPAN:
            recent.popleft()
        recent.append((at, self._correction_bound(step - self.applied_x)))
        self._applied_bound = sum(b for _, b in recent)
        self._prev_x = self.applied_x
        self.applied_x = step
        self.model = model
        self._applied_t = at
        self._step_times.append(at)
        self._hold_until = self._last_t + FLANK_HOLD_OFF   # the prediction's transient
        self.switches += 1
        if self.target is not None and np.array_equal(self.target, self.applied_x):
            self.target = None

    def refused(self, reason: str) -> None:
        """The target cannot be applied (``reason``): the model in use stays."""
        self.target = None
        self.refusals += 1
        self.last_refusal = reason

    # ---- read-out --------------------------------------------------------------------------
    def estimates(self) -> dict[str, Any]:
        """The current estimate as parameter values (dotted keys)."""
        return self.layout.overrides(self.theta)

    def applied_values(self) -> dict[str, Any]:
        """The values of the model in use (dotted keys)."""
        return self.layout.overrides(self.applied_x)
