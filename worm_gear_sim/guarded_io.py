# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Reading untrusted text files with bounded memory: the one YAML loader of the package
(no aliases, limited nesting) and a size-limited UTF-8 read.  Standard library and PyYAML
only, so that the records' readers and the configuration use the same guard.

A parameter file is a few kB; the node's own params parser (rcl's) has no YAML aliases.
A 1 kB alias bomb expands to gigabytes in ``yaml.safe_load``; a 5 000-deep nesting
overflows the parser's recursion.  Both are refused here with a message naming the file.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml

__all__ = ['GuardedFileError', 'read_text_file', 'guarded_yaml_load', 'MAX_CONFIG_BYTES',
           'MAX_CONFIG_DEPTH']

#: Largest parameter file (or bag metadata.yaml) read [bytes].
MAX_CONFIG_BYTES = 1_000_000
#: Deepest nesting of a YAML document (the package's files use 3 levels).
MAX_CONFIG_DEPTH = 20


class GuardedFileError(ValueError):
    """A file refused by a guard; the message names the file and the limit."""


class _GuardedLoader(yaml.SafeLoader):
    """yaml.SafeLoader without aliases and with a nesting limit, reading ``1.6e8`` and
    ``1e-3`` as floats as YAML 1.2 and the node's params parser do (PyYAML's YAML 1.1
    wants a dot: ``1.6e+8``, and left them strings)."""

    def __init__(self, stream: Any) -> None:
        super().__init__(stream)
        self._depth = 0

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise GuardedFileError(f'YAML alias *{event.anchor} at line '
                                   f'{event.start_mark.line + 1}: aliases are not supported '
                                   "(nor by the node's params parser)")
        self._depth += 1
        if self._depth > MAX_CONFIG_DEPTH:
            mark = self.peek_event().start_mark
            raise GuardedFileError(f'nested deeper than {MAX_CONFIG_DEPTH} levels at line '
                                   f'{mark.line + 1}')
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1


_GuardedLoader.add_implicit_resolver(
    'tag:yaml.org,2002:float',
    re.compile(r'^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$'), list('-+0123456789'))


def read_text_file(path: str | Path, max_bytes: int, what: str) -> str:
    """The UTF-8 text of ``path``; GuardedFileError naming it if it is missing, a
    directory, larger than ``max_bytes`` (``what``: 'a parameter file', ...), unreadable
    or not text."""
    p = Path(path)
    if not p.exists():
        raise GuardedFileError(f'file not found: {p}')
    if p.is_dir():
        raise GuardedFileError(f'{p}: is a directory')
    try:
        size = p.stat().st_size
        if size > max_bytes:
            raise GuardedFileError(f'{p}: {size} bytes; {what} is at most {max_bytes} bytes')
        data = p.read_bytes()
    except OSError as exc:
        raise GuardedFileError(f'{p}: cannot read ({exc.strerror or exc})') from None
    try:
        text = data.decode('utf-8')
    except UnicodeDecodeError as exc:
        raise GuardedFileError(f'{p}: not a text file (byte {data[exc.start]:#04x} at '
                               f'offset {exc.start} is not UTF-8)') from None
    if '\x00' in text:
        raise GuardedFileError(f'{p}: not a text file (NUL byte at offset '
                               f'{text.index(chr(0))})')
    return text


def guarded_yaml_load(text: str, where: str) -> Any:
    """Parse YAML text without aliases and at most MAX_CONFIG_DEPTH levels deep;
    GuardedFileError naming ``where`` (and the line) otherwise."""
    try:
        return yaml.load(text, Loader=_GuardedLoader)  # noqa: S506 - a SafeLoader
    except GuardedFileError as exc:
        raise GuardedFileError(f'{where}: {exc}') from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where_in = f' at line {mark.line + 1}, column {mark.column + 1}' if mark else ''
        problem = getattr(exc, 'problem', None) or str(exc).splitlines()[0]
        raise GuardedFileError(f'{where}: broken YAML{where_in}: {problem}') from None
    except RecursionError:
        raise GuardedFileError(f'{where}: nested too deep') from None
