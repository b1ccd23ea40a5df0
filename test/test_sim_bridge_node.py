"""The sim_bridge node in-process on maze2d-umaze, as fast as possible: latched map, cmd_vel
drives odom, stale commands stop, sim clock, bad input logged and ignored, a configuration that
cannot work raised, LiDAR scans, obstacles from a scenario file (markers, contacts by kind)."""
import json
import math
import os
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
from geometry_msgs.msg import PoseWithCovarianceStamped, Twist, TwistStamped  # noqa: E402
from nav_msgs.msg import OccupancyGrid, Odometry  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import Image, LaserScan  # noqa: E402
from std_msgs.msg import Bool, String  # noqa: E402
from visualization_msgs.msg import Marker, MarkerArray  # noqa: E402

from ecahd_core.errors import EcahdError  # noqa: E402
from ecahd_core.maps import builtin_map  # noqa: E402
from ecahd_ros.conversions import msg_to_grid, pose_from_xy_yaw, yaw_from_quaternion  # noqa: E402
from ecahd_ros.qos import MAP_QOS  # noqa: E402
from sim_bridge.node import SimBridge  # noqa: E402

START = (1.5, 1.5, 0.0)  # umaze corridor y in [1, 2], free for x in [1, 4]
DT = 0.02  # 1 / rate_hz (50)



@pytest.fixture
def bridge_setup(ros_context):
    """make(**params) -> (bridge, probe node, executor), everything torn down afterwards."""
    created = []

    def make(**params):
        # odometry in map (the true pose) unless a test asks for REP-105's odom
        values = {"map": "maze2d-umaze", "realtime_factor": 0.0, "start_x": START[0],
                  "start_y": START[1], "start_yaw": START[2], "odom_frame": "map", **params}
        bridge = SimBridge(context=ros_context,
                           parameter_overrides=[Parameter(k, value=v) for k, v in values.items()])
        probe = rclpy.create_node("probe", context=ros_context)
        executor = SingleThreadedExecutor(context=ros_context)
        executor.add_node(bridge)
        executor.add_node(probe)
        created.append((executor, bridge, probe))
        return bridge, probe, executor

    yield make
    for executor, bridge, probe in created:
        executor.shutdown()
        bridge.destroy_node()
        probe.destroy_node()


def spin_until(executor, condition, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "condition not met within the time limit"
        executor.spin_once(timeout_sec=0.01)


def publish_when_matched(executor, publisher, msg) -> None:
    """Publish once the bridge's subscription is matched (a volatile message sent before
    discovery is lost)."""
    spin_until(executor, lambda: publisher.get_subscription_count() > 0)
    publisher.publish(msg)


def test_late_subscriber_gets_the_latched_map(bridge_setup):
    bridge, probe, executor = bridge_setup()
    spin_until(executor, lambda: bridge.sim.state.t >= 0.5)
    received = []
    probe.create_subscription(OccupancyGrid, "map", received.append, MAP_QOS)
    spin_until(executor, lambda: received)
    assert np.array_equal(msg_to_grid(received[0]).occupied,
                          builtin_map("maze2d-umaze", 0.1).occupied)


def test_twist_drives_along_x_until_the_command_goes_stale(bridge_setup):
    bridge, probe, executor = bridge_setup(control_timeout=0.5)
    odom = []
    probe.create_subscription(Odometry, "odom", odom.append, 100)
    pub = probe.create_publisher(Twist, "cmd_vel", 10)
    cmd = Twist()
    cmd.linear.x = 0.5
    publish_when_matched(executor, pub, cmd)
    spin_until(executor, lambda: bridge.sim.state.v > 0)  # the command arrived ...
    spin_until(executor, lambda: bridge.sim.state.v == 0.0)  # ... and went stale
    t_stop = bridge.sim.state.t
    spin_until(executor, lambda: odom and odom[-1].header.stamp.sec >= math.ceil(t_stop) + 1)
    # one command, then the control timeout of 0.5 s sim time at 0.5 m/s: 0.25 m (+- a step)
    s = bridge.sim.state
    assert s.x - START[0] == pytest.approx(0.25, abs=0.5 * DT + 1e-9)
    assert (s.y, s.yaw) == pytest.approx(START[1:])
    moving = [m for m in odom if m.twist.twist.linear.x > 0]
    assert moving and len(moving) <= round(0.5 / DT) + 1
    last = odom[-1]
    assert (last.header.frame_id, last.child_frame_id) == ("map", "base_link")
    assert last.pose.pose.position.x == pytest.approx(s.x)
    assert last.twist.twist.linear.x == 0.0
    xs = [m.pose.pose.position.x for m in odom]
    assert xs == sorted(xs)  # along +x only


def test_clock_advances_in_sim_steps(bridge_setup):
    bridge, probe, executor = bridge_setup(rate_hz=50.0)
    clocks, collisions = [], []
    probe.create_subscription(Clock, "clock", clocks.append, 100)
    probe.create_subscription(Bool, "collision", collisions.append, 100)
    spin_until(executor, lambda: len(clocks) >= 50 and collisions)
    ns = [c.clock.sec * 10**9 + c.clock.nanosec for c in clocks]
    assert all(b > a for a, b in zip(ns, ns[1:]))
    assert all(n % (DT * 1e9) == 0 for n in ns)  # whole steps of 20 ms
    assert collisions[-1].data is False  # standing still in free space


def test_nan_cmd_vel_is_ignored_and_logged(bridge_setup, capfd):
    bridge, probe, executor = bridge_setup()
    pub = probe.create_publisher(Twist, "cmd_vel", 10)
    cmd = Twist()
    cmd.linear.x = float("nan")
    publish_when_matched(executor, pub, cmd)
    spin_until(executor, lambda: bridge.rejected_commands == 1)
    t = bridge.sim.state.t
    spin_until(executor, lambda: bridge.sim.state.t >= t + 0.2)
    assert (bridge.sim.state.x, bridge.sim.state.y) == START[:2]
    assert "non-finite" in capfd.readouterr().err


def test_twist_stamped_when_enabled(bridge_setup):
    bridge, probe, executor = bridge_setup(enable_stamped_cmd_vel=True)
    pub = probe.create_publisher(TwistStamped, "cmd_vel", 10)
    cmd = TwistStamped()
    cmd.header.frame_id = "base_link"
    cmd.twist.linear.x = 1.0
    publish_when_matched(executor, pub, cmd)
    spin_until(executor, lambda: bridge.sim.state.x > START[0] + 0.1)
    assert bridge.sim.state.y == pytest.approx(START[1])


def test_initialpose_teleports_and_a_pose_in_a_wall_is_ignored(bridge_setup):
    bridge, probe, executor = bridge_setup()
    pub = probe.create_publisher(PoseWithCovarianceStamped, "initialpose", 10)
    msg = PoseWithCovarianceStamped()
    msg.header.frame_id = "map"
    msg.pose.pose = pose_from_xy_yaw(0.5, 0.5, 0.0)  # inside the outer wall: ignored
    publish_when_matched(executor, pub, msg)
    msg.pose.pose = pose_from_xy_yaw(3.5, 2.5, math.pi / 2)  # umaze cell (3, 2) is free
    pub.publish(msg)
    spin_until(executor, lambda: bridge.sim.state.x == 3.5)
    s = bridge.sim.state
    assert (s.y, s.yaw, s.contact_count) == pytest.approx((2.5, math.pi / 2, 0))
    odom = []
    probe.create_subscription(Odometry, "odom", odom.append, 10)
    spin_until(executor, lambda: odom)
    assert yaw_from_quaternion(odom[-1].pose.pose.orientation) == pytest.approx(math.pi / 2)


def test_camera_image_is_rgb8_top_view(bridge_setup):
    bridge, probe, executor = bridge_setup(publish_camera=True, camera_rate_hz=10.0)
    images = []
    probe.create_subscription(Image, "camera/image_raw", images.append, 10)
    spin_until(executor, lambda: len(images) >= 2)
    img = images[-1]
    assert (img.encoding, img.height, img.width, img.step) == ("rgb8", 256, 256, 256 * 3)
    assert len(img.data) == 256 * 256 * 3


@pytest.mark.parametrize("params, match", [
    ({"map": "no-such-map"}, "no-such-map"),
    ({"rate_hz": -5.0}, "rate_hz"),
    ({"scan_beams": 0}, "scan_beams"),
    ({"scan_range_min": 2.0, "scan_range_max": 1.0}, "scan_range_max"),
    ({"obstacles_file": "/nonexistent/scenario.yaml"}, "cannot read scenario"),
])
def test_a_configuration_that_cannot_work_is_raised(ros_context, params, match):
    values = {"map": "maze2d-umaze", **params}
    with pytest.raises(EcahdError, match=match):
        SimBridge(context=ros_context,
                  parameter_overrides=[Parameter(k, value=v) for k, v in values.items()])


def test_scan_is_a_full_turn_laserscan_at_the_scan_rate(bridge_setup):
    # umaze corridor y in [1, 2], x in [1, 4]; robot at (1.5, 1.5) facing +x, LiDAR 0.1 m ahead
    bridge, probe, executor = bridge_setup(scan_rate_hz=10.0, scan_beams=4, scan_offset_x=0.1,
                                           scan_range_max=5.0)
    scans = []
    probe.create_subscription(LaserScan, "scan", scans.append, 10)
    spin_until(executor, lambda: len(scans) >= 3)
    s = scans[-1]
    assert s.header.frame_id == "base_scan"
    assert (s.angle_min, s.angle_increment) == pytest.approx((-math.pi, math.pi / 2))
    assert s.angle_max == pytest.approx(s.angle_min + 3 * s.angle_increment)  # pi - increment
    assert (s.range_min, s.range_max, s.scan_time) == pytest.approx((0.1, 5.0, 0.1))
    # beams -pi, -pi/2, 0, pi/2: walls x = 1, y = 1, x = 4 and y = 2 seen from (1.6, 1.5)
    assert list(s.ranges) == pytest.approx([0.6, 0.5, 2.4, 0.5], abs=1e-5)
    stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in scans]
    assert np.diff(stamps) == pytest.approx(np.full(len(stamps) - 1, 0.1))  # sim time


def test_no_scan_when_disabled(bridge_setup):
    bridge, probe, executor = bridge_setup(publish_scan=False)
    assert bridge.count_publishers("scan") == 0


def test_obstacles_file_bad_entry_logged_markers_and_contact_detail(bridge_setup, tmp_path,
                                                                     capfd):
    # obstacle 1: a cylinder r = 0.2 rolling from (3.5, 1.5) to (1.9, 1.5) at 2 m/s: it touches
    # the robot (r = 0.4 at x = 1.5) once its centre is at x <= 2.1, after 0.7 s
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text("obstacles:\n"
                        "  - {shape: box, x: 3.5, y: 3.5, size: [0.4, 0.4]}\n"
                        "  - {shape: cylinder, radius: 0.2, path: [[3.5, 1.5], [1.9, 1.5]], "
                        "speed: 2.0}\n"
                        "  - {shape: cone, x: 2.0, y: 2.0}\n")
    bridge, probe, executor = bridge_setup(obstacles_file=str(scenario))
    assert "obstacle 2 {'shape': 'cone'" in capfd.readouterr().err
    markers, details = [], []
    probe.create_subscription(MarkerArray, "sim_obstacles", markers.append, 10)
    probe.create_subscription(String, "collision_detail", details.append, 10)
    spin_until(executor, lambda: markers and details)
    kinds = {m.id: m.type for m in markers[-1].markers}
    assert kinds == {0: Marker.CUBE, 1: Marker.CYLINDER}
    assert all(m.header.frame_id == "map" for m in markers[-1].markers)
    detail = json.loads(details[0].data)
    assert (detail["kind"], detail["obstacle"]) == ("moving_obstacle", 1)
    assert detail["t"] == pytest.approx(0.7, abs=DT + 1e-9)
    assert (detail["x"], detail["y"]) == pytest.approx(START[:2])


def test_obstacles_never_appear_on_the_map(bridge_setup, tmp_path):
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text("obstacles:\n  - {shape: box, x: 3.5, y: 1.5, size: [0.4, 0.4]}\n")
    bridge, probe, executor = bridge_setup(obstacles_file=str(scenario))
    received = []
    probe.create_subscription(OccupancyGrid, "map", received.append, MAP_QOS)
    spin_until(executor, lambda: received)
    assert np.array_equal(msg_to_grid(received[0]).occupied,
                          builtin_map("maze2d-umaze", 0.1).occupied)


@pytest.mark.parametrize("odom_frame", ["map", "odom"])
def test_tf_as_a_robot_publishes_it(bridge_setup, odom_frame):
    """REP-105: with odom_frame 'odom' the odometry starts where the robot starts, /tf holds
    odom -> base_link and the stand-in localisation's map -> odom; with 'map', map ->
    base_link. Either way, map -> base_link through /tf is the simulated pose, and /tf_static
    holds base_link -> base_scan from scan_offset_*."""
    from tf2_msgs.msg import TFMessage

    from ecahd_core.frames import TransformBuffer
    from ecahd_ros.qos import TF_QOS, TF_STATIC_QOS
    from ecahd_ros.tf_listener import stamp_seconds

    bridge, probe, executor = bridge_setup(odom_frame=odom_frame, start_yaw=0.4,
                                           scan_offset_x=0.1, scan_offset_yaw=math.pi)
    buffer, odoms = TransformBuffer(), []

    def feed(msg, static):
        for t in msg.transforms:
            tr, q = t.transform.translation, t.transform.rotation
            from ecahd_core.frames import Transform
            buffer.set_transform(t.header.frame_id, t.child_frame_id,
                                 stamp_seconds(t.header.stamp),
                                 Transform.checked((tr.x, tr.y, tr.z), (q.x, q.y, q.z, q.w)),
                                 static=static)

    probe.create_subscription(TFMessage, "/tf", lambda m: feed(m, False), TF_QOS)
    probe.create_subscription(TFMessage, "/tf_static", lambda m: feed(m, True), TF_STATIC_QOS)
    probe.create_subscription(Odometry, "odom", odoms.append, 10)
    cmd = probe.create_publisher(Twist, "cmd_vel", 10)
    twist = Twist()
    twist.linear.x, twist.angular.z = 0.3, 0.2
    spin_until(executor, lambda: cmd.get_subscription_count() > 0)
    for _ in range(30):
        cmd.publish(twist)
        executor.spin_once(timeout_sec=0.01)
    spin_until(executor, lambda: len(odoms) > 20 and "base_scan" in buffer.frames())
    assert odoms[-1].header.frame_id == odom_frame
    if odom_frame == "odom":  # odometry from where the robot started; map -> odom is that pose
        first = odoms[0].pose.pose
        assert (first.position.x, first.position.y) == pytest.approx((0.0, 0.0), abs=0.05)
        assert buffer.lookup("map", "odom").xy_yaw() == pytest.approx((START[0], START[1], 0.4))
    # every odometry message, placed in map through /tf at its stamp, is where /tf puts
    # base_link; the robot drove (0.3 m/s, turning), so these are not all the start pose
    moved = 0
    for msg in odoms[-10:]:
        t = stamp_seconds(msg.header.stamp)
        pose = msg.pose.pose
        want = buffer.pose_in("map", odom_frame, t, (pose.position.x, pose.position.y,
                                                     yaw_from_quaternion(pose.orientation)))
        got = buffer.lookup("map", "base_link", t).xy_yaw()
        assert got == pytest.approx(want, abs=1e-6)
        moved += np.hypot(got[0] - START[0], got[1] - START[1]) > 0.01
    assert moved
    scan = buffer.lookup("base_link", "base_scan")
    assert scan.translation == pytest.approx([0.1, 0.0, 0.0])
    assert abs(scan.yaw()) == pytest.approx(math.pi)
