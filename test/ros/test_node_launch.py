# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""launch/worm_gear_sim.launch.py, read as source (launch and launch_ros are not on PyPI):
it names the console scripts of setup.py and files that the package installs.  The
installed layout (share/worm_gear_sim/launch, config, urdf) is checked on a colcon build in
test_packaging.py."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
LAUNCH = ROOT / 'launch' / 'worm_gear_sim.launch.py'


def launch_constants(path: Path = LAUNCH) -> dict[str, object]:
    """Module-level NAME = <literal or os.path.join of literals> of a launch file."""
    tree = ast.parse(path.read_text(), filename=str(path))
    out: dict[str, object] = {}
    for node in tree.body:
        if isinstance(node, ast.Assign) and len(node.targets) == 1 and \
                isinstance(node.targets[0], ast.Name):
            v = node.value
            if isinstance(v, ast.Constant):
                out[node.targets[0].id] = v.value
            elif isinstance(v, ast.Call) and ast.unparse(v.func) == 'os.path.join':
                out[node.targets[0].id] = '/'.join(a.value for a in v.args)
    out['functions'] = [n.name for n in tree.body if isinstance(n, ast.FunctionDef)]
    return out


def console_scripts() -> dict[str, str]:
    tree = ast.parse((ROOT / 'setup.py').read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            for k, v in zip(node.keys, node.values):
                if isinstance(k, ast.Constant) and k.value == 'console_scripts':
                    return dict(s.value.split(' = ') for s in v.elts)
    raise AssertionError('no console_scripts in setup.py')


def test_launch_file_names_the_installed_executables_and_files():
    c = launch_constants()
    assert 'generate_launch_description' in c['functions']
    scripts = console_scripts()
    assert c['PACKAGE'] == 'worm_gear_sim'
    assert scripts[c['EXECUTABLE']] == 'worm_gear_sim.ros.startup:node_main'
    assert c['DEMO_EXECUTABLE'] in scripts
    assert (ROOT / c['PARAMS']).is_file() and c['PARAMS'] == 'config/worm_gear_sim.yaml'
    assert (ROOT / c['URDF']).is_file()
    setup = (ROOT / 'setup.py').read_text()
    for pattern in ("glob('launch/*.launch.py')", "glob('config/*.yaml')",
                    "glob('urdf/*.urdf')"):
        assert pattern in setup, pattern
    text = LAUNCH.read_text()
    for arg in ('params_file', 'demo', 'demo_pattern', 'robot_state_publisher'):
        assert f"DeclareLaunchArgument('{arg}'" in text, arg
    compile(text, str(LAUNCH), 'exec')


def test_pedestal_launch_file_runs_the_pedestal_executable_on_the_installed_file():
    path = ROOT / 'launch' / 'pedestal.launch.py'
    c = launch_constants(path)
    assert 'generate_launch_description' in c['functions']
    assert console_scripts()[c['EXECUTABLE']] == 'worm_gear_sim.ros.startup:pedestal_main'
    assert (ROOT / c['PEDESTAL']).is_file() and c['PEDESTAL'] == 'config/pedestal.yaml'
    text = path.read_text()
    assert "DeclareLaunchArgument('pedestal_file'" in text and "'--pedestal'" in text
    compile(text, str(path), 'exec')
