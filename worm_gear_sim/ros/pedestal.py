# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""A pedestal in one process (``worm_gear_sim_pedestal``): one
:class:`~.node.WormGearSimNode` per drive of ``config/pedestal.yaml``, each in its own
namespace with its own parameters (``/azimuth/worm_gear_sim``, ...: every topic, parameter
and counter of a single-drive node), plus :class:`PedestalNode` (``/pedestal``), which takes
``/pedestal/reference_trajectory`` (its own ``~/`` topic: a drive node in the root
namespace listens on ``/reference_trajectory``, and must not take the pedestal's)
naming any of the drives' worm input joints, splits it by joint,
compensates each with its drive's live model (parameter sets apply) and publishes the
merged trajectory, joints in the input's order, on ``/pedestal/compensated_trajectory``
(to be remapped to the controller's ``joint_trajectory``), and reports its trajectory
counters on /diagnostics (status ``pedestal: trajectories``).  Why one process with a node
per drive: docs/pedestal.md.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rclpy.node import Node

from ..pedestal import load_pedestal
from ..topics import DIAGNOSTICS_TOPIC, PEDESTAL_TRAJECTORY_TOPIC
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
    drives = [WormGearSimNode(namespace=d.name, defaults=d.config, adaptation=False,
                              **kwargs) for d in load_pedestal(path)]
    return [*drives, PedestalNode(drives, **kwargs)]
