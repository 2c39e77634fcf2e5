# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The node's interface beyond its topic names (those, and the message types, are the core's
:mod:`worm_gear_sim.records.topics`, which the bag reader and writer share): the queue depth of the
reference stream and the reasons the node rejects input with.  The interface itself is
described on docs/node.md."""

from __future__ import annotations

from ..realtime import Reject

__all__ = ['REFERENCE_DEPTH', 'REJECT_REASONS', 'NODE_REJECT_REASONS']

REFERENCE_DEPTH = 1000   # every sample matters to the filter: reliable, keep last 1000 (1 s
#                          at 1 kHz: a stalled executor loses none)
REJECT_REASONS = tuple(r.value for r in Reject)          # the pipeline's (core) reasons
NODE_REJECT_REASONS = ('empty_position', 'wrong_joint',   # message-level, checked by the
                       'load_empty_effort', 'load_wrong_joint')   # node
