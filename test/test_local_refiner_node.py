"""The local_refiner node in-process on maze2d-large: a plan and odometry give forward cmd_vel
towards the next waypoint within the limits; a segment through a wall corner is refined by DD; no
plan, stale odometry and a reached goal give zero velocity. Plus the pure controller math."""
import json
import math
import os
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
from conftest import rig_factory  # noqa: E402
from geometry_msgs.msg import Twist, TwistStamped  # noqa: E402
from nav_msgs.msg import OccupancyGrid, Odometry, Path  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from ecahd_core.errors import EcahdError  # noqa: E402
from ecahd_core.maps import builtin_map  # noqa: E402
from ecahd_ros.conversions import grid_to_msg, path_to_xy, pose_from_xy_yaw, xy_to_path  # noqa: E402
from ecahd_ros.qos import PLAN_QOS  # noqa: E402
from ecahd_core.controller import lookahead_point, pure_pursuit  # noqa: E402
from ecahd_ros.local_refiner import LocalRefiner, LocalRefinerParams  # noqa: E402
from ecahd_ros.qos import MAP_QOS  # noqa: E402

RATE = 20.0  # [Hz] control_rate in these tests
# maze2d-large: y in [1, 2] is free for x in [1, 3]; x in [2, 3] is free for y in [1, 4]
PLAN = [(1.5, 1.5), (2.5, 1.5), (2.5, 2.5), (2.5, 3.5)]
CORNER_PLAN = [(1.5, 1.5), (2.5, 2.5), (2.5, 3.5)]  # cuts wall cell [1, 2] x [2, 3]


def params(**over) -> LocalRefinerParams:
    from ecahd_ros.local_refiner import PARAMETERS

    values = {spec.name: spec.default for spec in PARAMETERS}  # the declared defaults
    values.update(over)
    return LocalRefinerParams(**values)



class Rig:
    def __init__(self, context, **over) -> None:
        values = {"control_rate": RATE, **over}
        self.node = LocalRefiner(context=context, parameter_overrides=[
            Parameter(k, value=v) for k, v in values.items()])
        self.probe = rclpy.create_node("probe", context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.probe)
        self.cmds, self.local, self.timings = [], [], []
        stamped = values.get("enable_stamped_cmd_vel", False)
        self.probe.create_subscription(TwistStamped if stamped else Twist, "cmd_vel",
                                       self.cmds.append, 100)
        self.probe.create_subscription(Path, "local_plan", self.local.append, 10)
        self.probe.create_subscription(String, "ecahd/timing", self.timings.append, 100)
        self.map_pub = self.probe.create_publisher(OccupancyGrid, "map", MAP_QOS)
        self.plan_pub = self.probe.create_publisher(Path, "plan", PLAN_QOS)
        self.odom_pub = self.probe.create_publisher(Odometry, "odom", 10)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.probe.destroy_node()

    def spin_until(self, condition, timeout: float = 10.0) -> None:
        deadline = time.monotonic() + timeout
        while not condition():
            assert time.monotonic() < deadline, "condition not met within the time limit"
            self.executor.spin_once(timeout_sec=0.01)

    def send_map(self) -> None:
        self.map_pub.publish(grid_to_msg(builtin_map("maze2d-large")))
        self.spin_until(lambda: self.node.planner is not None)

    def send_plan(self, xy) -> None:
        self.plan_pub.publish(xy_to_path(np.asarray(xy, dtype=float), "map"))

    def send_odom(self, x, y, yaw=0.0) -> None:
        self.spin_until(lambda: self.odom_pub.get_subscription_count() > 0)
        msg = Odometry()
        msg.header.frame_id = "map"
        msg.pose.pose = pose_from_xy_yaw(x, y, yaw)
        self.odom_pub.publish(msg)
        self.spin_until(lambda: self.node.runner.pose is not None
                        and self.node.runner.pose[:2] == pytest.approx((x, y)))

    def segment_timings(self) -> list[dict]:
        """The per-segment timing records (J check / DD), without the control ticks'."""
        records = [json.loads(m.data) for m in self.timings]
        return [r for r in records if r["stage"] != "control"]

    def next_cmds(self, n: int) -> list:
        start = len(self.cmds)
        self.spin_until(lambda: len(self.cmds) >= start + n)
        return [c.twist if isinstance(c, TwistStamped) else c for c in self.cmds[start:]]


@pytest.fixture
def rig(ros_context):
    yield from rig_factory(Rig, ros_context)


# a 0.3 m square robot: 0.35 m from the corridor walls, beyond J's 0.1 m margin, so a straight
# corridor segment costs 0 (the 0.4 m circle's outline lies within the margin: c^l ~ 18 > c_th)
SMALL_ROBOT = "[[0.15, 0.15], [-0.15, 0.15], [-0.15, -0.15], [0.15, -0.15]]"


def test_plan_and_odom_give_forward_motion_within_the_limits(rig):
    r = rig(footprint=SMALL_ROBOT)
    r.send_map()
    r.send_odom(1.5, 1.5, 0.0)  # facing +x, the first waypoint (2.5, 1.5) straight ahead
    r.send_plan(PLAN)
    r.spin_until(lambda: r.local and r.segment_timings())
    local = path_to_xy(r.local[-1])
    assert local.shape == (4, 2)  # P^l
    np.testing.assert_allclose(local[[0, -1]], [[1.5, 1.5], [2.5, 1.5]])
    timing = r.segment_timings()[-1]
    assert timing["stage"] == "j_check" and timing["c_before"] <= 0.1  # a free segment
    cmds = r.next_cmds(8)
    v = np.array([c.linear.x for c in cmds])
    w = np.array([c.angular.z for c in cmds])
    assert v[-1] > 0 and np.all(v >= 0) and np.all(v <= 0.5 + 1e-9)
    assert np.all(np.abs(w) <= 1.5 + 1e-9) and np.all(np.abs(w) < 0.05)  # straight ahead
    # |dv| <= max_accel / control_rate per tick, from standing (the tick that started the
    # segment, before these, already drove: v[0] is at most two ticks of acceleration)
    assert np.all(np.abs(np.diff(v)) <= 1.0 / RATE + 1e-9) and v[0] <= 2.0 / RATE + 1e-9


def test_colliding_segment_is_refined_by_dd(rig):
    r = rig()
    r.send_map()
    r.send_odom(1.5, 1.5, math.pi / 4)
    r.send_plan(CORNER_PLAN)
    r.spin_until(lambda: r.segment_timings())
    timing = r.segment_timings()[-1]
    assert timing["stage"] == "dd" and timing["c_before"] > 0.1
    assert timing["c_after"] < timing["c_before"]  # guided DD moved off the corner
    assert r.node.dd_calls == 1
    local = path_to_xy(r.local[-1])
    np.testing.assert_allclose(local[[0, -1]], [[1.5, 1.5], [2.5, 2.5]], atol=1e-6)


def test_dd_disabled_follows_the_straight_plan_and_never_runs_dd(rig, monkeypatch):
    from ecahd_core.planning.dense import DenseStage

    def no_dd(*args, **kwargs):
        raise AssertionError("DD ran with dd_enabled false")

    monkeypatch.setattr(DenseStage, "refine", no_dd)
    r = rig(dd_enabled=False)
    r.send_map()
    assert r.node.planner.dd is None  # no DD model loaded
    r.send_odom(1.5, 1.5, math.pi / 4)
    r.send_plan(CORNER_PLAN)  # the segment that DD refines when enabled (test above)
    r.spin_until(lambda: r.segment_timings())
    timing = r.segment_timings()[-1]
    # J still judges the straight plan (diagnostics), above c_th, and nothing refines it
    assert timing["stage"] == "j_check" and timing["c_before"] > 0.1
    assert timing["c_after"] == timing["c_before"]
    assert r.node.dd_calls == 0
    np.testing.assert_allclose(path_to_xy(r.local[-1]),
                               np.linspace([1.5, 1.5], [2.5, 2.5], 4), atol=1e-9)
    assert r.next_cmds(3)  # and it drives
    assert r.node.dd_calls == 0


def test_every_control_tick_publishes_its_wall_time(rig):
    r = rig()
    r.send_map()
    r.send_odom(1.5, 1.5, math.pi / 4)
    r.send_plan(CORNER_PLAN)  # the first tick after the plan may start a segment (J + DD)
    cmds = r.next_cmds(5)
    r.spin_until(lambda: sum(json.loads(m.data)["stage"] == "control" for m in r.timings) >= 5)
    control = [json.loads(m.data) for m in r.timings if json.loads(m.data)["stage"] == "control"]
    assert len(control) >= len(cmds) - 1  # one per tick (a record follows its command)
    for c in control:
        assert c["ms"] >= 0 and math.isfinite(c["stamp"]) and set(c) == {"stage", "ms", "stamp", "reason", "monitor", "map_ready",
                                                      "wall"}


def test_zero_without_a_plan(rig):
    r = rig()
    r.send_odom(1.5, 1.5)
    cmds = r.next_cmds(3)
    assert all(c.linear.x == 0.0 and c.angular.z == 0.0 for c in cmds)


def test_zero_when_odometry_goes_stale(rig):
    r = rig(stale_timeout=0.3)
    r.send_odom(1.5, 1.5)
    r.send_plan(PLAN)  # no map: straight local plans, followed unchecked
    r.spin_until(lambda: r.cmds and r.cmds[-1].linear.x > 0)
    time.sleep(0.35)
    cmds = r.next_cmds(3)
    assert all(c.linear.x == 0.0 and c.angular.z == 0.0 for c in cmds)


def test_zero_at_the_goal_and_stamped_commands(rig):
    r = rig(enable_stamped_cmd_vel=True)
    r.send_odom(2.5, 3.4, math.pi / 2)  # 0.1 m from the last point
    r.send_plan(PLAN)
    cmds = r.next_cmds(3)
    assert all(c.linear.x == 0.0 and c.angular.z == 0.0 for c in cmds)
    assert r.node.waypoints is None  # the plan is done
    assert r.cmds[-1].header.frame_id == "base_link"


@pytest.mark.parametrize("clock", ["steady", "ros"])
def test_control_clock_steady_ticks_while_sim_time_stands_still(rig, clock):
    """With use_sim_time and a /clock that stops: the steady control timer keeps publishing,
    stamped with the (standing) sim time; the one on the node's clock stops with it."""
    from rosgraph_msgs.msg import Clock

    r = rig(use_sim_time=True, control_clock=clock, enable_stamped_cmd_vel=True)
    clock_pub = r.probe.create_publisher(Clock, "/clock", 10)
    r.spin_until(lambda: clock_pub.get_subscription_count() > 0)
    msg = Clock()
    msg.clock.sec = 7
    clock_pub.publish(msg)
    r.spin_until(lambda: r.node.get_clock().now().nanoseconds == 7 * 10**9)
    if clock == "steady":  # commands sent before the clock came may still be on their way
        r.spin_until(lambda: r.cmds and r.cmds[-1].header.stamp.sec == 7)
    before = len(r.cmds)
    deadline = time.monotonic() + 0.5  # 10 periods of wall time, no sim time passing
    while time.monotonic() < deadline:
        r.executor.spin_once(timeout_sec=0.01)
    ticks = len(r.cmds) - before
    if clock == "steady":
        assert ticks >= 5
        assert all(c.header.stamp.sec == 7 for c in r.cmds[before:])
    else:
        assert ticks <= 1  # at most one that was due when the clock jumped to 7 s


def test_bad_parameter_is_named():
    with pytest.raises(EcahdError, match="max_accel"):
        params(max_accel=0.0)
    with pytest.raises(EcahdError, match="control_clock"):
        params(control_clock="wall")


# --------------------------------------------------------------------------- controller
def test_lookahead_point_walks_along_the_path():
    path = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    # from (0.2, 0): the first resampled point >= 0.4 m away is (0.6, 0)
    np.testing.assert_allclose(lookahead_point(path, np.array([0.2, 0.0]), 0.4), [0.6, 0.0])
    # near the end the end itself
    np.testing.assert_allclose(lookahead_point(path, np.array([1.0, 0.9]), 0.4), [1.0, 1.0])


@pytest.mark.parametrize("yaw,expect_v", [(0.0, True), (math.pi, False)])
def test_pure_pursuit_limits(yaw, expect_v):
    p = params()
    v, w = pure_pursuit((0.0, 0.0, yaw), np.array([1.0, 0.2]), 5.0, 0.45, 0.1, p)
    if expect_v:  # target ahead, slightly left: forward at max_v, turning left
        assert v == pytest.approx(0.5) and 0 < w <= 1.5
        # w = v * 2 sin(alpha) / L with alpha = atan2(0.2, 1), L = hypot(1, 0.2)
        assert w == pytest.approx(0.5 * 2 * math.sin(math.atan2(0.2, 1.0)) / math.hypot(1, 0.2))
    else:  # target behind: slow down within max_accel and turn on the spot
        assert v == pytest.approx(0.35) and abs(w) == pytest.approx(1.5)


def test_a_scan_waits_for_the_odometry_of_its_stamp(rig, monkeypatch):
    """A scan that arrives before the odometry of its own stamp is placed with that pose (a
    turning robot placed with the pose 20 ms older marks walls tens of cm off), not the
    older one; a scan whose odometry never comes goes on after SCAN_POSE_WAIT, counted."""
    from sensor_msgs.msg import LaserScan

    from ecahd_ros import local_refiner

    r = rig(use_scan=True)
    r.send_map()
    node, submitted = r.node, []
    monkeypatch.setattr(node._scan_worker, "submit", submitted.append)

    def odom(t, x, y, yaw):
        msg = Odometry()
        msg.header.frame_id = "map"
        msg.header.stamp.sec, msg.header.stamp.nanosec = int(t), int(round((t % 1) * 1e9))
        msg.pose.pose = pose_from_xy_yaw(x, y, yaw)
        node._on_odom(msg)

    def scan(t):
        msg = LaserScan()
        msg.header.frame_id = "base_scan"
        msg.header.stamp.sec, msg.header.stamp.nanosec = int(t), int(round((t % 1) * 1e9))
        msg.angle_min, msg.angle_increment = -math.pi, 2 * math.pi / 8
        msg.range_min, msg.range_max = 0.1, 8.0
        msg.ranges = [1.0] * 8
        node._on_scan(msg)

    odom(1.00, 1.5, 1.5, 0.0)
    scan(1.02)
    assert submitted == []  # its odometry is not here yet
    odom(1.02, 1.51, 1.5, 0.03)
    assert len(submitted) == 1
    assert submitted[0][0] == pytest.approx((1.51, 1.5, 0.03))
    scan(1.01)  # between two known poses: interpolated at once
    assert submitted[1][0] == pytest.approx((1.505, 1.5, 0.015))
    assert node.counters["scans_unsynced"] == 0
    scan(9.0)  # a stamp the odometry never reaches
    monkeypatch.setattr(local_refiner, "SCAN_POSE_WAIT", 0.0)
    time.sleep(0.01)
    odom(1.04, 1.52, 1.5, 0.06)
    assert len(submitted) == 3 and submitted[2][0] == pytest.approx((1.52, 1.5, 0.06))
    assert node.counters["scans_unsynced"] == 1


def test_inputs_from_another_clock_are_said(rig):
    """local_refiner on the wall clock (no use_sim_time) fed odometry and scans stamped by a
    simulator's /clock (seconds since its start): it says so, naming use_sim_time, instead of
    the collision monitor silently judging every scan decades old."""
    from sensor_msgs.msg import LaserScan

    r = rig(use_scan=True)
    r.send_map()
    node = r.node
    r.spin_until(lambda: node.world is not None)
    odom = Odometry()
    odom.header.frame_id = "map"
    odom.header.stamp.sec = 12  # sim time
    odom.pose.pose = pose_from_xy_yaw(1.5, 1.5, 0.0)
    node._on_odom(odom)
    scan = LaserScan()
    scan.header.frame_id = "base_scan"
    scan.header.stamp.sec = 12
    scan.angle_min, scan.angle_increment = -math.pi, 2 * math.pi / 8
    scan.range_min, scan.range_max = 0.1, 8.0
    scan.ranges = [1.0] * 8
    node._on_scan(scan)
    assert node._stamps.mismatches == 2 and node._stamps.stale == 0


def test_health_is_on_diagnostics(rig):
    """/diagnostics says 'waiting for a map' (WARN) before the map, then OK with the control
    loop's measured rate near control_rate and its tick latency."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

    r = rig()
    got = []
    r.probe.create_subscription(DiagnosticArray, "/diagnostics", got.append, 10)
    r.spin_until(lambda: got, timeout=5.0)
    first = got[-1].status[0]
    assert first.name == "ecahd_ros: local_refiner" and first.level == DiagnosticStatus.WARN
    assert first.message == "waiting for a map"
    r.send_map()
    n = len(got)
    r.spin_until(lambda: len(got) >= n + 2, timeout=5.0)
    status = got[-1].status[0]
    values = {kv.key: kv.value for kv in status.values}
    assert status.level == DiagnosticStatus.OK, status.message
    assert values["map"] == "maze2d-large" and values["dd"] == "ready"
    assert 0.5 * RATE < float(values["control_rate_hz"]) < 1.5 * RATE
    assert 0 < float(values["control_ms_p50"]) <= float(values["control_ms_p99"])
    assert values["stamps_from_another_clock"] == "0"


def test_scans_are_placed_by_the_tf_of_their_frame(rig, monkeypatch):
    """A scan in `base_scan` is placed on base_link by /tf_static's base_link -> base_scan
    (here 0.2 m ahead, turned round); where tf does not join them, by scan_offset_*."""
    from geometry_msgs.msg import TransformStamped
    from sensor_msgs.msg import LaserScan
    from tf2_msgs.msg import TFMessage

    from ecahd_ros.qos import TF_STATIC_QOS

    r = rig(use_scan=True, scan_offset_x=0.05)
    r.send_map()
    node, submitted = r.node, []
    monkeypatch.setattr(node._scan_worker, "submit", submitted.append)
    odom = Odometry()
    odom.header.frame_id = "map"
    odom.pose.pose = pose_from_xy_yaw(1.5, 1.5, 0.0)
    node._on_odom(odom)

    def scan():
        msg = LaserScan()
        msg.header.frame_id = "base_scan"
        msg.angle_min, msg.angle_increment = -math.pi, 2 * math.pi / 8
        msg.range_min, msg.range_max = 0.1, 8.0
        msg.ranges = [1.0] * 8
        node._on_scan(msg)

    scan()
    assert submitted[-1][2] == pytest.approx((0.05, 0.0, 0.0))  # no tf: the parameters
    pub = r.probe.create_publisher(TFMessage, "/tf_static", TF_STATIC_QOS)
    r.spin_until(lambda: pub.get_subscription_count() > 0)
    t = TransformStamped()
    t.header.frame_id, t.child_frame_id = "base_link", "base_scan"
    t.transform.translation.x, t.transform.rotation.z, t.transform.rotation.w = 0.2, 1.0, 0.0
    pub.publish(TFMessage(transforms=[t]))
    r.spin_until(lambda: node.tf.received >= 1)
    scan()
    x, y, yaw = submitted[-1][2]
    assert (x, y, abs(yaw)) == pytest.approx((0.2, 0.0, math.pi))


def test_deactivated_it_stops_the_robot_and_stops_commanding(rig):
    """Lifecycle: driving while active; deactivate sends one zero velocity and then no command
    at all; activate again drives on; cleanup lets go of the runner."""
    from rclpy.lifecycle import TransitionCallbackReturn

    r = rig(footprint=SMALL_ROBOT)
    r.send_map()
    r.send_odom(1.5, 1.5, 0.0)
    r.send_plan(PLAN)
    cmds = r.next_cmds(8)
    assert cmds[-1].linear.x > 0  # driving
    assert r.node.trigger_deactivate() == TransitionCallbackReturn.SUCCESS
    n = len(r.cmds)
    time_end = time.monotonic() + 0.5
    while time.monotonic() < time_end:
        r.executor.spin_once(timeout_sec=0.01)
    stopped = r.cmds[n - 1:]  # the zero velocity was published before the publisher stopped
    last = stopped[-1].twist if isinstance(stopped[-1], TwistStamped) else stopped[-1]
    assert last.linear.x == 0.0 and last.angular.z == 0.0
    assert len(r.cmds) <= n + 1  # nothing after it while inactive (at 20 Hz: 10 ticks)
    assert r.node.trigger_activate() == TransitionCallbackReturn.SUCCESS
    assert r.next_cmds(3)[-1].linear.x >= 0.0  # commanding again
    assert r.node.trigger_deactivate() == TransitionCallbackReturn.SUCCESS
    assert r.node.trigger_cleanup() == TransitionCallbackReturn.SUCCESS
    assert r.node.runner is None and r.node.params is None


def test_an_updated_map_of_the_site_keeps_dd_and_j_sees_its_new_walls(rig):
    """A map update with a box across the y = 5.5 corridor: the node keeps the site's DD model,
    records the share of changed cells, and J judges a straight segment through the box on the
    new map (DD refines it); a map of another extent is refused and the update kept."""
    from ecahd_core.maps import GridMap

    r = rig(footprint=SMALL_ROBOT)
    r.send_map()
    site = builtin_map("maze2d-large")
    data = site.data.copy()
    data[50:60, 35:40] = 100  # x in [3.5, 4.0], y in [5.0, 6.0]: wall to wall
    updated = GridMap(data, site.resolution, site.origin, name=site.name)
    r.map_pub.publish(grid_to_msg(updated))
    r.spin_until(lambda: r.node.grid.fingerprint() == updated.fingerprint())
    assert r.node.planner.dd is not None  # the site's model kept
    assert r.node.map_changed == pytest.approx(50 / data.size)
    r.send_odom(2.5, 5.5, 0.0)
    r.send_plan([(2.5, 5.5), (4.5, 5.5)])  # straight through the new box
    r.spin_until(lambda: r.segment_timings())
    timing = r.segment_timings()[-1]
    assert timing["c_before"] > 0.1 and timing["stage"] == "dd"
    r.map_pub.publish(grid_to_msg(builtin_map("maze2d-medium")))  # another extent: refused
    deadline = time.monotonic() + 1.0
    while time.monotonic() < deadline:
        r.executor.spin_once(timeout_sec=0.01)
    assert r.node.grid.fingerprint() == updated.fingerprint()


@pytest.mark.parametrize("horizon", [0.5, 0.0])
def test_the_static_guard_never_commands_the_robot_into_a_wall(rig, horizon):
    """The circle 0.02 m from the corridor's south wall (y = 5), heading south-east to a plan
    point ahead: pure pursuit's arcs would swing it into the wall. With the static guard
    (static_guard_horizon 0.5 s, the default) no published command, held 0.5 s, touches the
    map by the exact checker, and the guard's stops are counted; without it (0) one does."""
    from ecahd_core.collision import check_collision
    from ecahd_core.collision_monitor import CollisionMonitor
    from ecahd_core.footprint import make_footprint

    r = rig(static_guard_horizon=horizon, collision_monitor=False, dd_enabled=False)
    r.send_map()
    pose = (2.6, 5.42, -0.7)
    r.send_odom(*pose)
    r.send_plan([pose[:2], (4.2, 5.42)])
    cmds = r.next_cmds(30)
    robot, grid = make_footprint("circle"), builtin_map("maze2d-large")
    arcs = CollisionMonitor(robot)
    t = np.linspace(0.0, 0.5, 11)
    touching = [c for c in cmds if (c.linear.x, c.angular.z) != (0.0, 0.0) and not
                check_collision(arcs.simulate(pose, c.linear.x, c.angular.z, t)[:, :2], robot,
                                grid).collision_free]
    if horizon:
        assert touching == [] and r.node.counters["guard_stop"] > 0
        assert max(c.linear.x for c in cmds) > 0  # it still drives where that is clear
    else:
        assert touching and r.node.counters["guard_stop"] == 0
