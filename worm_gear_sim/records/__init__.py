# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Records of a drive: commanded and measured angles from CSV files and rosbag2 bags.

:class:`Record` (the command theta1 and the measured theta2..theta4 on one time base),
:func:`read_record` and the readers and writers of :mod:`.csv_io` and :mod:`.bag_io`
(``rosbags``: no ROS installation needed); :func:`write_bag` writes a prediction with the
node's topics.  Import from here.  Formats: docs/data-formats.md.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from .bag_io import (
    BAG_VERSION,
    DEFAULT_COMMAND_TOPICS,
    DEFAULT_MEASURED_TOPICS,
    BagStream,
    Series,
    align_by_stamp,
    bag_topics,
    prediction_streams,
    read_bag,
    read_series,
    write_bag,
    write_streams,
)
from .csv_io import ANGLE_UNITS, TIME_UNITS, read_csv, write_csv_columns, write_csv_header
from .record import Record, RecordError

__all__ = ['Record', 'RecordError', 'read_csv', 'read_bag', 'read_record', 'write_bag',
           'BagStream', 'prediction_streams', 'write_streams', 'bag_topics', 'Series',
           'read_series', 'align_by_stamp',
           'ANGLE_UNITS', 'TIME_UNITS', 'DEFAULT_COMMAND_TOPICS',
           'DEFAULT_MEASURED_TOPICS', 'write_csv_header', 'write_csv_columns', 'BAG_VERSION']


def read_record(path: str | Path, **kwargs: Any) -> Record:
    """A CSV file (``*.csv``) or a rosbag2 bag (a directory, ``*.db3`` or ``*.mcap``)."""
    p = Path(path)
    if p.is_dir() or p.suffix.lower() in ('.db3', '.mcap', '.yaml'):
        if p.suffix.lower() == '.yaml':
            p = p.parent
        bag_keys = ('command_topic', 'joint_states_topic', 'joint_names', 'name',
                    'require_measured', 'interpolation', 'min_samples')
        return read_bag(p, **{k: v for k, v in kwargs.items() if k in bag_keys})
    csv_keys = ('columns', 'name', 'min_samples', 'require_measured')
    return read_csv(p, **{k: v for k, v in kwargs.items() if k in csv_keys})
