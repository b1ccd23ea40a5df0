"""local_refiner: ECAHD's local stage as a node (paper Algorithm 1 lines 13-18, Algorithm 2) with a
pure-pursuit style controller that follows the result.

For the current segment of the global plan (the robot's pose -> the plan's next waypoint) it
builds the straight local plan LocalPlan of P^l points, evaluates the collision cost c^l of J
(surface sweep of the footprint) and, when c^l > c_th, replaces it by a Dense Diffusion sample
guided by J (``HierarchicalPlanner.refine``); if the refined plan is still above c_th, its two
interior points are polished by descending J (``polish_steps``, our rule beyond the paper; both
ends stay: the robot's pose and the global planner's waypoint). This happens once per segment,
inside the control tick: the first tick after a plan (or a map) arrives, and the tick in which
the robot comes within ``waypoint_tolerance`` of the waypoint it is heading for; every other
tick only tracks the current dense local plan. So the "control" timing records (the whole tick)
include every J check and DD run, and the plan and map callbacks stay cheap.

With ``dd_enabled`` false ("ECAHD w/o DD" of Table III, and the baselines' "no local planner")
the straight local plans are followed as they are: J is still evaluated on each one (so the
"j_check" timing records keep c_before, with c_after = c_before, for the diagnostics), DD never
runs and no DD model is loaded.

Controller (every 1 / control_rate s): ``ecahd_core.controller``'s pure pursuit along the
dense local plan, then the remaining waypoints, within max_v, max_w and max_accel. A zero
command is published when there is no plan, when the odometry is older than ``stale_timeout``
(or the plan older than ``plan_timeout`` when that is > 0), and once the goal (the plan's last
point) is within ``goal_tolerance``; the plan is then dropped until a new one arrives.

Parameters (read-only, declared in :data:`PARAMETERS`): see the table there.

Subscribes:
    plan (nav_msgs/Path; reliable, transient_local, depth 1): the global plan, frame
        ``global_frame``; an empty path stops the robot.
    odom (nav_msgs/Odometry; reliable, depth 10): pose in ``global_frame``.
    map (nav_msgs/OccupancyGrid; reliable, transient_local, depth 1): builds J's cost map and
        loads the DD model; without a map the straight local plans are followed unchecked.
Publishes:
    cmd_vel (geometry_msgs/Twist, or TwistStamped with ``enable_stamped_cmd_vel``; reliable,
        depth 10).
    local_plan (nav_msgs/Path; reliable, depth 1): the current dense local plan (P^l points).
    local_plan_footprints (visualization_msgs/MarkerArray; reliable, depth 1): the footprint
        outline at each local plan point (blue; red when c^l is still above c_th).
    ecahd/timing (std_msgs/String; reliable, depth 10): JSON {"stage": "j_check" | "dd", "ms",
        "c_before", "c_after", "stamp"} per segment, "dd" when DD ran (ms = J check + DD); and
        {"stage": "control", "ms", "stamp"} after every control tick: the wall time of the
        whole control callback, a J check + DD started in it included (so it is no planning
        time of its own: ``ecahd eval-bag`` reports its p50 / p99 apart from inference time).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import torch
from geometry_msgs.msg import Point, Twist, TwistStamped
from nav_msgs.msg import OccupancyGrid, Odometry, Path
from rclpy.node import Node
from std_msgs.msg import String
from visualization_msgs.msg import Marker, MarkerArray

from ecahd_core.controller import lookahead_point, pure_pursuit, straight_local_plan
from ecahd_core.errors import EcahdError, PlanningError
from ecahd_core.planner import DenseConfig
from ecahd_ros.conversions import (msg_to_grid, path_to_xy, timing_message, xy_to_path,
                                   yaw_from_quaternion)
from ecahd_ros.qos import MAP_QOS, PLAN_QOS, STREAM_QOS, VIZ_QOS
from ecahd_ros.params import (ParamSpec, declare_parameters, read_parameters, require,
                              require_non_negative, require_positive, robot_spec)
from ecahd_ros.spin import spin_node

PARAMETERS = [
    ParamSpec("dd_model", "", "DD checkpoint path; '' = the shipped model for map_name"),
    ParamSpec("map_name", "maze2d-large", "name of the map on 'map' (checked against the "
                                          "checkpoint with the grid's fingerprint)"),
    ParamSpec("robot", "circle", "footprint preset: circle, quadruped, humanoid"),
    ParamSpec("footprint", "", "Nav2 footprint polygon '[[x, y], ...]' [m]; overrides robot"),
    ParamSpec("footprint_padding", 0.0, "[m] grows the footprint (Nav2 footprint_padding)"),
    ParamSpec("global_frame", "map", "frame of plans and odometry poses"),
    ParamSpec("c_th", DenseConfig().c_th, "DD refines a local plan whose collision cost c^l "
                                          "exceeds this"),
    ParamSpec("dd_enabled", True, "run Dense Diffusion at all; false: follow the straight local "
                                  "plans (ECAHD w/o DD; J still checked for the diagnostics)"),
    ParamSpec("polish_steps", DenseConfig().polish_steps,
              "J-descent steps on a DD local plan still above c_th (ours); 0 = the paper"),
    ParamSpec("control_rate", 10.0, "[Hz] cmd_vel rate"),
    ParamSpec("max_v", 0.5, "[m/s] limit on |linear velocity|"),
    ParamSpec("max_w", 1.5, "[rad/s] limit on |angular velocity|"),
    ParamSpec("max_accel", 1.0, "[m/s^2] limit on |linear acceleration|"),
    ParamSpec("lookahead", 0.25, "[m] pure-pursuit lookahead distance (0.4 cut corners: 3.7% "
                                 "of sim steps in wall contact over 5 demo episodes, 0.25: 0%)"),
    ParamSpec("waypoint_tolerance", 0.3, "[m] reaching a waypoint this close starts the next "
                                         "segment"),
    ParamSpec("goal_tolerance", 0.25, "[m] the goal (last plan point) counts as reached"),
    ParamSpec("stale_timeout", 1.0, "[s] odometry older than this stops the robot"),
    ParamSpec("plan_timeout", 0.0, "[s] a plan older than this stops the robot; 0 = never"),
    ParamSpec("enable_stamped_cmd_vel", False, "publish geometry_msgs/TwistStamped on cmd_vel"),
    ParamSpec("seed", 0, "seed of the DD sampler's torch.Generator"),
    ParamSpec("torch_threads", 1, "torch.set_num_threads for this process"),
]


@dataclass(frozen=True, kw_only=True)
class LocalRefinerParams:
    """The node's validated parameters (see :data:`PARAMETERS` for units)."""

    dd_model: str
    map_name: str
    robot: str
    footprint: str
    footprint_padding: float
    global_frame: str
    c_th: float
    dd_enabled: bool
    polish_steps: int
    control_rate: float
    max_v: float
    max_w: float
    max_accel: float
    lookahead: float
    waypoint_tolerance: float
    goal_tolerance: float
    stale_timeout: float
    plan_timeout: float
    enable_stamped_cmd_vel: bool
    seed: int
    torch_threads: int

    def __post_init__(self) -> None:
        require_positive(self, "control_rate", "max_v", "max_w", "max_accel", "lookahead",
                         "waypoint_tolerance", "goal_tolerance", "stale_timeout",
                         "torch_threads")
        require_non_negative(self, "c_th", "footprint_padding", "plan_timeout", "seed",
                             "polish_steps")
        require(bool(self.global_frame), "global_frame", self.global_frame, "non-empty")


def footprint_markers(footprint, local: np.ndarray, frame_id: str, stamp,
                      colliding: bool) -> MarkerArray:
    """The footprint outline at each point of ``local`` (P, 2), facing along the path."""
    out = MarkerArray()
    clear = Marker()
    clear.action = Marker.DELETEALL
    out.markers.append(clear)
    d = np.diff(local, axis=0)
    heading = np.arctan2(d[:, 1], d[:, 0])
    heading = np.append(heading, heading[-1])
    outlines = footprint.transformed(local, heading, which="polygon")  # (P, V, 2)
    for i, poly in enumerate(outlines):
        m = Marker()
        m.header.frame_id, m.header.stamp = frame_id, stamp
        m.ns, m.id, m.type, m.action = "local_plan_footprints", i, Marker.LINE_STRIP, Marker.ADD
        m.pose.orientation.w = 1.0
        m.scale.x = 0.02
        m.color.r, m.color.g, m.color.b, m.color.a = ((0.9, 0.1, 0.1, 1.0) if colliding
                                                      else (0.1, 0.3, 0.9, 0.8))
        for px, py in np.concatenate([poly, poly[:1]]):
            m.points.append(Point(x=float(px), y=float(py), z=0.0))
        out.markers.append(m)
    return out


class LocalRefiner(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("local_refiner", **kwargs)
        declare_parameters(self, PARAMETERS)
        self.params: LocalRefinerParams | None = None
        self.planner = None  # HierarchicalPlanner (its local stage only) once a map arrives
        self.points = DenseConfig().points  # P^l
        self.waypoints: np.ndarray | None = None  # (P, 2) [m] the global plan
        self.target = 0  # index of the waypoint the current segment ends at
        self.local: np.ndarray | None = None  # (P^l, 2) [m] the current dense local plan
        self.local_costs: tuple[float, float] | None = None  # c^l before / after DD
        self.dd_calls = 0
        self.pose: tuple[float, float, float] | None = None  # x [m], y [m], yaw [rad]
        self.odom_time = None  # rclpy Time of the latest odometry
        self.plan_time = None
        self.v = 0.0  # [m/s] last commanded linear velocity
        try:
            self.params = read_parameters(self, PARAMETERS, LocalRefinerParams)
            from ecahd_core.footprint import make_footprint

            p = self.params
            self.footprint = make_footprint(robot_spec(p.robot, p.footprint),
                                            padding=p.footprint_padding)
        except EcahdError as exc:
            self.get_logger().error(f"local_refiner cannot start: {exc}")
            return
        torch.set_num_threads(p.torch_threads)
        self.generator = torch.Generator().manual_seed(p.seed)
        self.dt = 1.0 / p.control_rate
        self._cmd_type = TwistStamped if p.enable_stamped_cmd_vel else Twist
        self._cmd_pub = self.create_publisher(self._cmd_type, "cmd_vel", STREAM_QOS)
        self._local_pub = self.create_publisher(Path, "local_plan", VIZ_QOS)
        self._fp_pub = self.create_publisher(MarkerArray, "local_plan_footprints", VIZ_QOS)
        self._timing_pub = self.create_publisher(String, "ecahd/timing", STREAM_QOS)
        self.create_subscription(Path, "plan", self._guard(self._on_plan), PLAN_QOS)
        self.create_subscription(Odometry, "odom", self._guard(self._on_odom), STREAM_QOS)
        self.create_subscription(OccupancyGrid, "map", self._guard(self._on_map), MAP_QOS)
        self._timer = self.create_timer(self.dt, self._guard(self._on_control_timed))
        dd = f"DD above c_th={p.c_th:g}" if p.dd_enabled else "DD disabled"
        self.get_logger().info(f"local refiner ready: P^l={self.points}, {dd}, "
                               f"{p.control_rate:g} Hz, robot {self.footprint.name!r}")

    def _guard(self, callback):
        """Wrap a callback so no exception escapes; a failure also stops the robot."""
        def wrapped(*args) -> None:
            try:
                callback(*args)
            except EcahdError as exc:
                self.get_logger().error(str(exc))
                self._stop()
            except Exception:  # noqa: BLE001 (a node must survive a bug in one message)
                import traceback

                self.get_logger().error(f"{callback.__name__} failed:\n"
                                        f"{traceback.format_exc()}")
                self._stop()
        return wrapped

    # ------------------------------------------------------------------------- callbacks
    def _on_map(self, msg: OccupancyGrid) -> None:
        from ecahd_core.cost import CostConfig
        from ecahd_core.model_zoo import load_model
        from ecahd_core.planner import HierarchicalPlanner

        p = self.params
        self.planner = None
        grid = msg_to_grid(msg, name=p.map_name)
        ckpt = (load_model("dd", grid, path=p.dd_model or None, footprint=self.footprint,
                           horizon=self.points) if p.dd_enabled else None)
        cost_config = CostConfig()
        # only the local stage (local_cost, refine) is used: no SD model here
        self.planner = HierarchicalPlanner(
            None, ckpt, costmap=cost_config.make_costmap(grid),
            footprint_points=self.footprint.points, cost_config=cost_config,
            dense=DenseConfig(points=self.points, c_th=p.c_th, enabled=p.dd_enabled,
                              polish_steps=p.polish_steps))
        self.get_logger().info(f"map {grid.name!r} received; "
                               f"{'DD model and ' if p.dd_enabled else ''}cost J ready")
        self.local = None  # the next control tick checks (and refines) the segment on this map

    def _on_plan(self, msg: Path) -> None:
        p = self.params
        if msg.header.frame_id != p.global_frame:
            raise PlanningError(f"plan in frame {msg.header.frame_id!r} ignored: expected "
                                f"{p.global_frame!r}")
        xy = path_to_xy(msg)
        if len(xy) == 0:
            self.get_logger().info("empty plan: stopping")
            self.waypoints = self.local = None
            self._stop()
            return
        if not np.all(np.isfinite(xy)):
            raise PlanningError("plan with non-finite coordinates ignored")
        self.waypoints = xy if len(xy) > 1 else np.concatenate([xy, xy])
        self.plan_time = self.get_clock().now()
        self.target = 1
        self.local = None  # the next control tick checks (and refines) the first segment

    def _on_odom(self, msg: Odometry) -> None:
        if msg.header.frame_id and msg.header.frame_id != self.params.global_frame:
            raise PlanningError(f"odometry in frame {msg.header.frame_id!r} ignored: expected "
                                f"{self.params.global_frame!r}")
        pose = msg.pose.pose
        xyyaw = (pose.position.x, pose.position.y, yaw_from_quaternion(pose.orientation))
        if not all(math.isfinite(v) for v in xyyaw):
            raise PlanningError("odometry with non-finite pose ignored")
        self.pose = xyyaw
        self.odom_time = self.get_clock().now()

    def _on_control_timed(self) -> None:
        """The control tick, its wall time published as a "control" timing record."""
        t0 = time.perf_counter()
        try:
            self._on_control()
        finally:
            ms = (time.perf_counter() - t0) * 1e3
            self._timing_pub.publish(timing_message(
                "control", ms, self.get_clock().now().nanoseconds * 1e-9))

    def _on_control(self) -> None:
        p = self.params
        if self.waypoints is not None and self.local is None and self.pose is not None:
            self._start_segment()  # a new plan or map: every J check and DD runs in a tick
        if self.waypoints is None or self.local is None or self.pose is None:
            return self._stop()
        now = self.get_clock().now()
        if (now - self.odom_time).nanoseconds * 1e-9 > p.stale_timeout:
            return self._stop()
        if p.plan_timeout > 0 and (now - self.plan_time).nanoseconds * 1e-9 > p.plan_timeout:
            return self._stop()
        xy = np.array(self.pose[:2])
        goal_distance = float(np.linalg.norm(self.waypoints[-1] - xy))
        if goal_distance < p.goal_tolerance:
            self.get_logger().info("goal reached")
            self.waypoints = self.local = None
            return self._stop()
        last = len(self.waypoints) - 1
        if (self.target < last
                and np.linalg.norm(self.waypoints[self.target] - xy) < p.waypoint_tolerance):
            self.target += 1  # a new segment starts: J check (+ DD) once, here
            self._start_segment()
        path = np.concatenate([self.local, self.waypoints[self.target + 1:]])
        target = lookahead_point(path, xy, p.lookahead)
        v, w = pure_pursuit(self.pose, target, goal_distance, self.v, self.dt, p)
        self._publish_cmd(v, w)

    # ----------------------------------------------------------------------------- stages
    def _start_segment(self) -> None:
        """Algorithm 1 lines 13-18 for the segment robot pose -> waypoints[target]."""
        p = self.params
        end = self.waypoints[self.target]
        start = np.array(self.pose[:2]) if self.pose is not None else \
            self.waypoints[self.target - 1]
        local = straight_local_plan(start, end, self.points)
        stage, c_before, c_after, ms = "straight", None, None, 0.0
        if self.planner is not None:  # both ends stay: the pose and the planner's waypoint
            t0 = time.perf_counter()
            result = self.planner.local_stage(torch.as_tensor(start, dtype=torch.float32),
                                              torch.as_tensor(end, dtype=torch.float32),
                                              end_fixed=True, generator=self.generator)
            ms = (time.perf_counter() - t0) * 1e3
            c_before, c_after = result.c_before, result.c_after
            stage = "dd" if result.dd_used else "j_check"
            self.dd_calls += int(result.dd_used)
            if result.dd_used or result.polished:
                local = result.plan.numpy().astype(np.float64)
                local[0], local[-1] = start, end
        self.local = local
        self.local_costs = (c_before, c_after)
        stamp = self.get_clock().now()
        self._local_pub.publish(xy_to_path(local, p.global_frame, stamp.to_msg()))
        self._fp_pub.publish(footprint_markers(
            self.footprint, local, p.global_frame, stamp.to_msg(),
            colliding=c_after is not None and c_after > p.c_th))
        if self.planner is not None:
            self._timing_pub.publish(timing_message(stage, ms, stamp.nanoseconds * 1e-9,
                                                    c_before=c_before, c_after=c_after))

    def _stop(self) -> None:
        if self.params is not None and hasattr(self, "_cmd_pub"):
            self._publish_cmd(0.0, 0.0)

    def _publish_cmd(self, v: float, w: float) -> None:
        self.v = v
        msg = self._cmd_type()
        twist = msg.twist if isinstance(msg, TwistStamped) else msg
        twist.linear.x, twist.angular.z = float(v), float(w)
        if isinstance(msg, TwistStamped):
            msg.header.stamp = self.get_clock().now().to_msg()
            msg.header.frame_id = "base_link"
        self._cmd_pub.publish(msg)


def main(args=None) -> None:
    spin_node(LocalRefiner, args)


if __name__ == "__main__":
    main()
