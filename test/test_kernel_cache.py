# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The numba cache is cleared when any source of the package changed (a callee's change
is invisible to numba's own per-file check), once, and kept otherwise."""

from __future__ import annotations

from worm_gear_sim.kernel_cache import STAMP, ensure_fresh_cache, sources_digest


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
