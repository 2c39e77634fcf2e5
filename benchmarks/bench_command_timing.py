# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Offline: what command timing does to ``~/feedforward`` and the prediction (no DDS).

A servo computes theta1_ref on its own regular 1 kHz grid (``j ms + phase``), not
phase-locked to the node's 1 kHz tick, and each command reaches the node's callback after
a delay (DDS + executor latency) uniform in [0, J].  When the delay carries commands across
a tick, some ticks get 0 commands and the next 2.  The reference is a constant-rate worm
ramp from rest at t = 0.  Each way of turning the stream into samples runs through the
node's own code (:class:`worm_gear_sim.ros.node.CommandQueue`, :class:`StreamClock`) and a
:class:`Compensator` of the default configuration:

* ``regular``: samples exactly at the ticks (a phase-locked servo): the reference;
* ``before``: the node before the change: the latest command, new or not, is a sample at
  every tick;
* ``tick`` (``node.command_timing: tick``, the default on the wall clock): the newest
  command since the previous tick is a sample at the tick; a tick without one adds none;
* ``reception``: each command a sample at its reception time (``node.command_timing:
  reception``; what ``use_sim_time`` does with the /clock reading);
* ``stream``: reception times smoothed onto the stream's steady rate (``node.command_timing:
  stream``).

Per row: ticks with 0/1/2+ commands; RMS and max of (published correction - regular
correction at the same tick) and the largest tick-to-tick change of the published
correction, over the constant-rate part (after 0.1 s); the RMS of the simulated antenna
angle theta4 against a run driven by the exact ramp (the prediction's timing).

Measured on the development VM (cross-process Float64 at 1 kHz, EventsExecutor, a 130 us
tick beside it): callback latency p10 106 us, p50 161 us, p90 278 us, p99 392 us, i.e. a J
of about 300 us; in the running node the tick (0.3-0.5 ms with its publishing) delays the
callbacks of the commands that arrive meanwhile, so the real delays are worse than this
uniform model (see ``bench_node.py --feedforward`` for the live figures).

    python benchmarks/bench_command_timing.py
    python benchmarks/bench_command_timing.py --rate 2.0 --phases-ms 0.4 0.9 --delays-us 0 300
"""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np

from worm_gear_sim import Config, SampledProfile, simulate
from worm_gear_sim.compensation import Compensator
from worm_gear_sim.ros.node import CommandQueue, StreamClock

TICK_NS = 1_000_000
Ticks = list[list[tuple[int, float]]]


def stream(rate: float, duration: float, phase_ms: float, delay_us: float,
           seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Reception times [ns] (sorted) and values of the servo's commands: the ramp on the
    servo's grid, received after a delay uniform in [0, delay_us]."""
    rng = np.random.default_rng(seed)
    grid = (np.arange(int(duration * 1e3)) + phase_ms) * 1e-3
    recv = grid + rng.uniform(0.0, delay_us * 1e-6, grid.size)
    recv_ns = np.round(recv * 1e9).astype(np.int64)
    order = np.argsort(recv_ns, kind='stable')
    return recv_ns[order], rate * grid[order]


def per_tick_samples(recv_ns: np.ndarray, values: np.ndarray, n_ticks: int,
                     scheme: str) -> Ticks:
    """The samples each tick k (at k ms; tick 0 starts at rest at 0) feeds, as the node
    does on the wall clock: ``scheme`` 'before' (the node before the change: the latest
    command, fresh or not, is a sample at every tick) or a ``node.command_timing``."""
    q = CommandQueue()
    clock = StreamClock(TICK_NS)
    out: Ticks = [[(0, 0.0)]]
    i = 0
    latest = 0.0
    last = 0
    for k in range(1, n_ticks):
        tick = k * TICK_NS
        while i < recv_ns.size and recv_ns[i] <= tick:
            ns = int(recv_ns[i])
            if scheme == 'stream':
                ns = clock(ns)
            elif scheme == 'tick':          # as the node: restamped to the next tick
                ns = last
            q.push('wall', ns, float(values[i]))
            latest = float(values[i])
            i += 1
        if scheme == 'before':
            q.clear()
            out.append([(tick, latest)])
        else:
            out.append(q.take('wall', last, tick, restamp=scheme == 'tick'))
        last = tick
    return out


def feedforward(cfg: Config, ticks: Ticks) -> np.ndarray:
    """The correction published at each tick (that of its last sample)."""
    comp = Compensator(cfg)
    comp.reset(0.0, 0.0)
    out = np.empty(len(ticks))
    d = 0.0
    t_last = 0.0
    for k, samples in enumerate(ticks):
        for ns, v in samples:
            t_last = max(ns * 1e-9, t_last)   # as the node: never back in time
            d = comp.update(t_last, v)
        out[k] = d
    return out


def drive_profile(ticks: Ticks) -> SampledProfile:
    """theta1 as the node applies it (linear): the samples plus a hold at every tick."""
    times, vals = [0.0], [0.0]
    for k, samples in enumerate(ticks[1:], start=1):
        for ns, v in samples:      # as the node: not before the previous tick (integrated)
            ns = max(ns, (k - 1) * TICK_NS + 1)
            if ns * 1e-9 > times[-1]:
                times.append(ns * 1e-9)
                vals.append(v)
            else:
                vals[-1] = v
        if k * 1e-3 > times[-1]:
            times.append(k * 1e-3)
            vals.append(vals[-1])
    return SampledProfile(np.array(times), np.array(vals))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--rate', type=float, default=2.0, help='worm ramp rate [rad/s] (2)')
    ap.add_argument('--duration', type=float, default=1.0, help='stream length [s] (1)')
    ap.add_argument('--phases-ms', type=float, nargs='*', default=[0.4, 0.9],
                    help='phases of the servo grid after the tick [ms] (0.4 0.9)')
    ap.add_argument('--delays-us', type=float, nargs='*', default=[0.0, 50.0, 300.0],
                    help='reception delays J, uniform in [0, J] [us] (0 50 300)')
    ap.add_argument('--seed', type=int, default=1)
    args = ap.parse_args(argv)

    cfg = Config()
    n_ticks = int(args.duration * 1e3)
    t_tick = np.arange(n_ticks) * 1e-3
    regular: Ticks = [[(0, 0.0)]] + [[(k * TICK_NS, args.rate * k * 1e-3)]
                                     for k in range(1, n_ticks)]
    d_reg = feedforward(cfg, regular)
    steady = t_tick >= 0.1                  # the stream clock has acquired
    exact = simulate(cfg, SampledProfile(t_tick, args.rate * t_tick), t_end=t_tick[-1],
                     record_every=100)
    steady_sim = exact.t >= 0.1

    print(f'{args.rate:g} rad/s worm ramp, 1 kHz ticks, 1 kHz servo grid at a phase after '
          f'the tick, received after a delay uniform in [0, J], {args.duration:g} s; '
          f'regular correction {np.mean(d_reg[steady]) * 1e6:.3f} urad')
    print(f'{"phase":>5s} {"J":>5s} {"samples":13s} {"per tick":>10s} {"ff RMS dev":>11s} '
          f'{"ff max dev":>11s} {"max |dff|":>10s} {"theta4 RMS":>11s}')
    print(f'{"[ms]":>5s} {"[us]":>5s} {"":13s} {"0/1/2+":>10s} {"[urad]":>11s} '
          f'{"[urad]":>11s} {"[urad]":>10s} {"dev [urad]":>11s}')

    def row(phase: str, delay: str, name: str, ticks: Ticks, arrivals: Ticks) -> None:
        counts = np.array([len(s) for s in arrivals[1:]])
        hist = '/'.join(str(int(np.sum(counts == c))) for c in (0, 1)) + \
            f'/{int(np.sum(counts >= 2))}'
        ff = feedforward(cfg, ticks)
        dev = (ff - d_reg)[steady]
        dff = np.abs(np.diff(ff))[steady[1:]]
        traj = simulate(cfg, drive_profile(ticks), t_end=t_tick[-1], record_every=100)
        th4 = (traj.theta4 - exact.theta4)[steady_sim]
        print(f'{phase:>5s} {delay:>5s} {name:13s} {hist:>10s} '
              f'{math.sqrt(np.mean(dev ** 2)) * 1e6:11.3f} {np.max(np.abs(dev)) * 1e6:11.3f} '
              f'{np.max(dff) * 1e6:10.3f} {math.sqrt(np.mean(th4 ** 2)) * 1e6:11.4f}')

    row('-', '-', 'regular', regular, regular)
    for phase in args.phases_ms:
        for d in args.delays_us:
            recv, vals = stream(args.rate, args.duration, phase, d, args.seed)
            arrivals = per_tick_samples(recv, vals, n_ticks, 'reception')
            for scheme in ('before', 'tick', 'reception', 'stream'):
                ticks = arrivals if scheme == 'reception' else \
                    per_tick_samples(recv, vals, n_ticks, scheme)
                row(f'{phase:g}', f'{d:g}', scheme, ticks, arrivals)
    return 0


if __name__ == '__main__':
    sys.exit(main())
