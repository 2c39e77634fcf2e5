# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Start-up of the node as a process (``python -m worm_gear_sim.ros``): every configuration
error gives one line naming the cause and exit code 2, never a traceback; Ctrl-C or SIGTERM
at any moment of the start-up (imports of numpy/scipy/numba/rclpy, rclpy.init, parameter
declaration) ends it quietly."""

from __future__ import annotations

import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip('rclpy')

pytestmark = pytest.mark.ros

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / 'config' / 'worm_gear_sim.yaml'
ERROR_PREFIX = 'worm_gear_sim_node: error: '


def _file(tmp_path: Path, name: str, text: str) -> str:
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def _cases(tmp_path: Path) -> list[tuple[list[str], list[str]]]:
    """(ROS arguments, words the one error line must contain)."""
    cfg = CONFIG.read_text()
    misspelt = cfg.replace('    module:', '    modulee:', 1)
    assert misspelt != cfg
    kinetic = cfg.replace('mu_kinetic:', 'mu_kinectic:', 1)
    assert kinetic != cfg
    d = tmp_path / 'a_directory.yaml'
    d.mkdir()
    return [
        (['--params-file', str(tmp_path / 'missing.yaml')], ['missing.yaml', 'no such file']),
        (['--params-file', str(d)], ['a_directory.yaml', 'not a regular file']),
        (['--params-file', _file(tmp_path, 'broken.yaml', 'worm_gear_sim:\n  ros__parameters:'
                                 '\n    geometry:\n      module: [3.0\n')],
         ['broken.yaml', 'line']),
        (['--params-file', _file(tmp_path, 'noros.yaml', 'worm_gear_sim:\n  params:\n    x: 1\n')],
         ['noros.yaml', 'ros__parameters']),
        (['--params-file', _file(tmp_path, 'misspelt.yaml', misspelt)],
         ['geometry.modulee', 'did you mean geometry.module?']),
        (['--params-file', _file(tmp_path, 'kinetic.yaml', kinetic)],
         ['friction.mu_kinectic', 'did you mean friction.mu_kinetic?']),
        (['--params-file', str(CONFIG), '-p', 'friction.mu_kinectic:=0.05'],
         ['friction.mu_kinectic', 'did you mean friction.mu_kinetic?']),
        (['-p', 'qos_overrides./worm_angle_comand.subscription.reliability:=reliable'],
         ['worm_angle_comand', 'did you mean qos_overrides./worm_angle_command.subscription'
                               '.reliability?']),
        (['-p', 'friction.mu_kinetic'], ["'-p friction.mu_kinetic'"]),
        (['-p', 'friction.mu_kinetic:=[1,'], ["'-p friction.mu_kinetic:=[1,'"]),
        (['-p', 'friction.mu_kinetic:=7.0'], ['friction.mu_kinetic', 'range']),
        (['-p', 'friction.mu_kinetic:=5'], ['friction.mu_kinetic', 'INTEGER', 'DOUBLE']),
        (['-p', 'friction.model:=coulomb'], ['friction.model', 'coulomb']),
        (['-p', 'input.accel_time:=0.5'], ['input.accel_time', 'move_time']),
        # an unknown section: the rule of the CLI's params files (validation.unknown_name)
        (['--params-file', _file(tmp_path, 'section.yaml', '/**:\n  ros__parameters:\n'
                                 '    bogus:\n      x: 1.0\n')],
         ['bogus.x', "unknown section 'bogus'"]),
    ]


def test_every_configuration_error_is_one_line_and_exit_code_2(tmp_path, ros_subprocess_env):
    cases = _cases(tmp_path)
    procs = []
    for i, (ros_args, _) in enumerate(cases):   # all at once: each start costs seconds
        out = open(tmp_path / f'out{i}.txt', 'w+')
        procs.append((subprocess.Popen(
            [sys.executable, '-m', 'worm_gear_sim.ros', '--ros-args', *ros_args],
            cwd=ROOT, env=ros_subprocess_env, stdout=out, stderr=subprocess.STDOUT), out))
        if i % 4 == 3:
            procs[-1][0].wait(timeout=180)
    failures = []
    for (proc, out), (ros_args, words) in zip(procs, cases):
        try:
            rc = proc.wait(timeout=180)
        except subprocess.TimeoutExpired:
            proc.kill()
            rc = 'timeout (the node started: the error was not detected)'
        out.seek(0)
        text = out.read()
        out.close()
        lines = [ln for ln in text.splitlines() if ln.strip()]
        ok = (rc == 2 and len(lines) == 1 and lines[0].startswith(ERROR_PREFIX)
              and all(w in lines[0] for w in words) and 'Traceback' not in text)
        if not ok:
            failures.append(f'{ros_args}: rc {rc}, expected words {words}:\n{text}')
    assert not failures, '\n\n'.join(failures)


def _catches_sigterm(pid: int) -> bool:
    """The process has a handler for SIGTERM (/proc SigCgt): the entry point has started.
    Python itself catches only SIGINT; before the entry point runs, the interpreter is
    still starting up (site, encodings: ~30 ms) and no code of the package can act."""
    try:
        for line in Path(f'/proc/{pid}/status').read_text().splitlines():
            if line.startswith('SigCgt:'):
                return bool(int(line.split()[1], 16) >> (signal.SIGTERM - 1) & 1)
    except OSError:
        pass
    return False


def test_early_signals_end_the_start_up_quietly(ros_subprocess_env):
    """30 SIGINT/SIGTERM at random moments of the start-up (imports of numpy, scipy, numba
    and rclpy, rclpy.init, parameter declaration, first spin), counted from the moment the
    entry point has installed its handlers: never a traceback, never a hang, exit code 0."""
    rng = random.Random(20261123)
    plan = [((signal.SIGINT, signal.SIGTERM)[i % 2], rng.uniform(0.0, 2.5)) for i in range(30)]
    failures = []
    for batch in range(0, len(plan), 5):            # 5 at a time: bounded wall time
        procs = []
        t0 = time.monotonic()
        for sig, delay in plan[batch:batch + 5]:
            procs.append((sig, delay, subprocess.Popen(
                [sys.executable, '-m', 'worm_gear_sim.ros', '--ros-args', '--params-file',
                 str(CONFIG)], cwd=ROOT, env=ros_subprocess_env, stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT, text=True)))
        started = {}
        while len(started) < len(procs) and time.monotonic() - t0 < 60.0:
            for _, _, p in procs:
                if p.pid not in started and _catches_sigterm(p.pid):
                    started[p.pid] = time.monotonic()
            time.sleep(0.0005)
        for sig, delay, p in sorted(procs, key=lambda x: started.get(x[2].pid, t0) + x[1]):
            time.sleep(max(0.0, started.get(p.pid, t0) + delay - time.monotonic()))
            p.send_signal(sig)
        for sig, delay, p in procs:
            try:
                text, _ = p.communicate(timeout=60)
            except subprocess.TimeoutExpired:
                p.kill()
                text = p.communicate()[0]
                failures.append(f'{sig.name} after {delay:.3f} s: hang\n{text}')
                continue
            if p.returncode != 0 or 'Traceback' in text or 'Fatal' in text:
                failures.append(f'{sig.name} after {delay:.3f} s: rc {p.returncode}\n{text}')
    assert not failures, '\n\n'.join(failures)


# A process that sends itself a signal at one named point of the start-up and then runs the
# node's entry point; the point is reached deterministically (an import hook, a wrapped
# constructor), not by timing.
_SELF_SIGNAL = r'''
import importlib.abc, importlib.util, os, signal, sys
where, signame = sys.argv[1], sys.argv[2]
sig = getattr(signal, signame)
if where.startswith('import:'):
    target = where.split(':', 1)[1]
    class Hook(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path, target_=None):
            if name != target:
                return None
            sys.meta_path.remove(self)
            spec = importlib.util.find_spec(name)
            real = spec.loader.exec_module
            def exec_module(module):
                os.kill(os.getpid(), sig)
                return real(module)
            spec.loader.exec_module = exec_module
            return spec
    sys.meta_path.insert(0, Hook())
from worm_gear_sim.ros.startup import node_main
if where in ('init', 'build', 'declare'):
    import rclpy
    from worm_gear_sim.ros import node as node_module
    if where == 'init':
        real_init = rclpy.init
        def init(**kw):
            os.kill(os.getpid(), sig)
            return real_init(**kw)
        rclpy.init = init
    elif where == 'build':
        real_ctor = node_module.WormGearSimNode.__init__
        def ctor(self, *a, **k):
            os.kill(os.getpid(), sig)
            real_ctor(self, *a, **k)
        node_module.WormGearSimNode.__init__ = ctor
    else:
        real_declare = rclpy.node.Node.declare_parameters
        def declare(self, *a, **k):
            os.kill(os.getpid(), sig)
            return real_declare(self, *a, **k)
        rclpy.node.Node.declare_parameters = declare
sys.argv = ['worm_gear_sim_node', '--ros-args', '--params-file', sys.argv[3]]
sys.exit(node_main())
'''


@pytest.mark.parametrize('where', ['import:numba', 'import:rclpy._rclpy_pybind11',
                                   'import:rclpy.executors', 'init', 'build', 'declare'])
def test_a_signal_at_each_point_of_the_start_up_ends_it_quietly(where, ros_subprocess_env):
    """SIGINT and SIGTERM at the imports (the process ends at once, nothing unwound), during
    rclpy.init and the node's construction (recorded; rclpy's handlers are installed only
    once the node is built): exit code 0 promptly, no traceback, no [FATAL], no abort."""
    for signame in ('SIGINT', 'SIGTERM'):
        run = subprocess.run([sys.executable, '-c', _SELF_SIGNAL, where, signame, str(CONFIG)],
                             cwd=ROOT, env=ros_subprocess_env, capture_output=True, text=True,
                             timeout=60)
        text = run.stdout + run.stderr
        assert run.returncode == 0, f'{where} {signame}: rc {run.returncode}\n{text}'
        assert 'Traceback' not in text and 'FATAL' not in text and 'free(' not in text, text
        assert 'spinning with' not in text, f'{where} {signame}: the node went on\n{text}'


# The context shut down at the worst moment of the events executor's first update: while it
# registers the nodes' waitables (a waitable's get_num_entities is where it asks them).  Until
# the fix this left callbacks the executor no longer tracked, and destroying it aborted the
# process ("Destroying callback manager with callbacks remaining", rc -6).  'signal' sends
# SIGTERM there (the node is in phase 'init': recorded only); 'shutdown' shuts the context
# down directly, as rclpy's signal thread does, which nothing in the start-up can prevent.
_MID_REGISTRATION = r'''
import os, signal, sys
import rclpy
from worm_gear_sim.ros import run
how = sys.argv[1]
real_build = run._build
def build(*a, **k):
    nodes = real_build(*a, **k)
    waitables = list(nodes[0].waitables)
    w = waitables[len(waitables) // 2]
    real = w.get_num_entities
    def hooked():
        if how == 'signal':
            os.kill(os.getpid(), signal.SIGTERM)
        else:
            rclpy.get_default_context().try_shutdown()
        return real()
    w.get_num_entities = hooked
    return nodes
run._build = build
from worm_gear_sim.ros.startup import node_main
sys.argv = ['worm_gear_sim_node', '--ros-args', '--params-file', sys.argv[2]]
sys.exit(node_main())
'''


@pytest.mark.parametrize('how', ['signal', 'shutdown'])
def test_a_shutdown_while_the_executor_registers_the_node_ends_quietly(how, ros_subprocess_env):
    run = subprocess.run([sys.executable, '-c', _MID_REGISTRATION, how, str(CONFIG)],
                         cwd=ROOT, env=ros_subprocess_env, capture_output=True, text=True,
                         timeout=60)
    text = run.stdout + run.stderr
    assert run.returncode == 0, f'{how}: rc {run.returncode}\n{text}'
    assert 'Traceback' not in text and 'Fatal' not in text and 'Destroying' not in text, text


# The same cut-short registration in the package's helper processes (the plant node of the
# live adaptation harness; the demo commander shares the code path: run.after_shutdown, leave).
_PLANT_MID_REGISTRATION = r'''
import sys
import rclpy
from worm_gear_sim.ros import plant
Real = plant.PlantNode
class Hooked(Real):
    def __init__(self, *a, **k):
        super().__init__(*a, **k)
        waitables = list(self.waitables)
        w = waitables[len(waitables) // 2]
        real = w.get_num_entities
        def hooked():
            rclpy.get_default_context().try_shutdown()
            return real()
        w.get_num_entities = hooked
plant.PlantNode = Hooked
sys.exit(plant.main(['plant', '--plant', sys.argv[1], '--record', sys.argv[2]]))
'''


def test_the_plant_node_ends_quietly_when_a_shutdown_cuts_its_registration(
        ros_subprocess_env, tmp_path):
    record = tmp_path / 'plant.npz'
    run = subprocess.run([sys.executable, '-c', _PLANT_MID_REGISTRATION, str(CONFIG),
                          str(record)], cwd=ROOT, env=ros_subprocess_env,
                         capture_output=True, text=True, timeout=60)
    text = run.stdout + run.stderr
    assert run.returncode == 0, f'rc {run.returncode}\n{text}'
    assert 'Fatal' not in text and 'Destroying' not in text, text
    assert 'plant: ' in text and record.exists()      # its exit work done before it left


def test_stop_signals_in_a_row_end_the_node_quietly(ros_subprocess_env, tmp_path):
    """Ctrl-C, then SIGTERM again and again until the process is gone (a terminal's Ctrl-C
    reaching the node while a script or a launch system stops it too): exit code 0 whatever
    phase of the stop each signal hits, the interpreter's own exit included (a signal there
    once ended the process with the default action, rc 143)."""
    import os

    from processes import start_logged
    for sig in (signal.SIGINT, signal.SIGTERM):
        proc, log = start_logged([sys.executable, '-m', 'worm_gear_sim.ros', '--ros-args',
                                  '--params-file', str(CONFIG)], ros_subprocess_env,
                                 tmp_path / f'node_{sig.name}.log')
        try:
            deadline = time.monotonic() + 120.0
            while 'spinning with' not in Path(log.name).read_text() and proc.poll() is None \
                    and time.monotonic() < deadline:
                time.sleep(0.05)
            assert proc.poll() is None, Path(log.name).read_text()
            proc.send_signal(sig)
            end = time.monotonic() + 30.0
            while proc.poll() is None and time.monotonic() < end:
                try:
                    os.kill(proc.pid, signal.SIGTERM)
                except ProcessLookupError:
                    break
                time.sleep(0.001)
            rc = proc.wait(timeout=30)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            log.close()
        text = Path(log.name).read_text()
        assert rc == 0, f'{sig.name} then SIGTERMs: rc {rc}\n{text}'
        assert 'Traceback' not in text and 'FATAL' not in text, text
