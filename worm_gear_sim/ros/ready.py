# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The node's start-up lines: "ready" (once every kernel its configuration runs is compiled
or loaded, :mod:`worm_gear_sim.adaptation.warmup`) and the warnings that go with it."""

from __future__ import annotations

from typing import Any

from ..adaptation.warmup import Warmed
from ..config.usable import Config
from ..dynamics.load import elastic_load_warning
from ..dynamics.modal import step_resolution_warning
from ..records.topics import COMMAND_TOPIC, REFERENCE_TOPIC

__all__ = ['log_ready']


def log_ready(node: Any, cfg: Config, kernels: Warmed) -> None:
    """Log "ready" with what the node waits for and how long its kernels took; then the
    kernel cache's folder when it is not the package's (one line), an under-resolved step or
    a load beyond the elastic limit (allowed, but not trustworthy), a feed-forward that could
    not be designed, ``adaptation.enabled`` on a node without live adaptation."""
    log = node.get_logger()
    log.info(f'ready: dt = {node.sim.dt:g} s, {cfg.node.publish_rate_hz:g} Hz, ratio '
             f'1:{node.rt.model.derived.ratio:.6g}; waiting for '
             f'{node.resolve_topic_name(REFERENCE_TOPIC)} (stamped) or '
             f'{node.resolve_topic_name(COMMAND_TOPIC)}; kernels ready in '
             f'{kernels.seconds:.2f} s')
    for note in (kernels.note, step_resolution_warning(node.rt.model),
                 elastic_load_warning(node.rt.model)):
        if note:
            log.warning(note)
    if node.rt.compensator is None:
        log.error(f'feed-forward unavailable ({node.rt.compensation_error}); no corrections')
    if node.adaptation is None and cfg.adaptation.enabled:
        log.warning('adaptation.enabled is true, but this node runs without live adaptation: '
                    'ignored')
