# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Text files the guarded way: reading untrusted ones with bounded memory (the one YAML
loader of the package: no aliases, limited nesting; a size-limited UTF-8 read) and writing
one atomically and durably (:func:`write_text_durably`: a temporary file beside the target,
fsync of the file and its directory, rename; only onto a regular file or a new path).
Standard library and PyYAML only, so that the records' readers, the configuration and the
node's written parameter files use the same guard.

A parameter file is a few kB; the node's own params parser (rcl's) has no YAML aliases.
A 1 kB alias bomb expands to gigabytes in ``yaml.safe_load``; a 5 000-deep nesting
overflows the parser's recursion.  Both are refused here with a message naming the file.
"""

from __future__ import annotations

import errno
import os
import re
import secrets
import stat
import tempfile
from pathlib import Path
from typing import Any

import yaml

__all__ = ['GuardedFileError', 'read_text_file', 'guarded_yaml_load', 'MAX_CONFIG_BYTES',
           'MAX_CONFIG_DEPTH', 'check_write_target', 'resolved_target', 'write_text_durably']

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


def resolved_target(path: str | Path) -> Path:
    """The file a write to ``path`` lands in: ``~`` expanded, relative to the working
    directory, symbolic links followed (two paths with the same result name one file)."""
    return Path(os.path.realpath(Path(os.fspath(path)).expanduser()))


def check_write_target(path: str | Path) -> Path:
    """The file :func:`write_text_durably` would write for ``path`` (``~`` expanded,
    symbolic links followed: a link keeps pointing at the file); GuardedFileError naming the
    reason if it is not a regular file or a new path in a writable directory (empty, a
    directory, ``/``, a device, a FIFO, a socket, below a file, a directory that takes no
    new file such as ``/proc``).  Leaves nothing behind (a writable directory is probed by
    creating and removing a file: :func:`_takes_a_file`)."""
    if not os.fspath(path).strip():
        raise GuardedFileError('empty path: name a file')
    target = resolved_target(path)
    try:
        mode = target.stat().st_mode
    except (FileNotFoundError, NotADirectoryError):
        mode = None
    except OSError as exc:
        raise GuardedFileError(f'{target}: cannot be checked ({exc.strerror or exc})') from None
    if mode is not None and not stat.S_ISREG(mode):
        raise GuardedFileError(f'{target}: is {_kind(mode)}, not a regular file; name a file')
    parent = target.parent
    while not parent.exists():              # created by the write
        parent = parent.parent
    if not parent.is_dir():
        raise GuardedFileError(f'{target}: {parent} is not a directory')
    if not (os.access(parent, os.W_OK | os.X_OK) and _takes_a_file(parent)):
        raise GuardedFileError(f'{target}: directory {parent} is not writable')
    return target


def _takes_a_file(directory: Path) -> bool:
    """Whether a file can be created in ``directory`` now: a probe file created and removed
    at once (as root, ``os.access`` says yes to ``/proc`` and to a read-only mount)."""
    try:
        fd, probe = tempfile.mkstemp(dir=directory, prefix='.write-probe-')
    except OSError:
        return False
    os.close(fd)
    os.unlink(probe)
    return True


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, 'a directory'), (stat.S_ISCHR, 'a character device'),
                       (stat.S_ISBLK, 'a block device'), (stat.S_ISFIFO, 'a FIFO'),
                       (stat.S_ISSOCK, 'a socket')):
        if test(mode):
            return name
    return 'not a regular file'


def write_text_durably(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically and durably, and return the file
    written: checked first (:func:`check_write_target`: nothing is created for a refused
    target), missing directories created, the text written to a temporary file in the
    target's directory, fsync'd, renamed onto the target, the directory fsync'd (a crash
    leaves the old file or the new one, never a part).  A new file gets the mode a file
    created by ``open(path, 'w')`` gets (0666 without the umask's bits), a replaced one
    keeps its mode.  GuardedFileError for a refused target; OSError from the system (the
    temporary file is removed)."""
    target = check_write_target(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    try:
        mode: int | None = stat.S_IMODE(target.stat().st_mode)
    except FileNotFoundError:
        mode = None
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, 'O_CLOEXEC', 0)
    for _ in range(100):
        tmp = target.parent / f'.{target.name}.{secrets.token_hex(4)}.tmp'
        try:                        # (the kernel applies the umask to 0o666)
            fd = os.open(tmp, flags, 0o666)
            break
        except FileExistsError:
            continue
    else:                                   # pragma: no cover - 100 random names taken
        raise GuardedFileError(f'{target}: no free temporary name in {target.parent}')
    try:
        with os.fdopen(fd, 'w', encoding='utf-8') as fh:
            if mode is not None:
                os.fchmod(fh.fileno(), mode)
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    dir_fd = os.open(target.parent, os.O_RDONLY | getattr(os, 'O_DIRECTORY', 0))
    try:
        os.fsync(dir_fd)
    except OSError as exc:      # a file system that cannot sync a directory: the rename
        if exc.errno != errno.EINVAL:       # is as durable as it makes it
            raise
    finally:
        os.close(dir_fd)
    return target
