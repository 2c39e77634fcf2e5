# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The step-resolution rule (modal.STEPS_PER_PERIOD): one source for the Simulator's warning
and the studies' amplitude step; the default step satisfies it with a whole number of steps
per 1 ms tick."""

import math
import signal
import sys
import time
import warnings

import pytest
from processes import start_logged, stop_and_read

from worm_gear_sim import Config, Simulator
from worm_gear_sim.dynamics.modal import (
    STEPS_PER_PERIOD,
    StepResolutionWarning,
    amplitude_time_step,
    modes,
    step_resolution,
    step_resolution_warning,
)


def test_default_step_resolves_the_worm_and_fills_a_tick():
    cfg = Config()
    f_top = modes(cfg).undamped_hz[-1]                          # 8588 Hz, independent eig
    assert step_resolution(cfg) == pytest.approx(2 * math.pi * f_top * cfg.integrator.time_step,
                                                 rel=1e-6)
    assert 1.0 / (f_top * cfg.integrator.time_step) >= STEPS_PER_PERIOD     # 29 steps
    per_tick = 1e-3 / cfg.integrator.time_step
    assert per_tick == pytest.approx(round(per_tick), abs=1e-9)             # 250
    assert step_resolution_warning(cfg) == ''
    assert amplitude_time_step(cfg) == cfg.integrator.time_step
    with warnings.catch_warnings():
        warnings.simplefilter('error', StepResolutionWarning)
        Simulator(cfg)                                           # no warning


@pytest.mark.parametrize('over, f_hz', [
    ({'integrator.time_step': 1e-5}, 8588.0),                    # the former default
    ({'shafts.worm_shaft_radius': 0.02}, 14590.0),               # a stiffer worm shaft
])
def test_under_resolved_step_warns_and_names_the_way_out(over, f_hz):
    cfg = Config().replace(over)
    dt = cfg.integrator.time_step
    with pytest.warns(StepResolutionWarning) as rec:
        Simulator(cfg)
    msg = str(rec[0].message)
    assert msg == step_resolution_warning(cfg)
    assert f'{1.0 / (f_hz * dt):.1f} steps per period' in msg and 'integrator.time_step' in msg
    # the way out is the studies' amplitude step: an integer divisor that satisfies the rule
    dt_amp = amplitude_time_step(cfg)
    assert dt / dt_amp == round(dt / dt_amp) > 1
    assert step_resolution_warning(cfg.replace({'integrator.time_step': dt_amp})) == ''
    assert f'<= {dt_amp:.3g} s' in msg
    # a coarse step is allowed (a warning, not an error): the run still integrates
    sim = Simulator(cfg, check=False)
    sim.advance_to(0.002, 0.01)
    assert sim.stats['failed_steps'] == 0


def test_node_logs_an_under_resolved_step_through_ros(tmp_path, ros_subprocess_env):
    """The node (as a process) with a coarse step: starts, says so once as a ROS warning
    (not as Python's two-line warning on stderr), and ends quietly on SIGINT."""
    pytest.importorskip('rclpy')
    log_path = tmp_path / 'node.log'
    proc, log = start_logged([sys.executable, '-m', 'worm_gear_sim.ros', '--ros-args',
                              '-p', 'integrator.time_step:=1e-05'], ros_subprocess_env,
                             log_path)
    deadline = time.monotonic() + 90.0
    while time.monotonic() < deadline and proc.poll() is None \
            and 'ready: dt = 1e-05 s' not in log_path.read_text():
        time.sleep(0.2)
    rc, text = stop_and_read(proc, log, signal.SIGINT)
    assert rc == 0, text
    assert 'ready: dt = 1e-05 s' in text, text
    notes = [ln for ln in text.splitlines() if 'steps per period' in ln]
    assert len(notes) == 1 and '[WARN]' in notes[0] and '11.6 steps per period' in notes[0]
    assert 'StepResolutionWarning' not in text and 'Traceback' not in text
