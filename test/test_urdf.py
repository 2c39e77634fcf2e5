# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""urdf/worm_gear_drive.urdf: what robot_state_publisher needs from it (one tree, every
joint of ``node.joint_names`` continuous on its body's axis) and dimensions equal to the
config's, so RViz draws the drive the model simulates."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from worm_gear_sim.config.files import load_config

ROOT = Path(__file__).resolve().parent.parent
URDF = ROOT / 'urdf' / 'worm_gear_drive.urdf'


@pytest.fixture(scope='module')
def robot() -> ET.Element:
    return ET.parse(URDF).getroot()


def _joints(robot: ET.Element) -> dict[str, ET.Element]:
    return {j.get('name'): j for j in robot.findall('joint')}


def _xyz(el: ET.Element | None, attr: str = 'xyz') -> tuple[float, ...]:
    assert el is not None
    return tuple(float(v) for v in el.get(attr, '0 0 0').split())


def _cylinders(link: ET.Element) -> list[tuple[float, float]]:
    return [(float(c.get('radius')), float(c.get('length')))
            for c in link.findall('visual/geometry/cylinder')]


def test_joint_names_are_the_configs(robot):
    cfg = load_config()
    assert robot.tag == 'robot'
    assert list(_joints(robot)) == list(cfg.node.joint_names)


def test_one_tree_of_absolute_continuous_joints(robot):
    links = {ln.get('name') for ln in robot.findall('link')}
    joints = _joints(robot)
    children = [j.find('child').get('link') for j in joints.values()]
    assert len(set(children)) == len(children) and set(children) <= links
    roots = links - set(children)
    assert roots == {'base_link'}
    axes = {'worm_input_joint': (1, 0, 0), 'worm_joint': (1, 0, 0),
            'worm_gear_joint': (0, 0, 1), 'antenna_joint': (0, 0, 1)}
    for name, j in joints.items():
        assert j.get('type') == 'continuous', name
        # the node publishes absolute angles: no joint may ride on another body
        assert j.find('parent').get('link') == 'base_link', name
        assert _xyz(j.find('axis')) == axes[name], name
        assert _xyz(j.find('origin'), 'rpy') == (0.0, 0.0, 0.0), name


def test_dimensions_equal_the_config(robot):
    cfg = load_config()
    g, s = cfg.geometry, cfg.shafts
    joints = _joints(robot)
    links = {ln.get('name'): ln for ln in robot.findall('link')}
    worm = _xyz(joints['worm_joint'].find('origin'))
    gear = _xyz(joints['worm_gear_joint'].find('origin'))
    motor = _xyz(joints['worm_input_joint'].find('origin'))
    antenna = _xyz(joints['antenna_joint'].find('origin'))
    # centre distance r_w + r_g between the worm axis (x) and the gear axis (z)
    assert math.hypot(worm[1] - gear[1], worm[2] - gear[2]) == pytest.approx(
        g.worm_pitch_radius + g.gear_pitch_radius, abs=1e-9)
    assert worm[0] - motor[0] == pytest.approx(s.worm_shaft_length, abs=1e-9)
    assert antenna[2] - gear[2] == pytest.approx(s.gear_shaft_length, abs=1e-9)
    assert (g.worm_pitch_radius, g.worm_length) in _cylinders(links['worm_link'])
    assert (g.gear_pitch_radius, g.gear_width) in _cylinders(links['worm_gear_link'])
    assert (s.worm_shaft_radius, s.worm_shaft_length) in _cylinders(links['worm_input_link'])
    assert (s.gear_shaft_radius, s.gear_shaft_length) in _cylinders(links['worm_gear_link'])
    assert g.flywheel_enabled
    assert (g.flywheel_radius, g.flywheel_length) in _cylinders(links['antenna_link'])


def test_materials_are_defined(robot):
    defined = {m.get('name') for m in robot.findall('material')}
    used = {m.get('name') for m in robot.findall('link/visual/material')}
    assert used <= defined
