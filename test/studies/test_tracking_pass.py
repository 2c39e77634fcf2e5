# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The tracking pass: the geometry against closed forms, trajectories streamed back to back
compensated as one long trajectory would be (the hand-over keeps the correction), the
pointing error cut >= 10x on both axes of the default pedestal, and the ``pass`` command."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worm_gear_sim.cli import main
from worm_gear_sim.config.pedestal import load_pedestal
from worm_gear_sim.joint_trajectory.compensate import JointTrajectoryData, TrajectoryCompensator
from worm_gear_sim.studies.tracking_pass import (
    evaluate_pass,
    pass_window,
    satellite_pass,
    stream_pass,
)


def test_the_pass_geometry_culminates_at_its_elevation_and_swings_the_azimuth():
    t = np.linspace(-300.0, 300.0, 60001)
    for deg in (30.0, 60.0, 85.0):
        az, el = satellite_pass(t, 500e3, math.radians(deg))
        assert np.degrees(el.max()) == pytest.approx(deg, abs=1e-6)
        assert np.argmax(el) == t.size // 2                # culmination at t = 0
        np.testing.assert_allclose(el, el[::-1], atol=1e-12)   # symmetric pass
    # the higher the pass, the faster the azimuth turns at culmination (the keyhole)
    rates = [np.max(np.abs(np.gradient(satellite_pass(t, 500e3, math.radians(d))[0], t)))
             for d in (30.0, 60.0, 85.0)]
    assert rates[0] < rates[1] < rates[2]
    # an overhead pass of a 500 km orbit is above the horizon for ~10 min (rises and sets)
    tt = np.linspace(-600.0, 600.0, 12001)
    _, el = satellite_pass(tt, 500e3, math.radians(89.9))
    above = tt[el > 0]
    assert 480.0 < above[-1] - above[0] < 780.0


def test_streamed_trajectories_are_compensated_like_one_long_trajectory():
    """Back-to-back trajectories, each replacing the last in the middle of its move: the
    correction continues across the hand-overs (the filter runs through the commanded
    history) and equals that of the one long trajectory within 1e-3 of its own size."""
    drives = {d.joint: d.config for d in load_pedestal()}
    j = tuple(drives)
    t, az, el = pass_window(12.0)
    sent, comp = stream_pass(drives, {j[0]: az - az[0], j[1]: el}, t, 1.0, 6.0, 3.0)
    assert len(sent) == 4 and all(s.stamp_ns < n.stamp_ns for s, n in zip(sent, sent[1:]))
    # one trajectory with every waypoint of the pass, lead-in/out as the streamed ones
    tw = np.concatenate([s.time_from_start + (s.stamp_ns - sent[0].stamp_ns) / 1e9
                         for s in sent])
    pos = np.vstack([s.positions for s in sent])
    vel = np.vstack([s.velocities for s in sent])
    tw, k = np.unique(np.round(tw, 9), return_index=True)
    one = TrajectoryCompensator(drives).compensate(
        JointTrajectoryData(j, tw, pos[k], vel[k], None, sent[0].stamp_ns), predict=False)
    for s, c in zip(sent[1:], comp[1:]):
        off = int(round((s.stamp_ns - sent[0].stamp_ns) * 1e-6))    # ms = samples
        for col, joint in enumerate(j):
            long = one.axes[joint]
            n = min(c.positions.shape[0], long.t.size - off, 3000)
            d_long = long.delta[off:off + n]
            d_chunk = c.positions[:n, col] - long.reference[off:off + n]
            assert np.max(np.abs(d_chunk - d_long)) <= 1e-3 * np.max(np.abs(d_long)), joint


def test_the_pass_cuts_the_pointing_error_10x_on_both_axes():
    drives = {d.joint: d.config for d in load_pedestal()}
    j = tuple(drives)
    t, az, el = pass_window(12.0)
    sent, comp = stream_pass(drives, {j[0]: az - az[0], j[1]: el}, t, 1.0, 6.0, 3.0)
    res = evaluate_pass(drives, sent, comp)
    rows = {r['joint']: r for r in res.table()}
    for joint in j:
        r = rows[joint]
        assert r['rms_raw_urad'] > 10.0, r                  # a real error to remove
        assert r['rms_ratio'] >= 10.0, r
        assert r['max_compensated_urad'] * 10 <= r['max_raw_urad'], r
    assert abs(res.reference[j[1]]).max() < math.pi / 2     # elevation in range


def test_the_pass_command_writes_its_table_csv_and_figure(tmp_path, capsys):
    assert main(['pass', '-o', str(tmp_path), '--duration', '6', '--chunk', '4',
                 '--every', '2']) == 0
    out = capsys.readouterr().out
    assert 'azimuth_worm_input_joint' in out and 'RMS ratio' in out
    assert (tmp_path / 'pass.png').stat().st_size > 10_000
    head = (tmp_path / 'pass.csv').read_text().splitlines()
    cols = next(line for line in head if not line.startswith('#')).split(',')
    assert cols[0] == 't' and 'elevation_worm_input_joint_compensated_error' in cols
    assert main(['pass', '--every', '30', '--chunk', '20']) == 2
    assert 'overlap' in capsys.readouterr().err
