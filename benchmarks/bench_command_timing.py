# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Offline: what command timing does to ``~/feedforward`` and the prediction (no DDS).

A servo computes theta1_ref on its own regular 1 kHz grid (``j ms + phase``), not
phase-locked to the node's 1 kHz tick, and each command reaches the node's callback after
a delay (DDS + executor latency) uniform in [0, J].  When the delay carries commands across
a tick, some ticks get 0 commands and the next 2.  The reference is a constant-rate worm
ramp from rest at t = 0.  Every row runs the node's own pipeline,
:class:`worm_gear_sim.realtime.RealtimePredictor` of the default configuration:

* ``regular``: samples exactly at the ticks (a phase-locked servo): the reference;
* ``before``: the node before the timing change: the latest command, new or not, is a
  sample at every tick;
* ``tick`` (``node.command_timing: tick``, the default on the wall clock): the newest
  command since the previous tick is a sample at the tick; a tick without one adds none;
* ``reception``: each command a sample at its reception time (``node.command_timing:
  reception``; what ``use_sim_time`` does with the /clock reading);
* ``stream``: reception times smoothed onto the stream's steady rate (``node.command_timing:
  stream``);
* ``stamped``: the stamped path (``worm_angle_reference``): each command carries its grid
  time (epoch ROS time) and is pushed when received.

Per row: ticks with 0/1/2+ commands; RMS and max of (published correction - the
regular correction of the ramp) and the largest change of the published correction
between ticks (stamped: between samples), over the constant-rate part (after 0.1 s); the
RMS of the predicted antenna angle theta4 against a run driven by the exact ramp, at the
prediction stamps (the prediction's timing); for ``stamped`` the largest deviation of its
corrections from the offline twin (the same pairs in stamp order, no clock).

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
from worm_gear_sim.realtime import RealtimePredictor

TICK_NS = 1_000_000
EPOCH = 1_700_000_000_000_000_000      # stamps of the stamped path: ROS time of 2023


def stream(rate: float, duration: float, phase_ms: float, delay_us: float,
           seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The servo's commands: grid times [ns] (its 1 kHz slots), reception times [ns]
    (sorted; the grid plus a delay uniform in [0, delay_us]) and values (the ramp at
    the grid time), in reception order."""
    rng = np.random.default_rng(seed)
    grid_ns = np.round((np.arange(int(duration * 1e3)) + phase_ms) * 1e6).astype(np.int64)
    recv_ns = grid_ns + np.round(rng.uniform(0.0, delay_us * 1e3, grid_ns.size)
                                 ).astype(np.int64)
    order = np.argsort(recv_ns, kind='stable')
    return grid_ns[order], recv_ns[order], rate * grid_ns[order] * 1e-9


def run_float64(cfg: Config, recv_ns: np.ndarray, values: np.ndarray, n_ticks: int,
                scheme: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The node's Float64 path through the core pipeline (``push_command`` + ``tick`` at
    k ms; tick 0 starts at rest at 0): ``scheme`` a ``node.command_timing``, or 'before'
    (the node before the timing change: the latest command, fresh or not, a sample at
    every tick).  Returns the correction published at each tick (the newest), the
    commands per tick, and theta4 of the prediction at each tick."""
    timing = 'tick' if scheme == 'before' else scheme
    p = RealtimePredictor(cfg.replace({'node.command_timing': timing}))
    p.push_command(0, 0.0)
    p.tick(0)
    ff, counts, th4 = np.zeros(n_ticks), np.zeros(n_ticks, int), np.zeros(n_ticks)
    i = 0
    latest = 0.0
    for k in range(1, n_ticks):
        tick = k * TICK_NS
        n0 = i
        while i < recv_ns.size and recv_ns[i] <= tick:
            if scheme != 'before':
                p.push_command(int(recv_ns[i]), float(values[i]))
            latest = float(values[i])
            i += 1
        if scheme == 'before':
            p.push_command(tick, latest)
        counts[k] = i - n0
        out = p.tick(tick)
        ff[k] = p.last_delta
        th4[k] = out.predictions[-1].theta[2]
    return ff, counts, th4


def run_stamped(cfg: Config, grid_ns: np.ndarray, recv_ns: np.ndarray,
                values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The stamped path: each command pushed on reception with its grid time as the
    stamp (epoch ROS time).  Returns stamps, corrections, theta4 of the predictions (at
    the stamps) and the number of rejected samples."""
    p = RealtimePredictor(cfg)
    p.push(EPOCH, 0.0, now_ns=EPOCH)                 # at rest at the servo's t = 0
    st, d, th4 = [], [], {}
    for g, r, v in zip(grid_ns, recv_ns, values):
        out = p.push(EPOCH + int(g), float(v), now_ns=EPOCH + int(r))
        for c in out.corrections:
            st.append(c.stamp_ns - EPOCH)
            d.append(c.delta)
        th4.update({q.stamp_ns - EPOCH: q.theta[2] for q in out.predictions})
    stamps = np.array(st)
    return stamps, np.array(d), np.array([th4[s] for s in st]), p.counters['rejected_samples']


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
    rate = args.rate
    # phase-locked samples at the ticks: the reference correction of the ramp (constant
    # once the filter has started up: the comparison holds for any phase of the grid)
    reg = RealtimePredictor(cfg, simulate=False)
    d_reg = np.array([reg.push(EPOCH + k * TICK_NS, rate * k * 1e-3).corrections[0].delta
                      for k in range(n_ticks)])
    steady_from = 0.1                       # s: the stream clock has acquired
    ff_steady = float(np.mean(d_reg[int(steady_from * 1e3):]))
    t_exact = np.arange(n_ticks + 2) * 1e-3
    exact = simulate(cfg, SampledProfile(t_exact, rate * t_exact), t_end=t_exact[-1])

    print(f'{rate:g} rad/s worm ramp, 1 kHz ticks, 1 kHz servo grid at a phase after the '
          f'tick, received after a delay uniform in [0, J], {args.duration:g} s; regular '
          f'correction {ff_steady * 1e6:.3f} urad')
    print(f'{"phase":>5s} {"J":>5s} {"samples":13s} {"per tick":>10s} {"ff RMS dev":>11s} '
          f'{"ff max dev":>11s} {"max |dff|":>10s} {"theta4 RMS":>11s} {"vs offline":>10s}')
    print(f'{"[ms]":>5s} {"[us]":>5s} {"":13s} {"0/1/2+":>10s} {"[urad]":>11s} '
          f'{"[urad]":>11s} {"[urad]":>10s} {"dev [urad]":>11s} {"max [rad]":>10s}')

    def row(phase: str, delay: str, name: str, t: np.ndarray, ff: np.ndarray,
            th4: np.ndarray, hist: str, twin: str = '-') -> None:
        steady = t >= steady_from
        dev = ff[steady] - ff_steady
        dff = np.abs(np.diff(ff[steady]))
        e4 = th4[steady] - np.interp(t[steady], exact.t, exact.theta4)
        print(f'{phase:>5s} {delay:>5s} {name:13s} {hist:>10s} '
              f'{math.sqrt(np.mean(dev ** 2)) * 1e6:11.3f} {np.max(np.abs(dev)) * 1e6:11.3f} '
              f'{np.max(dff) * 1e6:10.3f} {math.sqrt(np.mean(e4 ** 2)) * 1e6:11.4f} '
              f'{twin:>10s}')

    t_tick = np.arange(n_ticks) * 1e-3
    row('-', '-', 'regular', t_tick, d_reg, np.interp(t_tick, exact.t, exact.theta4),
        f'0/{n_ticks - 1}/0')
    for phase in args.phases_ms:
        for d in args.delays_us:
            grid, recv, vals = stream(rate, args.duration, phase, d, args.seed)
            for scheme in ('before', 'tick', 'reception', 'stream'):
                ff, counts, th4 = run_float64(cfg, recv, vals, n_ticks, scheme)
                c = counts[1:]
                hist = f'{np.sum(c == 0)}/{np.sum(c == 1)}/{np.sum(c >= 2)}'
                row(f'{phase:g}', f'{d:g}', scheme, t_tick, ff, th4, hist)
            stamps, dl, th4s, rejected = run_stamped(cfg, grid, recv, vals)
            # the offline twin: the same (stamp, value) pairs in stamp order, no clock
            twin = RealtimePredictor(cfg, simulate=False)
            ref = {c.stamp_ns - EPOCH: c.delta for g, v in
                   zip([0, *np.sort(grid)], [0.0, *np.sort(vals)])
                   for c in twin.push(EPOCH + int(g), float(v)).corrections}
            worst = max(abs(x - ref[s]) for s, x in zip(stamps.tolist(), dl))
            row(f'{phase:g}', f'{d:g}', 'stamped', stamps * 1e-9, dl, th4s,
                f'rej {rejected}', f'{worst:.1e}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
