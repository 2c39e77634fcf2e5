# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Parameters: the YAML and the code agree, derived quantities, clear errors."""

import math
from pathlib import Path

import pytest
import yaml

from worm_gear_sim.config.files import load_config
from worm_gear_sim.config.usable import Config, config_from_mapping
from worm_gear_sim.dynamics.derived import derive
from worm_gear_sim.schema.validation import ConfigError

REPO = Path(__file__).resolve().parents[2]
YAML_PATH = REPO / 'config' / 'worm_gear_sim.yaml'


def test_yaml_equals_code_defaults():
    raw = yaml.safe_load(YAML_PATH.read_text())['/**']['ros__parameters']
    flat = Config().to_flat_dict()
    yaml_flat = {f'{s}.{k}': v for s, sec in raw.items() for k, v in sec.items()}
    assert set(yaml_flat) == set(flat), set(yaml_flat) ^ set(flat)
    for key, value in flat.items():
        assert yaml_flat[key] == value, key
        # ROS fixes types at declaration: a double must be written as a float in the YAML
        assert type(yaml_flat[key]) is type(value), key
    assert load_config(YAML_PATH) == Config()


def test_derived_quantities_table1():
    d = derive(Config())
    # solid cylinders J = 1/2 rho pi L R^4, K = G pi R^4 / (2 L)
    assert d.J_w == pytest.approx(0.5 * 7850 * math.pi * 0.015 * 0.0158 ** 4)
    assert d.J_g == pytest.approx(0.5 * 8800 * math.pi * 0.02 * 0.056 ** 4)
    assert d.J_4 == pytest.approx(0.5 * 7850 * math.pi * 0.03 * 0.12 ** 4)
    assert d.K_w == pytest.approx(77e9 * math.pi * 0.01534 ** 4 / 0.4)
    assert d.K_g == pytest.approx(77e9 * math.pi * 0.0175 ** 4 / 0.74)
    k_l = 206e9 * math.pi * 0.01534 ** 2 / 0.2
    assert d.k_ws == pytest.approx(k_l * 2e8 / (k_l + 2e8))
    assert d.l_w == pytest.approx(0.001, rel=1e-7)              # lead per radian
    assert d.ratio == pytest.approx(56.0, rel=1e-6)
    assert math.degrees(d.lead_angle) == pytest.approx(3.6215, abs=1e-3)
    assert d.lead_angle_consistent
    paper = derive(Config().replace({'geometry.lead_convention': 'paper'}))
    assert paper.l_w == pytest.approx(0.006283185)
    assert paper.ratio == pytest.approx(8.9127, rel=1e-4)
    table_angle = derive(Config().replace({'geometry.lead_angle': math.radians(3 + 41 / 60)}))
    assert not table_angle.lead_angle_consistent


def test_one_rigid_ratio_in_every_holder():
    """output_per_input = l_w / r_g (theta4 per theta1) is one value: the derived quantity,
    the model, the simulator's trajectories and the real-time pipeline carry the same float;
    ratio is its inverse, the reduction (56)."""
    from worm_gear_sim import DriveModel, RealtimePredictor, simulate
    for cfg in (Config(), Config().replace({'geometry.lead_convention': 'paper'})):
        d = derive(cfg)
        assert d.output_per_input == d.l_w / cfg.geometry.gear_pitch_radius
        assert d.ratio * d.output_per_input == pytest.approx(1.0, rel=1e-15)
        model = DriveModel(cfg)
        assert model.output_per_input == d.output_per_input
        assert model.rigid_motion.tolist() == [1.0, d.output_per_input, d.output_per_input]
        assert simulate(model, t_end=1e-4).output_per_input == d.output_per_input
        rt = RealtimePredictor(model, compensate=False)
        assert rt.model is model and rt.sim is not None and rt.sim.model is model


def test_moved_names_say_where_they_went():
    """load_config, default_config_path (config_io) and derive, Derived (derived) moved
    out of params; their one-release aliases are gone (with the params -> config_io import
    that closed a loop), and the error names the new home."""
    import worm_gear_sim.config.usable as params
    for name, home in (('load_config', 'config_io'), ('default_config_path', 'config_io'),
                       ('derive', 'derived'), ('Derived', 'derived')):
        with pytest.raises(AttributeError, match=f'moved to worm_gear_sim.{home}.{name}'):
            getattr(params, name)
    with pytest.raises(AttributeError, match='no attribute'):
        params.no_such_name  # noqa: B018


def test_replace_is_validated_and_all_or_nothing():
    cfg = Config()
    new = cfg.replace({'mesh.stiffness_model': 'linear', 'friction.model': 'off'})
    assert new.mesh.stiffness_model == 'linear' and cfg.mesh.stiffness_model == 'nonlinear'
    with pytest.raises(ConfigError) as exc:
        cfg.replace({'mesh.stiffness_model': 'linear', 'shafts.worm_shaft_radius': -1.0})
    assert exc.value.key == 'shafts.worm_shaft_radius'
    assert cfg.mesh.stiffness_model == 'nonlinear'


@pytest.mark.parametrize('key, value, words', [
    ('shafts.worm_bearing_axial_stiffness', -2e8, 'must be > 0'),
    ('shafts.gear_bearing_axial_stiffness', 0.0, 'must be > 0'),
    ('mesh.worm_tooth_stiffness_linear', float('nan'), 'finite'),
    ('materials.youngs_modulus', float('inf'), 'finite'),
    ('friction.model', 'coulomb', 'one of'),
    ('integrator.newton_max_iterations', 2.5, 'integer'),
    ('geometry.flywheel_enabled', 'yes', 'true or false'),
    ('damping.modal_damping_ratios', [0.1, 0.1], '3 entries'),
    ('node.joint_names', ['a', 'a', 'b', 'c'], 'unique'),
    ('integrator.newmark_beta', 0.2, 'conditionally stable'),
    ('input.accel_time', 0.015, 'move_time'),
    ('geometry.worm_pitch_radius', 'big', 'number'),
])
def test_invalid_values_name_the_key(key, value, words):
    with pytest.raises(ConfigError) as exc:
        Config().replace({key: value})
    assert exc.value.key == key
    assert key in str(exc.value) and words in str(exc.value)


def test_unknown_keys_suggest_the_right_one():
    with pytest.raises(ConfigError) as exc:
        config_from_mapping({'mesh': {'stiffnes_model': 'linear'}})
    assert exc.value.key == 'mesh.stiffnes_model'
    assert 'unknown parameter' in str(exc.value) and 'mesh.stiffness_model' in str(exc.value)
    with pytest.raises(ConfigError, match='unknown section'):
        config_from_mapping({'meshes': {'stiffness_model': 'linear'}})


def test_file_errors(tmp_path):
    with pytest.raises(ConfigError, match='not found'):
        load_config(tmp_path / 'missing.yaml')
    broken = tmp_path / 'broken.yaml'
    broken.write_text('worm_gear_sim:\n  ros__parameters:\n    mesh: {stiffness_model: [\n')
    with pytest.raises(ConfigError, match='broken YAML at line'):
        load_config(broken)
    wrong = tmp_path / 'wrong.yaml'
    wrong.write_text('worm_gear_sim:\n  ros__parameters:\n    friction:\n'
                     '      regularization_velocity: -1.0\n')
    with pytest.raises(ConfigError) as exc:
        load_config(wrong)
    assert exc.value.key == 'friction.regularization_velocity'
    no_block = tmp_path / 'noblock.yaml'
    no_block.write_text('worm_gear_sim:\n  mesh: {}\n')
    with pytest.raises(ConfigError, match='ros__parameters'):
        load_config(no_block)


def test_ros_layout_variants(tmp_path):
    f = tmp_path / 'wild.yaml'
    f.write_text('/**:\n  ros__parameters:\n    use_sim_time: true\n'
                 '    mesh: {stiffness_model: linear}\n')
    assert load_config(f).mesh.stiffness_model == 'linear'
    f.write_text('/radar/worm_gear_sim:\n  ros__parameters:\n    friction: {model: "off"}\n')
    assert load_config(f).friction.model == 'off'
    f.write_text('geometry: {flywheel_enabled: false}\n')      # plain sections, offline use
    assert load_config(f).geometry.flywheel_enabled is False
    assert load_config(YAML_PATH, overrides={'load.output_torque': 2.0}).load.output_torque == 2


def test_metadata_covers_every_parameter():
    meta = Config.metadata()
    assert set(meta) == set(Config().to_flat_dict())
    for key, m in meta.items():
        assert m['description'], key
    assert meta['integrator.time_step']['read_only']


def _full_path(base, changes):
    """The whole set validated field by field (what replace did before it checked only the
    changed fields): the reference of the fast path."""
    nested = base.to_nested_dict()
    for key, value in changes.items():
        sec, _, name = key.partition('.')
        nested[sec][name] = value
    return config_from_mapping(nested, usable=False)


@pytest.mark.parametrize('changes', [
    {'materials.gear_shaft_shear_modulus': 8.1e10, 'damping.modal_damping_ratios': [0.01, 0, 0]},
    {'friction.mu_kinetic': 3, 'mesh.stiffness_model': 'linear'},          # int -> float
    {'integrator.max_subdivision_level': 4.0},                             # float -> int
    {'materials.flywheel_density': -1.0},                                  # range
    {'damping.modal_damping_ratios': [0.01, -0.1, 0.0]},                   # list entry
    {'mesh.stiffness_model': 'cubic'},                                     # choices
    {'friction.mu_kinetic': float('nan')},                                 # finite
    {'materials.flywheel_density': 'heavy', 'geometry.lead': -1.0},        # two bad: the first
    {'mesh.backlash': 0.06},                                               # cross-field
    {'input.accel_time': 0.6, 'input.move_time': 1.0},                     # cross-field
    {'mesh.worm_error_harmonics': [0.0, 0.0, 0.0]},                        # cross-field
])
def test_replace_checks_the_changed_fields_like_the_full_validation(changes):
    base = load_config(YAML_PATH).replace({'geometry.lead_angle': 0.064286})
    try:
        want = _full_path(base, changes)
    except ConfigError as exc:
        with pytest.raises(ConfigError) as got:
            Config.replace(base, changes)
        assert (got.value.key, str(got.value)) == (exc.key, str(exc))
        return
    got = base.replace(changes)
    assert got == want and hash(got) == hash(want) and type(got) is Config
    assert got.to_flat_dict() == want.to_flat_dict()
    assert all(type(a) is type(b) for a, b in zip(got.to_flat_dict().values(),
                                                  want.to_flat_dict().values()))
    assert base.to_flat_dict() != got.to_flat_dict()     # the base is untouched


def test_replace_names_an_unknown_key_first():
    with pytest.raises(ConfigError) as exc:
        Config().replace({'friction.mu_kinetic': 0.1, 'mesh.stifness_model': 'linear',
                          'mesh.phase': 1.0})
    assert exc.value.key == 'mesh.stifness_model'
    assert 'did you mean mesh.stiffness_model' in str(exc.value)
