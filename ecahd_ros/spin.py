"""The one ``main()`` body every node shares (ros2/examples, Jazzy): init, spin, stop on Ctrl-C
or external shutdown, always destroy the node and shut down."""
from __future__ import annotations

from collections.abc import Callable

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node


def spin_node(make_node: Callable[[], Node], args=None) -> None:
    """Create the node after ``rclpy.init`` and spin it until interrupted; ``destroy_node`` runs
    in every case (nodes release their resources, e.g. close a bag, there)."""
    rclpy.init(args=args)
    node = make_node()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
