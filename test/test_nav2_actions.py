"""Nav2's actions on global_planner, in-process on maze2d-large, the probe playing map server,
odometry and a Nav2 client (a behaviour tree, the simple commander): navigate_to_pose's goals are
planned, fed back, reached with their heading, cancelled, pre-empted and refused with Nav2's
error codes; compute_path_to_pose answers with a dense collision-free path. The types are
Jazzy's own."""
import math
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
from conftest import rig_factory  # noqa: E402
nav2_msgs = pytest.importorskip("nav2_msgs.action")
from action_msgs.msg import GoalStatus  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from nav_msgs.msg import OccupancyGrid, Odometry, Path  # noqa: E402
from rclpy.action import ActionClient  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from ecahd_core.collision import check_collision  # noqa: E402
from ecahd_core.footprint import make_footprint  # noqa: E402
from ecahd_core.maps import builtin_map  # noqa: E402
from ecahd_ros import nav2_actions  # noqa: E402
from ecahd_ros.conversions import grid_to_msg, heading_of, path_to_xy, pose_from_xy_yaw  # noqa: E402
from ecahd_ros.global_planner import GlobalPlanner  # noqa: E402
from ecahd_ros.qos import MAP_QOS, PLAN_QOS  # noqa: E402

NavigateToPose, ComputePathToPose = nav2_msgs.NavigateToPose, nav2_msgs.ComputePathToPose
ROBOT, GOAL = (1.5, 1.5), (6.5, 5.5)  # free corridor cells of maze2d-large
WALL = (0.2, 0.2)  # the maze's border wall
PINNED_HASHES = {  # computed here from Jazzy's definitions (no Jazzy install to read them off)
    "nav2_msgs/action/NavigateToPose_FeedbackMessage":
        "RIHS01_9d1f6fa2eb975ce733b419ac2e97b134d8ff92b6478b6559feed9a50bdfd82b3",
    "nav2_msgs/action/ComputePathToPose_FeedbackMessage":
        "RIHS01_a086c8f040554ab5883b433bded128a1d1a732d21ca57596b7fdbe7ad2d0b64a"}


# ------------------------------------------------------------------------------ the types
def test_the_types_are_jazzys():
    """Field for field and constant for constant what `ros2 interface show` prints on ROS 2
    Jazzy (nav2_msgs 1.3), so the type hashes are the distribution's; the hashes are pinned so
    that an edit of interfaces/nav2_msgs cannot pass unnoticed."""
    assert NavigateToPose.Goal.get_fields_and_field_types() == {
        "pose": "geometry_msgs/PoseStamped", "behavior_tree": "string"}
    assert NavigateToPose.Result.get_fields_and_field_types() == {
        "error_code": "uint16", "error_msg": "string"}
    assert NavigateToPose.Feedback.get_fields_and_field_types() == {
        "current_pose": "geometry_msgs/PoseStamped",
        "navigation_time": "builtin_interfaces/Duration",
        "estimated_time_remaining": "builtin_interfaces/Duration",
        "number_of_recoveries": "int16", "distance_remaining": "float"}
    r = NavigateToPose.Result
    assert (r.NONE, r.UNKNOWN, r.FAILED_TO_LOAD_BEHAVIOR_TREE, r.TF_ERROR) == (0, 9000, 9001,
                                                                               9002)
    assert ComputePathToPose.Goal.get_fields_and_field_types() == {
        "goal": "geometry_msgs/PoseStamped", "start": "geometry_msgs/PoseStamped",
        "planner_id": "string", "use_start": "boolean"}
    assert ComputePathToPose.Result.get_fields_and_field_types() == {
        "path": "nav_msgs/Path", "planning_time": "builtin_interfaces/Duration",
        "error_code": "uint16", "error_msg": "string"}
    assert ComputePathToPose.Feedback.get_fields_and_field_types() == {}
    c = ComputePathToPose.Result
    assert [c.NONE, c.UNKNOWN, c.INVALID_PLANNER, c.TF_ERROR, c.START_OUTSIDE_MAP,
            c.GOAL_OUTSIDE_MAP, c.START_OCCUPIED, c.GOAL_OCCUPIED, c.TIMEOUT,
            c.NO_VALID_PATH] == [0, *range(200, 209)]
    # the node's copies of the codes (it reads them without nav2_msgs)
    assert (nav2_actions.NAVIGATE_UNKNOWN, nav2_actions.TF_ERROR) == (r.UNKNOWN, r.TF_ERROR)
    assert (nav2_actions.PATH_UNKNOWN, nav2_actions.INVALID_PLANNER, nav2_actions.PATH_TF_ERROR,
            nav2_actions.START_OUTSIDE_MAP, nav2_actions.GOAL_OUTSIDE_MAP,
            nav2_actions.START_OCCUPIED, nav2_actions.GOAL_OCCUPIED,
            nav2_actions.NO_VALID_PATH) == (c.UNKNOWN, c.INVALID_PLANNER, c.TF_ERROR,
                                            c.START_OUTSIDE_MAP, c.GOAL_OUTSIDE_MAP,
                                            c.START_OCCUPIED, c.GOAL_OCCUPIED, c.NO_VALID_PATH)


def test_the_type_hashes_are_pinned(ros_context):
    """The hashes rosidl computes from those definitions (on the feedback topics' types, which
    include the Feedback message), as `ros2 topic info -v` shows them."""
    node = rclpy.create_node("hash_probe", context=ros_context)
    clients = [ActionClient(node, t, n) for t, n in ((NavigateToPose, "navigate_to_pose"),
                                                     (ComputePathToPose, "compute_path_to_pose"))]
    try:
        got = {}
        for name in ("navigate_to_pose", "compute_path_to_pose"):
            info = node.get_subscriptions_info_by_topic(f"/{name}/_action/feedback")
            got[info[0].topic_type] = str(info[0].topic_type_hash)
        assert got == PINNED_HASHES
    finally:
        for client in clients:
            client.destroy()
        node.destroy_node()


# ------------------------------------------------------------------------------ the rig
class Rig:
    """global_planner, a probe (map, odometry, Nav2 clients, plan listener), one executor."""

    def __init__(self, context, **params) -> None:
        self.planner = GlobalPlanner(context=context, parameter_overrides=[
            Parameter(k, value=v) for k, v in params.items()])
        self.probe = rclpy.create_node("probe", context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.planner)
        self.executor.add_node(self.probe)
        self.plans, self.feedback = [], []
        self.probe.create_subscription(Path, "plan", self.plans.append, PLAN_QOS)
        self.map_pub = self.probe.create_publisher(OccupancyGrid, "map", MAP_QOS)
        self.odom_pub = self.probe.create_publisher(Odometry, "odom", 10)
        self.goal_pub = self.probe.create_publisher(PoseStamped, "goal_pose", 10)
        self.navigate = ActionClient(self.probe, NavigateToPose, "navigate_to_pose")
        self.compute = ActionClient(self.probe, ComputePathToPose, "compute_path_to_pose")

    def close(self) -> None:
        self.executor.shutdown()
        self.navigate.destroy()
        self.compute.destroy()
        self.planner.destroy_node()
        self.probe.destroy_node()

    def spin_until(self, condition, timeout: float = 10.0, what: str = "condition") -> None:
        deadline = time.monotonic() + timeout
        while not condition():
            assert time.monotonic() < deadline, f"not within {timeout:g} s: {what}"
            self.executor.spin_once(timeout_sec=0.01)

    def spin_for(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.01)

    def ready(self, odom: bool = True) -> None:
        self.spin_until(lambda: self.map_pub.get_subscription_count() > 0)
        self.map_pub.publish(grid_to_msg(builtin_map("maze2d-large")))
        if odom:
            self.odom(ROBOT)
        self.spin_until(lambda: self.planner.ready and (self.planner.pose is not None or not odom),
                        what="map (and odometry) in")
        self.spin_until(lambda: self.navigate.server_is_ready()
                        and self.compute.server_is_ready(), what="the action servers")

    def odom(self, xy, yaw: float = 0.0) -> None:
        msg = Odometry()
        msg.header.frame_id, msg.child_frame_id = "map", "base_link"
        msg.pose.pose = pose_from_xy_yaw(float(xy[0]), float(xy[1]), yaw)
        self.spin_until(lambda: self.odom_pub.get_subscription_count() > 0)
        self.odom_pub.publish(msg)

    def send(self, xy, yaw: float | None = 0.0, frame: str = "map"):
        """A navigate_to_pose goal -> its (accepted) client goal handle."""
        goal = NavigateToPose.Goal()
        goal.pose.header.frame_id = frame
        goal.pose.pose = pose_from_xy_yaw(float(xy[0]), float(xy[1]), yaw or 0.0)
        if yaw is None:
            goal.pose.pose.orientation.w = goal.pose.pose.orientation.z = 0.0
        future = self.navigate.send_goal_async(goal, feedback_callback=self.feedback.append)
        self.spin_until(future.done, what="the goal answered")
        return future.result()

    def result(self, handle, timeout: float = 10.0):
        future = handle.get_result_async()
        self.spin_until(future.done, timeout, "the goal's result")
        return future.result()

    def path(self, goal_xy, goal_yaw=0.0, start_xy=None, planner_id=""):
        goal = ComputePathToPose.Goal()
        goal.goal.header.frame_id = "map"
        goal.goal.pose = pose_from_xy_yaw(float(goal_xy[0]), float(goal_xy[1]), goal_yaw)
        goal.planner_id = planner_id
        if start_xy is not None:
            goal.use_start = True
            goal.start.header.frame_id = "map"
            goal.start.pose = pose_from_xy_yaw(float(start_xy[0]), float(start_xy[1]), 0.0)
        future = self.compute.send_goal_async(goal)
        self.spin_until(future.done, what="the path request answered")
        handle = future.result()
        assert handle.accepted
        return self.result(handle, timeout=30.0)


@pytest.fixture
def rig(ros_context):
    yield from rig_factory(Rig, ros_context)


# ------------------------------------------------------------------------ navigate_to_pose
def test_a_goal_is_planned_fed_back_and_reached_with_its_heading(rig):
    r = rig()
    r.ready()
    heading = math.pi / 2
    handle = r.send(GOAL, heading)
    assert handle.accepted
    r.spin_until(lambda: r.plans, what="a plan")
    plan = r.plans[-1]
    assert path_to_xy(plan)[-1] == pytest.approx(GOAL)
    assert heading_of(plan.poses[-1].pose.orientation) == pytest.approx(heading)
    t0 = time.monotonic()
    r.spin_until(lambda: len(r.feedback) >= 5, what="feedback")
    assert (time.monotonic() - t0) / 4 < 0.5  # at least 2 Hz
    fb = r.feedback[-1].feedback
    assert fb.current_pose.header.frame_id == "map"
    assert (fb.current_pose.pose.position.x, fb.current_pose.pose.position.y) == \
        pytest.approx(ROBOT)
    assert fb.distance_remaining >= math.dist(ROBOT, GOAL) - 1e-3  # along the plan
    assert fb.navigation_time.sec + fb.navigation_time.nanosec * 1e-9 > 0
    # the robot gets there, facing the wrong way: not reached yet
    r.odom(GOAL, yaw=0.0)
    r.spin_for(0.5)
    assert handle.status == GoalStatus.STATUS_EXECUTING
    assert r.feedback[-1].feedback.distance_remaining < 0.3
    r.odom(GOAL, yaw=heading - 0.1)  # within yaw_goal_tolerance (0.25 rad)
    result = r.result(handle)
    assert result.status == GoalStatus.STATUS_SUCCEEDED
    assert result.result.error_code == NavigateToPose.Result.NONE


def test_bad_goals_end_with_nav2_error_codes_and_the_node_keeps_serving(rig):
    r = rig()
    r.ready()
    for xy, frame, code, words in [
            (WALL, "map", ComputePathToPose.Result.GOAL_OCCUPIED, "inside an obstacle"),
            ((40.0, 3.0), "map", ComputePathToPose.Result.GOAL_OUTSIDE_MAP, "outside the map"),
            (GOAL, "nowhere", NavigateToPose.Result.TF_ERROR, "nowhere"),
            ((math.nan, 1.0), "map", NavigateToPose.Result.UNKNOWN, "non-finite")]:
        handle = r.send(xy, 0.0, frame)
        result = r.result(handle)
        assert result.status == GoalStatus.STATUS_ABORTED
        assert result.result.error_code == code
        assert words in result.result.error_msg
    assert r.plans == []  # nothing planned for any of them
    handle = r.send(GOAL, None)  # a good one is still served
    r.spin_until(lambda: r.plans, what="a plan")
    assert handle.status == GoalStatus.STATUS_EXECUTING


def test_a_goal_with_no_heading_is_reached_facing_any_way(rig):
    r = rig()
    r.ready()
    handle = r.send(GOAL, None)
    r.spin_until(lambda: r.plans, what="a plan")
    assert heading_of(r.plans[-1].poses[-1].pose.orientation) is None
    r.odom(GOAL, yaw=2.5)
    assert r.result(handle).status == GoalStatus.STATUS_SUCCEEDED


def test_cancel_stops_the_robot_and_ends_the_goal_canceled(rig):
    r = rig()
    r.ready()
    handle = r.send(GOAL)
    r.spin_until(lambda: r.plans, what="a plan")
    t0 = time.monotonic()
    cancel = handle.cancel_goal_async()
    r.spin_until(cancel.done, what="the cancel answered")
    result = r.result(handle)
    assert result.status == GoalStatus.STATUS_CANCELED
    assert time.monotonic() - t0 < 1.0
    assert len(r.plans[-1].poses) == 0  # the empty plan: local_refiner stops the robot
    assert r.planner.goal is None


def test_a_new_goal_pre_empts_the_running_one(rig):
    r = rig()
    r.ready()
    first = r.send(GOAL)
    r.spin_until(lambda: r.plans, what="a plan")
    second = r.send((10.5, 1.5))
    result = r.result(first)
    assert result.status == GoalStatus.STATUS_ABORTED
    assert result.result.error_code == 0 and "pre-empted" in result.result.error_msg
    r.spin_until(lambda: path_to_xy(r.plans[-1])[-1].tolist() == [10.5, 1.5],
                 what="the second goal planned")
    assert second.status == GoalStatus.STATUS_EXECUTING
    msg = PoseStamped()  # a goal on goal_pose pre-empts it too
    msg.header.frame_id = "map"
    msg.pose.position.x, msg.pose.position.y = GOAL
    r.goal_pub.publish(msg)
    result = r.result(second)
    assert result.status == GoalStatus.STATUS_ABORTED and "goal_pose" in result.result.error_msg


def test_fifty_goals_and_cancels_in_a_burst(rig):
    """A client gone mad: 50 goals, a third of them cancelled, as fast as it can (about 4 s
    here, each goal planned on arrival); every goal ends, the node keeps planning and the
    last goal is reached."""
    r = rig()
    r.ready()
    rng = np.random.default_rng(3)
    free = [(1.5, 1.5), (6.5, 5.5), (10.5, 1.5), (4.5, 7.5), (1.5, 7.5)]
    handles = []
    t0 = time.monotonic()
    for i in range(50):
        h = r.send(free[rng.integers(len(free))], float(rng.uniform(-3, 3)))
        handles.append(h)
        if i % 3 == 0:
            h.cancel_goal_async()
        r.spin_for(0.02)
    assert time.monotonic() - t0 < 20.0  # each waits for its acceptance: ~4 s here
    last = r.send(GOAL, 0.0)
    ends = [r.result(h) for h in handles]
    assert all(e.status in (GoalStatus.STATUS_ABORTED, GoalStatus.STATUS_CANCELED,
                            GoalStatus.STATUS_SUCCEEDED) for e in ends)
    r.spin_until(lambda: r.plans and len(r.plans[-1].poses)
                 and path_to_xy(r.plans[-1])[-1].tolist() == list(GOAL), what="last planned")
    r.odom(GOAL, 0.0)
    assert r.result(last).status == GoalStatus.STATUS_SUCCEEDED


def test_an_inactive_node_rejects_goals(rig):
    r = rig()
    r.ready()
    r.planner.trigger_deactivate()
    handle = r.send(GOAL)
    assert not handle.accepted


# --------------------------------------------------------------------- compute_path_to_pose
def test_compute_path_to_pose_is_dense_and_collision_free(rig):
    r = rig()
    r.ready()
    answer = r.path(GOAL, goal_yaw=1.0)
    assert answer.status == GoalStatus.STATUS_SUCCEEDED
    result = answer.result
    assert result.error_code == 0
    xy = path_to_xy(result.path)
    assert result.path.header.frame_id == "map"
    assert xy[0] == pytest.approx(ROBOT, abs=1e-3) and xy[-1] == pytest.approx(GOAL, abs=1e-3)
    steps = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    assert steps.max() <= nav2_actions.PATH_SPACING + 1e-6
    report = check_collision(xy, make_footprint("circle"), builtin_map("maze2d-large"))
    assert report.collision_free
    assert heading_of(result.path.poses[-1].pose.orientation) == pytest.approx(1.0)
    assert result.planning_time.sec + result.planning_time.nanosec > 0
    assert r.plans == []  # nothing for the robot to follow: a path, not a mission


def test_compute_path_to_pose_refuses_with_nav2_codes(rig):
    r = rig()
    r.ready(odom=False)
    c = ComputePathToPose.Result
    assert r.path(GOAL).result.error_code == c.TF_ERROR  # no robot pose to start from
    assert r.path(GOAL, start_xy=ROBOT, planner_id="GridBased").result.error_code == \
        c.INVALID_PLANNER
    assert r.path(WALL, start_xy=ROBOT).result.error_code == c.GOAL_OCCUPIED
    assert r.path(GOAL, start_xy=(-3.0, 1.0)).result.error_code == c.START_OUTSIDE_MAP
    answer = r.path(GOAL, start_xy=ROBOT)
    assert answer.status == GoalStatus.STATUS_SUCCEEDED
