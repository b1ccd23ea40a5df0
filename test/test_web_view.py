"""web_view in-process: what a browser fetches (the page, the map as a PNG, the state it draws)
follows the topics; a port already taken fails at start-up with one line. (The page itself was
checked in Chromium: `ecahd demo --view`, docs/commands.md.)"""
import json
import math
import urllib.error
import urllib.request

import cv2
import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
from nav_msgs.msg import OccupancyGrid, Odometry, Path  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from conftest import spin_until  # noqa: E402
from ecahd_core.errors import EcahdError  # noqa: E402
from ecahd_core.maps import builtin_map  # noqa: E402
from ecahd_ros.conversions import grid_to_msg, pose_from_xy_yaw, xy_to_path  # noqa: E402
from ecahd_ros.qos import MAP_QOS, PLAN_QOS  # noqa: E402
from ecahd_ros.web_view import WebView, view_state  # noqa: E402


def _get(port: int, path: str) -> bytes:
    with urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=5) as answer:
        return answer.read()


def test_the_view_follows_the_topics(ros_context):
    view = WebView(context=ros_context, parameter_overrides=[Parameter("port", value=0),
                                                             Parameter("robot",
                                                                       value="quadruped")])
    probe = rclpy.create_node("probe", context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    for node in (view, probe):
        executor.add_node(node)
    try:
        port = view.port
        assert b"<canvas" in _get(port, "/")
        with pytest.raises(urllib.error.HTTPError):
            _get(port, "/map.png")  # no map yet: 404
        state = json.loads(_get(port, "/state.json"))
        assert state["map"] is None and state["robot"] is None
        grid = builtin_map("maze2d-large")
        map_pub = probe.create_publisher(OccupancyGrid, "map", MAP_QOS)
        plan_pub = probe.create_publisher(Path, "plan", PLAN_QOS)
        odom_pub = probe.create_publisher(Odometry, "odom", 10)
        map_pub.publish(grid_to_msg(grid))
        plan = xy_to_path(np.array([[1.5, 1.5], [6.5, 5.5]]), "map")
        plan.poses[-1].pose = pose_from_xy_yaw(6.5, 5.5, math.pi / 2)
        plan_pub.publish(plan)
        odom = Odometry()
        odom.header.frame_id = "map"
        odom.pose.pose = pose_from_xy_yaw(1.5, 1.5, 0.5)
        spin_until(executor, lambda: odom_pub.get_subscription_count() > 0, 5, "subscribed")
        odom_pub.publish(odom)
        spin_until(executor, lambda: view.state()["robot"] and view.state()["goal"]
                   and view.state()["map"], 5, "map, plan and pose in")
        state = json.loads(_get(port, "/state.json"))
        assert state["map"] == {"x0": 0.0, "y0": 0.0, "x1": 12.0, "y1": 9.0, "version": 1,
                                "name": "map", "resolution": pytest.approx(0.1)}
        assert state["robot"] == [1.5, 1.5, 0.5]
        assert state["goal"] == {"xy": [6.5, 5.5], "yaw": pytest.approx(math.pi / 2, abs=1e-4)}
        assert state["plan"] == [[1.5, 1.5], [6.5, 5.5]]
        outline = np.array(state["footprint"])  # the quadruped's rectangle, turned by 0.5 rad
        assert outline.mean(axis=0) == pytest.approx([1.5, 1.5], abs=0.02)
        png = cv2.imdecode(np.frombuffer(_get(port, "/map.png"), np.uint8),
                           cv2.IMREAD_GRAYSCALE)
        assert png.shape == grid.occupied.shape
        assert np.array_equal(png[::-1] == 0, grid.occupied)  # the top row is the far edge
    finally:
        executor.shutdown()
        view.destroy_node()
        probe.destroy_node()


def test_a_taken_port_fails_at_start_up(ros_context):
    first = WebView(context=ros_context, parameter_overrides=[Parameter("port", value=0)])
    try:
        with pytest.raises(EcahdError, match=f"{first.port}.*port parameter"):
            WebView(context=ros_context, parameter_overrides=[
                Parameter("port", value=first.port)])
    finally:
        first.destroy_node()


def test_long_plans_are_thinned_but_keep_their_goal():
    plan = np.stack([np.linspace(0, 10, 4999), np.zeros(4999)], axis=1)
    state = view_state(plan=plan, goal_yaw=None)
    assert len(state["plan"]) <= 2001 and state["plan"][-1] == [10.0, 0.0]
    assert state["goal"] == {"xy": [10.0, 0.0], "yaw": None}
