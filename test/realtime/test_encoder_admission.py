# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The admission of encoder samples (measured_joint_states) shared by the live model check
and the live adaptation, and the windowed figures they compute from what is admitted:

* the rule: each reason in its order, one sample used per command period however many
  come, a steady encoder with jittering stamps never losing a sample;
* glitches (finite absurd values 1e300 and 1e150, another drive's encoder +3 rad, a joint
  named twice) rejected and counted by both consumers, their state untouched;
* the windowed sums: whatever was admitted (huge finite values too), the RMS equals a
  direct recomputation over the window, and what left the window leaves no trace;
* the published estimate carries its plausibility, and an implausible one is never
  applied."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from worm_gear_sim.adaptation import per_sample as ps
from worm_gear_sim.adaptation.estimator import Adapter
from worm_gear_sim.adaptation.live import LiveAdaptation
from worm_gear_sim.adaptation.plausibility import values_problem
from worm_gear_sim.config.usable import Config
from worm_gear_sim.realtime import RealtimePredictor
from worm_gear_sim.realtime.encoder_admission import EncoderAdmission
from worm_gear_sim.realtime.model_check import ModelCheck, ResidualMonitor

NAMES = ('worm_joint', 'worm_gear_joint', 'antenna_joint')
BASE_NS = 1_000_000_000
MS = 1_000_000


def _flat(t):
    return (0.0, 0.0, 0.0)


# ---- the rule ----------------------------------------------------------------------------
def test_each_reason_in_its_order():
    adm = EncoderAdmission(NAMES, (0, 1, 2), 'no_monitored_joint', max_residual=0.25,
                           period=MS)
    ok = adm.admit(BASE_NS, NAMES, [0.0, 0.1, -0.2], _flat)
    assert ok == ([0, 1, 2], [0.0, 0.1, -0.2], (0.0, 0.0, 0.0))
    cases = [((math.nan, ['antenna_joint'], [0.0]), 'non_finite'),
             ((BASE_NS, ['antenna_joint'], [0.0]), 'out_of_order'),
             ((BASE_NS - 1, ['antenna_joint'], [0.0]), 'out_of_order'),
             ((BASE_NS + MS // 2 - 1, ['antenna_joint'], [0.0]), 'surplus'),
             ((BASE_NS + MS, ['antenna_joint'], [0.0, 1.0]), 'malformed'),
             ((BASE_NS + MS, ['antenna_joint', 'antenna_joint'], [0.0, 1.0]), 'malformed'),
             ((BASE_NS + MS, ['elevation_joint'], [0.0]), 'no_monitored_joint'),
             ((BASE_NS + MS, ['antenna_joint'], [math.inf]), 'non_finite'),
             ((BASE_NS + MS, ['antenna_joint'], ['x']), 'non_finite'),
             ((BASE_NS + MS, ['worm_joint'], [0.2500001]), 'implausible'),
             ((BASE_NS + MS, ['antenna_joint'], [1e300]), 'implausible'),
             ((BASE_NS + MS, ['antenna_joint'], [-1e150]), 'implausible'),
             ((BASE_NS + MS, ['antenna_joint'], [3.0]), 'implausible')]
    for args, reason in cases:
        assert adm.admit(*args, _flat) == reason, (args, reason)
    assert adm.admit(BASE_NS + MS, ['antenna_joint'], [0.0], lambda t: None) == \
        'outside_prediction'
    # none of them was used: the next sample at the due stamp is
    assert adm.admit(BASE_NS + MS // 2, ['x', 'antenna_joint'], [9.0, 0.25], _flat) == \
        ([2], [0.25], (0.0, 0.0, 0.0))
    # a consumer that uses the antenna only ignores the other joints
    ant = EncoderAdmission(NAMES, (2,), 'other_joint', max_residual=0.25, period=MS)
    assert ant.admit(BASE_NS, ['worm_joint'], [0.0], _flat) == 'other_joint'
    assert ant.admit(BASE_NS, ['worm_joint', 'antenna_joint'], [7.0, 0.1], _flat)[1] == [0.1]


def test_a_flood_has_one_sample_used_per_period_and_a_jittering_encoder_loses_none():
    adm = EncoderAdmission(NAMES, (2,), 'other_joint', period=MS)
    reasons: dict = {}
    used = []
    for k in range(2000):                      # 20 samples per ms for 100 ms
        s = BASE_NS + k * (MS // 20)
        got = adm.admit(s, ['antenna_joint'], [0.0], _flat)
        if isinstance(got, str):
            reasons[got] = reasons.get(got, 0) + 1
        else:
            used.append(s)
    # 100 periods: 101 used (k + 1 in k periods: the half period a jittering encoder may
    # come early), then one per period
    assert reasons == {'surplus': 2000 - len(used)} and len(used) == 101
    assert used[1] - used[0] == MS // 2 and np.all(np.diff(used[1:]) == MS)
    rng = np.random.default_rng(3)
    adm.reset()
    stamps = BASE_NS + np.arange(5000) * MS + rng.integers(-MS // 4, MS // 4, 5000)
    assert all(not isinstance(adm.admit(int(s), ['antenna_joint'], [0.0], _flat), str)
               for s in stamps)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(1, 3 * MS), min_size=1, max_size=400))
def test_at_most_k_plus_one_samples_in_k_periods(gaps):
    """Any stamps: at most k + 1 used in any k periods; stamps a period apart or more: all
    used."""
    adm = EncoderAdmission(NAMES, (2,), 'other_joint', period=MS)
    stamps = BASE_NS + np.cumsum(gaps)
    used = np.array([s for s in stamps
                     if not isinstance(adm.admit(int(s), ['antenna_joint'], [0.0], _flat),
                                       str)])
    for k in (1, 2, 5):
        ends = np.searchsorted(used, used + k * MS, side='left')   # within [s, s + k P)
        assert np.all(ends - np.arange(used.size) <= k + 1)
    if min(gaps[1:], default=MS) >= MS:
        assert used.size == stamps.size


# ---- the model check ----------------------------------------------------------------------
def _check(**kw) -> ModelCheck:
    chk = ModelCheck(NAMES, window=0.05, warn_threshold=[1e-3, 1e-4, 1e-4], history=512,
                     **kw)
    for k in range(400):
        chk.predicted(k * 1e-3, [0.0, 0.0, 0.0])
    return chk


@pytest.mark.parametrize('glitch', [1e300, 1e150, -1e150])
def test_a_glitch_leaves_the_model_check_finite_and_right_once_it_left_the_window(glitch):
    """Without a plausibility bound the glitch is taken: its window shows it, and the
    window after it shows the samples in it exactly (before, the running sums held NaN for
    ever after 1e300 and cancelled to exactly 0, "model matches", after 1e150)."""
    chk = _check()
    rng = np.random.default_rng(1)
    resid = rng.normal(0.0, 3e-5, 300)
    resid[100] = glitch
    t = np.arange(resid.size) * 1e-3
    for k, r in enumerate(resid):
        chk.measured(float(t[k]), {'antenna_joint': r})
        inside = (t > t[k] - 0.05) & (t <= t[k])
        win = resid[inside]
        ref = math.inf if inside[100] and abs(glitch) > 1e154 else \
            math.sqrt(np.mean(np.square(win)))
        got = chk.monitor.rms()[2]
        assert got == pytest.approx(ref, rel=1e-9), k
    st_ = chk.status(0.299)
    assert st_.level == 'OK' and st_.message == 'model matches the drive'
    assert st_.values['residual_rms_antenna_joint [rad]'] == f'{ref:.3e}'


@pytest.mark.parametrize('value', [1e300, 1e150, 3.0])
def test_the_model_check_rejects_implausible_samples_and_says_so(value):
    chk = _check(max_residual=0.25, period=1e-3)
    for k in range(100):
        chk.measured(k * 1e-3, {'antenna_joint': 2e-5})
    with pytest.raises(ValueError, match='residual_plausible_max'):
        chk.measured(0.1, {'antenna_joint': value})
    assert chk.rejections == {'implausible': 1}
    assert chk.monitor.rms()[2] == pytest.approx(2e-5, rel=1e-12)
    st_ = chk.status(0.1)
    assert st_.level == 'WARN' and 'implausible' in st_.message
    assert st_.values['rejected_implausible'] == '1'
    for k in range(101, 200):                   # another drive's encoder: never taken
        with pytest.raises(ValueError, match='residual_plausible_max'):
            chk.measured(k * 1e-3, {'antenna_joint': value})
    assert chk.monitor.samples == 100 and chk.status(0.2).level == 'WARN'
    assert chk.status(0.26).level == 'STALE'       # a window after the last one


def test_a_joint_named_twice_is_malformed_not_its_first_value():
    chk = ModelCheck(NAMES, window=0.05, warn_threshold=1e-4)
    for k in range(10):
        chk.predicted_ns(BASE_NS + k * MS, [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match='named twice'):
        chk.measured_message_ns(BASE_NS + MS, ['antenna_joint', 'antenna_joint'], [0.0, 1.0])
    assert chk.rejections == {'malformed': 1} and chk.monitor.samples == 0


def test_the_model_check_uses_one_sample_per_command_period():
    chk = _check(period=1e-3)
    for k in range(2000):                       # 20 per ms over 100 ms
        chk._offer(k * 5e-5, ['antenna_joint'], [1e-5])
    assert chk.monitor.samples == 101 and chk.rejections == {'surplus': 1899}


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(1e-4, 5e-3),
                          st.one_of(st.tuples(st.sampled_from([-1.0, 1.0]),
                                              st.floats(-12.0, 150.0)).map(
                                                  lambda p: p[0] * 10.0 ** p[1]),
                                    st.just(0.0), st.just(math.nan))),
                min_size=1, max_size=300),
       st.floats(2e-3, 0.05))
def test_the_sliding_rms_equals_a_direct_recomputation(samples, window):
    """Any time-ordered residuals, huge finite ones (1e-12 <= |r| <= 1e150, the squares
    finite) and unmeasured ones among them: the windowed RMS equals the RMS of the residuals
    in the window."""
    mon = ResidualMonitor(('a',), window, 1e-4)
    t = np.cumsum([dt for dt, _ in samples])
    r = np.array([v for _, v in samples])
    for k in range(t.size):
        mon.update(float(t[k]), [r[k]], [0.0])
        inside = (t > t[k] - window) & (t <= t[k]) & ~np.isnan(r)
        got = mon.rms()[0]
        if not inside.any():
            assert math.isnan(got)
            continue
        w = r[inside]
        scale = np.max(np.abs(w))
        ref = scale * math.sqrt(np.mean(np.square(w / scale))) if scale > 0 else 0.0
        assert got == pytest.approx(ref, rel=1e-9, abs=0.0), k


# ---- the adaptation's window ----------------------------------------------------------------
def _direct_rms(rows, lams, x):
    """sqrt(sum w (y - phi x)^2 / sum w), w the product of the later lams (long double)."""
    num = den = np.longdouble(0.0)
    for (phi, y), lam in zip(rows, lams):
        num *= np.longdouble(lam)
        den = den * np.longdouble(lam) + 1
        num += (np.longdouble(y) - np.dot(np.asarray(phi, np.longdouble),
                                          np.asarray(x, np.longdouble))) ** 2
    return float(np.sqrt(num / den).item())


@settings(max_examples=80, deadline=None)
@given(st.integers(1, 6), st.data())
def test_the_adaptation_window_rms_equals_a_direct_recomputation(n, data):
    """Rows [phi, y] of any size (a glitch of 1e150 among rows of 1e-6), forgetting as the
    adapter's window forgets: the RMS of y - phi x for any x equals the direct weighted sum,
    to 1e-9 of itself plus the rounding of y - phi x (1e-13 of the rows' scale).  The sums
    of phi phi^T, phi y and y^2 it replaced failed both ways: inf for ever after |y| > 1e154,
    and cancellation where y is large and y - phi x small."""
    m = data.draw(st.integers(1, 200))
    mag = st.one_of(st.floats(-1e-3, 1e-3), st.floats(-1.0, 1.0), st.floats(-1e150, 1e150))
    rows = [(data.draw(st.lists(st.floats(-1.0, 1.0), min_size=n, max_size=n)),
             data.draw(mag)) for _ in range(m)]
    lams = [data.draw(st.floats(0.9, 1.0)) for _ in range(m)]
    x = np.array(data.draw(st.lists(st.floats(-10.0, 10.0), min_size=n, max_size=n)))
    explained = data.draw(st.booleans())        # y = phi x + small: the cancellation case
    R, sc = np.zeros((n + 2, n + 1)), np.zeros(1)
    for k, ((phi, y), lam) in enumerate(zip(rows, lams)):
        if explained and abs(y) <= 1.0:
            y = float(np.dot(phi, x)) + 1e-6 * y
            rows[k] = (phi, y)
        ps._window_step(R, sc, np.array(phi, float), float(y), float(lam))
    got = ps.window_norm(R, x) / math.sqrt(sc[0])
    ref = _direct_rms(rows, lams, x)
    scale = _direct_rms([(np.abs(phi), abs(y) + np.dot(np.abs(phi), np.abs(x)))
                         for phi, y in rows], lams, np.zeros(n))
    assert math.isfinite(got)
    assert abs(got - ref) <= 1e-9 * ref + 1e-13 * scale


def test_a_huge_row_does_not_leave_the_adapter_window_infinite():
    """A row of 1e300 (the sums squared it to inf, for ever): finite, and once its weight
    has decayed away the window shows the other rows alone, to 1e-9 (their residuals 1e-6
    of their size: no trace of the large row's rounding)."""
    R, sc = np.zeros((3, 2)), np.zeros(1)
    lam = math.exp(-1e-3 / 0.01)                 # a 10 ms window at 1 kHz
    rng = np.random.default_rng(0)
    rows = [(1.0, 1e300)] + [(1.0, 1.0 + 1e-6 * rng.normal()) for _ in range(80_000)]
    for phi, y in rows:
        ps._window_step(R, sc, np.array([phi]), y, lam)
    x = np.array([1.0])
    ref = _direct_rms(rows[1:], [lam] * (len(rows) - 1), x)
    assert ps.window_norm(R, x) / math.sqrt(sc[0]) == pytest.approx(ref, rel=1e-9)


# ---- the live adaptation ----------------------------------------------------------------
@pytest.fixture
def live():
    cfg = Config().replace({'adaptation.enabled': True, 'node.compensation_applied': True})
    pred = RealtimePredictor(cfg, apply_compensation=True, base_ns=BASE_NS)
    la = LiveAdaptation(pred, cfg.node.joint_names[1:])
    for k in range(200):
        la.predicted(BASE_NS + k * MS, (0.0, 0.0, 1e-4 * k))
    return la


def _adapter_state(la: LiveAdaptation):
    ad = la.adapter
    return [ad.theta.copy(), ad.P.copy(), ad._R.copy(), list(la.waiting)]


@pytest.mark.parametrize('offset', [1e300, 1e150, -1e150, 3.0])
def test_glitches_and_another_drives_encoder_leave_the_adaptation_untouched(live, offset):
    names = live.joint_names
    assert live.measured(BASE_NS + MS, names, [0.0, 0.0, 1e-4 + 1e-6]) is None
    before = _adapter_state(live)
    for k in range(2, 150):
        assert live.measured(BASE_NS + k * MS, names, [0.0, 0.0, 1e-4 * k + offset]) == \
            'implausible'
    after = _adapter_state(live)
    for a, b in zip(before, after):
        assert np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b
    assert live.counters['rejected_implausible'] == 148
    assert live.counters['rejected'] == 148 and live.plausibility() == (True, '')


def test_a_flood_has_one_sample_per_period_enter_the_adaptation(live):
    antenna = [live.joint_names[2]]
    for k in range(20 * 150):                    # 20 per ms for 150 ms
        s = BASE_NS + k * (MS // 20)
        live.measured(s, antenna, [1e-4 * s / MS * 1e-0 - 1e-4 * BASE_NS / MS])
    assert len(live.waiting) == 151               # (k + 1 in k periods)
    assert live.counters['rejected_surplus'] == 20 * 150 - 151
    assert live.counters['rejected'] == live.counters['rejected_surplus']


def test_an_implausible_estimate_is_published_as_such_and_never_applied(live):
    ad: Adapter = live.adapter
    lay = ad.layout
    ad.theta[lay.i_load] = -9052.0               # an encoder offset read as load
    plausible, why = live.plausibility()
    assert not plausible and 'elastically' in why and '-9052' in why
    level, msg, values = live.status()
    assert values['estimate plausible'].startswith('no: ') and 'elastically' in \
        values['estimate plausible']
    # the switching rule would take it (the window favours it): refused, the reason kept
    ad._first_t = 0.0
    ad.window_rms = lambda: {'estimate': 1e-6, 'applied': 1e-3, 'nominal': 1e-3}
    d = ad.poll(10.0)
    assert d.step is None and ad.target is None and ad.refusals == 1
    assert 'elastically' in ad.last_refusal
    assert values_problem(ad.model, {'mesh.backlash': 0.2})    # beyond its range
    assert values_problem(ad.model, lay.overrides(ad.applied_x)) == ''
