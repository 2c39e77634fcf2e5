# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The fallback of :func:`~worm_gear_sim.identification.calibrate.calibrate`: a fit made with
the default teeth prior that is refused is followed by a fit with every key free, kept only
when the held-out move accepts it; and the split of play and load by the unloading dither,
kept only when its fit lifts the gear off its flank and the held-out move accepts it.

The fits are stand-ins (the local fit is tested elsewhere; here only the choice between two
fits is): each call of ``identify`` returns a prepared result, and the judge is real: the
held-out move is simulated on a drive that differs from the base, and each stand-in's config
is simulated on it.  Short moves (the steps' design, 0.12 rad of worm travel)."""

from __future__ import annotations

import dataclasses
import math

import pytest

import worm_gear_sim.identification.calibrate as calibrate_module
from worm_gear_sim import Config
from worm_gear_sim.identification import FitOptions
from worm_gear_sim.identification.calibrate import calibrate, plant_runner
from worm_gear_sim.identification.excitation import Limits
from worm_gear_sim.identification.fit import PRIORS
from worm_gear_sim.identification.report import FitResult

KG = 'materials.gear_shaft_shear_modulus'
TEETH = 'mesh.gear_tooth_stiffness_multiplier'
KEYS = [KG, TEETH]
LIMITS = Limits(0.12, 6.0, 1500.0)


def _plant() -> Config:
    base = Config()
    return base.replace({KG: 1.3 * base.materials.gear_shaft_shear_modulus})


def _result(cfg: Config, priors: dict, problems: list[str]) -> FitResult:
    """A fit result whose config is ``cfg`` (what the judge simulates)."""
    n = len(KEYS)
    flat = cfg.to_flat_dict()
    return FitResult(
        keys=list(KEYS), units=['Pa', '1'], base_values=[1.0] * n,
        values=[float(flat[k]) for k in KEYS], ci95=[(math.nan, math.nan)] * n,
        std_x=[math.nan] * n, log_scale=[True] * n, correlation=[[1.0, 0.0], [0.0, 1.0]],
        rms_before={}, rms_after={}, scale={}, noise={}, per_record=[], cost=0.0,
        converged=not problems, trustworthy=not problems, problems=list(problems),
        warnings=[], strategy={'priors': dict(priors)}, starts=[], frequency_info={},
        seconds=0.0, config=cfg, base_config=Config(), output_verdicts={'theta4': 'matched'})


@pytest.fixture(scope='module')
def plant_run():
    """The drive (the plant: the base with a stiffer gear shaft) as calibrate runs it."""
    return plant_runner(_plant(), 1e4, ('theta4',), 1e-6, 2 * math.pi / 2 ** 20)


def _calibrate(monkeypatch, run, free_config: Config, options: FitOptions | None = None):
    """calibrate() with identify replaced: the first fit (default prior) is refused; the free
    fit returns ``free_config`` with no problem of its own."""
    calls: list[FitOptions] = []

    def fake_identify(base, train, keys, *, options=None, outputs=None):
        calls.append(options)
        if options.priors is None:          # the default prior was used, and refused
            return _result(base, {TEETH: PRIORS[TEETH]}, ['a stand-in problem'])
        return _result(free_config, {}, [])

    monkeypatch.setattr(calibrate_module, 'identify', fake_identify)
    monkeypatch.setattr('worm_gear_sim.identification.uncertainty.prediction_bound',
                        lambda res, train, held: ('bound', res.config))
    return calibrate(Config(), KEYS, LIMITS, run, options=options), calls


def test_a_refused_fit_with_the_prior_is_replaced_by_a_free_fit_the_held_out_accepts(
        monkeypatch, plant_run):
    res, calls = _calibrate(monkeypatch, plant_run, _plant())
    assert len(calls) == 2 and calls[1].priors == {}
    assert res.accepted, res.reasons
    assert res.fit.strategy['priors'] == {} and res.config is res.fit.config
    assert res.estimate(KG) == pytest.approx(_plant().materials.gear_shaft_shear_modulus)
    assert any('refitted with every key free' in w for w in res.fit.warnings)
    # the teeth key, free now, is no better seen than with the prior: said so, and how
    # (bench_calibration seed 1 drive 16: 13.57 against a true 1.14, and not flagged)
    assert list(res.not_seen) == [TEETH]
    assert 'fitted free after the fit with its prior was refused' in res.not_seen[TEETH]
    assert 'known extra load torque' in res.not_seen[TEETH]
    assert res.not_seen[TEETH] in res.fit.warnings
    assert res.worst_held_out() <= 0.05
    assert res.bounds and res.bounds[0][1] is res.config


def test_a_free_fit_the_held_out_refutes_is_not_kept(monkeypatch, plant_run):
    """The free fit has no problem of its own but predicts the held-out move badly (it is the
    base, not the plant): the refused fit stays, with its reasons; nothing accepted."""
    res, calls = _calibrate(monkeypatch, plant_run, Config())
    assert len(calls) == 2
    assert not res.accepted
    assert res.reasons[0] == 'a stand-in problem'
    assert res.fit.strategy['priors'] == {TEETH: PRIORS[TEETH]}
    assert not any('refitted' in w for w in res.fit.warnings)
    assert TEETH not in res.not_seen       # the stand-in says nothing of it (no prior line)
    # the judge refuted the free fit on its own merits: its held-out error is above 5 %
    from worm_gear_sim.identification.report import prediction_errors
    rel = prediction_errors(Config(), res.held_out)[0]['theta4']['rel']
    assert rel > calibrate_module.ACCEPT_REL, rel


def test_priors_given_by_the_caller_are_not_overridden(monkeypatch, plant_run):
    """The fallback is for the default prior only: a caller's own priors are kept."""
    opt = dataclasses.replace(FitOptions(), priors={TEETH: 0.05})
    calls: list[FitOptions] = []

    def fake_identify(base, train, keys, *, options=None, outputs=None):
        calls.append(options)
        return _result(base, dict(options.priors), ['a stand-in problem'])

    monkeypatch.setattr(calibrate_module, 'identify', fake_identify)
    res = calibrate(Config(), KEYS, LIMITS, plant_run, options=opt)
    assert len(calls) == 1 and not res.accepted


# ---- the split of play and load by the unloading dither (the same stand-in machinery) ----
PLAY, LOAD = 'mesh.backlash', 'load.output_torque'
SPLIT_KEYS = [PLAY, LOAD]
SWEEP_LIMITS = Limits(0.2, 6.0, 1500.0, 2.0)


def _split_plant() -> Config:
    return Config().replace({PLAY: 2.0 * math.pi / 180 / 60, LOAD: 2.0})


@pytest.fixture(scope='module')
def sweep_run():
    """The sweeps' drive, each move simulated once (calibrate is called several times)."""
    run = plant_runner(_split_plant(), 1e4, ('theta4',), 1e-6, 2 * math.pi / 2 ** 20)
    cache: dict = {}
    return lambda move: cache.setdefault(move.name, run(move))


def _split_result(cfg: Config, not_seen: dict) -> FitResult:
    res = _result(cfg, {}, [])
    flat = cfg.to_flat_dict()
    res.keys, res.values = list(SPLIT_KEYS), [float(flat[k]) for k in SPLIT_KEYS]
    res.not_seen = dict(not_seen)
    return res


@pytest.mark.parametrize('split_config, split_not_seen, kept', [
    ('plant', {}, True),                    # lifts the gear, held-out accepts: kept
    ('base', {}, False),                    # the held-out move refutes it
    ('plant', {PLAY: 'still hidden'}, False),   # the dither did not lift the gear
])
def test_the_split_refit_is_kept_only_if_it_lifts_the_gear_and_the_held_out_accepts(
        monkeypatch, sweep_run, split_config, split_not_seen, kept):
    hidden = {PLAY: f'{PLAY}: not seen: the gear stays on one flank', LOAD: 'not separable'}
    calls = []

    def fake_identify(base, train, keys, *, options=None, outputs=None):
        assert [r.name for r in train] == ['slow_sweep', 'fast_sweep']
        return _split_result(_split_plant(), hidden)     # accepted, play hidden

    def fake_split(base, records, keys, fitted, options, outputs=None):
        calls.append([r.name for r in records])
        cfg = _split_plant() if split_config == 'plant' else Config()
        return _split_result(cfg, split_not_seen)

    monkeypatch.setattr(calibrate_module, 'identify', fake_identify)
    monkeypatch.setattr(calibrate_module, 'split_refit', fake_split)
    monkeypatch.setattr('worm_gear_sim.identification.uncertainty.prediction_bound',
                        lambda res, train, held: ('bound', [r.name for r in train]))
    res = calibrate(Config(), SPLIT_KEYS, SWEEP_LIMITS, sweep_run)
    assert calls == [['slow_sweep', 'fast_sweep', 'unload_dither']]
    assert res.accepted          # the sweeps' fit was accepted: it stays so either way
    if kept:
        assert PLAY not in res.not_seen and LOAD not in res.not_seen
        assert any('told apart by the unload_dither' in w for w in res.fit.warnings)
        assert [r.name for r in res.train][-1] == 'unload_dither'
    else:
        assert res.not_seen == hidden
        assert any('did not tell the play from the load' in w for w in res.fit.warnings)
        assert [r.name for r in res.train] == ['slow_sweep', 'fast_sweep']
