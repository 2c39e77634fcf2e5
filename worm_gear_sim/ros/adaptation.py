# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Live adaptation in the node (``adaptation.enabled``): the wiring, no algorithm.

:class:`NodeAdaptation`, a member of every drive node, holds the core's ``LiveAdaptation``
beside the node's pipeline: it hands it predictions and ``measured_joint_states``, swaps in
the steps it decides, publishes ``~/adapted_parameters`` and serves
``~/write_adapted_parameters`` and ``~/reset_adaptation`` and the ``adaptation`` status.
The interface: docs/adaptation.md ("In the node").
"""

from __future__ import annotations

import json
from collections.abc import Callable, Collection, Sequence
from typing import Any

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from std_msgs.msg import String
from std_srvs.srv import Trigger

from .._support.guarded_io import GuardedFileError, check_write_target, write_text_durably
from ..adaptation.live import LiveAdaptation, in_slices
from ..config.files import params_document, params_yaml_text
from ..config.usable import Config
from ..realtime import Output, RealtimePredictor
from ..records.topics import MEASURED_TOPIC
from ..schema.validation import ConfigError
from . import diagnostics as diag
from .statuses import HARDWARE_ID

__all__ = ['NodeAdaptation', 'ADAPTED_TOPIC', 'WRITE_SERVICE', 'RESET_SERVICE']

ADAPTED_TOPIC = '~/adapted_parameters'
WRITE_SERVICE = '~/write_adapted_parameters'
RESET_SERVICE = '~/reset_adaptation'
PARAMS_FILE = 'adaptation.params_file'


class NodeAdaptation:
    """The live adaptation of the drive node ``node`` (module docstring) beside its
    pipeline ``rt``; ``config``: the node's declared set at the start; ``warn(cause,
    text)``: the node's throttled warning (``text`` or a callable that makes it);
    ``publish(pub, msg)``: its counted publish; ``rebuild()``: prepares the node's declared
    set again and swaps it in (through :meth:`pipeline` and :meth:`swapped`, as a parameter
    set)."""

    def __init__(self, node: Node, rt: RealtimePredictor, config: Config,
                 warn: Callable[[str, Any], None], publish: Callable[[Any, Any], None],
                 rebuild: Callable[[], None]) -> None:
        self.node, self.rt = node, rt
        self._warn, self._publish, self._rebuild = warn, publish, rebuild
        self._log = node.get_logger()
        self._clock = node.get_clock()
        #: the core's adaptation, once it has run (kept while it is off: frozen)
        self.live: LiveAdaptation | None = None
        #: who else writes to a file (the pedestal's other drives: their name, or None);
        #: a parameter set naming one such file is refused, and so is the write
        self.file_user: Callable[[str], str | None] = lambda path: None
        self.enabled = config.adaptation.enabled
        self._reset_pending = False
        qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self._pub = node.create_publisher(String, ADAPTED_TOPIC, qos)
        self._srv_write = node.create_service(Trigger, WRITE_SERVICE, self._on_write)
        self._srv_reset = node.create_service(Trigger, RESET_SERVICE, self._on_reset)
        if self.enabled:
            self._start()
            try:
                check_write_target(config.adaptation.params_file)
            except GuardedFileError as exc:
                self._log.warning(f'{PARAMS_FILE}: {exc}; {WRITE_SERVICE} will refuse it')

    def _start(self) -> None:
        self.live = LiveAdaptation(self.rt, self.rt.config.node.joint_names[1:],
                                   submit=in_slices())

    @property
    def running(self) -> LiveAdaptation | None:
        """The adaptation while it learns (``adaptation.enabled``), else None."""
        return self.live if self.enabled else None

    # ---- the loop ----------------------------------------------------------------------
    def predictions(self, out: Output, stamp_ns: int | None) -> None:
        """The pipeline's predictions of one callback (already published; ``stamp_ns``:
        the stamp they were published with, None: their own), then the decision."""
        live = self.running
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
                self._log.info(msg)
        if live.counters['switches'] != switches:
            self.publish()
        elif late == 0 and live.counters['late_steps']:
            self.publish()                            # the first late step: at once

    def measured(self, stamp_ns: int, names: Sequence[str], positions: Sequence[float]
                 ) -> None:
        """An encoder message (its stamp, or the reception time if unstamped)."""
        live = self.running
        if live is None:
            return
        late = live.counters['late_samples']
        reason = live.measured(stamp_ns, names, positions)
        if late == 0 and live.counters['late_samples']:
            self.publish()      # the first late sample: the node no longer equals the twin,
            #                     said at once (counters are cumulative)
        if reason is not None:
            self._warn('adaptation_' + reason, lambda: (
                f'adaptation: rejected {MEASURED_TOPIC} sample ({reason}); '
                f'{live.counters["rejected_" + reason]} so far'))

    # ---- parameter sets (the node's ParameterUpdates) -----------------------------------
    def pipeline(self, declared: Config, names: Collection[str]) -> Config:
        """The set the pipeline is to run for the operator's set ``declared`` (a set of
        ``names``): it with the adapted values it keeps on top; ConfigError if
        ``adaptation.params_file`` is named and no file can be written there, or if the
        set is not usable with them."""
        if PARAMS_FILE in names:
            path = declared.adaptation.params_file
            try:
                check_write_target(path)
            except GuardedFileError as exc:
                raise ConfigError(PARAMS_FILE, str(exc)) from None
            if (user := self.file_user(path)) is not None:
                raise ConfigError(PARAMS_FILE, f'{path}: {user} writes to this file; name '
                                  'one of this drive\'s own')
        if self.live is None or self._reset_pending:
            return declared
        carried = self.live.carried_values(declared, names)
        if not carried:
            return declared
        try:
            return declared.replace(carried)
        except ConfigError as exc:
            raise ConfigError(exc.key, f'{exc.reason} (with the adapted values in use: '
                              f'{", ".join(carried)}; {RESET_SERVICE} returns to the '
                              'declared set)', exc.keys) from None

    def swapped(self, declared: Config, names: Collection[str]) -> None:
        """The pipeline runs :meth:`pipeline`'s set for ``declared`` now: what was learnt
        is carried over (or forgotten after a reset); adaptation switched on or off."""
        live, was = self.live, self.enabled
        self.enabled = declared.adaptation.enabled
        if live is None:
            if self.enabled:
                self._start()
            return
        if self._reset_pending:
            self._reset_pending = False
            self._log.info(live.forget())
        else:
            for note in live.carry_over(declared, names):
                self._log.info(f'adaptation: {note}')
        if was and not self.enabled:
            self._log.info(f'adaptation off: the model in use stays as it is '
                           f'({live.counters["switches"]} adapted steps), learning stops')
        elif self.enabled and not was:
            self._log.info('adaptation on again: resumes from the estimate kept')
        self.publish()

    # ---- outputs -----------------------------------------------------------------------
    def publish(self) -> None:
        """~/adapted_parameters (once adaptation has run)."""
        live = self.live
        if live is None:
            return
        plausible, why = live.plausibility()
        doc = {'stamp_ns': self._clock.now().nanoseconds, 'enabled': self.enabled,
               'estimate': live.estimates(), 'plausible': plausible, 'plausibility': why,
               'in_use': live.adapter.applied_values(), 'counters': live.counters,
               'last_refusal': live.last_refusal}
        self._publish(self._pub, String(data=json.dumps(doc)))

    def status(self, name: str) -> Any:
        """The ``adaptation`` status of /diagnostics."""
        live = self.live
        if live is None:
            return diag.status(name, 'adaptation', diag.OK, 'off (adaptation.enabled false)',
                               {}, HARDWARE_ID)
        level, msg, values = live.status()
        if not self.enabled:
            level, msg = 'OK', (f'off (adaptation.enabled false): the model in use keeps '
                                f'{live.counters["switches"]} adapted steps, frozen')
        return diag.status(name, 'adaptation', diag.WARN if level == 'WARN' else diag.OK,
                           msg, values, HARDWARE_ID)

    def shutdown(self) -> None:
        """Drop a step being prepared (its slices run on the sample thread, nowhere else)."""
        pending = None if self.live is None else self.live.pending
        if pending is not None and hasattr(pending.future, 'cancel'):
            pending.future.cancel()

    # ---- services ----------------------------------------------------------------------
    def _on_write(self, request: Any, response: Any) -> Any:
        """Write the model in use as a params file (atomic and durable; refused targets:
        nothing written)."""
        live = self.live
        cfg = live.params_config() if live is not None else self.rt.config
        path = cfg.adaptation.params_file
        header = '# worm_gear_sim: the model in use, written by ~/write_adapted_parameters\n'
        if (user := self.file_user(path)) is not None:
            response.success = False
            response.message = f'not written: {user} writes to {path}'
            self._warn('adaptation_write', response.message)
            return response
        try:
            written = write_text_durably(path, header + params_yaml_text(params_document(cfg)))
        except (OSError, ValueError) as exc:       # GuardedFileError is a ValueError
            response.success = False
            response.message = f'could not write {path}: {exc}'
            self._warn('adaptation_write', response.message)
            return response
        response.success = True
        n = 0 if live is None else live.counters['switches']
        response.message = f'wrote {written} ({n} adapted steps in the model in use)'
        return response

    def _on_reset(self, request: Any, response: Any) -> Any:
        """Forget what was learnt (module docstring)."""
        response.success = True
        if self.live is None:
            response.message = ('nothing to reset: adaptation has not run; the model in use '
                                'is the declared set')
            return response
        self._reset_pending = True
        self._rebuild()
        self._log.info(f'{RESET_SERVICE}: the model in use returns to the declared set')
        response.message = ('reset: the model in use returns to the declared set (swapped '
                             'in between two samples), the estimate restarts from the prior')
        return response
