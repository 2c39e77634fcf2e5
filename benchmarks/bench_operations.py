# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Operations soak: the node in operation with real processes, against invariants.

    ROS_DOMAIN_ID=131 python benchmarks/bench_operations.py --minutes 10

Starts the node (``python -m worm_gear_sim.ros``, adaptation on, load and drag estimated,
``adaptation.params_file`` in the work directory) and a plant node (``python -m
worm_gear_sim.ros.plant``: 3 N m of load and 10 N m s/rad of drag, none in the node's
model) as processes, with the harness of the live adaptation
(:mod:`worm_gear_sim.ros.live_adaptation`: the processes, the handshake, the stamped sector
scan streamed on the simulated clock).  This process is the operator: once the load is
learnt it runs, in turn until the time is up, with ``--settle`` seconds of scan after each:

* a pause of the servo (no reference for 0.5 s of stream time: the node holds as stale),
  then the scan resumes;
* parameter sets: ``adaptation.params_file`` to its own value, ``node.max_command_jump``;
* ``adaptation.enabled`` false, then true;
* encoder glitches on ``measured_joint_states``: 1e300, NaN, the antenna named twice,
  another drive's encoder (+3 rad), then a flood (``--flood`` messages at once);
* ``~/write_adapted_parameters``, then the node stopped and started again from the file
  it wrote (the scan paused meanwhile, the plant goes on);
* five trajectories on ``reference_trajectory`` at once, each replacing the one before;

and prints each invariant with its figure: the processes that ended by themselves
(crashes), tracebacks in their logs, silent resets (an operation after which the model in
use is back at the declared load without a reset), the stamped references sent outside the
deliberate pauses and how many came back answered (the plant's encoder sample stamped with
each one's stamp), and the learnt load against the plant's after every operation (within
10 %), the trajectories compensated.  ``test/ros/test_operations_soak.py`` runs it for 45 s.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

LOAD, DRAG = 'load.output_torque', 'load.output_viscous_coefficient'
PLANT = {LOAD: 3.0, DRAG: 10.0}
START = {'adaptation.keys': [LOAD, DRAG], 'adaptation.window': 0.5,
         'adaptation.step_interval': 0.1, 'adaptation.max_step': 0.05}
TOLERANCE = 0.10
PAUSE_S = 0.5


def _commander_class() -> Any:
    from worm_gear_sim.ros.live_adaptation import ScenarioCommander

    class OperatorCommander(ScenarioCommander):
        """The scan's commander with pauses; keeps the stamps sent and answered."""

        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            self.paused = False
            self.sent: list[int] = []
            self.answered: set[int] = set()
            self.last_position = 0.0

        def pause(self) -> None:
            self.paused = True

        def resume(self) -> None:
            """The scan goes on where it stopped, stamped after the clock."""
            ahead = int(self.ahead * 1e9)
            if self.t0_ns is not None:
                gap = self.clock_ns + ahead + self.period_ns - self.stamp(self.k_next)
                if gap > 0:
                    self.t0_ns += gap
            drive = self.streams[0]
            drive.last_measured_ns = max(drive.last_measured_ns, self.clock_ns)
            self._wall = time.monotonic()
            self.paused = False

        def _on_timer(self) -> None:
            if self.paused:           # the clock runs with the wall clock, no reference
                wall = time.monotonic()
                self.clock_ns += int((wall - self._wall) * self.speed * 1e9)
                self._wall = wall
                c = self._clock_msg
                c.clock.sec, c.clock.nanosec = divmod(self.clock_ns, 1_000_000_000)
                self.pub_clock.publish(c)
                return
            k = self.k_next
            super()._on_timer()
            if self.t0_ns is not None and not self.holding:
                self.sent.extend(self.stamp(i) for i in range(k, self.k_next))

        def _on_measured(self, s: Any, msg: Any) -> None:
            super()._on_measured(s, msg)
            ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            self.answered.add(ns)
            if msg.position:
                self.last_position = float(msg.position[-1])

    return OperatorCommander


def run_operations(minutes: float, *, context: Any, env: dict[str, str], workdir: Path,
                   settle: float = 1.5, flood: int = 500, log: Any = print) -> dict[str, Any]:
    """The soak (module docstring); returns its figures."""
    from rcl_interfaces.msg import Parameter as ParameterMsg
    from rcl_interfaces.msg import ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import JointState
    from std_srvs.srv import Trigger
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from worm_gear_sim.config.usable import Config
    from worm_gear_sim.records.topics import (
        COMPENSATED_TRAJECTORY_TOPIC,
        MEASURED_TOPIC,
        TRAJECTORY_TOPIC,
        private_topic,
    )
    from worm_gear_sim.ros.live_adaptation import (
        node_command,
        plant_command,
        start_process,
        stop_process,
        write_params,
    )
    from worm_gear_sim.schema.sections import NODE_NAME
    from worm_gear_sim.studies.adaptation_twin import prepare_start, scenario

    workdir.mkdir(parents=True, exist_ok=True)
    params_file = workdir / 'adapted.yaml'
    cfg = prepare_start(Config().replace({**START,
                                          'adaptation.params_file': str(params_file)}))
    plant = Config().replace(PLANT)
    ahead = cfg.compensation.preview_time + 0.02
    max_lag = 0.5 * (cfg.adaptation.sample_delay - 0.02)
    seconds = minutes * 60.0 + 60.0
    t, x = scenario(cfg, 'sector', seconds)
    antenna = cfg.node.joint_names[3]
    logs: list[str] = []
    crashes = 0
    commander = _commander_class()(t, [('', cfg.node.joint_names[0], x)], ahead,
                                   max_lag=max_lag, context=context)
    glitch_pub = commander.create_publisher(JointState, MEASURED_TOPIC, 1000)
    traj_pub = commander.create_publisher(JointTrajectory, TRAJECTORY_TOPIC, 1000)
    trajectories = {'sent': 0, 'answered': 0}

    def on_trajectory(msg: Any) -> None:
        trajectories['answered'] += 1

    commander.create_subscription(JointTrajectory, '/' + private_topic(
        COMPENSATED_TRAJECTORY_TOPIC, NODE_NAME), on_trajectory, 10)
    ex = SingleThreadedExecutor(context=context)
    ex.add_node(commander)
    figures: dict[str, Any] = {'operations': 0, 'loads': [], 'silent_resets': 0,
                               'failed_calls': 0, 'restarts_of_node': 0, 'stalls': 0}
    declared_load = float(cfg.to_flat_dict()[LOAD])
    pause_windows: list[tuple[int, int]] = []
    stopped: list[int] = []       # the last stamp sent before each stop of the node
    marks: list[tuple[int, str]] = []      # the last stamp sent before each operation
    starting: list[tuple[int, int]] = []   # a restarted node: first stamp sent, answered

    def spin(seconds: float, until: Any = None) -> bool:
        """Spin for ``seconds`` or until ``until()``; True if it came.  A stream that
        answers nothing for 2 s goes on (the clock past the last answer): its commands
        were lost, e.g. sent by a restarted node before the plant matched its publisher."""
        end = time.monotonic() + seconds
        seen, t_seen = commander.measured_count, time.monotonic()
        while time.monotonic() < end:
            if until is not None and until():
                return True
            ex.spin_once(timeout_sec=0.005)
            if node_p.poll() is not None or plant_p.poll() is not None:
                raise RuntimeError('a process ended')
            now = time.monotonic()
            if commander.measured_count != seen or commander.paused:
                seen, t_seen = commander.measured_count, now
            elif now - t_seen > 2.0:    # nothing answered for 2 s: the clock goes on
                figures['stalls'] += 1
                commander.streams[0].last_measured_ns = commander.clock_ns
                t_seen = now
        return until is not None and until()

    def wait(ready: Any, what: str, timeout: float = 120.0) -> None:
        end = time.monotonic() + timeout
        while not ready():
            if time.monotonic() > end or node_p.poll() is not None or \
                    plant_p.poll() is not None:
                raise RuntimeError(what)
            ex.spin_once(timeout_sec=0.01)

    def call(srv_type: Any, name: str, request: Any) -> Any:
        client = commander.create_client(srv_type, f'/{NODE_NAME}/{name}')
        try:
            wait(lambda: client.service_is_ready(), f'{name} not ready', 30.0)
            fut = client.call_async(request)
            wait(fut.done, f'{name} unanswered', 30.0)
            return fut.result()
        finally:
            commander.destroy_client(client)

    def set_parameter(name: str, value: Any) -> bool:
        v = ParameterValue()
        if isinstance(value, bool):
            v.type, v.bool_value = ParameterType.PARAMETER_BOOL, value
        elif isinstance(value, float):
            v.type, v.double_value = ParameterType.PARAMETER_DOUBLE, value
        else:
            v.type, v.string_value = ParameterType.PARAMETER_STRING, str(value)
        req = SetParameters.Request(parameters=[ParameterMsg(name=name, value=v)])
        res = call(SetParameters, 'set_parameters', req)
        ok = bool(res.results[0].successful)
        figures['failed_calls'] += not ok
        return ok

    def glitch(names: list[str], values: list[float]) -> None:
        m = JointState(name=names, position=values)
        ns = commander.last_measured_ns + 1
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(ns, 1_000_000_000)
        glitch_pub.publish(m)

    def in_use_load() -> float:
        return float(commander.adapted.get('in_use', {}).get(LOAD, float('nan')))

    def operation(name: str, action: Any) -> None:
        marks.append((commander.sent[-1] if commander.sent else 0, name))
        action()
        spin(settle)
        load = in_use_load()
        figures['operations'] += 1
        figures['loads'].append((name, load))
        if load == declared_load:
            figures['silent_resets'] += 1
        log(f'  {name:<28} learnt load {load:.3f} N m (plant {PLANT[LOAD]:g})')

    def pause() -> None:
        commander.pause()
        t0 = commander.clock_ns
        spin(PAUSE_S)
        pause_windows.append((t0, commander.clock_ns))
        commander.resume()

    def restart() -> None:
        nonlocal node_p, node_fh
        res = call(Trigger, 'write_adapted_parameters', Trigger.Request())
        figures['failed_calls'] += not res.success
        commander.pause()
        stopped.append(commander.sent[-1] if commander.sent else 0)
        logs.append(stop_process(node_p, node_fh))
        figures['restarts_of_node'] += 1
        args = node_command(params_file)
        log = workdir / f'node-{figures["restarts_of_node"]}.log'
        node_p, node_fh = start_process(args, env, log)
        commander._alive.clear()          # until the new node's /diagnostics
        commander.streams[0].adapted = {}
        wait(commander.connected, 'the restarted node did not connect')
        commander.resume()
        first_sent = len(commander.sent)
        wait(lambda: bool(commander.adapted), 'no ~/adapted_parameters after the restart',
             60.0)
        # until the restarted node's first answer (its publisher matched by the plant; the
        # commands it sent before are lost and the stream goes on after 2 s without answer)
        answered = len(commander.answered)
        if not spin(60.0, lambda: len(commander.answered) > answered):
            raise RuntimeError('no answer after the restart')
        first = max(commander.answered)
        starting.append((commander.sent[first_sent] if len(commander.sent) > first_sent
                         else first, first))

    def glitches() -> None:
        near = commander.last_position
        for names, values in (([antenna], [1e300]), ([antenna], [float('nan')]),
                              ([antenna, antenna], [near, near]), ([antenna], [near + 3.0])):
            glitch(names, values)
            spin(0.05)

    def flood_() -> None:
        for _ in range(flood):
            glitch([antenna], [commander.last_position])

    def replace_trajectories() -> None:
        """Five trajectories of 2 s (a slew of the worm), each replacing the one before."""
        for j in range(5):
            msg = JointTrajectory(joint_names=[cfg.node.joint_names[0]])
            for i in range(21):
                point = JointTrajectoryPoint(positions=[0.05 * (j + 1) * i / 20])
                point.time_from_start.sec, point.time_from_start.nanosec = divmod(
                    i * 100_000_000, 1_000_000_000)
                msg.points.append(point)
            traj_pub.publish(msg)
            trajectories['sent'] += 1

    operations = [
        ('pause and resume', pause),
        ('params_file to its value', lambda: set_parameter(
            'adaptation.params_file', str(params_file))),
        ('node.max_command_jump', lambda: set_parameter('node.max_command_jump', 1.0)),
        ('adaptation off', lambda: set_parameter('adaptation.enabled', False)),
        ('adaptation on', lambda: set_parameter('adaptation.enabled', True)),
        ('encoder glitches', glitches),
        (f'encoder flood ({flood})', flood_),
        ('write + restart from file', restart),
        ('trajectory replacements (5)', replace_trajectories),
    ]
    # the processes last, right before the try that stops them whatever happens
    node_args = node_command(write_params(cfg, workdir / 'start.yaml'))
    node_p, node_fh = start_process(node_args, env, workdir / 'node-0.log')
    plant_p, plant_fh = start_process(
        plant_command(write_params(plant, workdir / 'plant.yaml'), workdir / 'plant_record.npz',
                      noise=1e-6, encoder_bits=20, seed=1), env, workdir / 'plant.log')
    wall0 = time.monotonic()
    try:
        wait(commander.connected, 'the node and the plant did not connect')
        commander.start()
        wait(commander.streaming, 'the plant did not answer')
        # learnt first: the load within the tolerance
        wait(lambda: abs(in_use_load() - PLANT[LOAD]) <= TOLERANCE * PLANT[LOAD],
             'the load was not learnt', 60.0)
        log(f'learnt {in_use_load():.3f} N m after {time.monotonic() - wall0:.1f} s')
        end = wall0 + minutes * 60.0
        i = 0
        while time.monotonic() < end and not commander.done():
            name, action = operations[i % len(operations)]
            operation(name, action)
            i += 1
        spin(0.5)
    except RuntimeError as exc:
        log(f'stopped: {exc}')
        figures['stopped'] = str(exc)
    finally:
        crashes += node_p.poll() is not None
        crashes += plant_p.poll() is not None
        logs.append(stop_process(node_p, node_fh))
        logs.append(stop_process(plant_p, plant_fh))
        if 'stopped' in figures:            # what the processes said last, for the report
            for name, text in (('node', logs[-2]), ('plant', logs[-1])):
                log(f'  the {name}\'s log ends:')
                for line in text.splitlines()[-8:]:
                    log(f'    {line}')
        ex.shutdown()
        commander.destroy_node()
    # the last ~1 s of stream may still be in flight: only stamps answered in time count
    last = max(commander.answered) if commander.answered else 0
    sent = [ns for ns in commander.sent if ns <= last]
    answered = sum(ns in commander.answered for ns in sent)
    # unanswered because the node was stopped (a restart) with them in flight
    flight = int(round((ahead + max_lag) * 1e9)) + 2 * commander.period_ns
    in_flight = sum(ns not in commander.answered and any(0 <= s - ns <= flight
                                                         for s in stopped) for ns in sent)
    # sent to a restarted node before its first answer (its publisher not matched yet)
    before_first = sum(ns not in commander.answered and any(a <= ns < b for a, b in starting)
                       for ns in sent)
    # the others, by the operation they followed
    after: dict[str, int] = {}
    for ns in sent:
        if ns in commander.answered or any(0 <= s - ns <= flight for s in stopped) or \
                any(a <= ns < b for a, b in starting):
            continue
        name = max((m for m in marks if m[0] < ns), default=(0, 'before any'))[1]
        after[name] = after.get(name, 0) + 1
    loads = np.array([v for _, v in figures['loads']], float)
    figures.update(
        crashes=crashes, tracebacks=sum(text.count('Traceback') for text in logs),
        sent=len(sent), answered=answered, pauses=len(pause_windows), in_flight=in_flight,
        unanswered_after=after, before_first_answer=before_first,
        load_within=int(np.sum(np.abs(loads - PLANT[LOAD]) <= TOLERANCE * PLANT[LOAD])),
        load_worst=float(np.max(np.abs(loads - PLANT[LOAD]) / PLANT[LOAD])) if loads.size
        else float('nan'),
        wall_s=time.monotonic() - wall0, trajectories_sent=trajectories['sent'],
        trajectories_answered=trajectories['answered'])
    return figures


def report(f: dict[str, Any], log: Any = print) -> None:
    log(f'crashes (a process ended by itself)   {f["crashes"]}')
    log(f'tracebacks in the logs                {f["tracebacks"]}')
    log(f'silent resets (load back to declared) {f["silent_resets"]} of '
        f'{f["operations"]} operations')
    log(f'stamped references answered / sent    {f["answered"]} / {f["sent"]} '
        f'(outside {f["pauses"]} deliberate pauses; of the others, in flight when the '
        f'node was stopped for a restart: {f["in_flight"]}, sent to a restarted node before '
        f'its first answer: {f["before_first_answer"]})')
    if f['unanswered_after']:
        log(f'  the other unanswered, by the operation they followed: {f["unanswered_after"]}')
    log(f'learnt load within 10 % of the plant  {f["load_within"]} of {f["operations"]} '
        f'operations (worst {100 * f["load_worst"]:.1f} %)')
    log(f'refused calls                         {f["failed_calls"]}')
    log(f'trajectories compensated / sent       {f["trajectories_answered"]} / '
        f'{f["trajectories_sent"]} (a replaced one may be superseded)')
    log(f'node restarts from its written file   {f["restarts_of_node"]}')
    log(f'stalls (nothing answered for 2 s)     {f["stalls"]}')
    log(f'wall time                             {f["wall_s"]:.0f} s')


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--minutes', type=float, default=10.0)
    ap.add_argument('--settle', type=float, default=1.5,
                    help='scan after each operation before the load is read [s]')
    ap.add_argument('--flood', type=int, default=500)
    args = ap.parse_args(argv)
    import rclpy
    domain = int(os.environ.get('ROS_DOMAIN_ID', '0'))
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED='1')
    env.pop('ROS_STATIC_PEERS', None)
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=domain)
    print(f'load: {os.getloadavg()}')
    try:
        with tempfile.TemporaryDirectory() as tmp:
            figures = run_operations(args.minutes, context=ctx, env=env, workdir=Path(tmp),
                                     settle=args.settle, flood=args.flood)
    finally:
        rclpy.try_shutdown(context=ctx)
    report(figures)
    print(f'load: {os.getloadavg()}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
