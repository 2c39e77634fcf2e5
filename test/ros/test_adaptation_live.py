# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Live adaptation end to end with real processes: the node and the plant node started as
processes (domain of the tests, discovery LOCALHOST), this process streaming a short sector
scan (``worm_gear_sim.ros.live_adaptation.run_live``).  The plant node answers every
command with an encoder sample, the node uses them (none rejected), learns the plant's load
and its feed-forward, applied by the plant, removes the error the load makes; and the run
is the offline twin's, bit for bit, when no encoder sample and no step came late (the
handshake before the run restarts the node and the plant with the clock going back)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip('rclpy')

pytestmark = pytest.mark.ros


def test_live_node_learns_the_plant_from_its_encoder(ros_dds_context, ros_subprocess_env,
                                                     tmp_path):
    from worm_gear_sim.config.usable import Config
    from worm_gear_sim.ros.live_adaptation import run_live
    from worm_gear_sim.studies.adaptation_twin import run_twin
    base = Config()
    plant = base.replace({'load.output_torque': 3.0, 'load.output_viscous_coefficient': 10.0})
    start = base.replace({'adaptation.keys': ['load.output_torque',
                                              'load.output_viscous_coefficient'],
                          'adaptation.window': 0.5, 'adaptation.step_interval': 0.1,
                          'adaptation.max_step': 0.05})
    run = run_live(plant, start, 'sector', 1.6, context=ros_dds_context,
                   env=ros_subprocess_env, workdir=tmp_path, seed=3)
    assert run.missing == 0, run.node_log[-2000:]                 # every stamp answered
    assert run.plant_counters['published'] >= run.t.size
    assert run.counters['rejected'] == 0 and run.counters['used'] > 300, run.node_log[-2000:]
    assert run.counters['switches'] >= 1
    assert run.in_use['load.output_torque'] == pytest.approx(3.0, rel=0.1)
    late = run.t >= 1.3
    rms_u = np.sqrt(np.mean(run.error_uncompensated[late] ** 2))
    rms_c = np.sqrt(np.mean(run.error_compensated[late] ** 2))
    assert rms_c < rms_u / 5.0
    early = run.t < 0.5                       # before the first window nothing changed
    assert np.allclose(run.error_compensated[early], run.error_uncompensated[early],
                       atol=2e-6)
    # the same computation as the twin's on the same samples: the node's decisions saw the
    # same encoder samples at the same stamps (none late), the plant process stepped the
    # same commands
    assert run.counters['late_samples'] == 0 and run.counters['late_steps'] == 0
    # the handshake before the run left nothing: the node's pipeline and adaptation and
    # the plant restarted at the run's first sample (the clock went back), so the live run
    # is the plain twin's, whatever the handshake took
    assert run.held >= 1 and run.plant_ns == run.t0_ns
    assert run.counters['restarts'] == 1 and run.plant_counters['restarts'] == 1
    twin = run_twin(plant, start, 'sector', 1.6, seed=3, base_ns=run.t0_ns)
    assert twin.counters['late_samples'] == 0 and twin.counters['switches'] >= 1
    assert np.array_equal(run.error_compensated, twin.error_compensated)
    assert run.in_use == twin.in_use
