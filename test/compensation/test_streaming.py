# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Feed-forward compensator: contract, causality, quasi-static exactness, bad input."""

import math

import numpy as np
import pytest

from worm_gear_sim.compensation.filters import design_filter, design_shaper
from worm_gear_sim.compensation.streaming import Compensator
from worm_gear_sim.config.usable import Config
from worm_gear_sim.dynamics.derived import derive
from worm_gear_sim.dynamics.modal import static_equilibrium
from worm_gear_sim.dynamics.model import pack_parameters
from worm_gear_sim.realtime import feedforward_series

LOADED = {'load.output_torque': 5.0, 'load.output_viscous_coefficient': 2.0}


def test_static_load_is_compensated_exactly():
    cfg = Config().replace(LOADED)
    comp = Compensator(cfg)
    x = 0.37
    comp.reset(x, 0.0)
    delta = comp.update(0.001, x)
    p = pack_parameters(cfg)
    ratio = derive(cfg).ratio
    u_plain = static_equilibrium(p, x)
    u_comp = static_equilibrium(p, x + delta)
    err_plain = u_plain[2] - x / ratio
    err_comp = u_comp[2] - x / ratio
    assert abs(err_plain) > 1e-4                      # the load really deflects the drive
    assert abs(err_comp) < 1e-6 * abs(err_plain)


def test_no_load_at_rest_gives_no_correction():
    comp = Compensator(Config())
    comp.reset(1.0, 2.0)
    assert comp.update(2.001, 1.0) == pytest.approx(0.0, abs=1e-12)


def test_constant_rate_correction_matches_steady_quasi_static():
    """At constant rate the filter has settled: the correction is the steady wind-up under
    load, drag and friction (it varies only slightly with the mesh phase: at phase 0 the
    cosine contact mapping is at a stiffness extreme, where the mesh stiffness is
    stationary)."""
    cfg = Config().replace(dict(LOADED, **{'mesh.phase_offset': 0.0}))
    ts = np.arange(0.0, 0.05, 1e-3)
    x = 5.0 * ts
    d = feedforward_series(cfg, ts, x)
    assert np.ptp(d[-20:]) < 1e-5 * abs(d[-1])
    # driving against load and drag: the worm must lead
    assert d[-1] > 0.0


def test_causal_future_samples_do_not_change_past_output():
    cfg = Config()
    ts = np.arange(0.0, 0.04, 1e-3)
    a = np.where(ts > 0.01, (ts - 0.01) * 3.0, 0.0)
    b = a.copy()
    b[25:] += 0.05                                   # different future from sample 25
    da = feedforward_series(cfg, ts, a)
    db = feedforward_series(cfg, ts, b)
    np.testing.assert_array_equal(da[:25], db[:25])
    assert np.any(da[25:] != db[25:])


def test_preview_uses_future_samples_only_within_horizon():
    cfg = Config().replace({'compensation.preview_time': 0.003})
    ts = np.arange(0.0, 0.04, 1e-3)
    a = np.zeros_like(ts)
    b = a.copy()
    b[25:] = 0.05
    da = feedforward_series(cfg, ts, a)
    db = feedforward_series(cfg, ts, b)
    np.testing.assert_array_equal(da[:22], db[:22])   # 25 - 3 samples of preview
    assert np.any(da[22:25] != db[22:25])


def test_disabled_returns_zero():
    cfg = Config().replace({'compensation.enabled': False, **LOADED})
    comp = Compensator(cfg)
    assert comp.update(0.001, 1.0) == 0.0


def test_filter_reproduces_polynomials():
    f = design_filter(design_shaper('zvd', 94.5, 0.0), 0.001, degree=4, lag_order=2)
    t = 0.2
    for coeffs in ([1.0, 2.0], [0.5, -1.0, 30.0]):
        x = np.polyval(coeffs[::-1], t - f.tau)
        r = f.weights @ x
        exact = [np.polyval(np.polyder(np.poly1d(coeffs[::-1]), m), t) if m else
                 np.polyval(coeffs[::-1], t) for m in range(3)]
        for m, atol in enumerate((1e-12, 1e-9, 1e-5)):   # round-off grows with the order
            assert r[m] == pytest.approx(exact[m], rel=1e-9, abs=atol)


@pytest.mark.parametrize('degree', [1, 2, 4, 7, 12])
def test_the_spline_and_its_derivatives_equal_scipys_bspline(degree):
    """The kernel's B-spline is evaluated piecewise from exact integer coefficients (no scipy
    at the node's start-up); it equals scipy's BSpline.basis_element to round-off for every
    derivative the filter may use, at the knots too (a piecewise-constant derivative takes
    the interval to the right of a knot, the left one at the end) and zero outside."""
    from scipy.interpolate import BSpline

    from worm_gear_sim.compensation.filters import _spline_derivs
    width = 0.0123 * (degree + 1)
    knots = np.linspace(0.0, width, degree + 2)
    x = np.concatenate([np.linspace(-0.3 * width, 1.3 * width, 4001), knots,
                        np.random.default_rng(degree).uniform(0.0, width, 500)])
    ref = BSpline.basis_element(knots, extrapolate=False)
    area = width / (degree + 1)
    for m, f in enumerate(_spline_derivs(width, degree, degree)):
        want = np.nan_to_num((ref if m == 0 else ref.derivative(m))(x), nan=0.0) / area
        got = f(x)
        assert np.max(np.abs(got - want)) <= 1e-13 * np.max(np.abs(want)), m
        assert np.all(got[(x < 0.0) | (x > width)] == 0.0)


@pytest.mark.parametrize('kind', ['zv', 'zvd', 'ei'])
def test_shapers_cancel_their_mode(kind):
    f, zeta = 94.5, 0.02
    s = design_shaper(kind, f, zeta)
    assert s.amplitudes.sum() == pytest.approx(1.0)
    wn = 2 * math.pi * f / math.sqrt(1 - zeta ** 2)
    grow = s.amplitudes * np.exp(zeta * wn * s.times)
    resid = abs(np.sum(grow * np.exp(2j * math.pi * f * s.times))) / np.sum(grow)
    assert resid < (0.06 if kind == 'ei' else 1e-6)


@pytest.mark.parametrize('bad', [(math.nan, 0.0), (0.001, math.inf)])
def test_update_rejects_non_finite(bad):
    comp = Compensator(Config())
    with pytest.raises(ValueError):
        comp.update(*bad)


def test_update_rejects_time_going_backwards():
    comp = Compensator(Config())
    comp.update(0.002, 0.0)
    with pytest.raises(ValueError, match='backwards'):
        comp.update(0.001, 0.0)


def test_reset_rejects_non_finite():
    with pytest.raises(ValueError):
        Compensator(Config()).reset(math.nan, 0.0)


def test_design_rejects_bad_values():
    with pytest.raises(ValueError):
        design_shaper('zzz', 94.5)
    with pytest.raises(ValueError):
        design_shaper('zv', -1.0)
    with pytest.raises(ValueError):
        design_filter(design_shaper('none', 1.0), 0.0)
    with pytest.raises(ValueError):
        design_filter(design_shaper('none', 1.0), 0.001, lag_order=3)
    with pytest.raises(ValueError, match='degree'):
        design_filter(design_shaper('none', 1.0), 0.001, degree=3, lag_order=2, n_deriv=3)
    with pytest.raises(ValueError):
        design_filter(design_shaper('none', 1.0), 0.001, n_deriv=6)


def test_reconfigure_keeps_history_and_changes_design():
    cfg = Config()
    comp = Compensator(cfg)
    comp.reset(0.0, 0.0)
    for k in range(1, 11):
        comp.update(k * 1e-3, 0.01 * k)
    comp.reconfigure(cfg.replace({'compensation.preview_time': 0.002, **LOADED}))
    assert 'preview 2 ms' in comp.describe()
    d = comp.update(0.011, 0.11)
    assert math.isfinite(d) and comp.reference == pytest.approx(0.09)   # t - 2 ms


def test_metric_helpers():
    from worm_gear_sim.studies.compensation_eval import METRIC_FLOOR, improvement, not_worse
    assert improvement('settling_time', math.inf, 0.01) == math.inf
    assert improvement('settling_time', math.inf, math.inf) == 1.0
    assert improvement('settling_time', 0.01, math.inf) == 0.0
    assert math.isnan(improvement('static_error', 1e-9, 2e-9))        # both at the floor
    assert improvement('residual_peak', 1e-4, 1e-5) == pytest.approx(10.0)
    assert improvement('residual_peak', 1e-4, 0.0) == pytest.approx(1e-4 / METRIC_FLOOR)
    assert not_worse('tracking_rms', 1e-4, 1.04e-4)
    assert not not_worse('tracking_rms', 1e-4, 1.06e-4)
    assert not_worse('static_error', 1e-9, 5e-8)                       # below the floor
    assert not not_worse('settling_time', 0.01, math.inf)


def test_move_metrics_on_synthetic_traces():
    from worm_gear_sim.studies.compensation_eval import Scenario, move_metrics
    t = np.arange(0.0, 1.0, 1e-4)
    scen = Scenario('s', t, np.zeros_like(t), 0.1, ((0.02, 0.08),))
    ring = np.where(t > 0.1, 2e-5 * np.exp(-(t - 0.1) / 0.05) * np.sin(600 * t), 0.0)
    e = 3e-6 + ring + np.where(t < 0.1, 1e-5, 0.0)
    m = move_metrics(t, e, scen, 600 / (2 * math.pi))
    assert m['static_error'] == pytest.approx(3e-6, rel=1e-3)
    assert m['tracking_rms'] == pytest.approx(1.3e-5, rel=1e-6)
    assert 0.0 < m['settling_time'] < 0.1
    assert m['residual_peak'] == pytest.approx(np.abs(ring).max(), rel=1e-3)
    undamped = 3e-6 + np.where(t > 0.1, 2e-5 * np.sin(600 * t), 0.0)
    assert math.isinf(move_metrics(t, undamped, scen, 600 / (2 * math.pi))['settling_time'])
