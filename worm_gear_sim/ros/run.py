# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The node's process: ``rclpy.init``, the executor, spinning until Ctrl-C / SIGTERM, and
the exit codes (0 after a signal at any time, 2 after a one-line configuration error).

Reached through :func:`worm_gear_sim.ros.startup.node_main` (console script
``worm_gear_sim_node``, ``python -m worm_gear_sim.ros``), which installs the start-up
signal handlers before the heavy imports.
"""

from __future__ import annotations

import argparse
import gc
import os
import sys
from typing import Any

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy_impl
from rclpy.signals import SignalHandlerOptions
from rclpy.signals import install_signal_handlers as install_rclpy_signal_handlers
from rclpy.task import Future
from rclpy.utilities import remove_ros_args

from ..schema.validation import ConfigError
from . import signals
from .config_errors import check_params_files, clean_rcl_message, config_error
from .node import WormGearSimNode
from .teardown import teardown_deadline

RCLError = _rclpy_impl.RCLError          # RCLInvalidROSArgsError derives from it

__all__ = ['main', 'make_executor', 'spin_until_shutdown', 'after_shutdown', 'leave',
           'STARTUP_CONFIG_ERRORS']

#: Errors of the parameters given at start-up: one line and exit code 2 (``config_errors``).
#: ValueError covers numerically unusable values (LinAlgError is one) until the core proves
#: a set usable itself.
STARTUP_CONFIG_ERRORS = (ConfigError, ParameterException, ValueError, ArithmeticError)


def make_executor(kind: str, context: Any = None) -> Any:
    """'events' (rclpy.experimental.EventsExecutor) or 'single_threaded'."""
    if kind == 'events':
        from rclpy.experimental import EventsExecutor
        return EventsExecutor(context=context)
    if kind == 'single_threaded':
        return SingleThreadedExecutor(context=context)
    raise ValueError(f'unknown executor {kind!r} (events | single_threaded)')


def spin_until_shutdown(executor: Any, context: Any = None, slice_s: float = 1.0) -> None:
    """Spin until the context shuts down (Ctrl-C, SIGTERM, rclpy.shutdown).

    The loop runs ``spin_until_future_complete`` on a future that never completes, with a
    finite ``slice_s``: with ros-rclpy 9.1.2 from PyPI, ``EventsExecutor.spin()`` (an
    unbounded deadline) busy-waits at 100 % CPU and never dispatches wall-clock timers, while
    a bounded deadline works (0.1 core for an empty 1 kHz timer).  Each slice processes
    every event until its deadline, so this is not a ``spin_once`` loop.
    """
    ctx = context if context is not None else rclpy.get_default_context()
    never = Future()
    while ctx.ok():
        executor.spin_until_future_complete(never, timeout_sec=slice_s)


def _parse_args(argv: list[str], pedestal: bool) -> argparse.Namespace:
    if pedestal:
        ap = argparse.ArgumentParser(
            prog='worm_gear_sim_pedestal',
            description='N worm drives (a pedestal: azimuth and elevation) in one process: '
                        'one node per drive in its namespace, plus the pedestal node that '
                        'splits and merges multi-joint trajectories (docs/pedestal.md).')
        ap.add_argument('--pedestal', default=None, metavar='PEDESTAL.yaml',
                        help='the drives (default: the package\'s config/pedestal.yaml)')
    else:
        ap = argparse.ArgumentParser(
            prog='worm_gear_sim_node',
            description='Worm-gear drive model in real time (parameters: --ros-args '
                        '--params-file config/worm_gear_sim.yaml).')
    ap.add_argument('--executor', choices=('events', 'single_threaded'), default=None,
                    help='override the node.executor parameter')
    return ap.parse_args(argv)


def main(args: list[str] | None = None, pedestal: bool = False) -> int:
    """Entry point of ``worm_gear_sim_node`` and ``python -m worm_gear_sim.ros`` (through
    :func:`worm_gear_sim.ros.startup.node_main`, which installs the signal handlers before
    the heavy imports).

    Returns 0 after Ctrl-C / SIGTERM at any time (no traceback), 2 after one line naming a
    configuration error (broken, missing or unreadable params file, malformed ``-p``,
    unknown or misspelt parameter, invalid or unusable value).  Portable across rclpy 7
    (Jazzy) and 9 (Kilted): ``rclpy.init`` + ``try/finally rclpy.try_shutdown()``.
    """
    signals.install_signal_handlers()
    argv = list(sys.argv if args is None else args)
    bad = check_params_files(argv)
    if bad:
        return config_error(bad)
    try:   # parses --ros-args, params files included: errors end here, before rclpy.init
        rest = remove_ros_args(args=argv)
    except RCLError as exc:
        return config_error(clean_rcl_message(exc))
    opts = _parse_args(rest[1:], pedestal)
    # From here until the node is built a signal is only recorded (.signals, phase 'init'):
    # rclpy's handler, which shuts every context down from its own thread, is installed
    # only when the node exists, so it never races rclpy.init or the node's construction.
    signals.set_phase('init')
    try:
        rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    except RCLError as exc:
        if signals.signalled():
            return 0
        return config_error(clean_rcl_message(exc))
    try:
        rc = _run(opts, pedestal)
    except (KeyboardInterrupt, ExternalShutdownException):
        rc = 0
    finally:
        signals.set_phase('stopping')
        with teardown_deadline():
            _quietly(rclpy.try_shutdown)
        signals.ignore_from_now()
    return leave(rc)


def _build(opts: argparse.Namespace, pedestal: bool) -> list[Any]:
    """The process's nodes: one drive, or a pedestal's drives and its trajectory node."""
    if not pedestal:
        return [WormGearSimNode()]
    from .pedestal import build_pedestal
    return build_pedestal(opts.pedestal)


def _run(opts: argparse.Namespace, pedestal: bool = False) -> int:
    context = rclpy.get_default_context()
    try:
        nodes = _build(opts, pedestal)
    except STARTUP_CONFIG_ERRORS as exc:
        if signals.signalled():     # Ctrl-C / SIGTERM came first: a quiet exit
            return 0
        return config_error(f'invalid parameters: {exc}')
    node = nodes[0]
    kind = opts.executor or node.config.node.executor
    executor = make_executor(kind)
    # Move everything allocated so far (numba, scipy, rclpy: a large heap) out of the
    # cyclic GC's reach: full collections of it took milliseconds and showed up as missed
    # ticks.  The nodes' warm-up collected the garbage of compiling before they said
    # "ready" (worm_gear_sim.adaptation.warmup): another full collection here, after "ready", took
    # 0.6 s with 380 000 objects on a loaded machine.
    gc.freeze()
    for n in nodes:
        executor.add_node(n)
    try:
        _register(executor, kind)
        # rclpy's handlers from now on (they chain to .signals, which ignores the 'ros'
        # phase): installed first, checked second, so that no signal falls between the two.
        signals.set_phase('ros')
        install_rclpy_signal_handlers(SignalHandlerOptions.ALL)
        if signals.signalled() or not context.ok():   # Ctrl-C / SIGTERM during the build
            return 0
        node.get_logger().info(f'spinning with the {kind} executor')
        spin_until_shutdown(executor, context)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        # The context went down while the executor was working: a callback publishing on
        # a context being torn down, or the events executor half-way through registering
        # the nodes' entities, which it cannot undo (after_shutdown).
        if not after_shutdown(executor, context):
            raise
    finally:
        signals.set_phase('stopping')
        with teardown_deadline():       # Fast DDS can hang in it (.teardown)
            _quietly(executor.shutdown, 1.0)
            for n in nodes:
                _quietly(n.destroy_node)
    return 0


def _register(executor: Any, kind: str) -> None:
    """Let the events executor register the nodes' subscriptions, timers, services and
    waitables (the update ``add_node`` posts, run by one ``spin_once``) while a signal is
    only recorded (phase 'init').  rclpy's signal handler shuts the context down from its
    own thread: in the middle of that registration it left callbacks the executor no
    longer tracks, and destroying the executor then aborted the process ("Destroying
    callback manager with callbacks remaining", rclpy 9.1.2)."""
    if kind == 'events':
        executor.spin_once(timeout_sec=1.0)


#: Executors whose destruction would abort the process (rclpy's EventsExecutor after a
#: registration interrupted by a shutdown, :func:`after_shutdown`): kept alive; the process
#: then ends by ``leave``.
_UNSAFE_TO_DESTROY: list[Any] = []


def after_shutdown(executor: Any, context: Any = None) -> bool:
    """Whether an exception out of the executor came with the context going down (a
    shutdown, not an error: True).  An events executor that raised so may hold callbacks it
    no longer tracks (a registration cut short): destroying it would abort the process, so
    it is kept alive, and the entry point ends through :func:`leave`."""
    ctx = context if context is not None else rclpy.get_default_context()
    if ctx.ok():
        return False
    if executor is not None and not isinstance(executor, SingleThreadedExecutor):
        _UNSAFE_TO_DESTROY.append(executor)
    return True


def leave(rc: int) -> int:
    """``rc``, or, after :func:`after_shutdown` kept an executor, the process ended now
    with ``rc`` (os._exit after flushing stdout and stderr: the interpreter's own exit
    would destroy the kept executor and abort)."""
    if _UNSAFE_TO_DESTROY:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(rc)
    return rc


def _quietly(fn: Any, *args: Any) -> None:
    try:
        fn(*args)
    except Exception:  # noqa: BLE001 - best effort at shutdown
        pass

