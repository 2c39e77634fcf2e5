# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Live model check: does the model still match the drive?

Pure core (no rclpy); the node feeds it.  Every tick the node pushes the predicted angles
(theta2, theta3, theta4) at the simulated time into a :class:`PredictionHistory`; every measured
JointState (the drive's encoders) that passes the admission
(:mod:`.encoder_admission`, the rule the live adaptation applies too) is compared with the
prediction interpolated at the measurement's stamp.  :class:`ResidualMonitor` keeps the
per-joint residual measured - predicted and its RMS over a sliding time window
(:class:`SlidingSums`: nothing that left the window stays in the sums); the status turns WARN
when a joint's RMS exceeds its threshold, or while samples are rejected as implausible.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..records.topics import MEASURED_TOPIC
from .encoder_admission import EncoderAdmission

__all__ = ['ResidualMonitor', 'SlidingSums', 'PredictionHistory', 'ModelCheck',
           'CheckStatus', 'MEASURED_JOINTS']

#: the measured angles, in the order of node.joint_names[1:4]
MEASURED_JOINTS: tuple[str, ...] = ('theta2', 'theta3', 'theta4')


class SlidingSums:
    """Column sums of the rows of a sliding time window, without a subtraction: what leaves
    the window leaves no trace in the sums (a running sum that subtracts the rows leaving
    keeps the rounding of every large row it ever held, and an infinite one for ever).

    Two stacks: the newest rows (:meth:`push`) and their running sum; the older rows with
    the sums from each row to the newest of them (suffix sums, computed once when the newest
    rows move there).  :meth:`expire` drops rows from the old end; :meth:`total` is the
    suffix sum of the oldest row left plus the running sum.  Each row is summed a bounded
    number of times (amortised O(1) per row), and the total is a sum of exactly the rows in
    the window: of non-negative rows, equal to any other order of summation within n eps."""

    def __init__(self, width: int) -> None:
        # the newest rows (Python lists: a row of a few numbers costs no numpy call)
        self._t: list[float] = []
        self._rows: list[Sequence[float]] = []
        self._sum = [0.0] * width
        self._old_t: list[float] = []            # the older rows: times and suffix sums
        self._suffix = np.zeros((0, width))
        self._head = 0                           # the oldest older row still in the window

    def __len__(self) -> int:
        return len(self._old_t) - self._head + len(self._t)

    def push(self, t: float, row: Sequence[float]) -> None:
        self._t.append(t)
        self._rows.append(row)
        self._sum = [a + b for a, b in zip(self._sum, row)]

    def expire(self, cut: float) -> None:
        """Drop the rows stamped at or before ``cut``."""
        old_t = self._old_t
        if self._head < len(old_t) and old_t[self._head] <= cut:
            self._head = bisect.bisect_right(old_t, cut, self._head)
        if self._head == len(old_t) and self._t and self._t[0] <= cut:
            self._old_t = self._t                # the newest rows become the older ones
            self._suffix = np.cumsum(np.array(self._rows[::-1], float), axis=0)[::-1]
            self._t, self._rows = [], []
            self._sum = [0.0] * len(self._sum)
            self._head = bisect.bisect_right(self._old_t, cut)

    def total(self) -> np.ndarray:
        total = np.array(self._sum)
        if self._head < len(self._old_t):
            total += self._suffix[self._head]
        return total


class ResidualMonitor:
    """Per-joint residual measured - predicted and its RMS over a sliding time window.

    ``update(t, measured, predicted)`` takes arrays over the monitored joints (a NaN entry:
    that joint was not measured in this sample) and returns the residuals; :meth:`rms` gives
    the windowed RMS per joint (NaN without samples) and :meth:`level` 'OK', 'WARN' (a
    joint's RMS above its threshold) or 'STALE' (no sample within the window).  Samples
    must come in time order; a bad one raises ValueError and is counted in ``rejected``.
    The windowed sums are :class:`SlidingSums`: the RMS is that of the samples in the
    window, whatever came before them.
    """

    def __init__(self, joints: Sequence[str], window: float,
                 warn_threshold: float | Sequence[float]):
        if not (math.isfinite(window) and window > 0):
            raise ValueError(f'window must be > 0 s, got {window!r}')
        thr = np.broadcast_to(np.asarray(warn_threshold, float), (len(joints),)).copy()
        if not np.all(np.isfinite(thr) & (thr > 0)):
            raise ValueError(f'warn_threshold must be > 0 rad, got {warn_threshold!r}')
        self.joints = tuple(joints)
        self.window = float(window)
        self.warn_threshold = thr
        self._sums = SlidingSums(2 * len(self.joints))   # squared residual, 1 if measured
        self.samples = 0
        self.rejected = 0
        self.last_t = -math.inf

    def update(self, t: float, measured: Sequence[float] | np.ndarray,
               predicted: Sequence[float] | np.ndarray) -> np.ndarray:
        try:
            m = [float(v) for v in measured]
            p = [float(v) for v in predicted]
        except (TypeError, ValueError):
            m = p = []
        if len(m) != len(self.joints) or len(p) != len(m) or not math.isfinite(t) \
                or t < self.last_t:
            self.rejected += 1
            raise ValueError('residual sample: need a finite time, not before the previous '
                             f'one, and one value per joint ({len(self.joints)})')
        r = [a - b for a, b in zip(m, p)]
        # (Python floats: |r| > 1.3e154 squares to inf, quietly, while in the window)
        ok = [v - v == 0.0 for v in r]
        self._sums.push(float(t), [v * v if f else 0.0 for v, f in zip(r, ok)]
                        + [1.0 if f else 0.0 for f in ok])
        self.samples += 1
        self.last_t = float(t)
        self._sums.expire(float(t) - self.window)
        return np.array(r)

    def rms(self, now: float | None = None) -> np.ndarray:
        """Windowed RMS per joint [rad] (NaN for a joint without samples in the window)."""
        if now is not None:
            self._sums.expire(now - self.window)
        total = self._sums.total()
        n = len(self.joints)
        sq, cnt = total[:n], total[n:]
        with np.errstate(invalid='ignore', divide='ignore'):
            return np.where(cnt > 0.5, np.sqrt(sq / np.maximum(cnt, 1.0)), np.nan)

    def level(self, now: float | None = None) -> str:
        r = self.rms(now)
        ok = ~np.isnan(r)
        if not np.any(ok):
            return 'STALE'
        return 'WARN' if np.any(r[ok] > self.warn_threshold[ok]) else 'OK'


class PredictionHistory:
    """The last ``capacity`` predicted states (t, theta2..theta4), interpolated linearly at a
    measurement's time."""

    def __init__(self, capacity: int = 256):
        if capacity < 2:
            raise ValueError('capacity must be >= 2')
        self._cap = int(capacity)
        # Python lists (up to twice the capacity between trims): a lookup near the newest
        # prediction, the usual case, costs a bisect, not numpy's per-call overhead
        self._t: list[float] = []
        self._x: list[tuple[float, float, float]] = []

    def push(self, t: float, theta: Sequence[float]) -> None:
        """Append the prediction at time t (times must increase; an equal time replaces)."""
        ts = self._t
        if ts and t <= ts[-1]:
            if t == ts[-1]:
                self._x[-1] = (float(theta[0]), float(theta[1]), float(theta[2]))
                return
            self.clear()       # the clock went back (sim time reset): start over
        if len(ts) == 2 * self._cap:
            del ts[:self._cap]
            del self._x[:self._cap]
        ts.append(float(t))
        self._x.append((float(theta[0]), float(theta[1]), float(theta[2])))

    def clear(self) -> None:
        self._t.clear()
        self._x.clear()

    def span(self) -> tuple[float, float] | None:
        ts = self._t
        if not ts:
            return None
        return ts[max(len(ts) - self._cap, 0)], ts[-1]

    def at(self, t: float) -> np.ndarray | None:
        """Prediction at t, or None if t is outside the stored span."""
        x = self.lookup(t)
        return None if x is None else np.array(x)

    def lookup(self, t: float) -> tuple[float, float, float] | None:
        """:meth:`at` as a tuple."""
        ts = self._t
        n = len(ts)
        if not n or not (ts[max(n - self._cap, 0)] <= t <= ts[-1]):
            return None
        k = bisect.bisect_left(ts, t)
        if ts[k] == t:
            return self._x[k]
        t0, t1 = ts[k - 1], ts[k]
        w = (t - t0) / (t1 - t0)
        x0, x1 = self._x[k - 1], self._x[k]
        return ((1.0 - w) * x0[0] + w * x1[0], (1.0 - w) * x0[1] + w * x1[1],
                (1.0 - w) * x0[2] + w * x1[2])


@dataclass(frozen=True)
class CheckStatus:
    """What /diagnostics shows: level OK/WARN/STALE, a message and key values."""

    level: str
    message: str
    values: dict[str, str]


class ModelCheck:
    """Measured joint positions vs the prediction at the same time.

    ``joint_names`` are node.joint_names[1:4] (theta2..theta4).  :meth:`predicted` is called
    each tick; an encoder message passes :class:`~.encoder_admission.EncoderAdmission` (the
    rule the live adaptation applies too) with ``max_residual`` [rad]
    (``node.residual_plausible_max``) and ``period`` [s] (the command period: at most one
    sample used per period): :meth:`offer_ns` returns (joint names, residuals) for the
    monitored joints it held, or the reason it was rejected for; :meth:`measured` and
    friends raise ValueError naming why instead.  Rejections are counted by reason."""

    def __init__(self, joint_names: Sequence[str], window: float,
                 warn_threshold: float | Sequence[float], history: int = 256, *,
                 max_residual: float = math.inf, period: float = 0.0):
        if len(joint_names) != 3:
            raise ValueError('joint_names: need the 3 measured joints (theta2..theta4)')
        self.joint_names = tuple(joint_names)
        self.monitor = ResidualMonitor(self.joint_names, window, warn_threshold)
        self.history = PredictionHistory(history)
        self.admission = EncoderAdmission(self.joint_names, (0, 1, 2), 'no_monitored_joint',
                                          max_residual=max_residual, period=float(period))
        self.rejections: dict[str, int] = {}
        self._args = (window, warn_threshold, history)
        self._base_ns: int | None = None
        self._implausible_t = -math.inf          # the last sample rejected as implausible
        self._rejected_t = math.nan              # and the last one rejected

    @classmethod
    def of(cls, node: Any) -> ModelCheck:
        """The node's check: ``node`` is a Config's ``node`` section (joint names, window,
        thresholds, plausibility bound, the command period of ``publish_rate_hz``)."""
        return cls(node.joint_names[1:], node.residual_window, node.residual_warn_rms,
                   max_residual=node.residual_plausible_max,
                   period=1.0 / node.publish_rate_hz)

    # ---- integer nanosecond stamps (ROS time), relative to the first one ------------------
    def _seconds(self, stamp_ns: int) -> float:
        if self._base_ns is None:
            self._base_ns = int(stamp_ns)
        return (int(stamp_ns) - self._base_ns) * 1e-9

    def predicted_ns(self, stamp_ns: int, theta: Sequence[float]) -> None:
        """:meth:`predicted` with a stamp in ns; a clock that jumps back by more than the
        history (a restarted /clock) restarts the check."""
        t = self._seconds(stamp_ns)
        sp = self.history.span()
        if sp is not None and t < sp[0]:
            self.restart()
            t = self._seconds(stamp_ns)
        self.predicted(t, theta)

    def offer_ns(self, stamp_ns: int, names: Sequence[str], positions: Sequence[float]
                 ) -> tuple[list[str], np.ndarray] | str:
        """A JointState's stamp [ns], names and positions: (the monitored joints it held,
        their residuals measured - predicted), or the reason it was rejected for (counted;
        no exception: the node's path for every message)."""
        if self._base_ns is None:
            self._rejected_t = math.nan
            return self._count('outside_prediction')
        return self._offer(self._seconds(stamp_ns), names, positions)

    def measured_ns(self, stamp_ns: int, positions: Mapping[str, float]
                    ) -> tuple[list[str], np.ndarray]:
        """:meth:`measured` with a stamp in ns."""
        return self._raise(self.offer_ns(stamp_ns, list(positions), list(positions.values())))

    def measured_message_ns(self, stamp_ns: int, names: Sequence[str],
                            positions: Sequence[float]) -> tuple[list[str], np.ndarray]:
        """A JointState's names and positions (equal lengths and no name twice, else
        rejected as 'malformed'), see :meth:`measured_ns`."""
        return self._raise(self.offer_ns(stamp_ns, names, positions))

    def status_ns(self, now_ns: int | None) -> CheckStatus:
        return self.status(None if now_ns is None or self._base_ns is None
                           else self._seconds(now_ns))

    def restart(self) -> None:
        """Forget predictions, residuals and the time base (counters of rejections stay)."""
        window, thr, history = self._args
        self.monitor = ResidualMonitor(self.joint_names, window, thr)
        self.history = PredictionHistory(history)
        self.admission.reset()
        self._base_ns = None
        self._implausible_t = -math.inf

    def predicted(self, t: float, theta: Sequence[float]) -> None:
        self.history.push(t, theta)

    def measured(self, t: float, positions: Mapping[str, float]
                 ) -> tuple[list[str], np.ndarray]:
        """The sample at ``t`` [s] (name -> position): (the monitored joints it held, their
        residuals), or ValueError naming why it was rejected."""
        return self._raise(self._offer(t, list(positions), list(positions.values())))

    def _count(self, reason: str) -> str:
        self.rejections[reason] = self.rejections.get(reason, 0) + 1
        return reason

    def _offer(self, t: float, names: Sequence[str], positions: Sequence[float]
               ) -> tuple[list[str], np.ndarray] | str:
        got = self.admission.admit(t, names, positions, self.history.lookup)
        if isinstance(got, str):
            if got == 'implausible':
                self._implausible_t = max(self._implausible_t, t)
            self._rejected_t = t
            return self._count(got)
        present, values, pred = got
        meas = np.full(3, np.nan)
        meas[present] = values
        r = self.monitor.update(t, meas, pred)
        return [self.joint_names[j] for j in present], r[present]

    def _raise(self, got: tuple[list[str], np.ndarray] | str
               ) -> tuple[list[str], np.ndarray]:
        if isinstance(got, str):
            raise ValueError(self.describe(got))
        return got

    def describe(self, reason: str) -> str:
        """What a rejection ``reason`` means (for the log)."""
        if reason == 'outside_prediction':
            sp = self.history.span()
            where = 'no prediction yet' if sp is None else \
                f'prediction covers {sp[0]:.6f} .. {sp[1]:.6f} s'
            t = self._rejected_t
            return where if math.isnan(t) else f'measurement at {t:.6f} s: {where}'
        return {'no_monitored_joint': 'measured joint state names none of '
                                      f'{", ".join(self.joint_names)}',
                'non_finite': 'measured joint state holds a non-finite value',
                'out_of_order': 'measurement not after the last one used',
                'surplus': 'more than one measured joint state per command period (the rest '
                           'are not used)',
                'malformed': 'names and positions of unequal length, or a joint named twice',
                'implausible': 'a joint farther than node.residual_plausible_max = '
                               f'{self.admission.max_residual:g} rad from the prediction',
                }.get(reason, reason)

    def rejection_text(self, reason: str) -> str:
        """The log line of a rejection (the node's, throttled)."""
        return (f'rejected {MEASURED_TOPIC}: {reason} ({self.describe(reason)}); '
                f'{self.rejections.get(reason, 0)} so far')

    def status(self, now: float | None = None) -> CheckStatus:
        rms = self.monitor.rms(now)
        level = self.monitor.level(now)
        values = {f'residual_rms_{n} [rad]': ('n/a' if not math.isfinite(v) else f'{v:.3e}')
                  for n, v in zip(self.joint_names, rms)}
        values['window [s]'] = f'{self.monitor.window:g}'
        values['samples'] = str(self.monitor.samples)
        values.update({f'rejected_{k}': str(v) for k, v in sorted(self.rejections.items())})
        if self.monitor.samples == 0:
            level, msg = 'OK', 'idle: no measured joint state received (optional input)'
        elif level == 'STALE':
            msg = f'no measured joint state within the last {self.monitor.window:g} s'
        elif level == 'WARN':
            bad = [f'{n} {v:.3g} rad > {thr:.3g}' for n, v, thr in
                   zip(self.joint_names, rms, self.monitor.warn_threshold)
                   if not math.isnan(v) and v > thr]
            msg = 'model does not match the drive: residual RMS ' + ', '.join(bad)
        else:
            msg = 'model matches the drive'
        latest = max(self.monitor.last_t, self._implausible_t) if now is None else now
        if latest - self._implausible_t < self.monitor.window:
            level = 'WARN'
            msg = (f'measured joint states farther than {self.admission.max_residual:g} rad '
                   'from the prediction, rejected as implausible (an encoder of another '
                   f'drive? a corrupted reading?): {self.rejections["implausible"]} so far; '
                   + msg)
        return CheckStatus(level, msg, values)
