# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The guarded write (guarded_io.write_text_durably): atomic (a temporary file beside the
target, renamed), durable (fsync of the file, then of its directory), only onto a regular
file or a new path (a directory, /, a character device, a FIFO are refused before anything
is created), and a new file's mode is the umask's, as open(path, 'w') makes it."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from worm_gear_sim._support.guarded_io import (
    GuardedFileError,
    check_write_target,
    write_text_durably,
)


def leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.endswith('.tmp'))


@pytest.fixture
def no_create(monkeypatch):
    """Record every os.open with O_CREAT (a refused target must come before any)."""
    calls: list[str] = []
    real = os.open

    def spy(path, flags, *args, **kw):
        if flags & os.O_CREAT:
            calls.append(os.fspath(path))
        return real(path, flags, *args, **kw)

    monkeypatch.setattr(os, 'open', spy)
    return calls


def test_a_new_file_is_written_and_fsynced_file_then_directory(tmp_path, monkeypatch):
    synced: list[str] = []
    real = os.fsync

    def spy(fd):
        mode = os.fstat(fd).st_mode
        synced.append('dir' if stat.S_ISDIR(mode) else 'file' if stat.S_ISREG(mode) else '?')
        return real(fd)

    monkeypatch.setattr(os, 'fsync', spy)
    target = tmp_path / 'sub' / 'adapted.yaml'         # a missing folder is created
    assert write_text_durably(target, 'a: 1\n') == target
    assert target.read_text() == 'a: 1\n'
    assert synced == ['file', 'dir']
    assert leftovers(target.parent) == []


@pytest.mark.parametrize('umask', [0o022, 0o027, 0o077, 0o002])
def test_a_new_file_gets_the_mode_of_the_umask(tmp_path, umask):
    old = os.umask(umask)
    try:
        write_text_durably(tmp_path / 'x.yaml', 'x\n')
        with open(tmp_path / 'y.yaml', 'w') as fh:      # what a plain open makes
            fh.write('y\n')
    finally:
        os.umask(old)
    mode = stat.S_IMODE((tmp_path / 'x.yaml').stat().st_mode)
    assert mode == 0o666 & ~umask == stat.S_IMODE((tmp_path / 'y.yaml').stat().st_mode)


def test_a_replaced_file_keeps_its_mode_and_a_link_stays_a_link(tmp_path):
    real = tmp_path / 'real.yaml'
    real.write_text('old\n')
    real.chmod(0o640)
    link = tmp_path / 'link.yaml'
    link.symlink_to(real)
    assert write_text_durably(link, 'new\n') == real
    assert link.is_symlink() and real.read_text() == 'new\n'
    assert stat.S_IMODE(real.stat().st_mode) == 0o640
    assert leftovers(tmp_path) == []


def test_a_failed_rename_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch):
    target = tmp_path / 'a.yaml'
    target.write_text('old\n')

    def fail(src, dst):
        raise OSError(28, 'No space left on device')

    monkeypatch.setattr(os, 'replace', fail)
    with pytest.raises(OSError, match='No space'):
        write_text_durably(target, 'new\n')
    assert target.read_text() == 'old\n' and leftovers(tmp_path) == []


def test_a_directory_is_refused_and_nothing_is_left_behind(tmp_path, no_create):
    folder = tmp_path / 'folder'
    folder.mkdir()
    for target in (folder, str(folder) + '/'):
        with pytest.raises(GuardedFileError, match='is a directory, not a regular file'):
            write_text_durably(target, 'x\n')
    assert no_create == [] and leftovers(tmp_path) == [] and leftovers(folder) == []


def test_the_root_directory_is_refused_before_any_file_is_created(no_create):
    with pytest.raises(GuardedFileError, match='/: is a directory'):
        check_write_target('/')
    with pytest.raises(GuardedFileError, match='is a directory'):
        write_text_durably('/', 'x\n')
    assert no_create == []


def test_a_character_device_is_refused_and_untouched(no_create):
    before = os.stat('/dev/null')
    with pytest.raises(GuardedFileError, match='a character device'):
        write_text_durably('/dev/null', 'x\n')
    after = os.stat('/dev/null')
    assert stat.S_ISCHR(after.st_mode) and after.st_rdev == before.st_rdev
    assert after.st_ino == before.st_ino and no_create == []


def test_a_fifo_is_refused_and_stays_a_fifo(tmp_path, no_create):
    fifo = tmp_path / 'pipe'
    os.mkfifo(fifo)
    with pytest.raises(GuardedFileError, match='a FIFO'):
        write_text_durably(fifo, 'x\n')
    assert stat.S_ISFIFO(fifo.stat().st_mode) and no_create == [] and leftovers(tmp_path) == []


def test_other_refusals_name_the_reason(tmp_path):
    (tmp_path / 'file').write_text('x')
    with pytest.raises(GuardedFileError, match='empty path'):
        check_write_target('  ')
    with pytest.raises(GuardedFileError, match='is not a directory'):
        check_write_target(tmp_path / 'file' / 'below.yaml')
    if os.geteuid() != 0:                   # root writes anywhere
        locked = tmp_path / 'locked'
        locked.mkdir()
        locked.chmod(0o500)
        try:
            with pytest.raises(GuardedFileError, match='not writable'):
                check_write_target(locked / 'a.yaml')
        finally:
            locked.chmod(0o700)
