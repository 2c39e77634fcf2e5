# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Params files read the same way by the command line and by the node: each value of its
parameter's type (``5.0`` for a float, ``12`` for an integer), an unknown dotted name an error,
a plain name unlike ours ignored with a warning; a value typed on a command line (``--set``,
``ros2 param set``) stays friendly.  The shipped and the written params files are keyed
``/**``, so a renamed node (``-r __node:=azimuth_drive``) takes them."""

from __future__ import annotations

from pathlib import Path

import pytest
from processes import cli_in_process

from worm_gear_sim.config.files import load_config, params_document, params_yaml_text
from worm_gear_sim.schema.validation import ConfigError, ForeignParameterWarning

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / 'config' / 'worm_gear_sim.yaml'


def _file(tmp_path: Path, body: str, name: str = 'p.yaml') -> Path:
    f = tmp_path / name
    f.write_text('/**:\n  ros__parameters:\n' + body)
    return f


@pytest.mark.parametrize('body, fragments', [
    ('    load:\n      output_torque: 5\n',
     ['load.output_torque', 'got the integer 5', 'write 5.0']),
    ('    integrator:\n      newton_max_iterations: 12.0\n',
     ['integrator.newton_max_iterations', 'got the float 12.0', 'write 12']),
    ('    damping:\n      modal_damping_ratios: [0.01, 0, 0.0]\n',
     ['damping.modal_damping_ratios', 'entry 1', 'write 0.0']),
    ('    bogus:\n      x: 1.0\n', ['bogus.x', "unknown section 'bogus'"]),
    ('    load:\n      output_torqe: 1.0\n', ['load.output_torqe', 'did you mean']),
])
def test_a_params_file_the_node_refuses_is_refused_by_the_cli(tmp_path, body, fragments):
    """The node refuses these at start-up (rcl's types, test/ros/test_node_startup.py); the CLI
    accepted the first three and the node only warned about the fourth."""
    f = _file(tmp_path, body)
    with pytest.raises(ConfigError) as err:
        load_config(f)
    for w in fragments:
        assert w in str(err.value), (w, str(err.value))
    r = cli_in_process('params', '--config', f)
    assert r.returncode == 2 and r.stderr.startswith('worm-gear-sim: error: '), r.stderr
    assert fragments[0] in r.stderr


def test_a_plain_name_of_another_node_is_ignored_with_a_warning(tmp_path):
    """A ``/**`` block shared by several nodes holds their keys too: ignored, said."""
    f = _file(tmp_path, '    robot_description: "<robot/>"\n    load:\n'
                        '      output_torque: 2.0\n')
    with pytest.warns(ForeignParameterWarning, match="ignoring parameter 'robot_description'"):
        cfg = load_config(f)
    assert cfg.load.output_torque == 2.0


def test_values_typed_on_a_command_line_stay_friendly():
    r = cli_in_process('params', '--set', 'load.output_torque=5',
                       '--set', 'integrator.newton_max_iterations=12.0')
    assert r.returncode == 0, r.stderr
    assert '"output_torque": 5.0' in r.stdout and '"newton_max_iterations": 12' in r.stdout


def test_blocks_for_the_node_merge_in_file_order(tmp_path):
    """As rcl: every block addressed to the node applies, a later one's value wins."""
    f = tmp_path / 'p.yaml'
    f.write_text('/**:\n  ros__parameters:\n    load:\n      output_torque: 1.0\n'
                 '      output_viscous_coefficient: 3.0\n'
                 'worm_gear_sim:\n  ros__parameters:\n    load:\n      output_torque: 2.0\n'
                 'other_node:\n  ros__parameters:\n    load:\n      output_torque: 9.0\n')
    cfg = load_config(f)
    assert (cfg.load.output_torque, cfg.load.output_viscous_coefficient) == (2.0, 3.0)
    assert load_config(f, node_name='azimuth_drive').load.output_torque == 1.0


def test_a_renamed_node_takes_the_shipped_and_the_written_params_files(ros_harness, tmp_path):
    """``-r __node:=azimuth_drive``: rcl gives the node the ``/**`` block of the shipped
    file and of a file the package writes (calibrate, identify, params --format yaml, the
    adaptation's write service); keyed ``worm_gear_sim:`` they were silently ignored."""
    from worm_gear_sim.ros.node import WormGearSimNode
    shipped = tmp_path / 'shipped.yaml'
    text = CONFIG.read_text()
    shipped.write_text(text.replace('      output_torque: 0.0', '      output_torque: 1.5'))
    assert shipped.read_text() != text
    written = tmp_path / 'written.yaml'
    written.write_text(params_yaml_text(params_document(
        load_config(CONFIG).replace({'load.output_torque': 2.5}))))
    h = ros_harness(sim_time=False)
    for path, want in ((shipped, 1.5), (written, 2.5)):
        node = WormGearSimNode(context=h.ctx, cli_args=[
            '--ros-args', '-r', '__node:=azimuth_drive', '--params-file', str(path)])
        try:
            assert node.get_name() == 'azimuth_drive'
            assert node.get_parameter('load.output_torque').value == want, path.name
            assert node.config.load.output_torque == want
        finally:
            node.destroy_node()
        assert load_config(path, node_name='azimuth_drive').load.output_torque == want


def test_a_value_set_at_run_time_is_as_friendly_as_set(ros_harness):
    """``ros2 param set`` types 12.0 for an integer parameter as the CLI's ``--set`` does
    (an integer for a double was already taken)."""
    from rclpy.parameter import Parameter
    h = ros_harness()
    res = h.set_parameters([Parameter('integrator.newton_max_iterations', value=14.0),
                            Parameter('load.output_torque', value=2)])
    assert all(r.successful for r in res), [r.reason for r in res]
    assert h.node.get_parameter('integrator.newton_max_iterations').value == 14
    assert h.node.config.integrator.newton_max_iterations == 14
    assert h.node.config.load.output_torque == 2.0
    res = h.set_parameters([Parameter('integrator.newton_max_iterations', value=14.5)])
    assert not res[0].successful                    # not an integer: refused
