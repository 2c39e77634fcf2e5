# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""What a calibration recommends: the candidate compensator with the smallest antenna error
on the sector scan, its figures those of the studies' compensation evaluation (the same
function, the same numbers), compensation off when no candidate beats the raw command."""

from __future__ import annotations

import pytest

from worm_gear_sim.config.usable import Config
from worm_gear_sim.studies import recommendation as R
from worm_gear_sim.studies.mismatch import benefit, sector_scan

PLAY = {'mesh.backlash': 5.8e-4, 'load.output_torque': 1.0}


def test_the_recommendation_is_the_best_candidate_with_the_studies_figures():
    drive = Config().replace(PLAY)
    rec = R.recommend_compensator(drive)
    assert len(rec.tried) == 3              # as configured, step crossing, no inverse
    best = min(rec.tried, key=lambda r: r['compensated_rms_rad'])
    assert rec.settings == best['settings'] and rec.compensated_rms == \
        best['compensated_rms_rad']
    twin = benefit(drive.replace(rec.settings), None, sector_scan(drive), how='causal')
    assert (twin['raw_rms'], twin['compensated_rms']) == (rec.raw_rms, rec.compensated_rms)
    assert rec.improvement == pytest.approx(twin['improvement']) and rec.improvement > 10
    assert rec.changed == () and 'as configured' in rec.lines()[0]
    assert 'µrad uncompensated' in rec.lines()[1]


def test_no_candidate_better_than_the_raw_command_recommends_compensation_off(monkeypatch):
    monkeypatch.setattr(R, 'benefit', lambda plant, model, move, raw, how: {
        'raw_rms': raw, 'compensated_rms': 2 * raw, 'improvement': 0.5})
    rec = R.recommend_compensator(Config())
    assert rec.settings == {'compensation.enabled': False}
    assert rec.changed == ('compensation.enabled',) and rec.improvement == 1.0
