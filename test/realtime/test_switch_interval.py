# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The interpreter switch interval lowered while workers compute (the trajectory worker
and the adaptation's share it): restored exactly when the last of overlapping workers
ends, whatever the order they end in."""

import sys
import threading

import pytest

from worm_gear_sim.realtime.switch_interval import WORKER_SWITCH_INTERVAL, short_switch_interval


@pytest.fixture
def default_interval():
    before = sys.getswitchinterval()
    sys.setswitchinterval(0.005)
    yield 0.005
    sys.setswitchinterval(before)


def test_overlapping_workers_restore_the_interval_when_the_last_ends(default_interval):
    """A starts, B starts, A ends first (the order in which each saving and restoring on
    its own left the interval lowered for good), then B ends."""
    a, b = short_switch_interval(), short_switch_interval()
    a.__enter__()
    assert sys.getswitchinterval() == pytest.approx(WORKER_SWITCH_INTERVAL)
    b.__enter__()
    a.__exit__(None, None, None)
    assert sys.getswitchinterval() == pytest.approx(WORKER_SWITCH_INTERVAL)   # B still runs
    b.__exit__(None, None, None)
    assert sys.getswitchinterval() == pytest.approx(default_interval)


def test_restored_after_an_exception_and_across_threads(default_interval):
    with pytest.raises(RuntimeError):
        with short_switch_interval():
            raise RuntimeError('preparation failed')
    assert sys.getswitchinterval() == pytest.approx(default_interval)
    inside = threading.Event()
    release = threading.Event()

    def worker():
        with short_switch_interval():
            inside.set()
            release.wait(5.0)

    threads = [threading.Thread(target=worker) for _ in range(3)]
    for t in threads:
        t.start()
    assert inside.wait(5.0)
    assert sys.getswitchinterval() == pytest.approx(WORKER_SWITCH_INTERVAL)
    release.set()
    for t in threads:
        t.join(5.0)
    assert sys.getswitchinterval() == pytest.approx(default_interval)
