# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The warm-up before "ready" (worm_gear_sim.adaptation.warmup) leaves no kernel to compile or
load: after it, a twin run over crossings of the play, detected steps and applied steps, with a
drive with play, load, drag and periodic error, makes numba compile or load nothing more.
Run in fresh processes (this one has kernels in memory already); without the warm-up the
same run loads those kernels (the run reaches them)."""

from __future__ import annotations

import json
import subprocess
import sys

SCRIPT = r'''
import json, sys
from numba.core.registry import CPUDispatcher

def overloads():
    return {f'{name}.{k}': len(v.overloads) for name, mod in list(sys.modules.items())
            if name.startswith('worm_gear_sim')
            for k, v in list(vars(mod).items())
            if isinstance(v, CPUDispatcher) and v.__module__ == name}

from worm_gear_sim import Config
from worm_gear_sim.studies.adaptation_twin import run_twin
from worm_gear_sim.adaptation.warmup import warm_up
cfg = Config().replace({'adaptation.enabled': True})
plant = Config().replace({'mesh.backlash': 8e-4, 'load.output_torque': 2.0,
                          'load.output_viscous_coefficient': 20.0,
                          'mesh.worm_error_harmonics': [2e-5, 1e-5]})
if sys.argv[1] == 'warm':
    warm_up(cfg)
before = overloads()
run = run_twin(plant, cfg, 'sector', 4.0)
after = overloads()
print(json.dumps({'new': sorted(k for k, n in after.items() if n != before.get(k, 0)),
                  'switches': run.counters['switches']}))
'''

#: Kernels only rarer samples reach (the filter's tail, the step detector, its play
#: measurement): the run must reach them.
RARE = {'worm_gear_sim.adaptation.per_sample.sample_tail',
        'worm_gear_sim.adaptation.per_sample.least_step',
        'worm_gear_sim.adaptation.per_sample._kalman_step',
        'worm_gear_sim.adaptation.flank_timing.detect_core'}


def _run(mode: str) -> dict:
    out = subprocess.run([sys.executable, '-c', SCRIPT, mode], capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_after_the_warm_up_nothing_is_compiled_or_loaded():
    cold = _run('cold')
    assert RARE <= set(cold['new']) and cold['switches'] > 0, cold   # the run reaches them
    warm = _run('warm')
    assert warm['new'] == [] and warm['switches'] == cold['switches'], warm


METHOD_SCRIPT = r'''
import json, sys
from numba.core.registry import CPUDispatcher

def overloads():
    return {f'{name}.{k}': len(v.overloads) for name, mod in list(sys.modules.items())
            if name.startswith('worm_gear_sim')
            for k, v in list(vars(mod).items())
            if isinstance(v, CPUDispatcher) and v.__module__ == name}

from worm_gear_sim import Config
from worm_gear_sim.studies.adaptation_twin import run_twin
from worm_gear_sim.adaptation.warmup import warm_up
seg = 'worm_gear_sim.dynamics.segment.advance_segment'
out = {}
warm_up(Config().replace({'adaptation.enabled': True}))
o = overloads()
out['fixed'] = [o.get(seg, 0), o.get(seg + '_adaptive', 0)]
cfg = Config().replace({'adaptation.enabled': True, 'integrator.method': 'adaptive'})
warm_up(cfg)
before = overloads()
out['adaptive'] = [before.get(seg, 0), before.get(seg + '_adaptive', 0)]
run_twin(cfg, cfg, 'sector', 0.3)
out['new'] = sorted(k for k, n in overloads().items() if n != before.get(k, 0))
print(json.dumps(out))
'''


def test_the_warm_up_compiles_the_integrator_method_the_config_uses():
    """A node with the fixed step warms the fixed step's segment and not the variable one's
    (integrator.method: adaptive); a node with the variable step warms its segment, and its
    adapting twin run then compiles or loads nothing more."""
    out = subprocess.run([sys.executable, '-c', METHOD_SCRIPT], capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got['fixed'] == [1, 0], got
    assert got['adaptive'] == [1, 1] and got['new'] == [], got
