"""map_publisher: serves a built-in maze or a Nav2 map YAML on ``map`` like Nav2's map_server.

Parameters:
    map (str, "maze2d-large"): a built-in maze (maze2d-umaze, maze2d-medium, maze2d-large) or a
        path to a Nav2 map_server YAML file.
    resolution (double, 0.1): [m/cell] rasterisation of built-in mazes (ignored for YAML files).
    frame_id (str, "map"): frame of the published grid.

Publishes ``map`` (nav_msgs/OccupancyGrid, reliable + transient_local + depth 1, latched).
"""
from __future__ import annotations

import rclpy
from rclpy.node import Node
from nav_msgs.msg import OccupancyGrid

from ecahd_core.errors import EcahdError
from ecahd_core.maps import DEFAULT_MAP, GridMap, load_map
from ecahd_ros.conversions import grid_to_msg
from ecahd_ros.qos import MAP_QOS
from ecahd_ros.params import ParamSpec, declare_parameters
from ecahd_ros.spin import spin_node

PARAMETERS = [
    ParamSpec("map", DEFAULT_MAP, "built-in maze name or path to a Nav2 map YAML"),
    ParamSpec("resolution", 0.1, "[m/cell] rasterisation of built-in mazes"),
    ParamSpec("frame_id", "map", "frame of the published grid"),
]


class MapPublisher(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("map_publisher", **kwargs)
        declare_parameters(self, PARAMETERS)
        self._pub = self.create_publisher(OccupancyGrid, "map", MAP_QOS)
        self.grid: GridMap | None = None
        try:
            self.grid = load_map(self.get_parameter("map").value,
                                 float(self.get_parameter("resolution").value))
        except EcahdError as exc:
            self.get_logger().error(f"cannot load map: {exc}")
            return
        msg = grid_to_msg(self.grid, self.get_clock().now().to_msg())
        msg.header.frame_id = self.get_parameter("frame_id").value
        self._pub.publish(msg)
        self.get_logger().info(f"published map {self.grid.name!r} "
                               f"({self.grid.width} x {self.grid.height} cells, "
                               f"{self.grid.resolution} m/cell)")


def main(args=None) -> None:
    spin_node(MapPublisher, args, name="map_publisher")


if __name__ == "__main__":
    main()
