# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The package's numba cache kept consistent with its sources (pure core, no numba import).

:func:`ensure_fresh_cache` clears the cached kernels when any ``.py`` source of the package
changed (a stamp of their SHA-1 under a file lock); :func:`choose_cache_dir` picks a writable
cache folder for a read-only installation, :func:`sources_digest` names a version's sources,
and :data:`NOTE` / :func:`take_note` say where the cache went.  The rules:
docs/performance.md ("The kernel cache").
"""

from __future__ import annotations

import hashlib
import os
import shutil
import stat
import tempfile
from collections.abc import Iterator, MutableMapping
from pathlib import Path

__all__ = ['ensure_fresh_cache', 'sources_digest', 'STAMP', 'choose_cache_dir', 'writable_dir',
           'take_note', 'NOTE', 'SUBFOLDER']

#: The stamp file, relative to the package folder.
STAMP = Path('__pycache__') / '.numba_sources'
_ROOT = Path(__file__).resolve().parent.parent
#: The folder's name under a user's cache folder (and, with the user id, in the temp dir).
SUBFOLDER = 'worm_gear_sim'
#: The one line that says where the kernels are cached when it is not the package's folder
#: ('' when it is).
NOTE = ''


def sources_digest(root: Path = _ROOT) -> str:
    """SHA-1 of the contents of every ``.py`` file under ``root``, in path order."""
    h = hashlib.sha1()
    for path in sorted(str(p) for p in root.rglob('*.py')):
        with open(path, 'rb') as fh:
            h.update(fh.read())
    return h.hexdigest()


def ensure_fresh_cache(root: Path = _ROOT) -> bool:
    """Clear the numba cache under ``root`` if its sources changed since the stamp (module
    docstring); True when it cleared."""
    if os.environ.get('NUMBA_CACHE_DIR'):
        return False
    stamp = root / STAMP
    digest = sources_digest(root)
    try:
        if stamp.read_text().strip() == digest:
            return False
    except OSError:
        pass
    try:
        stamp.parent.mkdir(exist_ok=True)
        import fcntl
        with open(stamp.parent / '.numba_sources.lock', 'w') as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            try:
                if stamp.read_text().strip() == digest:
                    return False              # another process cleared meanwhile
            except OSError:
                pass
            for pattern in ('*.nbi', '*.nbc'):
                for f in root.rglob(pattern):
                    f.unlink(missing_ok=True)
            tmp = stamp.with_suffix('.tmp')
            tmp.write_text(digest + '\n')
            os.replace(tmp, stamp)
    except (OSError, ImportError):
        return False                          # read-only, or no flock: leave it as it is
    return True


def writable_dir(path: Path) -> bool:
    """Whether ``path`` is (or can be made) a folder this process can write into: made if
    missing, then a file written and removed in it (os.access alone is not enough: root
    passes every permission check, and a read-only file system fails only the write)."""
    try:
        path.mkdir(parents=True, exist_ok=True)
        if not os.access(path, os.W_OK | os.X_OK):
            return False
        fd, name = tempfile.mkstemp(dir=path, prefix='.write_test_')
        os.close(fd)
        os.unlink(name)
        return True
    except (OSError, RuntimeError):           # (RuntimeError: no home directory)
        return False


def _package_writable(root: Path) -> bool:
    """numba's own cache: a ``__pycache__`` beside each of the package's modules."""
    folders = sorted({p.parent for p in root.rglob('*.py')})
    return all(writable_dir(f / '__pycache__') for f in folders)


def _private(path: Path) -> bool:
    """A folder this user owns, not a link, that nobody else may write into."""
    try:
        path.mkdir(mode=0o700, exist_ok=True)
        st = os.lstat(path)
    except OSError:
        return False
    return stat.S_ISDIR(st.st_mode) and st.st_uid == os.geteuid() and \
        not st.st_mode & (stat.S_IWGRP | stat.S_IWOTH)


def _candidates(env: MutableMapping[str, str]) -> Iterator[tuple[Path, bool]]:
    """(folder, keeps other versions' subfolders out: True) in the order they are tried."""
    xdg = env.get('XDG_CACHE_HOME', '')
    if os.path.isabs(xdg):
        yield Path(xdg) / SUBFOLDER, True
    else:
        home = env.get('HOME', '')
        if os.path.isabs(home):
            yield Path(home) / '.cache' / SUBFOLDER, True
    try:
        tmp = Path(tempfile.gettempdir())
    except OSError:
        return
    shared = tmp / f'{SUBFOLDER}-{os.geteuid()}'
    if _private(shared):
        yield shared, True
    try:
        yield Path(tempfile.mkdtemp(prefix=f'{SUBFOLDER}-kernels-')), False
    except OSError:
        return


def _prune(base: Path, keep: str) -> None:
    """Remove the subfolders of other source digests (best effort)."""
    try:
        for d in base.iterdir():
            if d.name != keep and len(d.name) == len(keep) and d.is_dir() and \
                    all(c in '0123456789abcdef' for c in d.name):
                shutil.rmtree(d, ignore_errors=True)
    except OSError:
        pass


def choose_cache_dir(root: Path = _ROOT, env: MutableMapping[str, str] | None = None
                     ) -> str:
    """Choose where numba caches the package's kernels (module docstring): sets
    ``NUMBA_CACHE_DIR`` in ``env`` (default ``os.environ``; and in numba's settings if numba
    is already imported) when it is not the package's folder; returns the one line that
    says so ('' when the package's own folder, or a writable ``NUMBA_CACHE_DIR``, is used;
    kept in :data:`NOTE`)."""
    global NOTE
    env = os.environ if env is None else env
    given = env.get('NUMBA_CACHE_DIR', '')
    if given:
        if writable_dir(Path(given)):
            return ''
        why = f'NUMBA_CACHE_DIR {given} is not writable'
    else:
        if _package_writable(root):
            return ''
        why = f'the package folder {root} is not writable'
    digest = sources_digest(root)[:16]
    for base, versioned in _candidates(env):
        folder = base / digest if versioned else base
        if writable_dir(folder):
            _set_cache_dir(env, str(folder))
            if versioned:
                _prune(base, digest)
            NOTE = f'worm_gear_sim: {why}; compiled kernels are cached in {folder}'
            return NOTE
    _compile_in_memory()
    NOTE = (f'worm_gear_sim: {why} and no cache folder is writable; the kernels are '
            'compiled in memory at every start')
    return NOTE


def _set_cache_dir(env: MutableMapping[str, str], folder: str) -> None:
    env['NUMBA_CACHE_DIR'] = folder
    import sys
    config = sys.modules.get('numba.core.config')
    if config is not None and env is os.environ:    # numba read its settings already
        config.CACHE_DIR = folder                     # type: ignore[attr-defined]


def _compile_in_memory() -> None:
    """No folder to cache in: numba compiles the ``cache=True`` kernels without a cache
    (else their definition raises 'cannot cache function')."""
    from numba.core.dispatcher import Dispatcher
    Dispatcher.enable_caching = lambda self: None     # type: ignore[method-assign]


def take_note() -> str:
    """:data:`NOTE` once (the node and the command line say it; '' afterwards)."""
    global NOTE
    note, NOTE = NOTE, ''
    return note
