"""The map_publisher node latches the map like Nav2's map_server; conversions round-trip."""
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from nav_msgs.msg import OccupancyGrid  # noqa: E402

from ecahd_core.maps import builtin_map  # noqa: E402
from ecahd_ros.conversions import (grid_to_msg, msg_to_grid, path_to_xy, xy_to_path,  # noqa: E402
                                   yaw_from_quaternion)
from ecahd_ros.map_publisher import MapPublisher  # noqa: E402
from ecahd_ros.qos import MAP_QOS  # noqa: E402



def test_grid_msg_round_trip():
    grid = builtin_map("maze2d-umaze", resolution=0.25)
    back = msg_to_grid(grid_to_msg(grid))
    assert np.array_equal(back.data, grid.data) and back.origin == grid.origin


def test_path_round_trip_and_heading():
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    path = xy_to_path(xy, "map")
    assert np.allclose(path_to_xy(path), xy)
    assert yaw_from_quaternion(path.poses[0].pose.orientation) == pytest.approx(0.0)
    assert yaw_from_quaternion(path.poses[1].pose.orientation) == pytest.approx(np.pi / 2)


def test_late_subscriber_gets_latched_map(ros_context):
    node = MapPublisher(context=ros_context,
                        parameter_overrides=[Parameter("map", value="maze2d-umaze"),
                                             Parameter("resolution", value=0.5)])
    listener = rclpy.create_node("listener", context=ros_context)
    received = []
    listener.create_subscription(OccupancyGrid, "map", received.append, MAP_QOS)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    executor.add_node(listener)
    deadline = time.monotonic() + 10.0
    while not received and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.1)
    executor.shutdown()
    assert received, "no map received within 10 s"
    grid = msg_to_grid(received[0])
    assert np.array_equal(grid.occupied, builtin_map("maze2d-umaze", resolution=0.5).occupied)
    node.destroy_node()
    listener.destroy_node()


def test_bad_map_is_logged_not_raised(ros_context):
    node = MapPublisher(context=ros_context,
                        parameter_overrides=[Parameter("map", value="no-such-map")])
    assert node.grid is None
    node.destroy_node()


def test_float32_resolution_keeps_the_fingerprint():
    # OccupancyGrid.info.resolution is float32: 0.1 travels as 0.10000000149; the map must keep
    # its identity so the models trained for it still load.
    grid = builtin_map("maze2d-large", resolution=0.1)
    msg = grid_to_msg(grid)
    msg.info.resolution = float(np.float32(0.1))  # what a subscriber receives
    assert msg.info.resolution != 0.1
    back = msg_to_grid(msg, name="maze2d-large")
    assert back.resolution == 0.1 and back.fingerprint() == grid.fingerprint()
