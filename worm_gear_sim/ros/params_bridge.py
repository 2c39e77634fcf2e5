# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Config <-> ROS 2 parameters: descriptors from :meth:`Config.metadata`, values both ways.

Every model parameter is declared under its dotted name (``mesh.stiffness_model``) with a
``ParameterDescriptor`` built from the field metadata (description with unit and choices,
``FloatingPointRange``/``IntegerRange`` where the core gives lo/hi, ``read_only``).  Values
are converted back into a :class:`~worm_gear_sim.config.usable.Config` by the core itself
(:func:`~worm_gear_sim.config.usable.config_from_mapping` / :meth:`Config.replace`), so the node
validates exactly as the core and the CLI do.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
)
from rclpy.parameter import Parameter

from ..config.files import ROS_RESERVED, load_config
from ..config.usable import Config
from ..schema.sections import SECTIONS
from ..schema.validation import ConfigError, unknown_name, value_kind
from ..schema.validation import suggest as suggest_name

__all__ = ['parameter_type', 'descriptor_for', 'declare_config', 'to_core_value',
           'coerce_parameter', 'is_model_parameter', 'check_overrides',
           'MODEL_PARAMETER_NAMES', 'file_defaults']

#: Dotted names of all model parameters, in declaration order.
MODEL_PARAMETER_NAMES: tuple[str, ...] = tuple(Config().to_flat_dict())
_NAMES = frozenset(MODEL_PARAMETER_NAMES)


def is_model_parameter(name: str) -> bool:
    """True for the dotted names that come from :class:`Config` (not qos_overrides etc.)."""
    return name in _NAMES


_ROS_TYPE = {
    'bool': ParameterType.PARAMETER_BOOL,
    'int': ParameterType.PARAMETER_INTEGER,
    'float': ParameterType.PARAMETER_DOUBLE,
    'str': ParameterType.PARAMETER_STRING,
    'str_list': ParameterType.PARAMETER_STRING_ARRAY,
    'float_list': ParameterType.PARAMETER_DOUBLE_ARRAY,
}


def parameter_type(default: Any) -> int:
    """ROS ParameterType of a Config default value (its kind: :func:`value_kind`)."""
    return _ROS_TYPE[value_kind(default)]


def _fmt(x: float) -> str:
    return f'{x:g}'


def descriptor_for(name: str, default: Any, meta: Mapping[str, Any]) -> ParameterDescriptor:
    """ParameterDescriptor of one model parameter from its core metadata."""
    ptype = parameter_type(default)
    text = str(meta.get('description', ''))
    unit = meta.get('unit') or ''
    if unit:
        text += f' [{unit}]'
    constraints = []
    lo, hi = meta.get('lo'), meta.get('hi')
    if lo is not None or hi is not None:
        left = ('(' if meta.get('lo_open') else '[') + (_fmt(lo) if lo is not None else '-inf')
        right = (_fmt(hi) if hi is not None else 'inf') + ']'
        constraints.append(f'range {left}, {right}')
    if meta.get('choices'):
        constraints.append('one of: ' + ', '.join(meta['choices']))
    if meta.get('length'):
        constraints.append(f'{meta["length"]} entries')
    desc = ParameterDescriptor(
        name=name, type=ptype, description=text,
        additional_constraints='; '.join(constraints),
        read_only=bool(meta.get('read_only', False)))
    if lo is not None and hi is not None:
        if ptype == ParameterType.PARAMETER_DOUBLE:
            desc.floating_point_range = [FloatingPointRange(
                from_value=float(lo), to_value=float(hi), step=0.0)]
        elif ptype == ParameterType.PARAMETER_INTEGER:
            desc.integer_range = [IntegerRange(
                from_value=int(math.ceil(lo)), to_value=int(math.floor(hi)), step=0)]
    return desc


def declare_config(node: Any, defaults: Config) -> dict[str, Any]:
    """Declare every model parameter on ``node`` (defaults from ``defaults``; values given
    by ``--params-file`` or ``parameter_overrides`` win).  Returns dotted name -> value."""
    meta = Config.metadata()
    flat = defaults.to_flat_dict()
    # rclpy types a parameter from its default, and an empty list reads as a byte array
    # (a params file's [] as not set): an empty double array is declared by its type, then
    # given its empty value explicitly typed (mesh.*_error_harmonics)
    empty = {name for name, value in flat.items()
             if isinstance(value, list) and not value and value_kind(value) == 'float_list'}
    declared = node.declare_parameters('', [
        (name, Parameter.Type.DOUBLE_ARRAY if name in empty else value,
         descriptor_for(name, value, meta[name]))
        for name, value in flat.items()])
    unset = [Parameter(p.name, Parameter.Type.DOUBLE_ARRAY, list(flat[p.name]))
             for p in declared if p.name in empty and p.type_ == Parameter.Type.NOT_SET]
    if unset:
        node.set_parameters(unset)
    return {p.name: to_core_value(node.get_parameter(p.name).value) if p.name in empty
            else to_core_value(p.value) for p in declared}


def check_overrides(node: Any) -> None:
    """Parameters given to ``node`` (params file, ``-p``, ``parameter_overrides``) that it
    does not declare, by the core's rule (:func:`~worm_gear_sim.schema.validation.unknown_name`,
    the one the command line applies to a params file): a misspelt model key, an unknown
    section or a QoS override of a topic it does not have raises :class:`ConfigError`
    naming it, with the closest declared name; a plain name unlike ours (another node's, in
    a shared ``/**`` block) is logged and ignored."""
    unknown = sorted(n for n in node._parameter_overrides if not node.has_parameter(n))
    for name in unknown:
        if name.split('.', 1)[0] == 'qos_overrides':
            qos = node.get_parameters_by_prefix('qos_overrides')
            hint = suggest_name(name, {'qos_overrides.' + n: None for n in qos})
            raise ConfigError(name, 'unknown parameter of this node' + hint)
        if name.split('.', 1)[0] in ROS_RESERVED:       # ROS's own, not declared here
            node.get_logger().warning(f'ignoring parameter {name!r}: not declared by '
                                      f'{node.get_name()}')
            continue
        err = unknown_name(name, MODEL_PARAMETER_NAMES, SECTIONS)
        if err is not None:
            raise err
        node.get_logger().warning(f'ignoring parameter {name!r}: not a parameter of '
                                  f'{node.get_name()}')


def to_core_value(value: Any) -> Any:
    """Parameter value (array.array, list, scalar) -> what :meth:`Config.replace` takes."""
    if isinstance(value, (str, bytes, bool, int, float)) or value is None:
        return value
    if isinstance(value, Iterable):
        return list(value)
    return value


def coerce_parameter(param: Parameter, declared_type: int) -> Parameter:
    """A value typed on a command line at run time (``ros2 param set``), as the CLI's
    ``--set`` takes it: an integer (or integer array) for a double (array) parameter, an
    integral double for an integer one; any other type is returned unchanged (rclpy
    rejects it).  Params files are strict (the type as written), in the node and in the
    CLI alike (:func:`~worm_gear_sim.schema.validation.coerce`)."""
    if declared_type == ParameterType.PARAMETER_DOUBLE and \
            param.type_ == Parameter.Type.INTEGER:
        return Parameter(param.name, Parameter.Type.DOUBLE, float(param.value))
    if declared_type == ParameterType.PARAMETER_INTEGER and \
            param.type_ == Parameter.Type.DOUBLE and float(param.value).is_integer():
        return Parameter(param.name, Parameter.Type.INTEGER, int(param.value))
    if declared_type == ParameterType.PARAMETER_DOUBLE_ARRAY and \
            param.type_ == Parameter.Type.INTEGER_ARRAY:
        return Parameter(param.name, Parameter.Type.DOUBLE_ARRAY,
                         [float(v) for v in param.value])
    return param


def file_defaults() -> Config:
    """Declaration defaults: the package's YAML (source tree or installed share/), falling
    back to the code defaults, which equal it (a test checks this)."""
    try:
        return load_config()
    except ConfigError:
        return Config()
