# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The numba cache is cleared when any source of the package changed (a callee's change
is invisible to numba's own per-file check), once, and kept otherwise; a read-only
installation caches its kernels in a writable folder (or compiles them in memory) and says
so in one line (test/ros/test_node_fresh_start.py starts the node so)."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
import tempfile
from pathlib import Path

from worm_gear_sim._support.kernel_cache import (
    STAMP,
    SUBFOLDER,
    choose_cache_dir,
    ensure_fresh_cache,
    sources_digest,
    take_note,
    writable_dir,
)


def test_a_changed_source_clears_the_cache_once(tmp_path, monkeypatch):
    monkeypatch.delenv('NUMBA_CACHE_DIR', raising=False)
    pkg = tmp_path / 'pkg'
    (pkg / 'sub' / '__pycache__').mkdir(parents=True)
    (pkg / 'a.py').write_text('x = 1\n')
    (pkg / 'sub' / 'b.py').write_text('y = 2\n')
    cached = [pkg / 'sub' / '__pycache__' / 'b.f-1.py311.nbi',
              pkg / 'sub' / '__pycache__' / 'b.f-1.py311.1.nbc']
    for f in cached:
        f.write_bytes(b'old')
    assert ensure_fresh_cache(pkg)                    # no stamp yet: cleared, stamped
    assert not any(f.exists() for f in cached)
    assert (pkg / STAMP).read_text().strip() == sources_digest(pkg)
    for f in cached:
        f.write_bytes(b'new')
    assert not ensure_fresh_cache(pkg)                # the same sources: kept
    assert all(f.exists() for f in cached)
    (pkg / 'a.py').write_text('x = 3\n')              # a callee's module changed
    assert ensure_fresh_cache(pkg)
    assert not any(f.exists() for f in cached)
    monkeypatch.setenv('NUMBA_CACHE_DIR', str(tmp_path / 'elsewhere'))
    (pkg / 'a.py').write_text('x = 4\n')
    assert not ensure_fresh_cache(pkg)                # numba caches elsewhere: not ours


# ---- where the cache is: a read-only installation --------------------------------------------
def _package(tmp_path, writable: bool = True):
    """A package folder with one module; not writable: its ``__pycache__`` is a regular file
    (no folder can be made there, for root either: permission bits do not stop root)."""
    pkg = tmp_path / 'pkg'
    pkg.mkdir()
    (pkg / 'a.py').write_text('x = 1\n')
    if not writable:
        (pkg / '__pycache__').write_text('a file where the folder would be')
    return pkg


def _unwritable(tmp_path, name: str):
    """A path no one can make a folder at: its parent is a regular file."""
    f = tmp_path / f'{name}_file'
    f.write_text('x')
    return f / name


def test_writable_dir_writes_a_file_and_says_no_where_root_cannot(tmp_path):
    assert writable_dir(tmp_path / 'new' / 'deep')
    assert (tmp_path / 'new' / 'deep').is_dir() and not any((tmp_path / 'new' / 'deep').iterdir())
    assert not writable_dir(_unwritable(tmp_path, 'x'))
    assert not writable_dir(Path('/proc/worm_gear_sim_cache'))     # a kernel file system


def test_the_package_folder_is_used_when_writable(tmp_path):
    env = {'HOME': str(tmp_path / 'home')}
    assert choose_cache_dir(_package(tmp_path), env) == ''
    assert 'NUMBA_CACHE_DIR' not in env


def test_a_read_only_package_caches_in_the_users_cache_folder(tmp_path):
    pkg = _package(tmp_path, writable=False)
    env = {'HOME': str(tmp_path / 'home')}
    note = choose_cache_dir(pkg, env)
    folder = tmp_path / 'home' / '.cache' / SUBFOLDER / sources_digest(pkg)[:16]
    assert env['NUMBA_CACHE_DIR'] == str(folder) and folder.is_dir()
    assert '\n' not in note and str(pkg) in note and str(folder) in note
    assert take_note() == note and take_note() == ''          # said once
    env = {'HOME': str(tmp_path / 'home'), 'XDG_CACHE_HOME': str(tmp_path / 'xdg')}
    choose_cache_dir(pkg, env)
    assert env['NUMBA_CACHE_DIR'].startswith(str(tmp_path / 'xdg' / SUBFOLDER))


def test_another_versions_kernels_are_never_loaded_and_are_removed(tmp_path):
    pkg = _package(tmp_path, writable=False)
    env = {'HOME': str(tmp_path / 'home')}
    choose_cache_dir(pkg, env)
    old = Path(env['NUMBA_CACHE_DIR'])
    (old / 'k.nbi').write_bytes(b'old')
    (pkg / 'a.py').write_text('x = 2\n')                         # another version
    env = {'HOME': str(tmp_path / 'home')}
    choose_cache_dir(pkg, env)
    assert Path(env['NUMBA_CACHE_DIR']) != old and not old.exists()


def test_a_read_only_home_falls_back_to_a_private_temp_folder(tmp_path, monkeypatch):
    pkg = _package(tmp_path, writable=False)
    tmp = tmp_path / 'tmp'
    tmp.mkdir()
    monkeypatch.setattr(tempfile, 'tempdir', str(tmp))
    env = {'HOME': str(_unwritable(tmp_path, 'home')), 'NUMBA_CACHE_DIR': ''}
    note = choose_cache_dir(pkg, env)
    shared = tmp / f'{SUBFOLDER}-{os.geteuid()}'
    assert env['NUMBA_CACHE_DIR'] == str(shared / sources_digest(pkg)[:16]), note
    assert stat.S_IMODE(shared.stat().st_mode) == 0o700
    # a shared folder others may write into is not taken: a fresh one of this process's
    shared.chmod(0o777)
    env = {'HOME': str(_unwritable(tmp_path, 'home2'))}
    choose_cache_dir(pkg, env)
    fresh = Path(env['NUMBA_CACHE_DIR'])
    assert fresh.parent == tmp and fresh.name.startswith(f'{SUBFOLDER}-kernels-')


def test_an_unwritable_numba_cache_dir_is_replaced(tmp_path):
    pkg = _package(tmp_path)
    env = {'HOME': str(tmp_path / 'home'), 'NUMBA_CACHE_DIR': str(_unwritable(tmp_path, 'nc'))}
    note = choose_cache_dir(pkg, env)
    assert 'NUMBA_CACHE_DIR' in note and env['NUMBA_CACHE_DIR'].startswith(
        str(tmp_path / 'home' / '.cache' / SUBFOLDER))
    env = {'NUMBA_CACHE_DIR': str(tmp_path / 'mine')}           # a writable one: as it is
    assert choose_cache_dir(pkg, env) == '' and env['NUMBA_CACHE_DIR'] == str(tmp_path / 'mine')


def test_with_no_writable_folder_the_kernels_compile_in_memory(tmp_path, monkeypatch):
    import worm_gear_sim._support.kernel_cache as kc
    pkg = _package(tmp_path, writable=False)
    monkeypatch.setattr(tempfile, 'tempdir', str(_unwritable(tmp_path, 'tmp')))
    calls = []
    monkeypatch.setattr(kc, '_compile_in_memory', lambda: calls.append(1))
    env = {'HOME': str(_unwritable(tmp_path, 'home'))}
    note = choose_cache_dir(pkg, env)
    assert calls == [1] and 'compiled in memory' in note and 'NUMBA_CACHE_DIR' not in env
    take_note()


def test_in_memory_compilation_makes_a_cached_kernel_without_a_cache(tmp_path):
    """The last resort as a process: numba's cache=True kernels defined and run with no
    folder to cache in (numba alone raises 'cannot cache function')."""
    src = tmp_path / 'mod.py'
    src.write_text('from numba import njit\n\n@njit(cache=True)\ndef f(x):\n    return x + 1\n')
    code = ('import sys; from worm_gear_sim._support import kernel_cache as kc; '
            'kc._compile_in_memory();'
            f'sys.path.insert(0, {str(tmp_path)!r}); import mod; print(mod.f(1))')
    env = dict(os.environ, NUMBA_CACHE_DIR='')
    (tmp_path / '__pycache__').write_text('not a folder')
    env['HOME'] = str(_unwritable(tmp_path, 'home'))
    out = subprocess.run([sys.executable, '-c', code], env=env, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == '2', out.stderr
