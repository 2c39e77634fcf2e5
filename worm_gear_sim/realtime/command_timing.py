# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Sample times for an unstamped command stream (pure core, no rclpy).

``std_msgs/Float64`` commands carry no time: :class:`CommandQueue` keeps the accepted
commands with their reception stamps until the pipeline's next tick, and
:class:`StreamClock` recovers the time grid of a steady stream from its reception stamps
(an alpha-beta tracker).  :class:`worm_gear_sim.realtime.RealtimePredictor` uses both for
its Float64 path (``push_command`` / ``tick``); they moved here from the node.
"""

from __future__ import annotations

import collections

__all__ = ['CommandQueue', 'StreamClock', 'COMMAND_QUEUE_LENGTH', 'STREAM_GAIN',
           'STREAM_WINDOW', 'STREAM_OUTLIER_RATE']

COMMAND_QUEUE_LENGTH = 16  # accepted commands kept between two ticks (the oldest dropped)
STREAM_GAIN = 0.02  # steady alpha of the stream clock (a memory of about 50 samples)
STREAM_WINDOW = 0.35  # periods: a stamp further from its grid slot is an outlier
STREAM_OUTLIER_RATE = 0.3  # re-lock when the outlier rate (1/8 smoothing) exceeds this


class StreamClock:
    """The time grid of a steady command stream, recovered from its reception stamps.

    A servo computes its commands on a regular grid; they reach the node's callback after
    a varying delay (DDS and executor latency: p10 ~100 us, p90 ~280 us on the
    development VM), which would reach the feed-forward as time jitter of the samples.  An
    alpha-beta tracker follows the grid's phase and period: each stamp is assigned the
    nearest grid slot after the previous sample (missed commands skip slots) and its
    deviation from the slot corrects phase and period, with least-squares gains while it
    acquires (exact for the first two stamps), then ``gain`` (critically damped).  A
    stamp further than ``window`` periods from its slot is an outlier and does not
    correct the tracker: a late one (a delayed callback) is placed on its slot, an early
    one (commands that queued up behind a stall, or a faster stream) on the previous
    sample's time, so that it replaces that sample's value (CommandQueue and Compensator
    merge equal times).  An outlier rate above ``max_outlier_rate`` (exponentially
    smoothed over ~8 stamps: three outliers in a row, or a new rate or phase) or a pause
    longer than ``max_period_ns`` re-lock: the stamp is taken as it is,
    with its interval as the period guess (if shorter than ``max_period_ns``).  The output
    never decreases while tracking and lags the grid by the mean delay (a constant); a
    stream at an integer fraction of the rate keeps the period (it skips slots).
    """

    def __init__(self, period_ns: float, gain: float = STREAM_GAIN,
                 window: float = STREAM_WINDOW, max_outlier_rate: float = STREAM_OUTLIER_RATE,
                 max_period_ns: float = 5e7) -> None:
        if not (0.0 < gain <= 1.0 and 0.0 < window < 0.5 and period_ns > 0.0
                and 0.0 < max_outlier_rate < 1.0):
            raise ValueError('StreamClock: need period_ns > 0, 0 < gain <= 1, '
                             '0 < window < 0.5, 0 < max_outlier_rate < 1')
        self.gain, self.window = float(gain), float(window)
        self.max_outlier_rate = float(max_outlier_rate)
        self.beta = gain * gain / (2.0 - gain)
        self.period0, self.max_period = float(period_ns), float(max_period_ns)
        self.relocks = 0
        self.outliers = 0                     # outliers placed on their slot, in all
        self.reset()

    def reset(self) -> None:
        self.period = self.period0            # estimated stream period [ns]
        self._t: float | None = None          # last output [ns]
        self._raw: int | None = None          # last reception stamp [ns]
        self._k = 0                           # stamps since the last (re)lock
        self._rate = 0.0                      # smoothed outlier rate

    def __call__(self, ns: int) -> int:
        """The sample time [ns] for a command received at ``ns``."""
        prev, self._raw = self._raw, ns
        t = self._t
        if t is not None and ns - t <= self.max_period:
            m = max(1, round((ns - t) / self.period))        # grid slots since the last
            pred = t + m * self.period
            e = ns - pred
            if abs(e) <= self.window * self.period:
                self._rate *= 0.875
                self._k += 1
                k = self._k
                self._t = pred + max(2.0 * (2 * k - 1) / (k * (k + 1)), self.gain) * e
                self.period += max(6.0 / (k * (k + 1)), self.beta) * e / m
                return int(round(self._t))
            self._rate += 0.125 * (1.0 - self._rate)
            if self._rate <= self.max_outlier_rate:
                self.outliers += 1
                # late (a delayed callback): on its slot; early (a stalled stream catching
                # up, a faster one): on the previous sample's time, whose value it replaces
                # (CommandQueue / Compensator merge)
                self._t = pred if e > 0.0 else t
                return int(round(self._t))
        if t is not None:
            self.relocks += 1
        if prev is not None and 0 < ns - prev <= self.max_period:
            self.period = float(ns - prev)
        self._t = float(ns)
        self._k = 1
        self._rate = 0.0
        return ns


class CommandQueue:
    """Accepted commands with their reception stamps, waiting for the next tick.

    ``push`` is O(1); at most ``maxlen`` samples are kept (on overflow the OLDEST is
    dropped and counted in :attr:`dropped`).  :meth:`take` turns them into the samples of
    one tick: times (ns on the node's time base) strictly increasing in (last tick, tick].
    """

    def __init__(self, maxlen: int = COMMAND_QUEUE_LENGTH) -> None:
        self._q: collections.deque = collections.deque(maxlen=maxlen)
        self.dropped = 0          # lost to overflow
        self.merged = 0           # stamp not after the previous sample: value replaced it
        self.restamped = 0        # stamp not after the previous tick: placed later

    def __len__(self) -> int:
        return len(self._q)

    def push(self, base: str, ns: int, value: float) -> None:
        if len(self._q) == self._q.maxlen:
            self.dropped += 1
        self._q.append((base, ns, value))

    def clear(self) -> int:
        """Forget the queued samples; returns how many there were."""
        n = len(self._q)
        self._q.clear()
        return n

    def take(self, base: str, last_ns: int, tick_ns: int, restamp: bool = True
             ) -> list[tuple[int, float]]:
        """The samples of the tick at ``tick_ns`` (previous tick at ``last_ns``):
        ``[(ns, value)]`` in reception order with strictly increasing times.

        * a stamp after the tick stays queued for a later tick, and so does every sample
          received after it;
        * a stamp not after the previous sample's is merged with it (same time, newest
          value): never a zero or negative time step;
        * ``restamp`` (``use_sim_time``): a stamp not after the previous tick (received
          after that tick but before /clock moved on, or a stamp on another time base)
          cannot act in the past: the sample takes the next time the node knows, that of
          the next sample (which supersedes it) or, if none follows, the tick.  Without
          ``restamp`` such a stamp is kept (smoothed stream times; the caller clamps what
          the simulator has already integrated).
        """
        out: list[tuple[int, float]] = []
        late: float | None = None
        q = self._q
        while q:
            b, ns, v = q[0]
            if b != base:
                ns = last_ns
            elif ns > tick_ns:
                break
            q.popleft()
            if out:
                if ns <= out[-1][0]:
                    out[-1] = (out[-1][0], v)
                    self.merged += 1
                else:
                    out.append((ns, v))
            elif restamp and ns <= last_ns:
                self.restamped += 1
                if late is not None:
                    self.merged += 1
                late = v
            else:
                if late is not None:
                    self.merged += 1
                    late = None
                out.append((ns, v))
        if late is not None:
            out.append((tick_ns, late))
        return out
