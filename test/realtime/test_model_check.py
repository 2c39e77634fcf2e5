# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Live model check core: windowed residual RMS, WARN threshold, prediction
history interpolation, rejected samples."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worm_gear_sim.realtime.model_check import ModelCheck, PredictionHistory, ResidualMonitor


def test_residual_monitor_windowed_rms_and_levels():
    mon = ResidualMonitor(('worm_joint', 'antenna_joint'), window=0.0105, warn_threshold=1e-4)
    assert mon.level(0.0) == 'STALE'
    rng = np.random.default_rng(0)
    t = np.arange(3000) * 1e-3
    resid = rng.normal(0, 5e-5, (t.size, 2))
    resid[:, 0] += 3e-4 * (t > 0.05)          # the worm residual jumps after 50 ms
    resid[t > 1.5, 0] = rng.normal(0, 5e-5, np.count_nonzero(t > 1.5))   # and recovers
    for ti, r in zip(t, resid):
        out = mon.update(ti, r + 1.0, np.ones(2))
        assert np.allclose(out, r)
        win = resid[(t > ti - 0.0105) & (t <= ti)]
        ref = np.sqrt(np.mean(win ** 2, axis=0))
        assert np.allclose(mon.rms(), ref, rtol=1e-9)
        assert mon.level() == ('WARN' if ref.max() > 1e-4 else 'OK')
    assert mon.level() == 'OK' and mon.samples == t.size
    assert mon.level(t[-1] + 0.02) == 'STALE'      # nothing within the last window
    mon2 = ResidualMonitor(('a', 'b'), 1.0, [1.0, 0.1])
    mon2.update(0.0, [0.5, np.nan], [0.0, 0.0])  # b not measured: ignored for b
    r = mon2.rms()
    assert r[0] == pytest.approx(0.5) and np.isnan(r[1]) and mon2.level() == 'OK'
    mon2.update(0.1, [np.nan, 0.2], [0.0, 0.0])  # per-joint threshold: b warns at 0.1
    assert mon2.level() == 'WARN'
    for bad in ((math.nan, [0, 0], [0, 0]), (-1.0, [0, 0], [0, 0]), (2.0, [0], [0])):
        with pytest.raises(ValueError):
            mon2.update(*bad)
    assert mon2.rejected == 3 and mon2.samples == 2
    for w, thr in ((0.0, 1.0), (1.0, -1.0), (math.inf, 1.0), (1.0, [1.0, math.nan])):
        with pytest.raises(ValueError):
            ResidualMonitor(('a', 'b'), w, thr)


def test_prediction_history_interpolates_and_wraps():
    h = PredictionHistory(capacity=8)
    assert h.at(0.0) is None and h.span() is None
    for k in range(20):
        h.push(k * 1e-3, [k, 2 * k, 3 * k])
    assert h.span() == pytest.approx((12e-3, 19e-3))
    assert np.allclose(h.at(15.25e-3), [15.25, 30.5, 45.75])
    assert np.allclose(h.at(19e-3), [19, 38, 57])
    assert h.at(11.9e-3) is None and h.at(19.1e-3) is None
    h.push(19e-3, [0, 0, 0])                   # same time: replaced
    assert np.allclose(h.at(19e-3), 0.0)
    h.push(5e-3, [1, 1, 1])                    # clock went back: history restarts
    assert h.span() == (5e-3, 5e-3) and np.allclose(h.at(5e-3), 1.0)


def test_model_check_residuals_status_and_rejections():
    names = ('worm_joint', 'worm_gear_joint', 'antenna_joint')
    chk = ModelCheck(names, window=0.05, warn_threshold=[1e-3, 1e-4, 1e-4])
    st = chk.status(0.0)
    assert st.level == 'OK' and 'idle' in st.message
    with pytest.raises(ValueError, match='no prediction yet'):
        chk.measured(0.0, {'antenna_joint': 0.0})
    for k in range(101):                        # prediction: theta4 = 0.01 t, 1 kHz ticks
        t = k * 1e-3
        chk.predicted(t, [t, 0.5 * t, 0.01 * t])
    # encoders at other times than the ticks: interpolated prediction
    joints, r = chk.measured(0.0505, {'antenna_joint': 0.01 * 0.0505 + 2e-5,
                                      'unrelated': 7.0})
    assert joints == ['antenna_joint'] and r == pytest.approx([2e-5], abs=1e-15)
    assert chk.status(0.0505).level == 'OK'
    joints, r = chk.measured(0.06, {'worm_joint': 0.06, 'antenna_joint': 0.01 * 0.06 + 5e-4})
    assert joints == ['worm_joint', 'antenna_joint'] and r == pytest.approx([0.0, 5e-4])
    st = chk.status(0.06)
    assert st.level == 'WARN' and 'antenna_joint' in st.message and 'worm_joint' not in \
        st.message
    for pos, t, reason in (({'x': 1.0}, 0.07, 'no_monitored_joint'),
                           ({'antenna_joint': math.nan}, 0.07, 'non_finite'),
                           ({'antenna_joint': 0.0}, 0.2, 'outside_prediction'),
                           ({'antenna_joint': 0.0}, 0.03, 'out_of_order')):
        with pytest.raises(ValueError):
            chk.measured(t, pos)
        assert chk.rejections[reason] == (2 if reason == 'outside_prediction' else 1)
    st = chk.status(0.06)
    assert st.values['samples'] == '2' and st.values['rejected_out_of_order'] == '1'
    assert chk.status(0.2).level == 'STALE'


def test_model_check_with_nanosecond_stamps_and_clock_restart():
    chk = ModelCheck(('w', 'g', 'a'), window=0.01, warn_threshold=1e-4)
    base = 1_700_000_000_123_456_789               # epoch stamps: float seconds would lose us
    with pytest.raises(ValueError, match='no prediction yet'):
        chk.measured_ns(base, {'a': 0.0})
    for k in range(50):
        chk.predicted_ns(base + k * 1_000_000, [0.0, 0.0, 1e-3 * k])
    joints, r = chk.measured_ns(base + 10_500_000, {'a': 10.5e-3 + 3e-5})
    assert joints == ['a'] and r[0] == pytest.approx(3e-5, rel=1e-6)
    assert chk.status_ns(base + 10_500_000).level == 'OK'
    chk.predicted_ns(5_000_000, [0.0, 0.0, 0.0])   # /clock restarted near zero
    assert chk.monitor.samples == 0 and chk.history.span() == (0.0, 0.0)
    joints, r = chk.measured_ns(5_000_000, {'a': 2e-4})
    assert r[0] == pytest.approx(2e-4) and chk.status_ns(5_000_000).level == 'WARN'
