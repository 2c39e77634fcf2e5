# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Packaging for a real ROS 2 install: package.xml declares every import as a rosdep key;
the README's workspace steps, ``colcon build`` (colcon-core + colcon-ros from PyPI, no ROS
install needed for an ament_python package) in a temporary workspace, then what
``ros2 run worm_gear_sim worm_gear_sim_node`` resolves (ament index marker -> prefix ->
``lib/worm_gear_sim/worm_gear_sim_node``), the installed config and package.xml, and the
installed executable run with the installed config, publishing JointState over DDS."""

from __future__ import annotations

import math
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from processes import start_logged, stop_and_read

from worm_gear_sim.config.files import load_config

ROOT = Path(__file__).resolve().parent.parent
PKG = 'worm_gear_sim'
EXE = 'worm_gear_sim_node'
PY = f'python{sys.version_info.major}.{sys.version_info.minor}'


def _colcon() -> str | None:
    here = Path(sys.executable).parent / 'colcon'
    return str(here) if here.exists() else shutil.which('colcon')


def _source_files() -> list[str]:
    """What a clone of this repository holds: tracked files plus new, not ignored ones (so
    the test also sees uncommitted work); without git, the tree minus venvs and outputs."""
    try:
        out = subprocess.run(['git', 'ls-files', '-z', '--cached', '--others',
                              '--exclude-standard'], cwd=ROOT, capture_output=True,
                             check=True, timeout=60).stdout.decode()
        return [f for f in out.split('\0') if f and (ROOT / f).is_file()]
    except (OSError, subprocess.SubprocessError):
        skip = {'.git', '.venv', 'build', 'install', 'log', '__pycache__'}
        return [str(p.relative_to(ROOT)) for p in ROOT.rglob('*')
                if p.is_file() and not skip & set(p.relative_to(ROOT).parts)
                and not p.relative_to(ROOT).parts[0].startswith('.venv')]


@pytest.fixture(scope='module')
def colcon_install(tmp_path_factory) -> Path:
    """The README's workspace steps (`On a real ROS 2 install`): the repository into
    ``ws/src/worm_gear_sim``, then ``colcon build --packages-select worm_gear_sim`` in
    ``ws``; returns the install base (isolated layout: <install>/worm_gear_sim/...)."""
    colcon = _colcon()
    if colcon is None:
        pytest.skip('colcon is not installed (pip install colcon-core colcon-ros '
                    'colcon-python-setup-py)')
    ws = tmp_path_factory.mktemp('ws')
    src = ws / 'src' / PKG
    for rel in _source_files():
        (src / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / rel, src / rel)
    env = dict(os.environ)
    env.pop('AMENT_PREFIX_PATH', None)
    env.pop('COLCON_PREFIX_PATH', None)
    proc = subprocess.run([colcon, 'build', '--packages-select', PKG], cwd=ws, env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert f'Finished <<< {PKG}' in proc.stdout, proc.stdout
    return ws / 'install'


def _ros_env(install: Path, base: dict[str, str]) -> dict[str, str]:
    """What sourcing install/setup.sh sets for this package."""
    prefix = install / PKG
    env = dict(base)
    env['AMENT_PREFIX_PATH'] = str(prefix)
    site = prefix / 'lib' / PY / 'site-packages'
    env['PYTHONPATH'] = os.pathsep.join([str(site)] + ([env['PYTHONPATH']]
                                                        if env.get('PYTHONPATH') else []))
    return env


def test_colcon_install_layout_resolves_like_ros2_run(colcon_install, monkeypatch):
    prefix = colcon_install / PKG
    marker = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / PKG
    assert marker.is_file()
    # `ros2 run` = ament index prefix of the package + lib/<package>/<executable>
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(prefix))
    ament = pytest.importorskip('ament_index_python.packages')
    assert Path(ament.get_package_prefix(PKG)) == prefix
    share = Path(ament.get_package_share_directory(PKG))
    exe = prefix / 'lib' / PKG / EXE
    assert exe.is_file() and os.access(exe, os.X_OK)
    demo = prefix / 'lib' / PKG / 'worm_gear_sim_demo'
    assert demo.is_file() and os.access(demo, os.X_OK)
    assert (share / 'package.xml').read_text() == (ROOT / 'package.xml').read_text()
    installed_cfg = share / 'config' / 'worm_gear_sim.yaml'
    assert installed_cfg.is_file()
    assert load_config(installed_cfg) == load_config(ROOT / 'config' / 'worm_gear_sim.yaml')
    assert (prefix / 'lib' / PY / 'site-packages' / PKG / 'ros' / 'node.py').is_file()
    urdf = share / 'urdf' / 'worm_gear_drive.urdf'      # for robot_state_publisher
    assert urdf.read_text() == (ROOT / 'urdf' / 'worm_gear_drive.urdf').read_text()
    assert not (prefix / 'bin' / EXE).exists()       # setup.cfg puts scripts in lib/<pkg>



def test_launch_file_installed_with_what_it_names(colcon_install):
    """share/worm_gear_sim/launch/worm_gear_sim.launch.py is installed and every file and
    executable it names (test/ros/test_node_launch.py checks the names against setup.py) is where
    `ros2 launch` will look for it."""
    prefix = colcon_install / PKG
    share = prefix / 'share' / PKG
    launch = share / 'launch' / 'worm_gear_sim.launch.py'
    assert launch.is_file()
    text = launch.read_text()
    assert text == (ROOT / 'launch' / 'worm_gear_sim.launch.py').read_text()
    for exe in ('worm_gear_sim_node', 'worm_gear_sim_demo'):
        assert f"'{exe}'" in text
        path = prefix / 'lib' / PKG / exe
        assert path.is_file() and os.access(path, os.X_OK), path
    for rel in ('config/worm_gear_sim.yaml', 'urdf/worm_gear_drive.urdf'):
        parts = rel.split('/')
        assert f"os.path.join('{parts[0]}', '{parts[1]}')" in text, rel
        assert (share / rel).is_file(), rel


def _share_kernel_cache(installed: Path) -> int:
    """Copy the source tree's numba cache (``__pycache__/*.nbi, *.nbc``) next to the installed
    copy of the same modules, so the installed node loads the kernels instead of compiling
    them again (30-70 s of CPU under the suite; what this test checks is the layout and the
    executable, not the compiler).  numba validates each entry against its source file
    (numba 0.68: a SHA-256 of its contents; the install copies the files unchanged) and the
    CPU: an entry that does not match is simply compiled again.  The package's stamp of its
    sources goes along (:mod:`worm_gear_sim._support.kernel_cache`): without it the installed
    package's first import took the copied cache for a stale one and deleted it, and every
    kernel was compiled again (the test took 46-53 s).  Returns the number of files copied."""
    from worm_gear_sim._support.kernel_cache import STAMP
    if (ROOT / PKG / STAMP).is_file():
        (installed / STAMP).parent.mkdir(exist_ok=True)
        shutil.copy2(ROOT / PKG / STAMP, installed / STAMP)
    n = 0
    for f in (ROOT / PKG).rglob('__pycache__/*.nb[ic]'):
        dest = installed / f.relative_to(ROOT / PKG)
        if dest.parent.parent.is_dir():
            dest.parent.mkdir(exist_ok=True)
            shutil.copy2(f, dest)
            n += 1
    return n


@pytest.mark.ros
def test_installed_executable_publishes_joint_states(colcon_install, ros_dds_context,
                                                     ros_subprocess_env, tmp_path):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64
    prefix = colcon_install / PKG
    exe = prefix / 'lib' / PKG / EXE
    cfg = prefix / 'share' / PKG / 'config' / 'worm_gear_sim.yaml'
    env = _ros_env(colcon_install, ros_subprocess_env)
    _share_kernel_cache(prefix / 'lib' / PY / 'site-packages' / PKG)
    proc, log = start_logged([str(exe), '--ros-args', '--params-file', str(cfg)], env,
                             tmp_path / 'node.log', cwd=tmp_path)
    node = rclpy.create_node('packaging_probe', context=ros_dds_context)
    ex = SingleThreadedExecutor(context=ros_dds_context)
    ex.add_node(node)
    got: list = []
    node.create_subscription(JointState, 'joint_states', got.append, 20)
    pub = node.create_publisher(Float64, 'worm_angle_command', 10)
    try:
        t0 = time.monotonic()
        while len(got) < 5 and proc.poll() is None and time.monotonic() - t0 < 120.0:
            pub.publish(Float64(data=0.1))
            ex.spin_once(timeout_sec=0.005)
    finally:
        ex.shutdown()
        node.destroy_node()
        rc, text = stop_and_read(proc, log, signal.SIGINT)
    assert len(got) >= 5, f'no JointState from the installed executable (rc {rc}):\n{text}'
    assert got[-1].position[0] == pytest.approx(0.1)
    assert all(math.isfinite(x) for x in got[-1].position)
    assert rc == 0, text
    assert 'Traceback' not in text, text
    # it ran the installed copy, not the source tree
    assert str(prefix / 'lib' / PY / 'site-packages') in subprocess.run(
        [sys.executable, '-c', 'import worm_gear_sim, sys; print(worm_gear_sim.__file__)'],
        env=env, capture_output=True, text=True, cwd=tmp_path).stdout


# ---- package.xml: every import is a declared rosdep key ------------------------------------
# Import name -> rosdep key.  ROS packages are their own keys; the others are keys of the
# rosdistro rosdep database (rosdep/python.yaml, checked 2026-08) except those in LOCAL_KEYS,
# which rosdep/worm_gear_sim.yaml defines.  A new third-party import fails the test below
# until it is added here and to package.xml.
ROSDEP_KEYS = {
    'numpy': 'python3-numpy', 'scipy': 'python3-scipy', 'yaml': 'python3-yaml',
    'numba': 'python3-numba', 'matplotlib': 'python3-matplotlib', 'tqdm': 'python3-tqdm',
    'dask': 'python3-dask', 'distributed': 'python3-distributed',
    'rosbags': 'python3-rosbags-pip', 'pytest': 'python3-pytest',
    'hypothesis': 'python3-hypothesis',
}
ROS_PACKAGES = {'rclpy', 'builtin_interfaces', 'std_msgs', 'std_srvs', 'sensor_msgs',
                'diagnostic_msgs', 'trajectory_msgs',
                'rcl_interfaces', 'rosgraph_msgs', 'ament_index_python', 'launch',
                'launch_ros'}
LOCAL_KEYS = {'python3-dask', 'python3-distributed'}
# Declared without an import: started by the launch file, not imported.
RUN_ONLY = {'robot_state_publisher'}
# Test tools in requirements.txt that a test may use before one does.
TEST_TOOLS = {'python3-hypothesis'}


def _imports(paths: list[Path]) -> set[str]:
    import ast
    names: set[str] = set()
    for path in paths:
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names.update(a.name.split('.')[0] for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split('.')[0])
            elif (isinstance(node, ast.Call) and getattr(node.func, 'attr', '') in
                  ('importorskip', 'import_module') and node.args
                  and isinstance(node.args[0], ast.Constant)):
                names.add(str(node.args[0].value).split('.')[0])
    # the tests' own helpers and the benchmarks a test runs
    local = {p.stem for d in ('test', 'benchmarks') for p in (ROOT / d).rglob('*.py')}
    return {n for n in names if n not in sys.stdlib_module_names and n != PKG
            and n not in local}


def _keys(modules: set[str]) -> set[str]:
    unknown = modules - set(ROSDEP_KEYS) - ROS_PACKAGES
    assert not unknown, f'no rosdep key known for {sorted(unknown)}: add it to package.xml ' \
                        'and ROSDEP_KEYS'
    return {ROSDEP_KEYS.get(m, m) for m in modules}


def _declared() -> dict[str, set[str]]:
    import xml.etree.ElementTree as ET
    root = ET.parse(ROOT / 'package.xml').getroot()
    out: dict[str, set[str]] = {}
    for tag in ('depend', 'exec_depend', 'test_depend', 'build_depend'):
        out[tag] = {e.text.strip() for e in root.findall(tag)}
    return out


def test_package_xml_declares_every_import_and_nothing_unused():
    runtime = _keys(_imports(sorted((ROOT / PKG).rglob('*.py'))
                             + sorted((ROOT / 'launch').glob('*.py'))))
    tests = _keys(_imports(sorted((ROOT / 'test').rglob('*.py')))) - runtime
    dec = _declared()
    run_dec = dec['depend'] | dec['exec_depend']
    assert runtime <= run_dec, f'undeclared run-time imports: {sorted(runtime - run_dec)}'
    test_dec = run_dec | dec['test_depend']
    assert tests <= test_dec, f'undeclared test imports: {sorted(tests - test_dec)}'
    unused = (run_dec - runtime - RUN_ONLY) | (dec['test_depend'] - tests - runtime - TEST_TOOLS)
    assert not unused, f'declared but imported nowhere: {sorted(unused)}'


def test_local_rosdep_keys_are_defined():
    import yaml
    rules = yaml.safe_load((ROOT / 'rosdep' / 'worm_gear_sim.yaml').read_text())
    declared = set().union(*_declared().values())
    assert set(rules) == LOCAL_KEYS & declared
    for key, rule in rules.items():       # apt package of the same name on Debian/Ubuntu
        assert rule['debian'] == [key] and rule['ubuntu'] == [key], key


def test_setup_py_and_package_xml_agree():
    import xml.etree.ElementTree as ET
    root = ET.parse(ROOT / 'package.xml').getroot()
    setup_py = (ROOT / 'setup.py').read_text()
    assert root.find('name').text == PKG
    assert f"version='{root.find('version').text}'" in setup_py
    assert root.find('export/build_type').text == 'ament_python'
