# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""``python -m worm_gear_sim.compensation_cli [options]``: the ``compensate`` command alone
(the same as ``worm-gear-sim compensate [options]``; the command lives in
:mod:`worm_gear_sim.cli.compensate`)."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from .cli import main as _cli_main

__all__ = ['main']


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``worm-gear-sim compensate`` with ``argv`` (default: sys.argv[1:])."""
    return _cli_main(['compensate', *(sys.argv[1:] if argv is None else argv)])


if __name__ == '__main__':
    sys.exit(main())
