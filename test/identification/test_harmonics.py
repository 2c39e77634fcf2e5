# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Identification of the periodic-error harmonics (identification/harmonics.py): known
answers from synthetic records of a drive with play, load and the error."""

import math

import pytest

from worm_gear_sim import Config
from worm_gear_sim.dynamics.profiles import TrapezoidalProfile
from worm_gear_sim.identification.data import IdentificationError, record_from_model
from worm_gear_sim.identification.harmonics import (
    fit_harmonics,
    harmonic_names,
    largest_share_error,
    parse_orders,
)

WORM = [30e-6, -12e-6, 6e-6, 9e-6, -2.5e-6, 4e-6]      # orders 1-3, each 2-30 urad
GEAR = [15e-6, -20e-6]                                 # order 1
DRIVE = {'mesh.backlash': 5.8e-4, 'load.output_torque': 1.0,
         'load.output_viscous_coefficient': 20.0}


def test_two_worm_revolutions_give_every_coefficient_within_5_percent():
    """Two worm revolutions (a 4 pi rad slew in 2 s), theta4 at 1 kHz with 1e-6 rad noise,
    play and load present and known: every coefficient within 5 % of the largest (measured
    1.7 %), each 'identified', the residual down to the noise."""
    plant = Config().replace(DRIVE, **{'mesh.worm_error_harmonics': WORM,
                                       'mesh.gear_error_harmonics': GEAR})
    rec = record_from_model(plant, TrapezoidalProfile(4 * math.pi, 2.0, 0.3), 2.2,
                            sample_rate=1000, noise_rad=1e-6, seed=1, name='slew')
    fit = fit_harmonics(Config().replace(DRIVE), [rec], 3, 1)
    assert fit.names == harmonic_names(3, 1)
    assert largest_share_error(fit.values, WORM + GEAR) <= 0.05, fit.table()
    assert set(fit.verdicts.values()) == {'identified'}, fit.table()
    assert fit.rms_after < 1.1e-6 < 1e-5 < fit.rms_before
    lo, hi = fit.ci95[0]
    assert lo < WORM[0] < hi
    assert list(fit.config.mesh.worm_error_harmonics) == pytest.approx(list(fit.values[:6]))


@pytest.mark.parametrize('text,expected', [('worm:3,gear:1', (3, 1)), ('gear:2', (0, 2)),
                                           (' worm:1 ', (1, 0))])
def test_orders_parse(text, expected):
    assert parse_orders(text) == expected


@pytest.mark.parametrize('text', ['worm:9', 'wheel:1', 'worm:x', '', 'worm:0'])
def test_bad_orders_name_the_part(text):
    with pytest.raises(IdentificationError, match='fit-harmonics'):
        parse_orders(text)


def test_cli_fit_harmonics_writes_the_fitted_yaml(tmp_path):
    """``identify DATA --fit-harmonics worm:1,gear:1 -o FITTED.yaml``: the YAML loads with
    the fitted coefficients (one worm revolution, 1e-6 rad noise: within 5 % of the
    largest), the report lists each with its verdict; a bad order is a one-line error."""
    import numpy as np

    from worm_gear_sim.cli import main
    from worm_gear_sim.config.files import load_config
    truth_w, truth_g = [30e-6, -12e-6], [1e-5, 5e-6]
    plant = Config().replace(**{'mesh.worm_error_harmonics': truth_w,
                                'mesh.gear_error_harmonics': truth_g})
    rec = record_from_model(plant, TrapezoidalProfile(2 * math.pi, 0.6, 0.1), 0.65,
                            sample_rate=1000, noise_rad=1e-6, seed=2)
    csv = tmp_path / 'rec.csv'
    np.savetxt(csv, np.column_stack([rec.t, rec.theta1, rec.measured['theta4']]),
               delimiter=',', header='t,theta1,theta4', comments='')
    out = tmp_path / 'fit.yaml'
    assert main(['identify', str(csv), '--fit-harmonics', 'worm:1,gear:1', '-o', str(out),
                 '-q']) == 0
    cfg = load_config(out)
    got = list(cfg.mesh.worm_error_harmonics) + list(cfg.mesh.gear_error_harmonics)
    assert largest_share_error(got, truth_w + truth_g) <= 0.05
    assert main(['identify', str(csv), '--fit-harmonics', 'worm:9', '-o', str(out),
                 '-q']) == 2
