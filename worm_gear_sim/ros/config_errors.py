# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The node's start-up errors: one line on stderr naming the cause, exit code
:data:`EXIT_CONFIG_ERROR` (2); the params-file checks and rcl's messages made one line.
Standard library only (used by :mod:`.run`)."""

from __future__ import annotations

import os
import re
import sys

__all__ = ['EXIT_CONFIG_ERROR', 'PROGRAM', 'config_error', 'clean_rcl_message',
           'check_params_files']

EXIT_CONFIG_ERROR = 2
PROGRAM = 'worm_gear_sim_node'

_RCL_LOCATION = re.compile(r',? at [^,]*\.c(pp)?:\d+')


def clean_rcl_message(text: str) -> str:
    """An rcl error on one line, without the C source locations
    (``..., at /project/src/rcl/arguments.c:352``) and rcl's generic prefixes."""
    text = _RCL_LOCATION.sub('', str(text))
    for prefix in ('failed to initialize rcl: ', 'Failed to parse ROS arguments: '):
        text = text.replace(prefix, '')
    return ' '.join(text.split())


def check_params_files(argv: list[str]) -> str:
    """'' if every ``--params-file`` in ``argv`` is a readable regular file, else the
    reason (rcl's own message for these cases is "Error opening YAML file" or a parse
    error at line 0)."""
    for flag, path in zip(argv, argv[1:]):
        if flag != '--params-file':
            continue
        if not os.path.exists(path):
            return f'params file {path}: no such file'
        if not os.path.isfile(path):
            return f'params file {path}: not a regular file'
        if not os.access(path, os.R_OK):
            return f'params file {path}: not readable (permission denied)'
    return ''


def config_error(text: str, program: str = PROGRAM) -> int:
    """Print the one-line start-up error of ``program`` and return
    :data:`EXIT_CONFIG_ERROR`."""
    print(f'{program}: error: {" ".join(str(text).split())}', file=sys.stderr, flush=True)
    return EXIT_CONFIG_ERROR
