# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Live model check: does the model still match the drive?

Pure core (no rclpy); the node feeds it.  Every tick the node pushes the predicted angles
(theta2, theta3, theta4) at the simulated time into a :class:`PredictionHistory`; every measured
JointState (the drive's encoders) is compared with the prediction interpolated at the
measurement's stamp.  :class:`ResidualMonitor` keeps the per-joint residual measured -
predicted and its RMS over a sliding time window; the status turns WARN when a joint's RMS
exceeds its threshold.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ['ResidualMonitor', 'PredictionHistory', 'ModelCheck', 'CheckStatus',
           'MEASURED_JOINTS']

#: the measured angles, in the order of node.joint_names[1:4]
MEASURED_JOINTS: tuple[str, ...] = ('theta2', 'theta3', 'theta4')


class ResidualMonitor:
    """Per-joint residual measured - predicted and its RMS over a sliding time window.

    ``update(t, measured, predicted)`` takes arrays over the monitored joints (a NaN entry:
    that joint was not measured in this sample) and returns the residuals; :meth:`rms` gives
    the windowed RMS per joint (NaN without samples) and :meth:`level` 'OK', 'WARN' (a
    joint's RMS above its threshold) or 'STALE' (no sample within the window).  Samples
    must come in time order; a bad one raises ValueError and is counted in ``rejected``.
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
        self._t: deque[float] = deque()
        self._sq: deque[np.ndarray] = deque()   # (2, n): squared residual, 1 if measured
        self._sum = np.zeros((2, len(self.joints)))
        self.samples = 0
        self.rejected = 0
        self.last_t = -math.inf

    def update(self, t: float, measured: npt.ArrayLike, predicted: npt.ArrayLike
               ) -> np.ndarray:
        m = np.asarray(measured, float)
        p = np.asarray(predicted, float)
        if m.shape != (len(self.joints),) or p.shape != m.shape or not math.isfinite(t) \
                or t < self.last_t:
            self.rejected += 1
            raise ValueError('residual sample: need a finite time, not before the previous '
                             f'one, and one value per joint ({len(self.joints)})')
        r = m - p
        ok = np.isfinite(r)
        entry = np.stack([np.where(ok, r * r, 0.0), ok.astype(float)])
        self._t.append(float(t))
        self._sq.append(entry)
        self._sum += entry
        self.samples += 1
        self.last_t = float(t)
        self._expire(float(t))
        return r

    def _expire(self, now: float) -> None:
        while self._t and self._t[0] <= now - self.window:
            self._t.popleft()
            self._sum -= self._sq.popleft()
        if not self._t:
            self._sum[:] = 0.0
        elif len(self._t) % 1024 == 0:   # bound the rounding drift of the running sums
            self._sum = np.sum(np.stack(self._sq), axis=0)

    def rms(self, now: float | None = None) -> np.ndarray:
        """Windowed RMS per joint [rad] (NaN for a joint without samples in the window)."""
        if now is not None:
            self._expire(now)
        sq, cnt = self._sum
        with np.errstate(invalid='ignore', divide='ignore'):
            return np.where(cnt > 0.5, np.sqrt(np.maximum(sq, 0.0) / np.maximum(cnt, 1.0)),
                            np.nan)

    def level(self, now: float | None = None) -> str:
        r = self.rms(now)
        ok = np.isfinite(r)
        if not np.any(ok):
            return 'STALE'
        return 'WARN' if np.any(r[ok] > self.warn_threshold[ok]) else 'OK'


class PredictionHistory:
    """The last ``capacity`` predicted states (t, theta2..theta4), interpolated linearly at a
    measurement's time."""

    def __init__(self, capacity: int = 256):
        if capacity < 2:
            raise ValueError('capacity must be >= 2')
        self._t = np.full(capacity, np.nan)
        self._x = np.full((capacity, 3), np.nan)
        self._n = 0
        self._i = 0

    def push(self, t: float, theta: Sequence[float]) -> None:
        """Append the prediction at time t (times must increase; an equal time replaces)."""
        cap = self._t.size
        if self._n and t <= self._t[(self._i - 1) % cap]:
            if t == self._t[(self._i - 1) % cap]:
                self._x[(self._i - 1) % cap] = theta
                return
            self.clear()       # the clock went back (sim time reset): start over
        self._t[self._i] = t
        self._x[self._i] = theta
        self._i = (self._i + 1) % cap
        self._n = min(self._n + 1, cap)

    def clear(self) -> None:
        self._n = 0
        self._i = 0

    def span(self) -> tuple[float, float] | None:
        if not self._n:
            return None
        cap = self._t.size
        return float(self._t[(self._i - self._n) % cap]), float(self._t[(self._i - 1) % cap])

    def at(self, t: float) -> np.ndarray | None:
        """Prediction at t, or None if t is outside the stored span."""
        sp = self.span()
        if sp is None or not (sp[0] <= t <= sp[1]):
            return None
        cap = self._t.size
        idx = (self._i - self._n + np.arange(self._n)) % cap
        ts, xs = self._t[idx], self._x[idx]
        k = int(np.searchsorted(ts, t, side='right'))
        if k >= ts.size:
            return xs[-1].copy()
        t0, t1 = ts[k - 1], ts[k]
        w = (t - t0) / (t1 - t0)
        return (1.0 - w) * xs[k - 1] + w * xs[k]


@dataclass(frozen=True)
class CheckStatus:
    """What /diagnostics shows: level OK/WARN/STALE, a message and key values."""

    level: str
    message: str
    values: dict[str, str]


class ModelCheck:
    """Measured joint positions vs the prediction at the same time.

    ``joint_names`` are node.joint_names[1:4] (theta2..theta4).  :meth:`predicted` is called
    each tick; :meth:`measured` with a message's stamp and its name -> position pairs returns
    (joint names, residuals) for the monitored joints it contained, or raises ValueError
    naming why the sample was rejected (no monitored joint, non-finite, outside the
    prediction history); rejections are counted by reason."""

    def __init__(self, joint_names: Sequence[str], window: float,
                 warn_threshold: float | Sequence[float], history: int = 256):
        if len(joint_names) != 3:
            raise ValueError('joint_names: need the 3 measured joints (theta2..theta4)')
        self.joint_names = tuple(joint_names)
        self.monitor = ResidualMonitor(self.joint_names, window, warn_threshold)
        self.history = PredictionHistory(history)
        self.rejections: dict[str, int] = {}
        self._args = (window, warn_threshold, history)
        self._base_ns: int | None = None

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

    def measured_ns(self, stamp_ns: int, positions: Mapping[str, float]
                    ) -> tuple[list[str], np.ndarray]:
        """:meth:`measured` with a stamp in ns."""
        if self._base_ns is None:
            raise self._reject('outside_prediction', 'no prediction yet')
        return self.measured(self._seconds(stamp_ns), positions)

    def measured_message_ns(self, stamp_ns: int, names: Sequence[str],
                            positions: Sequence[float]) -> tuple[list[str], np.ndarray]:
        """A JointState's names and positions (equal lengths, else rejected as
        'malformed'), see :meth:`measured_ns`."""
        if len(names) != len(positions):
            raise self._reject('malformed', f'{len(names)} names but {len(positions)} '
                               'positions')
        return self.measured_ns(stamp_ns, dict(zip(names, positions)))

    def status_ns(self, now_ns: int | None) -> CheckStatus:
        return self.status(None if now_ns is None or self._base_ns is None
                           else self._seconds(now_ns))

    def restart(self) -> None:
        """Forget predictions, residuals and the time base (counters of rejections stay)."""
        window, thr, history = self._args
        self.monitor = ResidualMonitor(self.joint_names, window, thr)
        self.history = PredictionHistory(history)
        self._base_ns = None

    def predicted(self, t: float, theta: Sequence[float]) -> None:
        self.history.push(t, theta)

    def _reject(self, reason: str, detail: str) -> ValueError:
        self.rejections[reason] = self.rejections.get(reason, 0) + 1
        return ValueError(detail)

    def measured(self, t: float, positions: Mapping[str, float]
                 ) -> tuple[list[str], np.ndarray]:
        meas = np.full(3, np.nan)
        for j, name in enumerate(self.joint_names):
            if name in positions:
                meas[j] = float(positions[name])
        present = [j for j, n in enumerate(self.joint_names) if n in positions]
        if not present:
            raise self._reject('no_monitored_joint', 'measured joint state names none of '
                               f'{", ".join(self.joint_names)}')
        if not np.all(np.isfinite(meas[present])) or not math.isfinite(t):
            raise self._reject('non_finite', 'measured joint state holds a non-finite value')
        pred = self.history.at(t)
        if pred is None:
            sp = self.history.span()
            where = 'no prediction yet' if sp is None else \
                f'prediction covers {sp[0]:.6f} .. {sp[1]:.6f} s'
            raise self._reject('outside_prediction', f'measurement at {t:.6f} s: {where}')
        if t < self.monitor.last_t:
            raise self._reject('out_of_order', f'measurement at {t:.6f} s is older than the '
                               'previous one')
        r = self.monitor.update(t, meas, pred)
        return [self.joint_names[j] for j in present], r[present]

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
                   if math.isfinite(v) and v > thr]
            msg = 'model does not match the drive: residual RMS ' + ', '.join(bad)
        else:
            msg = 'model matches the drive'
        return CheckStatus(level, msg, values)
