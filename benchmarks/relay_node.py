# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The floor of bench_pedestal.py: a process with one "empty" node per axis that does only
the per-sample message traffic of the drive node (subscribe ``worm_angle_reference``,
publish ``~/compensated_command`` with the same stamp and position, the same QoS and the
same executor and spin loop), no physics.  Whatever it costs, rclpy and DDS cost.

    python benchmarks/relay_node.py azimuth elevation
"""

from __future__ import annotations

import sys


def main(namespaces: list[str]) -> int:
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    from worm_gear_sim.ros.interface import REFERENCE_DEPTH
    from worm_gear_sim.ros.run import make_executor, spin_until_shutdown

    rclpy.init()
    ex = make_executor('events')
    qos = QoSProfile(depth=REFERENCE_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
    nodes = []
    for ns in namespaces:
        node = rclpy.create_node('worm_gear_sim', namespace=ns)
        pub = node.create_publisher(JointState, '~/compensated_command', qos)
        out = JointState()
        out.position = [0.0]

        def relay(msg: JointState, pub=pub, out=out) -> None:
            out.header.stamp = msg.header.stamp
            out.name = msg.name
            out.position[0] = msg.position[0]
            pub.publish(out)
        node.create_subscription(JointState, 'worm_angle_reference', relay, qos)
        ex.add_node(node)
        nodes.append(node)
    try:
        spin_until_shutdown(ex)
    except KeyboardInterrupt:
        pass
    finally:
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:] or ['azimuth', 'elevation']))
