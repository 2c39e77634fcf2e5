# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Per-sample cost of the real-time pipeline (no ROS): the compensator update, compiled
against the former Python implementation side by side, and the whole
``RealtimePredictor.push`` per stamped sample, with its parts.

The stream is a 1 kHz stamped worm slew at 2 rad/s with reversals (epoch stamps, +-0.2 ms
jitter), the default configuration plus a 5 N m antenna load.  Each figure is the minimum
over ``--repeats`` runs of ``--samples`` samples (other jobs on a shared machine only add
time); the load average is printed because absolute figures depend on it.

* ``compensator``: ``Compensator.update`` (compiled: history in arrays, one numba kernel
  for the interpolation walk, the quadrature and the model inverse) against
  ``PythonCompensator`` below, the implementation before (history in lists, ``np.interp``
  and a matrix-vector product, the inverse in Python calling the compiled friction and
  compliance functions); both on the same stream, their corrections compared; and the
  compiled update on a drive with 2 arcmin of play and the backlash inverse (two more
  weight rows, the flank decision) against the same without play, side by side;
* ``push``: ``RealtimePredictor.push`` per sample: validation, the compensator, 1 ms of
  physics (100 Newmark steps), one Correction and one Prediction (with shaft torques),
  for the plain, preview and compensation-applied settings; and its parts: the simulator's
  ``advance_to`` for 1 ms alone and ``push`` with ``simulate=False`` (what
  ``feedforward_series`` runs);
* ``parameter change``: ``prepare`` + ``reconfigure`` of a running pipeline with a new
  (already proven) parameter set, what the node does off and on its executor after a
  parameter update: one ``DriveModel`` shared by the simulator's trial, the compensator's
  design and the swap.
* ``stale hold``: a pause of the stream (30 samples in time, then ``hold`` 2 ms past G:
  the stream goes stale and is saved for a retraction) and the late sample that retracts
  it, per call against a push in time (medians of ``--cycles``, thread CPU time: what the
  call costs this process whatever else runs), corrections only and with the physics.
  Public calls only: ``PYTHONPATH=<another tree> python benchmarks/bench_realtime.py``
  times that tree's pipeline.

    python benchmarks/bench_realtime.py
    python benchmarks/bench_realtime.py --samples 5000 --repeats 9 --cycles 500
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import time

import numpy as np

from worm_gear_sim import Config
from worm_gear_sim.compensation.streaming import Compensator
from worm_gear_sim.dynamics.equations import friction_coefficient, mesh_compliance
from worm_gear_sim.dynamics.simulation import Simulator
from worm_gear_sim.realtime import RealtimePredictor

EPOCH = 1_700_000_000_000_000_000
LOAD = {'load.output_torque': 5.0, 'load.output_viscous_coefficient': 2.0}


class PythonCompensator:
    """The per-sample update as it was before it was compiled (for the comparison only):
    the same design (taken from a Compensator), Python lists and numpy calls per sample."""

    def __init__(self, comp: Compensator) -> None:
        self.c = comp
        model = comp.model
        cfg, d = model.config, model.derived
        self.p, self.ratio, self.out_per_in = model.p, d.ratio, model.output_per_input
        # the quantities of the inverse by name (the values the packed vector holds)
        self.Kw, self.Kg, self.J4, self.Jg = d.K_w, d.K_g, d.J_4, d.J_g
        self.cout, self.Tload = cfg.load.output_viscous_coefficient, cfg.load.output_torque
        self.rw, self.rg, self.lw = cfg.geometry.worm_pitch_radius, \
            cfg.geometry.gear_pitch_radius, d.l_w
        self.sl, self.cl = math.sin(d.lead_angle), math.cos(d.lead_angle)
        self.cphi = math.cos(cfg.geometry.pressure_angle)

    def reset(self, x: float, t: float) -> None:
        self.ht, self.hx = [t], [x]

    def update(self, t: float, x: float) -> float:
        ht, hx, c = self.ht, self.hx, self.c
        if t == ht[-1]:
            hx[-1] = x
        else:
            ht.append(t)
            hx.append(x)
        t_old = t - c.filter.lag_span - c.preview
        while len(ht) > 2 and ht[1] <= t_old:
            del ht[0]
            del hx[0]
        te = t - c.preview
        ref = float(np.interp(te, ht, hx))
        r = c._W @ np.interp(te - c._tau, ht, hx)
        k = self.out_per_in
        return self.theta1(r[0] * k, r[1] * k, r[2] * k) - ref

    def theta1(self, y0: float, y1: float, y2: float) -> float:
        p = self.p
        Kg, J4, Jg, cout, Tload = self.Kg, self.J4, self.Jg, self.cout, self.Tload
        rw, rg, lw, sl, cl = self.rw, self.rg, self.lw, self.sl, self.cl
        Ts = J4 * y2 + cout * y1 + Tload
        th3 = y0 + Ts / Kg
        th3_1 = y1 + cout * y2 / Kg
        Tm = (Jg + J4) * y2 + cout * y1 + Tload
        v_s = rw * cl * th3_1 * self.ratio + rg * sl * th3_1
        mu, _ = friction_coefficient(p, v_s, Tm)
        A = self.cphi * sl + mu * cl
        B = self.cphi * cl - mu * sl
        Wn = Tm / (rg * B)
        kgws = mesh_compliance(p, th3 * self.ratio, th3, mu)[0]
        th2 = (Wn * kgws / cl + rg * th3) / lw
        return th2 + rw * A * Wn / self.Kw


def slew(n: int, seed: int = 1) -> tuple[list[int], list[float]]:
    rng = np.random.default_rng(seed)
    st = EPOCH + np.arange(n, dtype=np.int64) * 1_000_000 + rng.integers(-200_000, 200_001, n)
    t = (st - EPOCH) * 1e-9
    tri = 2.0 * (0.25 - np.abs((t % 0.5) - 0.25))       # 2 rad/s, reversal every 250 ms
    return st.tolist(), tri.tolist()


def best(fn, repeats: int) -> float:
    out = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        out = min(out, time.perf_counter() - t0)
    return out


def streaming(comp, t: list[float], x: list[float]):
    """A run: reset ``comp`` and stream the samples through ``update``."""
    def run():
        comp.reset(x[0], t[0])
        for a, b in zip(t, x):
            comp.update(a, b)
    return run


def interleaved(fa, fb, repeats: int) -> tuple[float, float]:
    """Minimum times of two runs taken in turn, so that both see the same load."""
    ta, tb = math.inf, math.inf
    for _ in range(repeats):
        ta = min(ta, best(fa, 1))
        tb = min(tb, best(fb, 1))
    return ta, tb


def stale_hold(cfg: Config, simulate: bool, cycles: int) -> tuple[float, float, float]:
    """Medians [us, thread CPU time] of a push in time, a stale hold and the retracting push
    (module docstring) over ``cycles`` pauses of a 1 kHz stamped triangle."""
    ms = 1_000_000
    p = RealtimePredictor(cfg, simulate=simulate, stale_margin=0.0)
    clock = time.thread_time_ns
    k = 0
    t_in, t_hold, t_retract = [], [], []

    def push(now: int | None = None) -> float:
        nonlocal k
        s = EPOCH + k * ms
        x = 2.0 * (0.25 - abs(((k * 1e-3) % 0.5) - 0.25))
        k += 1
        t0 = clock()
        o = p.push(s, x, now_ns=s if now is None else now)
        t1 = clock()
        assert o.accepted
        return (t1 - t0) * 1e-3

    for _ in range(200):
        push()
    for _ in range(cycles):
        t_in += [push() for _ in range(30)]
        now = EPOCH + (k - 1) * ms + p.stale_after_ns + 2 * ms
        t0 = clock()
        p.hold(now)
        t_hold.append((clock() - t0) * 1e-3)
        assert p.stale
        t_retract.append(push(now))
        assert not p.stale
    assert p.counters['stale_retractions'] == cycles
    return statistics.median(t_in), statistics.median(t_hold), statistics.median(t_retract)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--samples', type=int, default=2000)
    ap.add_argument('--repeats', type=int, default=7)
    ap.add_argument('--cycles', type=int, default=200, help='pauses of the stale hold case')
    args = ap.parse_args(argv)
    n, rep = args.samples, args.repeats
    cfg = Config().replace(LOAD)
    st, x = slew(n)
    t = [(s - st[0]) * 1e-9 for s in st]
    print(f'load average {os.getloadavg()[0]:.2f} (1 min), {os.cpu_count()} cores; '
          f'{n} samples, min of {rep} runs')

    comp = Compensator(cfg)
    old = PythonCompensator(comp)
    comp.reset(x[0], t[0])
    d_new = [comp.update(a, b) for a, b in zip(t, x)]
    old.reset(x[0], t[0])
    d_old = [old.update(a, b) for a, b in zip(t, x)]
    diff = max(abs(a - b) for a, b in zip(d_new, d_old))

    run_new, run_old = streaming(comp, t, x), streaming(old, t, x)
    t_old, t_new = interleaved(run_old, run_new, rep)
    print(f'compensator update: Python {t_old / n * 1e6:.2f} us, compiled '
          f'{t_new / n * 1e6:.2f} us per sample: {t_old / t_new:.1f}x faster; '
          f'largest difference of the corrections {diff:.1e} rad')

    played = Compensator(cfg.replace({'mesh.backlash': 2 * math.pi / 180 / 60}))
    t_none, t_play = interleaved(run_new, streaming(played, t, x), rep)
    print(f'compensator update with 2 arcmin of play and the backlash inverse: '
          f'{t_play / n * 1e6:.2f} us per sample, {t_play / t_none:.2f}x the update without '
          f'play ({t_none / n * 1e6:.2f} us)')

    sim = Simulator(cfg, theta1=x[0])

    def run_sim():
        sim.reset(x[0], 0.0)
        for a, b in zip(t, x):
            sim.advance_to(a, b)

    t_sim = best(run_sim, rep)
    steps = round(1e-3 / cfg.integrator.time_step)
    print(f'simulator advance_to, 1 ms ({steps} steps) alone: {t_sim / n * 1e6:.1f} us')

    cases = [('push, corrections only (simulate=False)', cfg, dict(simulate=False)),
             ('push (P = 0)', cfg, {}),
             ('push (P = 2 ms)', cfg.replace({'compensation.preview_time': 0.002}), {}),
             ('push (P = 0, compensation applied)', cfg, dict(apply_compensation=True))]
    for name, c, kw in cases:
        def run(c=c, kw=kw):
            p = RealtimePredictor(c, **kw)
            for s, v in zip(st, x):
                p.push(s, v, now_ns=s)
        t_p = best(run, rep)
        print(f'{name:40s} {t_p / n * 1e6:7.1f} us per sample')

    for simulate in (False, True):
        t_in, t_hold, t_retract = stale_hold(cfg, simulate, args.cycles)
        print(f'stale hold ({"with physics" if simulate else "corrections only"}): push in time '
              f'{t_in:.1f} us, stale hold {t_hold:.1f} us ({t_hold / t_in:.2f}x), retracting '
              f'push {t_retract:.1f} us ({t_retract / t_in:.2f}x); medians of {args.cycles}')

    rt = RealtimePredictor(cfg)
    changes = [cfg.replace({'load.output_torque': 5.0 + 0.01 * (i + 1)}) for i in range(50)]
    t_change = []
    for c in changes:                   # proven sets: check_usable is a look-up here
        t0 = time.perf_counter()
        rt.reconfigure(rt.prepare(c))
        t_change.append(time.perf_counter() - t0)
    print(f'{"parameter change (prepare + reconfigure)":40s} '
          f'{statistics.median(t_change[5:]) * 1e3:7.2f} ms (median of {len(changes) - 5})')
    return 0


if __name__ == '__main__':
    sys.exit(main())
