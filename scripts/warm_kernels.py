# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Compile the package's numba kernels into its on-disk cache before the test suite starts.

Without it every pytest worker (and every node process a test starts before a worker has
written the cache) compiles the same kernels at the same time: on a cold cache (a fresh
clone, or ``scripts/setup_env.sh`` clearing a stale one) that is the suite's largest single
cost.  Two processes compile disjoint paths side by side:

    python scripts/warm_kernels.py          # both paths, in two processes
    python scripts/warm_kernels.py sim      # one path in this process (sim | comp)

``sim``: the Newmark kernel called from Python (``simulate``, with the fixed and the
variable step) and every kernel a node warms before it says "ready"
(``worm_gear_sim.adaptation.warmup``: pipeline, adaptation; for each integrator method); ``comp``:
the compensator's kernel and the model inverse, a known trajectory's correction (the node's
trajectory worker) without and with play, and the adaptation's estimator.
Each process compiles only what its path calls; what one compiled the other loads from the
cache.  Nothing here is checked: the tests check the results.
"""

from __future__ import annotations

import subprocess
import sys
import time


def _sim() -> None:
    from worm_gear_sim import Config
    from worm_gear_sim.adaptation.warmup import warm_up
    from worm_gear_sim.dynamics.simulation import simulate
    cfg = Config()
    simulate(cfg, t_end=0.002)
    simulate(cfg.replace({'integrator.method': 'adaptive'}), t_end=0.002)
    for method in ('fixed', 'adaptive'):   # what a node warms before "ready"
        warm_up(cfg.replace({'adaptation.enabled': True, 'integrator.method': method}))


def _comp() -> None:
    from worm_gear_sim import Config
    from worm_gear_sim.compensation.streaming import Compensator
    c = Compensator(Config())
    c.reset(0.0, 0.0)
    for k in range(1, 4):
        c.update(1e-3 * k, 0.01 * k)
    # a known trajectory (the node's trajectory worker), without and with play
    import numpy as np

    from worm_gear_sim.joint_trajectory.compensate import trajectory_feedforward
    t = np.arange(20) * 1e-3
    for cfg in (Config(), Config().replace({'mesh.backlash': 2e-4})):
        trajectory_feedforward(cfg, t, 0.5 * t)
    # the adaptation's estimator (the twin: the node's adapting loop offline)
    from worm_gear_sim.studies.adaptation_twin import run_twin
    run_twin(Config(), Config().replace({'adaptation.window': 0.2}), 'sector', 0.3)


PATHS = {'sim': _sim, 'comp': _comp}


def main(argv: list[str]) -> int:
    if argv:
        t0 = time.perf_counter()
        PATHS[argv[0]]()
        print(f'[warm] {argv[0]}: {time.perf_counter() - t0:.1f} s', flush=True)
        return 0
    procs = [subprocess.Popen([sys.executable, __file__, name]) for name in PATHS]
    return max(p.wait() for p in procs)


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
