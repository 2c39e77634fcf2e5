# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Live adaptation in the node (``adaptation.enabled``): the wiring, no algorithm.

:class:`AdaptiveNode` is the node (:class:`~.node.WormGearSimNode`) plus the core's
:class:`~worm_gear_sim.adaptation.live.LiveAdaptation` beside its real-time pipeline, the
same object the offline twin (``worm-gear-sim adapt``) drives:

* every prediction the pipeline makes goes to it (after the node has published it), then
  its decision is taken (bounded steps, no jump in the command): a step is prepared in a
  worker thread (the model, the compensator design) and swapped in at a stamp fixed when it
  was decided (:data:`~worm_gear_sim.adaptation.live.APPLY_LEAD` later, as in the twin);
  the sample callback only swaps (a step prepared late moves to the next fixed stamp and is
  counted, ``late_steps``);
* every ``measured_joint_states`` message goes to it after the model check; a rejected
  sample (non-finite, out of order, no antenna joint, outside the predictions) is counted
  and logged once per LOG_THROTTLE_S;
* ``~/adapted_parameters`` (std_msgs/String, JSON, transient local, depth 1): the estimate
  and the values in use, on every applied step, every diagnostics period and at the first
  late encoder sample and the first late step (so the last message's late counters are 0
  only if none came late).  A JSON
  text keeps the harmonics' arrays and the dotted names as they are in a params file;
  diagnostic_msgs/KeyValue would carry the same as strings without a header, and a message
  of our own would need an interface package;
* ``~/write_adapted_parameters`` (std_srvs/Trigger): writes the model in use as a params
  file (``adaptation.params_file``) that the node can start from (``--params-file``);
* /diagnostics: a status ``adaptation`` (off, waiting, steps applied, refusals, the
  windowed residual of the estimate, the model in use and the nominal set).

A parameter set from outside (the parameter service) replaces the model: the adaptation
restarts from it (and stops when ``adaptation.enabled`` is set false).  The node's own
parameters keep their declared values; the adapted ones are on the topic and in the file.
"""

from __future__ import annotations

import concurrent.futures
import json
import os
import tempfile
from pathlib import Path
from typing import Any

from rclpy.qos import DurabilityPolicy, QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger

from ..adaptation.live import LiveAdaptation, in_worker
from ..config_io import params_document, params_yaml_text
from ..topics import MEASURED_TOPIC
from . import diagnostics as diag
from .callbacks import stamp_ns
from .node import WormGearSimNode
from .statuses import HARDWARE_ID

__all__ = ['AdaptiveNode', 'ADAPTED_TOPIC', 'WRITE_SERVICE']

ADAPTED_TOPIC = '~/adapted_parameters'
WRITE_SERVICE = '~/write_adapted_parameters'


class AdaptiveNode(WormGearSimNode):
    """The node with live adaptation (module docstring); off by default, then it only adds
    the topic, the service and an ``adaptation: off`` status."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.adaptation: LiveAdaptation | None = None
        self._adapt_config: Any = None
        self._adapt_builder = concurrent.futures.ThreadPoolExecutor(
            max_workers=1, thread_name_prefix='worm_gear_sim_adapt')
        super().__init__(*args, **kwargs)
        qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self._pub_adapted = self.create_publisher(String, ADAPTED_TOPIC, qos)
        self._srv_write = self.create_service(Trigger, WRITE_SERVICE, self._on_write)
        self._sync_adaptation()

    # ---- the loop ----------------------------------------------------------------------
    def _sync_adaptation(self) -> LiveAdaptation | None:
        """The adaptation for the pipeline's current model (restarted when the model was
        replaced from outside; None when off)."""
        rt = getattr(self, 'rt', None)
        if rt is None:                                # during the base constructor
            return None
        cfg = rt.config
        if cfg is not self._adapt_config:
            self._adapt_config = cfg
            self.adaptation = LiveAdaptation(rt, cfg.node.joint_names[1:],
                                             submit=in_worker(self._adapt_builder)) \
                if cfg.adaptation.enabled else None
        return self.adaptation

    def _handle(self, out: Any, topic: str, stamp: int, value: float | None = None,
                stamp_ns: int | None = None) -> None:
        super()._handle(out, topic, stamp, value, stamp_ns)
        live = self._sync_adaptation()
        if live is None or not out.predictions:
            return
        for p in out.predictions:
            live.predicted(p.stamp_ns if stamp_ns is None else stamp_ns, p.theta)
        last = out.predictions[-1].stamp_ns if stamp_ns is None else stamp_ns
        switches, late = live.counters['switches'], live.counters['late_steps']
        for msg in live.step(last):
            if msg.startswith('adapted set not applied'):
                self._warn('adaptation_refused', msg)
            else:
                self.get_logger().info(msg)
        if live.counters['switches'] != switches:
            self._adapt_config = self.rt.config       # our own step, not an outside set
            self._publish_adapted()
        elif late == 0 and live.counters['late_steps']:
            self._publish_adapted()                   # the first late step: at once

    def _on_measured(self, msg: JointState) -> None:
        super()._on_measured(msg)
        live = self._sync_adaptation()
        if live is None:
            return
        stamp = stamp_ns(msg.header.stamp) or self._clock.now().nanoseconds
        late = live.counters['late_samples']
        reason = live.measured(stamp, msg.name, msg.position)
        if late == 0 and live.counters['late_samples']:
            self._publish_adapted()     # the first late sample: the node no longer equals
            #                             the twin, said at once (counters are cumulative)
        if reason is not None:
            self._warn('adaptation_rejected', f'adaptation: rejected {MEASURED_TOPIC} sample '
                       f'({reason}); {live.counters["rejected"]} so far')

    # ---- outputs -----------------------------------------------------------------------
    def _publish_adapted(self) -> None:
        live = self.adaptation
        if live is None:
            return
        ad = live.adapter
        doc = {'stamp_ns': self._clock.now().nanoseconds, 'estimate': live.estimates(),
               'in_use': ad.applied_values(), 'counters': live.counters,
               'last_refusal': live.last_refusal}
        self._publish(self._pub_adapted, String(data=json.dumps(doc)))

    def publish_diagnostics(self) -> None:
        super().publish_diagnostics()
        if self._sync_adaptation() is not None:
            self._publish_adapted()

    def diagnostic_statuses(self) -> list[Any]:
        statuses = super().diagnostic_statuses()
        name, hardware_id = diag.identity(self)
        live = self._sync_adaptation()
        if live is None:
            st = diag.status(name, 'adaptation', diag.OK, 'off (adaptation.enabled false)', {},
                             HARDWARE_ID)
        else:
            level, msg, values = live.status()
            st = diag.status(name, 'adaptation', diag.WARN if level == 'WARN' else diag.OK,
                             msg, values, HARDWARE_ID)
        st.hardware_id = hardware_id
        return statuses + [st]

    def destroy_node(self) -> None:
        self._adapt_builder.shutdown(wait=False, cancel_futures=True)
        super().destroy_node()

    def _on_write(self, request: Any, response: Any) -> Any:
        """Write the model in use as a params file (atomic: a temporary file renamed)."""
        live = self._sync_adaptation()
        path = Path(self.rt.config.adaptation.params_file).expanduser()
        try:
            cfg = live.params_config() if live is not None else self.rt.config
            header = '# worm_gear_sim: the model in use, written by ~/write_adapted_parameters\n'
            text = header + params_yaml_text(params_document(cfg))
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix='.tmp')
            with os.fdopen(fd, 'w') as fh:
                fh.write(text)
            os.replace(tmp, path)
        except (OSError, ValueError) as exc:
            response.success = False
            response.message = f'could not write {path}: {exc}'
            return response
        response.success = True
        n = 0 if live is None else live.counters['switches']
        response.message = f'wrote {path.resolve()} ({n} adapted steps in the model in use)'
        return response
