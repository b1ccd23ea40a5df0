"""Nav2's two planning actions, served by global_planner with ROS 2 Jazzy's ``nav2_msgs`` types
(same package, names and definitions as Nav2's, so behaviour trees, Nav2's simple commander,
RViz's Nav2 goal tool and the waypoint follower talk to them as to Nav2's own):

``navigate_to_pose`` (nav2_msgs/action/NavigateToPose; bt_navigator's): the goal pose, in
    ``global_frame`` or any frame tf joins to it, is planned to as a ``goal_pose`` message is
    and reached with its heading (``yaw_goal_tolerance``: local_refiner turns in place at the
    goal). Feedback every FEEDBACK_PERIOD s: current pose, distance remaining along the plan,
    navigation time, estimated time remaining, re-plans (``number_of_recoveries``). A new goal,
    or one on ``goal_pose``, pre-empts the running one (aborted, error_code NONE, "pre-empted");
    a cancel stops the robot at once (an empty plan) and ends the goal CANCELED within one
    feedback period. Errors (``error_code``, ``error_msg``): the goal off the map or in an
    obstacle (ComputePathToPose's GOAL_OUTSIDE_MAP 204 / GOAL_OCCUPIED 206, as Nav2's
    bt_navigator passes on its planner's code), no plan can be made (NO_VALID_PATH 208), a
    frame tf cannot join (TF_ERROR 9002), the heading not reached (UNKNOWN 9000). Goals are
    rejected while the node is not active (lifecycle).
``compute_path_to_pose`` (nav2_msgs/action/ComputePathToPose; planner_server's): one dense,
    collision-checked path: SD, DD guided by J, the exact rule and the safety net
    (:class:`ecahd_core.planning.dense_path.DensePathPlanner`; method astar: A* with the
    footprint's clearance), points at most PATH_SPACING apart, the last pose with the goal's
    orientation. The robot does not move. ``planner_id``: "" or the node's ``method``, else
    INVALID_PLANNER; ``use_start`` false plans from the robot's pose (none yet: TF_ERROR).
    A path the exact checker finds in collision is never returned (NO_VALID_PATH, the net's
    reason in error_msg). It runs on the executor thread (a second or so on a big map).

Where ``nav2_msgs`` is not installed (a ROS install without Nav2; ``scripts/venv.sh`` builds it
into a pip-only install) the node serves neither and says so once.
"""
from __future__ import annotations

import math

import numpy as np
from builtin_interfaces.msg import Duration
from geometry_msgs.msg import PoseStamped
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.task import Future

from ecahd_core.errors import EcahdError
from ecahd_core.frames import FrameError
from ecahd_ros.conversions import heading_of, pose_from_xy_yaw, xy_to_path

try:  # Nav2's types: the distribution's, or built by scripts/venv.sh
    from nav2_msgs.action import ComputePathToPose, NavigateToPose
except ImportError:  # pragma: no cover (a ROS install without nav2_msgs)
    ComputePathToPose = NavigateToPose = None

# Jazzy's error codes (the types' constants; here so the node reads them without nav2_msgs)
NAVIGATE_UNKNOWN, TF_ERROR = 9000, 9002  # NavigateToPose.Result
PATH_UNKNOWN, INVALID_PLANNER, PATH_TF_ERROR = 200, 201, 202  # ComputePathToPose.Result
START_OUTSIDE_MAP, GOAL_OUTSIDE_MAP, START_OCCUPIED, GOAL_OCCUPIED = 203, 204, 205, 206
NO_VALID_PATH = 208

FEEDBACK_PERIOD = 0.1  # [s] navigate_to_pose's feedback and goal checks (Nav2's BT: 10 Hz)
PATH_SPACING = 0.05  # [m] compute_path_to_pose's points (Nav2's planners: the costmap's cell)
PLANNER_IDS = ("", "ecahd")  # besides the node's method


def available() -> bool:
    """Whether ``nav2_msgs`` is importable (the actions can be served)."""
    return NavigateToPose is not None


class GoalError(EcahdError):
    """A goal or path request that cannot be served, with its Nav2 error code."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code


def duration(seconds: float) -> Duration:
    seconds = max(float(seconds), 0.0)
    whole = int(seconds)
    return Duration(sec=whole, nanosec=int((seconds - whole) * 1e9))


def pose_in_frame(msg: PoseStamped, frame: str, buffer, tolerance: float, what: str,
                  tf_error: int) -> tuple[float, float, float | None]:
    """A PoseStamped's (x, y, yaw or None) in ``frame`` (through tf when it is in another one,
    at the newest transform); GoalError(tf_error) when tf cannot join the frames, and
    GoalError(0) for non-finite values."""
    p = msg.pose.position
    try:
        yaw = heading_of(msg.pose.orientation)
    except EcahdError as exc:
        raise GoalError(0, f"{what} rejected: {exc}") from None
    if not (math.isfinite(p.x) and math.isfinite(p.y)):
        raise GoalError(0, f"{what} rejected: non-finite position ({p.x}, {p.y})")
    source = msg.header.frame_id or frame
    if source == frame:
        return p.x, p.y, yaw
    try:
        x, y, placed = buffer.pose_in(frame, source, None, (p.x, p.y, yaw or 0.0),
                                      tolerance=tolerance)
    except FrameError as exc:
        raise GoalError(tf_error, f"{what} in frame {source!r}: {exc}") from None
    return x, y, (placed if yaw is not None else None)


def check_point(grid, xy, what: str, outside: int, occupied: int) -> np.ndarray:
    """``xy`` (2,) [m] on ``grid`` and free, else GoalError with Nav2's code for it."""
    xy = np.asarray(xy, dtype=np.float64).reshape(2)
    if not grid.in_bounds(xy):
        x0, y0, x1, y1 = grid.bounds
        raise GoalError(outside, f"{what} ({xy[0]:.2f}, {xy[1]:.2f}) is outside the map "
                                 f"[{x0:.2f}, {x1:.2f}] x [{y0:.2f}, {y1:.2f}] m")
    if not grid.is_free(xy):
        raise GoalError(occupied, f"{what} ({xy[0]:.2f}, {xy[1]:.2f}) is inside an obstacle")
    return xy


def path_message(path: np.ndarray, yaw: float | None, frame: str, stamp):
    """(M, 2) [m] -> nav_msgs/Path with points at most PATH_SPACING apart (straight between
    the checked points, so nothing the exact checker did not judge), each facing the next, the
    last with ``yaw`` when the goal has one."""
    from ecahd_core.collision import densify

    dense = densify(np.asarray(path, dtype=np.float64), step=PATH_SPACING)[:, :2]
    msg = xy_to_path(dense, frame, stamp)
    if yaw is not None and msg.poses:
        msg.poses[-1].pose = pose_from_xy_yaw(float(dense[-1, 0]), float(dense[-1, 1]), yaw)
    return msg


class NavigateToPoseServer:
    """``navigate_to_pose`` on ``node`` (a GlobalPlanner): see the module docstring. The node
    provides ``start_mission(x, y, yaw) -> Mission`` (GoalError when it cannot be planned; the
    node's ``mission`` from then on), ``stop_goal()``, ``robot_pose`` (x, y, yaw or None),
    ``goal_pose_in(msg)``, ``now()``, ``active``."""

    def __init__(self, node) -> None:
        self.node = node
        self.current = None  # (goal handle, Future of its result)
        self.server = ActionServer(node, NavigateToPose, "navigate_to_pose",
                                   execute_callback=self._execute,
                                   goal_callback=self._on_request,
                                   cancel_callback=self._on_cancel)
        self.timer = node.create_timer(FEEDBACK_PERIOD, self._tick)

    def destroy(self) -> None:
        self.end(NAVIGATE_UNKNOWN, "the node is shutting down")
        self.node.destroy_timer(self.timer)
        self.server.destroy()

    def _on_request(self, goal) -> GoalResponse:
        if not self.node.active:
            self.node.get_logger().warning("navigate_to_pose goal rejected: global_planner is "
                                           "not active (lifecycle)")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _on_cancel(self, handle) -> CancelResponse:
        if self.current is not None and self.current[0] is handle:
            self.node.stop_goal()  # stop now; the goal ends CANCELED at the next tick
        return CancelResponse.ACCEPT

    async def _execute(self, handle):
        self.end(NavigateToPose.Result.NONE, "pre-empted by a new navigate_to_pose goal")
        try:
            x, y, yaw = self.node.goal_pose_in(handle.request.pose)
            self.node.start_mission(x, y, yaw)
        except GoalError as exc:
            self.node.get_logger().error(f"navigate_to_pose: {exc}")
            handle.abort()
            return NavigateToPose.Result(error_code=exc.code or NAVIGATE_UNKNOWN,
                                         error_msg=str(exc))
        done = Future()
        self.current = (handle, done)
        self.node.get_logger().info(
            f"navigate_to_pose: goal ({x:.2f}, {y:.2f}"
            + (f", {math.degrees(yaw):.0f} deg)" if yaw is not None else ", any heading)"))
        return await done

    def end(self, code: int, message: str) -> None:
        """Abort the running goal (pre-emption, a failure): ``code`` and ``message`` in its
        result."""
        if self.current is None:
            return
        handle, done = self.current
        self.current, self.node.mission = None, None
        if handle.is_active:
            handle.abort()
        done.set_result(NavigateToPose.Result(error_code=code, error_msg=message))

    def _finish(self, how: str, message: str = "") -> None:
        handle, done = self.current
        self.current, self.node.mission = None, None
        getattr(handle, how)()
        done.set_result(NavigateToPose.Result(error_code=NavigateToPose.Result.NONE,
                                              error_msg=message))

    def _tick(self) -> None:
        if self.current is None:
            return
        handle, _ = self.current
        mission = self.node.mission
        if handle.is_cancel_requested:
            self.node.stop_goal()
            self.node.get_logger().info("navigate_to_pose: goal canceled")
            self._finish("canceled", "canceled")
            return
        pose = self.node.robot_pose
        if pose is None:
            return
        progress = mission.update(pose, self.node.now())
        feedback = NavigateToPose.Feedback()
        feedback.current_pose.header.frame_id = self.node.params.global_frame
        feedback.current_pose.header.stamp = self.node.get_clock().now().to_msg()
        feedback.current_pose.pose = pose_from_xy_yaw(*pose)
        feedback.distance_remaining = float(progress.distance_remaining)
        feedback.navigation_time = duration(progress.elapsed)
        feedback.estimated_time_remaining = duration(progress.time_remaining)
        feedback.number_of_recoveries = min(progress.replans, 32767)
        handle.publish_feedback(feedback)
        if progress.state == "succeeded":
            self.node.get_logger().info(
                f"navigate_to_pose: goal reached in {progress.elapsed:.1f} s, "
                f"{progress.replans} re-plan(s)")
            self._finish("succeed")
        elif progress.state == "failed":
            self.node.stop_goal()
            self.node.get_logger().error(f"navigate_to_pose: {progress.message}")
            self.end(mission.code or NAVIGATE_UNKNOWN, progress.message)


class ComputePathServer:
    """``compute_path_to_pose`` on ``node`` (a GlobalPlanner): see the module docstring. The
    node provides ``dense_path(start, goal) -> DensePath``, ``goal_pose_in(msg)``,
    ``robot_pose``, ``grid``, ``active``."""

    def __init__(self, node) -> None:
        self.node = node
        self.server = ActionServer(node, ComputePathToPose, "compute_path_to_pose",
                                   execute_callback=self._execute,
                                   goal_callback=self._on_request)

    def destroy(self) -> None:
        self.server.destroy()

    def _on_request(self, goal) -> GoalResponse:
        return GoalResponse.ACCEPT if self.node.active else GoalResponse.REJECT

    def _execute(self, handle):
        R = ComputePathToPose.Result
        t0 = self.node.now()
        try:
            path, yaw = self._plan(handle.request)
        except GoalError as exc:
            self.node.get_logger().error(f"compute_path_to_pose: {exc}")
            handle.abort()
            return R(error_code=exc.code or PATH_UNKNOWN, error_msg=str(exc),
                     planning_time=duration(self.node.now() - t0))
        except EcahdError as exc:
            self.node.get_logger().error(f"compute_path_to_pose: {exc}")
            handle.abort()
            return R(error_code=R.NO_VALID_PATH, error_msg=str(exc),
                     planning_time=duration(self.node.now() - t0))
        result = R(error_code=R.NONE)
        result.path = path_message(path, yaw, self.node.params.global_frame,
                                   self.node.get_clock().now().to_msg())
        result.planning_time = duration(self.node.now() - t0)
        handle.succeed()
        return result

    def _plan(self, request) -> tuple[np.ndarray, float | None]:
        node = self.node
        if request.planner_id not in (*PLANNER_IDS, node.params.method):
            raise GoalError(INVALID_PLANNER,
                            f"unknown planner_id {request.planner_id!r}: this planner is "
                            f"{node.params.method!r} (or leave it empty)")
        grid = node.grid
        if grid is None:
            raise GoalError(PATH_UNKNOWN, "no map yet")
        gx, gy, yaw = node.goal_pose_in(request.goal, tf_error=PATH_TF_ERROR, what="goal")
        if request.use_start:
            sx, sy, _ = node.goal_pose_in(request.start, tf_error=PATH_TF_ERROR, what="start")
        elif node.robot_pose is None:
            raise GoalError(PATH_TF_ERROR, "no robot pose yet (odometry through tf) to start from")
        else:
            sx, sy, _ = node.robot_pose
        start = check_point(grid, (sx, sy), "start", START_OUTSIDE_MAP, START_OCCUPIED)
        goal = check_point(grid, (gx, gy), "goal", GOAL_OUTSIDE_MAP, GOAL_OCCUPIED)
        found = node.dense_path(start, goal)
        if not found.safe:
            raise GoalError(NO_VALID_PATH, f"no collision-free path: {found.reason}")
        node.get_logger().info(
            f"compute_path_to_pose: ({start[0]:.2f}, {start[1]:.2f}) -> ({goal[0]:.2f}, "
            f"{goal[1]:.2f}), {len(found.path)} points in {found.ms:.0f} ms (net: {found.rule})")
        return found.path, yaw
