# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""What every command of ``worm-gear-sim`` shares: the one-line error, the parser class, the
``--config``/``--set`` options and the run's config, printing helpers."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ..config.files import parse_set, resolve_config
from ..config.usable import Config

PROG = 'worm-gear-sim'


class CliError(Exception):
    """A usage or input error: reported as one line, exit status 2."""

    def __init__(self, message: str, prog: str = PROG):
        super().__init__(message)
        self.prog = prog


class Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors become :class:`CliError` (one line, no usage dump)."""

    def error(self, message: str):
        raise CliError(message, self.prog)

    def exit(self, status: int = 0, message: str | None = None):
        if status:
            raise CliError((message or '').strip() or f'exit status {status}', self.prog)
        if message:
            sys.stdout.write(message)
        raise SystemExit(0)


def fit_in_process(args: argparse.Namespace) -> bool:
    """Whether a fit (``identify``, ``calibrate``) runs in this process: ``--serial``, or
    neither ``--workers`` nor ``--scheduler`` (on one machine the in-process fit, its
    evaluations on forked worker processes, is the fastest: docs/identification.md)."""
    return bool(getattr(args, 'serial', False)) or (
        getattr(args, 'workers', None) is None and getattr(args, 'scheduler', None) is None)


def add_config_options(p: argparse.ArgumentParser, end_time: bool = True) -> None:
    """``--config``, repeatable ``--set`` and (optionally) ``--end-time``."""
    g = p.add_argument_group('configuration')
    g.add_argument('--config', '-c', metavar='FILE', help='parameter file: YAML (ROS '
                   'layout or plain sections) or a JSON written by "params" '
                   '(default: the package config/worm_gear_sim.yaml)')
    g.add_argument('--set', '-s', action='append', default=[], metavar='KEY=VALUE',
                   help='override one dotted parameter, e.g. mesh.stiffness_model=linear '
                   '(repeatable)')
    if end_time:
        g.add_argument('--end-time', type=float, metavar='S',
                       help='simulated duration (= --set input.end_time=S)')


def config_from_args(args: argparse.Namespace, extra: Mapping[str, Any] | None = None
                     ) -> Config:
    """The run's config from ``--config``, ``--set``, ``--end-time`` and ``--csv``."""
    ex = dict(extra or {})
    if getattr(args, 'end_time', None) is not None:
        ex['input.end_time'] = args.end_time
    csv_in = getattr(args, 'input_csv', None)
    if csv_in:
        p = Path(csv_in)
        if not p.is_file():
            raise CliError(f'input CSV not found: {p}')
        ex['input.profile'] = 'csv'
        ex['input.csv_path'] = str(p.resolve())
    return resolve_config(args.config, args.set, ex)


def header(args: argparse.Namespace) -> str:
    """The command line and the config of a run, for the header of an output file."""
    argv = ' '.join(getattr(args, '_argv', []) or [])
    return (f'command: {PROG} {argv}\nconfig: {args.config or "package default"}; '
            f'overrides: {json.dumps(parse_set(args.set))}')


def say(args: argparse.Namespace, msg: str) -> None:
    """Print unless ``--quiet``."""
    if not getattr(args, 'quiet', False):
        print(msg)
