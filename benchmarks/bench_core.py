#!/usr/bin/env python3
# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Benchmark of the compiled Newmark-Newton kernel.

Prints, in one run:
  * ns/step of the kernel on the paper's 18-step move (0.5 s) for the node's old setting
    (tanh friction, plain Newmark at 10 us), the set-valued friction with the
    frequency-matched worm at the old 10 us and at the default 4 us, other models, and the
    real-time factor;
  * mean Newton solves and force evaluations per step (what bounds the time);
  * the cost of one force evaluation (the transcendental-heavy part) and of one 1 kHz tick
    through Simulator.advance_to (what the node pays per tick), old, new and the variable
    step side by side;
  * pointwise accuracy of theta2/theta4 at the node step, of the fixed and the variable step
    against the event-driven Radau solution of test_against_radau, and the antenna
    ring-down;
  * the speed-up over scipy's Radau at equal accuracy of the antenna angle theta4;
  * the floor: the same step written plainly (kernel_floor.py: the default model's
    equations in slip, one or two force evaluations per step, no branches) on the same
    move, and the kernel's ratio to it, measured side by side.

    python benchmarks/bench_core.py            # full run (~2-4 min)
    python benchmarks/bench_core.py --quick    # skip the Radau comparison
    python benchmarks/bench_core.py --step-limit   # only: what sets the step (below)
    python benchmarks/bench_core.py --adaptive     # only: the variable step beside the fixed

The variable step (``integrator.method: adaptive``) beside the fixed one, on the 18-step move
and a +-5 deg sector scan, alternating (``benchmarks/adaptive_steps.py``: the same table, and
the step-size history as a figure), is part of the run.

``--step-limit`` prints the pointwise theta2 / theta4 accuracy of the default move at 4-10 us
with each ingredient of the model switched off in turn (the friction law, its Stribeck
curve, the nonlinear mesh, the worm's frequency matching), and the Python and call cost of
a tick apart from its steps: what would have to change for the step to grow.

Timings are the minimum over repeats (other load on the machine only makes them slower).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
import warnings

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..'))

from worm_gear_sim import Config, Simulator, make_profile, simulate  # noqa: E402
from worm_gear_sim.dynamics.equations import mesh_forces  # noqa: E402
from worm_gear_sim.dynamics.integrator import N_STATS, S_EVALS, S_SOLVES, advance  # noqa: E402
from worm_gear_sim.dynamics.modal import StepResolutionWarning  # noqa: E402

OLD = {'friction.direction': 'regularized', 'integrator.worm_frequency_matching': False,
       'integrator.time_step': 1e-5}
# (name, overrides): the kernel rows; the node's old setting (tanh friction, plain Newmark,
# 10 us), the set-valued friction with the frequency-matched worm at the old 10 us step, and
# the default (the same at 4 us, the step that resolves theta2 pointwise)
ROWS = [
    ('old default (tanh, 10 us)', OLD),
    ('set-valued, matched, 10 us', {'integrator.time_step': 1e-5}),
    ('default (4 us)', {}),
    ('linear, constant mu', {'mesh.stiffness_model': 'linear', 'friction.model': 'constant'}),
    ('linear, frictionless', {'mesh.stiffness_model': 'linear', 'friction.model': 'off'}),
]
ADAPTIVE = {'integrator.method': 'adaptive'}
SLEW = {'input.profile': 'ramp', 'input.target_angle': 4.0, 'input.move_time': 2.0}
MODELS = {
    'nonlinear (default)': {},
    'linear, constant mu': {'mesh.stiffness_model': 'linear', 'friction.model': 'constant'},
    'linear, frictionless': {'mesh.stiffness_model': 'linear', 'friction.model': 'off'},
}


def move_grid(cfg: Config, t_end: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """The command theta1 and its rate on the step grid of the configured move."""
    dt = cfg.integrator.time_step
    prof = make_profile(cfg.input)
    grid = np.arange(1, int(round(t_end / dt)) + 1) * dt
    return (np.concatenate(([0.0], prof.theta1(grid))),
            np.concatenate(([0.0], prof.theta1_dot(grid))))


def kernel_ns_per_step(cfg: Config, t_end: float = 0.5, repeats: int = 7, rest: bool = False):
    """(ns, Newton solves, force evaluations) per step of the configured move, or (``rest``)
    of the drive held at rest under a constant command."""
    dt = cfg.integrator.time_step
    th, td = move_grid(cfg, t_end)
    if rest:
        th, td = np.zeros_like(th), np.zeros_like(td)
    n = th.shape[0] - 1
    e3, ea = np.empty((0, 3)), np.empty((0, 8))
    best = np.inf
    for _ in range(repeats):
        sim = Simulator(cfg)
        st = np.zeros(N_STATS, dtype=np.int64)
        ctl = sim._ctl.copy()
        t0 = time.perf_counter()
        advance(sim.p, sim.C, sim._u, sim._v, sim._a, th, td, dt, 0, e3, e3, e3, ea, st, ctl,
                np.empty(0))
        best = min(best, time.perf_counter() - t0)
    return best / n * 1e9, st[S_SOLVES] / n, st[S_EVALS] / n


def force_eval_ns(cfg: Config, n: int = 200_000) -> float:
    from numba import njit

    @njit(cache=False)
    def loop(p, n):
        s = 0.0
        for i in range(n):
            f = mesh_forces(p, 0.1 + i * 1e-12, 0.0018, 0.0018, 1e-2 * (i % 7 - 3), 0.01, 0.0,
                            0.1)
            s += f[0] + f[3] + f[7]
        return s
    sim = Simulator(cfg)
    loop(sim.p, 10)
    best = np.inf
    for _ in range(5):
        t0 = time.perf_counter()
        loop(sim.p, n)
        best = min(best, time.perf_counter() - t0)
    return best / n * 1e9


def advance_to_call_us(cfg: Config, ticks: int = 2000) -> float:
    """Wall time of one 1 kHz tick (1 ms of steps) through Simulator.advance_to."""
    sim = Simulator(cfg)
    prof = make_profile(cfg.input)
    t = np.arange(1, ticks + 1) * 1e-3
    cmd = prof.theta1(t)
    t0 = time.perf_counter()
    for tk, c in zip(t, cmd):
        sim.advance_to(tk, c)
    return (time.perf_counter() - t0) / ticks * 1e6


def pointwise_accuracy(over: dict) -> tuple[float, float]:
    """max |theta - theta_ref| / oscillation amplitude for theta2 and theta4 at every step of
    the move and 5 ms of ringing, against Newmark at 0.05 us of the same model
    (bench_step.errors; test_against_radau checks that reference against Radau)."""
    from bench_step import errors
    dt = Config().replace(over).integrator.time_step
    return errors(over, steps=(dt,))[0][dt]


def radau_pointwise(over: dict, t_end: float = 0.024) -> tuple[float, float, int]:
    """(theta2, theta4 error as fractions of their oscillation amplitudes, steps checked):
    max over every step of the 18-step move and 4 ms of ringing against the event-driven
    Radau solution of test_against_radau (the reference its pointwise-target test uses);
    the variable step recorded on 1 ms ticks, checked at every step it took (its log)."""
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'test'))
    from test_against_radau import radau_set_valued
    cfg = Config().replace(over)
    prof = make_profile(cfg.input)
    if cfg.integrator.method == 'fixed':
        tr = simulate(cfg, t_end=t_end)
        t, theta = tr.t, tr.theta
    else:
        sim = Simulator(cfg)
        sim.log_steps(100_000)
        sim.run(prof, t_end, record_every=int(round(1e-3 / cfg.integrator.time_step)))
        t, theta = sim.step_log['t'], sim.step_log['theta']
    th1 = prof.theta1(t)
    ref, _ = radau_set_valued(cfg, t, t_end)
    ratio = Simulator(cfg).derived.output_per_input
    osc2 = np.abs(ref[:, 0] - th1).max()
    osc4 = np.abs(ref[:, 2] - th1 * ratio).max()
    return (float(np.abs(theta[:, 0] - ref[:, 0]).max() / osc2),
            float(np.abs(theta[:, 2] - ref[:, 2]).max() / osc4), len(t))


def ring_down_of(over: dict, horizon: float = 0.5) -> float:
    """The antenna's ring-down over 0.5 s after the 18-step move (trajectory.ring_down)."""
    from worm_gear_sim import DriveModel, static_equilibrium
    from worm_gear_sim.dynamics.trajectory import ring_down
    model = DriveModel(Config().replace(over))
    dt = model.config.integrator.time_step
    n, k = round((0.02 + horizon) / dt), max(1, int(1e-5 / dt + 1e-9))
    while n % k:                # a row about every 10 us, and one at the end of the run
        k -= 1
    tr = simulate(model, t_end=0.02 + horizon, record_every=k)
    eq = static_equilibrium(model, float(tr.theta1[-1]))
    return ring_down(tr, 0.02, eq[2], horizon)


def radau_comparison(horizon: float = 0.05):
    """Speed-up over Radau at equal theta4 accuracy (reference: Newmark at 50 ns, which the
    test suite checks against Radau at rtol 1e-11)."""
    from scipy.integrate import solve_ivp

    cfg = Config().replace(OLD)        # Radau needs the smooth (tanh) law
    sample = 1e-5
    ref = simulate(cfg.replace({'integrator.time_step': 5e-8}), t_end=horizon,
                   record_every=200)
    t_s = ref.t
    dt = 1e-5
    t0 = time.perf_counter()
    nm = simulate(cfg.replace({'integrator.time_step': dt}), t_end=horizon)
    t_newmark = time.perf_counter() - t0
    err_nm4 = np.abs(nm.theta4 - ref.theta4).max()
    err_nm2 = np.abs(nm.theta2 - ref.theta2).max()
    osc4 = np.abs(ref.output_error).max()
    osc2 = np.abs(ref.worm_error).max()

    sim = Simulator(cfg)
    p = sim.p                       # the packed vector the compiled mesh_forces takes
    d = sim.derived
    M = np.array([d.J_w, d.J_g, d.J_4])
    prof = make_profile(cfg.input)
    kg = d.K_g

    def rhs(t, y):
        f = mesh_forces(p, y[0], y[1], y[2], y[3], y[4], y[5],
                        float(prof.theta1(np.array([t]))[0]))
        return np.array([y[3], y[4], y[5], f[0] / M[0], f[1] / M[1], f[2] / M[2]])

    def jac(t, y):
        f = mesh_forces(p, y[0], y[1], y[2], y[3], y[4], y[5],
                        float(prof.theta1(np.array([t]))[0]))
        J = np.zeros((6, 6))
        J[0, 3] = J[1, 4] = J[2, 5] = 1.0
        J[3:, :3] = np.array([[f[3], f[4], 0.0], [f[5], f[6], kg], [0.0, kg, -kg]]) / M[:, None]
        J[3:, 3:] = np.array([[f[7], f[8], 0.0], [f[9], f[10], 0.0], [0, 0, 0]]) / M[:, None]
        return J

    breaks = [0.0, 0.004, 0.016, 0.02, horizon]
    rows = []
    for rtol in (1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9):
        atol = np.r_[np.full(3, rtol * 1e-3), np.full(3, rtol)]
        y = np.zeros(6)
        out = np.empty((len(t_s), 3))
        t0 = time.perf_counter()
        nfev = 0
        for a, b in zip(breaks[:-1], breaks[1:]):
            sel = (t_s >= a) & (t_s <= b)
            sol = solve_ivp(rhs, (a, b), y, method='Radau', jac=jac, rtol=rtol, atol=atol,
                            dense_output=True)
            out[sel] = sol.sol(t_s[sel])[:3].T
            y = sol.y[:, -1]
            nfev += sol.nfev
        t_radau = time.perf_counter() - t0
        e4 = np.abs(out[:, 2] - ref.theta4).max()
        e2 = np.abs(out[:, 0] - ref.theta2).max()
        rows.append((rtol, t_radau, e4, e2, nfev))
        if e4 <= err_nm4:
            break
    return dict(t_newmark=t_newmark, err_nm4=err_nm4, err_nm2=err_nm2, osc4=osc4, osc2=osc2,
                rows=rows, horizon=horizon, sample=sample)


def floor_rows(rounds: int = 3) -> None:
    """The kernel's default row and the plain floor of the same step, measured in
    alternation (min over ``rounds``), and their ratio."""
    from kernel_floor import floor_constants, floor_ns_per_step
    cfg = Config()
    dt = cfg.integrator.time_step
    th, _ = move_grid(cfg)
    sim = Simulator(cfg)
    k = floor_constants(sim.model)
    fl1 = fl2 = kern = np.inf
    for _ in range(rounds):
        fl1 = min(fl1, floor_ns_per_step(k, sim._u, sim._v, sim._a, th, dt, 1, 3))
        fl2 = min(fl2, floor_ns_per_step(k, sim._u, sim._v, sim._a, th, dt, 2, 3))
        kern = min(kern, kernel_ns_per_step(cfg, repeats=3)[0])
    print(f'# floor: the default step written plainly (kernel_floor.py), same move, min of '
          f'{rounds} alternating rounds')
    print(f'  floor, 1 force evaluation/step  {fl1:7.1f} ns/step  {dt / (fl1 * 1e-9):6.1f}x '
          'real time')
    print(f'  floor, 2 force evaluations/step {fl2:7.1f} ns/step  {dt / (fl2 * 1e-9):6.1f}x '
          'real time')
    print(f'  kernel, default (4 us)          {kern:7.1f} ns/step  {dt / (kern * 1e-9):6.1f}x '
          f'real time (target >= 40x): {kern / fl1:.2f}x the 1-evaluation floor, '
          f'{kern / fl2:.2f}x the 2-evaluation floor')


#: (name, overrides) of --step-limit: the default and each ingredient switched off in turn
STEP_CASES = [
    ('default (nonlinear mesh, set-valued Stribeck)', {}),
    ('set-valued Stribeck, linear mesh', {'mesh.stiffness_model': 'linear'}),
    ('tanh Stribeck, nonlinear mesh', {'friction.direction': 'regularized'}),
    ('constant mu, nonlinear mesh', {'friction.model': 'constant'}),
    ('frictionless, nonlinear mesh', {'friction.model': 'off'}),
    ('constant mu, linear mesh', {'mesh.stiffness_model': 'linear',
                                  'friction.model': 'constant'}),
    ('default, worm not frequency-matched', {'integrator.worm_frequency_matching': False}),
]
LIMIT_STEPS = (4e-6, 5e-6, 6e-6, 8e-6, 1e-5)


def tick_overhead_us(n: int = 20_000) -> tuple[float, float]:
    """(advance_to of one step, advance_segment of one step) in us: the per-tick cost that
    is not the steps (the Python of advance_to, and numba's dispatch of the compiled call)."""
    from worm_gear_sim.dynamics.stepping import advance_segment
    sim = Simulator(Config())
    dt = sim.dt
    t0 = time.perf_counter()
    for _ in range(n):
        sim.advance_to(sim.t + dt * 1.0000001, 0.0)
    whole = (time.perf_counter() - t0) / n * 1e6
    args = (sim.p, sim.C, sim._u.copy(), sim._v.copy(), sim._a.copy(), sim._theta1,
            sim._theta1_dot, sim._t0, sim._k, dt, 1, sim._cmd_t, 0.0, 0.0, sim.t + dt, 0.0,
            sim._stats.copy(), sim._ctl.copy(), sim._load_on_grid(1))
    t0 = time.perf_counter()
    for _ in range(n):
        advance_segment(*args)
    return whole, (time.perf_counter() - t0) / n * 1e6


def step_limit() -> None:
    from bench_step import errors
    print(f'# what sets the step (load {os.getloadavg()[0]:.2f}): pointwise error / oscillation '
          'amplitude, theta2 / theta4, 18-step move + 5 ms ringing, against Newmark at '
          '0.05 us of the same model (targets 0.05 / 0.001)')
    print(f'{"case":46s} ' + ' '.join(f'{dt * 1e6:>14.0f}us' for dt in LIMIT_STEPS))
    for name, over in STEP_CASES:
        out, _, _ = errors(over, steps=LIMIT_STEPS)
        print(f'{name:46s} ' + ' '.join(f'{e2:7.4f}/{e4:7.1e}' for e2, e4 in out.values()),
              flush=True)
    for _ in range(3):
        whole, call = tick_overhead_us()
        print(f'one tick of ONE step: advance_to {whole:.2f} us, of which the compiled call '
              f'advance_segment {call:.2f} us (load {os.getloadavg()[0]:.2f})')


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--quick', action='store_true', help='skip the Radau comparison')
    ap.add_argument('--step-limit', action='store_true', help='only what sets the step')
    ap.add_argument('--adaptive', action='store_true',
                    help='only the variable step beside the fixed one')
    args = ap.parse_args(argv)
    # the coarse rows are deliberate: the tables report each step's resolution themselves
    warnings.simplefilter('ignore', StepResolutionWarning)
    if args.step_limit:
        step_limit()
        return 0
    from adaptive_steps import side_by_side
    if args.adaptive:
        side_by_side()
        return 0
    print(f'# worm_gear_sim kernel benchmark  ({platform.processor() or platform.machine()}, '
          f'{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}, python '
          f'{platform.python_version()})')
    print('# 18-step move (0.1131 rad trapezoidal in 20 ms) simulated for 0.5 s; min of 7 runs')
    print(f'{"model":28s} {"dt [us]":>8s} {"ns/step":>9s} {"x real time":>12s} '
          f'{"solves/step":>12s} {"evals/step":>11s}')
    for name, over in ROWS:
        cfg = Config().replace(over)
        dt = cfg.integrator.time_step
        ns, solves, evals = kernel_ns_per_step(cfg)
        print(f'{name:28s} {dt * 1e6:8.0f} {ns:9.1f} {dt / (ns * 1e-9):12.1f} '
              f'{solves:12.3f} {evals:11.3f}')
    print()
    for name, over in MODELS.items():
        print(f'one force evaluation (mesh_forces), {name}: '
              f'{force_eval_ns(Config().replace(over)):.1f} ns')
    print('Simulator.advance_to, one 1 kHz tick (1 ms of steps), min of 3 x 2000 ticks:')
    ticks = {}
    for name, over in ROWS[:3]:
        ticks[name] = min(advance_to_call_us(Config().replace(over)) for _ in range(3))
        print(f'  {name:28s} {ticks[name]:7.1f} us  (target <= 30 us)')
    ticks['adaptive'] = min(advance_to_call_us(Config().replace(ADAPTIVE)) for _ in range(3))
    print(f'  {"variable step (adaptive)":28s} {ticks["adaptive"]:7.1f} us  (target <= 30 us;'
          f' default / adaptive {ticks[ROWS[2][0]] / ticks["adaptive"]:.2f})')
    a, b, c = (ticks[n] for n, _ in ROWS[:3])
    print(f'  ratio to the old setting: set-valued at 10 us {b / a:.2f}, default (4 us) '
          f'{c / a:.2f}; default / set-valued at 10 us {c / b:.2f}')
    slew = Config().replace(SLEW)
    t_slew = min(advance_to_call_us(slew) for _ in range(3))
    ns, solves, evals = kernel_ns_per_step(slew, t_end=0.25, repeats=3)
    print(f'  default, worm slewing at 2 rad/s    {t_slew:7.1f} us  (kernel {ns:.1f} ns/step, '
          f'{solves:.3f} solves, {evals:.3f} evaluations per step)')
    ns, solves, evals = kernel_ns_per_step(Config(), t_end=0.1, repeats=5, rest=True)
    print(f'  default, at rest (no load, constant command): kernel {ns:.1f} ns/step ({solves:.3f}'
          f' solves, {evals:.3f} evaluations per step, counted as if computed: a step that '
          'leaves state and control unchanged is repeated, not computed again)')
    floor_rows()
    print()
    side_by_side()
    print()
    print('# accuracy at the node step, pointwise at every step over 25 ms (move + 5 ms '
          'ringing) against Newmark at 0.05 us of the same model, fraction of the oscillation '
          'amplitude (targets theta2 <= 0.05, theta4 <= 0.001)')
    for name, over in ROWS[:3]:
        for mesh in ('linear', 'nonlinear'):
            o = dict(over)
            if mesh == 'linear':
                o.update({'mesh.stiffness_model': 'linear', 'friction.model': 'constant'})
            e2, e4 = pointwise_accuracy(o)
            print(f'  {name:28s} {mesh:9s} theta2 {e2:.4f}  theta4 {e4:.2e}')
    print('# accuracy against the event-driven Radau solution, pointwise at every step over '
          '24 ms (move + 4 ms ringing), set-valued friction, fraction of the oscillation '
          'amplitude (targets theta2 <= 0.05, theta4 <= 0.001)')
    for name, over in (('default (4 us)', {}), ('variable step (adaptive)', ADAPTIVE)):
        for mesh, m in (('linear', {'mesh.stiffness_model': 'linear',
                                    'friction.model': 'constant'}), ('nonlinear', {})):
            e2, e4, n = radau_pointwise(dict(over, **m))
            print(f'  {name:28s} {mesh:9s} theta2 {e2:.4f}  theta4 {e4:.2e}  ({n} steps)')
    print('# antenna ring-down over 0.5 s after the move (exact-stick limit: tanh as v_eps -> 0,'
          ' test_integrator)')
    for name, over in (('old default (tanh 1e-4, 10 us)', OLD),
                       ('set-valued, 10 us', {'integrator.time_step': 1e-5}),
                       ('set-valued, 4 us (default)', {}),
                       ('set-valued, 1 us', {'integrator.time_step': 1e-6}),
                       ('tanh 1e-7 m/s, 20 ns', {'friction.direction': 'regularized',
                                                 'friction.regularization_velocity': 1e-7,
                                                 'integrator.time_step': 2e-8})):
        print(f'  {name:32s} {100 * ring_down_of(over):.2f} %')
    if args.quick:
        return 0
    print()
    r = radau_comparison()
    print(f'# equal-accuracy comparison with scipy Radau, nonlinear model with the tanh law, '
          f'{r["horizon"] * 1e3:.0f} ms horizon, errors against Newmark at 50 ns')
    print(f'Newmark dt=10us: {r["t_newmark"] * 1e3:.2f} ms wall, theta4 error '
          f'{r["err_nm4"]:.2e} rad ({r["err_nm4"] / r["osc4"]:.1e} of its oscillation '
          f'amplitude), theta2 error {r["err_nm2"]:.2e} rad '
          f'({r["err_nm2"] / r["osc2"]:.1e}: the 8.6 kHz worm mode is not resolved at 10 us)')
    for rtol, t_r, e4, e2, nfev in r['rows']:
        print(f'Radau rtol={rtol:.0e}: {t_r:8.2f} s wall, {nfev:7d} f-evals, theta4 error '
              f'{e4:.2e}, theta2 error {e2:.2e}')
    rtol, t_r, e4, _, _ = r['rows'][-1]
    if e4 <= r['err_nm4']:
        print(f'speed-up at equal theta4 accuracy: {t_r / r["t_newmark"]:.0f}x '
              f'(target >= 1000x)')
    else:
        print(f'Radau did not reach the Newmark accuracy down to rtol {rtol:.0e}; speed-up '
              f'at its best accuracy already {t_r / r["t_newmark"]:.0f}x')
    return 0


if __name__ == '__main__':
    sys.exit(main())
