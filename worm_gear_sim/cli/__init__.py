# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``worm-gear-sim``: the offline command line (no ROS needed).

One module per command group, each with a ``register(subparsers)`` function; a new command
group is one more name in :data:`COMMAND_MODULES`.  Every command takes ``--config`` (YAML
in the ROS layout or plain sections, or a JSON written by ``params``) and repeatable
``--set key=value`` dotted overrides (:mod:`worm_gear_sim.config.files`).  Errors are reported
as one line on stderr with a non-zero exit status (2: bad usage or input, 1: the run failed);
``--debug`` shows the traceback instead.  See docs/studies.md.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from .._support.kernel_cache import take_note
from ..config.files import (
    PARAMS_FORMAT,
    load_params_json,
    params_document,
    parse_set,
    resolve_config,
)
from ..schema.validation import ConfigError
from .common import PROG, CliError, Parser

__all__ = ['main', 'build_parser', 'resolve_config', 'parse_set', 'params_document',
           'load_params_json', 'CliError', 'PARAMS_FORMAT', 'COMMAND_MODULES', 'COMMANDS']

#: The command groups, in --help order: modules of this package with ``register(sub)``.
COMMAND_MODULES: tuple[str, ...] = (
    'simulate',      # simulate
    'studies',       # experiment, sweep
    'modes',         # modes, params
    'compensate',    # compensate
    'identify',      # identify
    'calibrate',     # calibrate
    'tracking_pass',  # pass
    'adapt',         # adapt
)
#: Each command's module: a command line that names one imports only that module (the others
#: pull in identification, Dask or matplotlib; a process pays for what it runs).
COMMANDS: dict[str, str] = {
    'simulate': 'simulate', 'experiment': 'studies', 'sweep': 'studies', 'modes': 'modes',
    'params': 'modes', 'compensate': 'compensate', 'identify': 'identify',
    'calibrate': 'calibrate', 'pass': 'tracking_pass', 'adapt': 'adapt',
}


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The argparse tree of ``worm-gear-sim`` (subcommands set ``func``): every command's,
    or, when ``argv`` names a command, that command's only (:data:`COMMANDS`)."""
    from .. import __version__
    parser = Parser(prog=PROG, description='Offline studies of the Chung & Shaw (2007) '
                    'worm-gear model: simulate, reproduce the experiment and parametric '
                    'studies, modes and resolved parameters.')
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    parser.add_argument('--debug', action='store_true',
                        help='show the full traceback on errors')
    parser.add_argument('--quiet', '-q', action='store_true', help='print less')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND', parser_class=Parser)
    named = [a for a in (argv or ()) if a in COMMANDS][:1]
    modules = [COMMANDS[named[0]]] if named else COMMAND_MODULES
    for name in modules:
        importlib.import_module(f'{__name__}.{name}').register(sub)
    parser.set_defaults(func=None, commands=tuple(COMMANDS))
    return parser


def _one_line(msg: str) -> str:
    return ' '.join(str(msg).split())


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``worm-gear-sim`` and ``python -m worm_gear_sim``; returns the exit
    status (0 ok, 1 the run failed, 2 bad usage or input, 130 interrupted)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = '--debug' in argv
    note = take_note()                  # the kernel cache is not the package's folder
    if note:
        print(note, file=sys.stderr)
    try:
        parser = build_parser(argv)
        args = parser.parse_args(argv)
        if not getattr(args, 'func', None):
            raise CliError(f'a command is required ({", ".join(args.commands)}); '
                           f'see {PROG} --help')
        args._argv = argv
        status = args.func(args)
        return int(status or 0)
    except SystemExit as exc:            # --help / --version
        code = exc.code
        return code if isinstance(code, int) else (0 if code is None else 2)
    except KeyboardInterrupt:
        print(f'{PROG}: interrupted', file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - every error becomes one line
        if debug:
            raise
        status, text = _describe(exc)
        prog = exc.prog if isinstance(exc, CliError) else PROG
        print(f'{prog}: error: {_one_line(text)}', file=sys.stderr)
        return status


def _describe(exc: BaseException) -> tuple[int, str]:
    from ..dynamics.stepping import SimulationError
    if isinstance(exc, CliError):
        return 2, str(exc)
    if isinstance(exc, ConfigError):
        return 2, str(exc)
    if isinstance(exc, (FileNotFoundError, IsADirectoryError, PermissionError)):
        name = getattr(exc, 'filename', None)
        return 2, f'{exc.strerror or exc}: {name}' if name else str(exc)
    if isinstance(exc, SimulationError):
        return 1, f'simulation failed: {exc}'
    if isinstance(exc, (ConnectionError, TimeoutError)):
        return 1, str(exc) or type(exc).__name__
    if isinstance(exc, OSError):
        return 1, str(exc)
    if isinstance(exc, ValueError):
        return 2, str(exc)
    return 1, (f'internal error: {type(exc).__name__}: {exc} (run with --debug for the '
               'traceback)')
