# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A pedestal in one process (``worm_gear_sim_pedestal``): one ``WormGearSimNode`` per drive
of ``config/pedestal.yaml``, each in its own namespace with its own parameters, plus
:class:`PedestalNode` (``/pedestal``), which splits ``/pedestal/reference_trajectory`` by
joint, compensates each with its drive's live model and publishes the merged
``/pedestal/compensated_trajectory``.  docs/pedestal.md.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rclpy.node import Node

from .._support.guarded_io import resolved_target
from ..config.pedestal import PARAMS_FILE_KEY, load_pedestal, shared_params_files
from ..records.topics import DIAGNOSTICS_TOPIC, PEDESTAL_TRAJECTORY_TOPIC
from ..schema.validation import ConfigError
from . import diagnostics as diag
from .callbacks import LogThrottle
from .node import LOG_THROTTLE_S, WormGearSimNode
from .trajectory_bridge import TrajectoryBridge, trajectory_status

__all__ = ['PedestalNode', 'build_pedestal', 'PEDESTAL_NODE_NAME', 'PEDESTAL_HARDWARE_ID']

PEDESTAL_NODE_NAME = 'pedestal'
PEDESTAL_HARDWARE_ID = 'worm_gear_sim_pedestal'


class PedestalNode(Node):
    """The pedestal's trajectory node over ``drives`` (their live models)."""

    def __init__(self, drives: list[WormGearSimNode], name: str = PEDESTAL_NODE_NAME,
                 **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        self.drives = drives
        self.counters: dict[str, Any] = {'publish_failures': 0}
        self.last_error = ''
        self._throttle = LogThrottle(LOG_THROTTLE_S)
        self.trajectories = TrajectoryBridge(self, self.models, self.counters, self._warn,
                                             self._publish, topic=PEDESTAL_TRAJECTORY_TOPIC)
        self._pub_diag = self.create_publisher(diag.DiagnosticArray, DIAGNOSTICS_TOPIC, 1)
        period = min((d.config.node.diagnostic_period for d in drives), default=1.0)
        self._diag_timer = self.create_timer(period, self.publish_diagnostics)
        self.get_logger().info(
            f'pedestal of {len(drives)} drives ({", ".join(self.trajectories.joints)}): '
            f'waiting for {self.resolve_topic_name(PEDESTAL_TRAJECTORY_TOPIC)}')

    def diagnostic_statuses(self) -> list[diag.DiagnosticStatus]:
        """Status 'trajectories' (every counter of the trajectory bridge, the node's
        publish failures, the drives it serves)."""
        name, hardware_id = diag.identity(self, PEDESTAL_HARDWARE_ID)
        st = trajectory_status(name, self.counters, self.trajectories, hardware_id)
        st.values.append(diag.KeyValue(key='publish_failures',
                                       value=str(self.counters['publish_failures'])))
        st.values.append(diag.KeyValue(key='drives', value=', '.join(
            d.get_fully_qualified_name() for d in self.drives)))
        return [st]

    def publish_diagnostics(self) -> None:
        if self.context.ok():
            self._publish(self._pub_diag, diag.array(self.get_clock().now().to_msg(),
                                                     self.diagnostic_statuses()))

    def models(self) -> dict[str, Any]:
        """Worm input joint -> the drive's model in force."""
        return {d.config.node.joint_names[0]: d.rt.model for d in self.drives}

    def _warn(self, cause: str, text: str) -> None:
        self.last_error = text
        line = self._throttle(cause, text)
        if line:
            self.get_logger().warning(line)

    def _publish(self, pub: Any, msg: Any) -> None:
        try:
            pub.publish(msg)
        except Exception as exc:  # noqa: BLE001 - never ends the node (WormGearSimNode)
            if self.context.ok():
                self.counters['publish_failures'] += 1
                self._warn('publish_failed', f'publish on {pub.topic_name} failed ({exc})')

    def destroy_node(self) -> None:
        self.trajectories.shutdown()
        super().destroy_node()


def build_pedestal(path: str | Path | None = None, **kwargs: Any) -> list[Node]:
    """The drive nodes of the pedestal file ``path`` (namespaces = drive names) and the
    pedestal node after them; ``kwargs`` (e.g. ``context``) go to every node."""
    drives: list[WormGearSimNode] = []
    try:
        for d in load_pedestal(path):
            drives.append(WormGearSimNode(namespace=d.name, defaults=d.config, **kwargs))
        shared = shared_params_files({n.get_namespace().strip('/'):
                                      n.config.adaptation.params_file for n in drives})
        if shared is not None:     # the start's own parameters (-p, --params-file) did it
            raise ConfigError(PARAMS_FILE_KEY, shared[1])
    except BaseException:
        for n in drives:
            n.destroy_node()
        raise
    for n in drives:
        assert n.adaptation is not None       # every drive node has its adaptation member
        n.adaptation.file_user = _other_user(n, drives)
    return [*drives, PedestalNode(drives, **kwargs)]


def _other_user(node: WormGearSimNode, drives: list[WormGearSimNode]) -> Any:
    """For ``node``'s adaptation: which other drive's declared ``adaptation.params_file``
    is the file a path names (its node's name), or None."""
    def user(path: str) -> str | None:
        target = resolved_target(path)
        for d in drives:
            if d is not node and resolved_target(d.config.adaptation.params_file) == target:
                return d.get_fully_qualified_name()
        return None
    return user
