# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The package's numba cache, kept consistent with its sources (pure core, no numba import).

The compiled kernels are cached on disk (``cache=True``, in the ``__pycache__`` folders of
the package).  numba checks a cached function against its own source file only: a kernel
whose callee changed in another module loads the old machine code, silently (measured: the
twin of the adaptation gave 537.9x instead of 27.0x over 10-20 s on one drive, the same
source with a cache left by an earlier checkout).  A pip upgrade or a ``git checkout`` leaves
the old cache files behind.  :func:`ensure_fresh_cache` runs when the package is first
imported (before any kernel can be compiled or loaded; it reads files only, no numba or
numpy): the SHA-1 of all the package's ``.py`` sources, in path order, is compared with
the stamp ``__pycache__/.numba_sources`` of the package; on a difference the package's
``*.nbi`` / ``*.nbc`` files are deleted and the stamp written (under a file lock: parallel
processes clear once).  ~3 ms per process.  A read-only installation is left as it is
(numba then caches elsewhere or not at all); ``NUMBA_CACHE_DIR`` moves numba's cache out of
the package, and then this does nothing.  ``scripts/setup_env.sh`` calls the same function.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

__all__ = ['ensure_fresh_cache', 'sources_digest', 'STAMP']

#: The stamp file, relative to the package folder.
STAMP = Path('__pycache__') / '.numba_sources'
_ROOT = Path(__file__).resolve().parent


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
