"""global_planner: ECAHD's Sparse Diffusion global planner as a node (paper Sec. III-A,
Algorithm 1 lines 2-11 with its shrinking horizon), and the Table III baselines' global planners.

A goal becomes a plan here. The node is a thin shell over
:class:`ecahd_core.planning.online.OnlinePlanner` (when to plan and what, unit-tested without
ROS), which makes every SD plan with :class:`ecahd_core.planning.rules.SparseStage`, the same
code as ``ecahd plan`` and the planning benchmarks (``test/test_online_offline.py``). With
``method`` "sd" (ECAHD): on ``goal_pose`` the node samples N
candidate global plans of P^g waypoints from the robot's pose (``odom``) to the goal in one
batch, keeps the best of N and publishes its waypoints on ``plan``. When the robot comes within
``waypoint_tolerance`` of the next waypoint p, it replans from its current pose with horizon
P^g - p (Algorithm 1: the global plan t^g_p shrinks by one waypoint per iteration), down to the
straight [pose, goal] at horizon 2. With ``replan`` "once" one SD plan serves the whole goal.
Goals that arrive faster than 20 per second are coalesced (the latest is planned).

The baselines plan once per goal (and again on a map update), with no per-waypoint replanning
and no ``replan_timeout``; their whole path goes out on ``plan`` for the local refiner to follow:
    "astar": A* with the footprint's clearance (circumscribed radius, ``footprint_padding``
        included; ``ecahd_core.astar``, as ``ecahd plan --method astar``), string-pulled, then
        resampled so consecutive points are at most ASTAR_SPACING (0.25 m) apart, its vertices
        kept. A pose in a cell without the clearance starts from the nearest one that has it.
    "fd": the Diffuser-style Full Diffusion model (100 points, ``fd_model``), guided by J when
        ``fd_guidance``; seeded by ``seed`` like SD.

Parameters (read-only): each declared once in :data:`PARAMETERS` with its default (from the
core config it sets: OnlinePlannerConfig, GlobalRunnerConfig, SparseConfig) and description;
``config/ecahd.yaml`` and docs/parameters.md list them all.
A parameter out of range, an unknown robot or an unreadable model ends the node at start-up
with one error line and exit code 1 (``ecahd_ros.spin``).

Actions (Nav2's, ``ecahd_ros.nav2_actions``; where nav2_msgs is installed or built):
    navigate_to_pose (nav2_msgs/action/NavigateToPose): a goal planned as on ``goal_pose`` and
        reached with its heading (``yaw_goal_tolerance``), feedback at 10 Hz, cancel,
        pre-emption, Nav2's error codes.
    compute_path_to_pose (nav2_msgs/action/ComputePathToPose): a dense collision-checked path
        (SD + DD + the exact rule + the safety net; the DD model of ``dd_model``).
Subscribes:
    map (nav_msgs/OccupancyGrid; reliable, transient_local, depth 1): rebuilds the planner and
        replans when a goal is active.
    goal_pose (geometry_msgs/PoseStamped; reliable, depth 10): frame must be ``global_frame``;
        finite, on the map and free, else logged and ignored (the current plan stays). A new
        goal pre-empts the current one (a navigate_to_pose goal too); a goal before map and
        odometry is queued. Its orientation is the heading to reach (all zeros: any).
    odom (nav_msgs/Odometry; reliable, depth 10): the robot's pose, in ``global_frame`` or in a
        frame /tf joins to it (REP-105's odom); non-finite or absurd poses are logged and
        ignored.
    /tf, /tf_static (tf2_msgs/TFMessage): map -> odom from the localisation.
    local_costmap (nav_msgs/OccupancyGrid; reliable, depth 1): local_refiner's window of the
        obstacles its scans found; re-plans avoid them for ``obstacle_memory`` s.
    ecahd/replan (std_msgs/String; reliable, depth 10): JSON ``{"reason": ...}`` from
        local_refiner when a segment is blocked: a re-plan from the pose (the second
        for a goal is A* round what is known, followed to the goal).
Publishes:
    /diagnostics (diagnostic_msgs/DiagnosticArray; every second): this node's health
        (``ecahd_ros.diagnostics``).
    plan (nav_msgs/Path; reliable, transient_local, depth 1): the selected sparse waypoints
        (sd) or the whole path (astar, fd), first = robot pose, last = the goal exactly, its
        orientation the goal's heading (all zeros: any); an empty path: the goal was cancelled.
    plan_candidates (visualization_msgs/MarkerArray; reliable, depth 1): sd only: the N
        candidates as line strips (grey), the chosen one highlighted (purple, wider).
    ecahd/timing (std_msgs/String; reliable, depth 10): JSON ``{"stage": "sd" | "astar" | "fd",
        "ms": <float>, "horizon": <int, points of the plan>, "stamp": <float s>}``, one per plan.
    ecahd/planner_ready (std_msgs/String; reliable, transient_local, depth 1): JSON ``{"map":
        <name>, "method": <method>, "ms": <float, building the planner for the map, a warm-up
        SD plan included>}`` once a map's planner is built: a goal sent before then waits for
        it (``ecahd demo`` waits for this before its first goal).
"""
from __future__ import annotations

import json
import math
import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import OccupancyGrid, Odometry, Path
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from ecahd_core.errors import EcahdError, PlanningError
from ecahd_core.model_zoo import learnt_map
from ecahd_core.planning.mission import Mission
from ecahd_core.planning.online import ASTAR_SPACING, OnlinePlanner, PlanOutcome
from ecahd_core.planning.sparse import SparseDiffusion
from ecahd_core.validation import validate_pose
from ecahd_ros.callbacks import check_frame, guard, now_seconds
from ecahd_ros.conversions import (candidate_markers, heading_of, msg_to_grid, no_heading,
                                   pose_from_xy_yaw, timing_message, xy_to_path)
from ecahd_ros.diagnostics import (DIAGNOSTICS_PERIOD, Latencies, diagnostic_array,
                                   node_status)
from ecahd_ros.global_planner_params import PARAMETERS, GlobalPlannerParams
from ecahd_ros import nav2_actions
from ecahd_ros.lifecycle import ManagedNode
from ecahd_ros.nav2_actions import GoalError, check_point, pose_in_frame
from ecahd_ros.params import (collision_cost, declare_parameters, lanes_for, load_lanes, make_robot,
                              read_parameters)
from ecahd_ros.qos import MAP_QOS, PLAN_QOS, STREAM_QOS, VIZ_QOS
from ecahd_ros.spin import spin_node
from ecahd_ros.tf_listener import TfListener, placed_odometry

# re-exported: the node module is where users look for its parameters and constants
__all__ = ["ASTAR_SPACING", "GlobalPlanner", "GlobalPlannerParams", "PARAMETERS", "main"]


class GlobalPlanner(ManagedNode):
    """The node: parameters in, messages in, :class:`~ecahd_core.planning.online.
    OnlinePlanner` (when and what to plan, the offline planner's SparseStage), messages out.
    A lifecycle node (``ecahd_ros.lifecycle``): configured and activated at start-up unless
    ``autostart`` is false; goals are planned only while active."""

    def __init__(self, **kwargs) -> None:
        super().__init__("global_planner", **kwargs)
        declare_parameters(self, PARAMETERS)
        self.planning: OnlinePlanner | None = None  # once configured
        self.pose: np.ndarray | None = None  # (2,) [m] latest valid odometry position
        self.robot_pose: tuple[float, float, float] | None = None  # (x, y, yaw) of it
        self.goal_yaw: float | None = None  # [rad] the goal's heading (None: any)
        self.tf: TfListener | None = None
        self._actions: list = []  # the Nav2 action servers, once configured
        self.mission: Mission | None = None  # the navigate_to_pose goal being driven to
        self._site = None  # the map the models were loaded for (updates of it keep them)
        self.map_changed = 0.0  # share of the map's cells changed since the models' map
        # configuration errors raise with autostart: spin_node exits non-zero with one line
        self.start(self.get_parameter("autostart").value)

    def configure(self) -> None:
        """Parameters, the model check, the planner, topics and timers (lifecycle configure)."""
        self.params: GlobalPlannerParams = read_parameters(self, PARAMETERS, GlobalPlannerParams)
        p = self.params
        self.footprint = make_robot(p)
        self.judged = make_robot(p, margin=p.clearance_margin)  # what waypoints must clear
        if p.method in ("sd", "fd"):  # an unreadable or mismatched model fails now
            from ecahd_core.model_zoo import check_model

            check_model(p.method, p.map_name,
                        path=(p.sd_model if p.method == "sd" else p.fd_model) or None,
                        footprint=self.footprint, horizon=p.horizon if p.method == "sd" else None)
        from ecahd_core.model_zoo import is_general

        # the generalist SD plans on any map: a map of another extent is planned on at once
        self._general = p.method == "sd" and is_general("sd", p.sd_model, p.map_name)
        self._lanes = load_lanes(p.lanes)  # an unreadable lane field fails now
        from ecahd_core.threads import lower_priority, set_torch_threads

        import torch

        set_torch_threads(p.torch_threads)
        lower_priority(p.nice)  # this thread spins the executor: SD and A* run on it
        self.planning = OnlinePlanner(p.online_config(), p.runner_config(), self.judged,
                                      clock=self._now,
                                      generator=torch.Generator().manual_seed(p.seed))
        self.tf = TfListener(self)  # odometry in odom is placed in global_frame through /tf
        for sub in self.tf.subscriptions:
            self.made(sub)
        self._plan_pub = self.made(self.create_lifecycle_publisher(Path, "plan", PLAN_QOS))
        self._cand_pub = self.made(self.create_lifecycle_publisher(
            MarkerArray, "plan_candidates", VIZ_QOS))
        self._timing_pub = self.made(self.create_lifecycle_publisher(
            String, "ecahd/timing", STREAM_QOS))
        self._ready_pub = self.made(self.create_lifecycle_publisher(
            String, "ecahd/planner_ready", MAP_QOS))
        # health also while inactive
        self._diag_pub = self.made(self.create_publisher(DiagnosticArray, "/diagnostics",
                                                          STREAM_QOS))
        self._plan_ms = Latencies()  # the last plans' wall times, for /diagnostics
        self._plans = 0
        self._map_time: float | None = None  # [s, node clock] when the map arrived
        for msg_type, topic, callback, qos in (
                (OccupancyGrid, "map", self._on_map, MAP_QOS),
                (PoseStamped, "goal_pose", self._on_goal, STREAM_QOS),
                (Odometry, "odom", self._on_odom, STREAM_QOS),
                (OccupancyGrid, "local_costmap", self._on_local_costmap, VIZ_QOS),
                (String, "ecahd/replan", self._on_replan, STREAM_QOS)):
            self.made(self.create_subscription(msg_type, topic, guard(self, callback), qos))
        # a goal coalesced in a burst is planned within one period even without odometry
        self.made(self.create_timer(p.runner_config().min_plan_interval,
                                     guard(self, self._on_pending)))
        self.made(self.create_timer(DIAGNOSTICS_PERIOD, guard(self, self._publish_diagnostics)))
        self._sd: SparseDiffusion | None = None  # the map's SD (compute_path_to_pose's too)
        self._dense = None  # DensePathPlanner on the map, built on the first path request
        self.navigate = None  # NavigateToPoseServer
        if nav2_actions.available():
            self.navigate = nav2_actions.NavigateToPoseServer(self)
            self._actions = [self.navigate, nav2_actions.ComputePathServer(self)]
        else:
            self.get_logger().warning("nav2_msgs is not installed: navigate_to_pose and "
                                      "compute_path_to_pose are not served (goal_pose is)")
        what = f"SD, N={p.num_candidates}, P^g={p.horizon}" if p.method == "sd" else p.method
        self.get_logger().info(f"global planner configured: {what}, robot "
                               f"{self.footprint.name!r}, waiting for map and odom")

    def release(self) -> None:
        """Undo :meth:`configure` (lifecycle cleanup and shutdown)."""
        for server in self._actions:
            server.destroy()
        self._actions, self.navigate, self.mission = [], None, None
        self.destroy_made()
        self.planning, self.tf, self.pose, self.robot_pose = None, None, None, None
        self._site = None

    @property
    def ready(self) -> bool:
        """A map arrived and the planner of ``method`` is built on it."""
        return self.planning is not None and self.planning.ready

    @property
    def runner(self):
        return self.planning.runner

    @property
    def goal(self) -> np.ndarray | None:
        return None if self.planning is None else self.planning.runner.goal

    @property
    def waypoints(self) -> np.ndarray | None:
        return None if self.planning is None else self.planning.runner.waypoints

    @property
    def grid(self):
        return None if self.planning is None else self.planning.grid

    def now(self) -> float:
        """The node's clock [s] (sim time with use_sim_time)."""
        return now_seconds(self)

    _now = now

    # ------------------------------------------------------------------------- callbacks
    def _on_map(self, msg: OccupancyGrid) -> None:
        p = self.params
        check_frame(msg.header.frame_id, p.global_frame, "map")
        t0 = time.perf_counter()
        received = msg_to_grid(msg, name=p.map_name)
        # with a model, an update of the site's map keeps it (MapError: another extent)
        learnt, changed = ((received, 0.0) if p.method == "astar" or self._general
                           else learnt_map(self._site, received))
        lanes = lanes_for(self._lanes, received, self.get_logger())
        # the keep-out places learnt from the demonstrations are walls to every planner here
        # (a per-map model keeps its site: they are walls it never learnt, detoured by A*)
        grid = received if lanes is None else lanes.with_keep_out(received)
        built = {}
        warm = ""
        if p.method == "sd":
            built["sd"] = sd = self._build_sd(grid, learnt)
            x0, y0, x1, y1 = grid.bounds  # the first real plan then costs what later ones do
            warm = f", warm-up plan {sd.warm_up((0.5 * (x0 + x1), 0.5 * (y0 + y1))):.0f} ms"
        elif p.method == "astar":
            from ecahd_core.astar import clearance_for_footprint, planner_for

            built["astar"] = planner_for(grid, clearance_for_footprint(self.judged))
        else:
            built["fd"] = self._build_fd(grid, learnt)
        had_goal = self.goal is not None
        self._sd, self._dense, self._site = built.get("sd"), None, learnt
        self.map_changed = changed
        self.planning.set_map(grid, **built, learnt=learnt, lanes=lanes)
        if learnt is not received:
            log = self.get_logger().warning if changed > p.map_change_warn else \
                self.get_logger().info
            log(f"map updated: {100 * changed:.2f}% of its cells changed since the map the "
                f"models learnt ({int(self.planning.memory.unlearnt.sum())} new wall cells, "
                f"detoured when SD crosses them)"
                + (f"; above map_change_warn ({100 * p.map_change_warn:g}%): consider "
                   f"training again" if changed > p.map_change_warn else ""))
        self._map_time = self._now()
        ms = (time.perf_counter() - t0) * 1e3
        spacing = self.planning.replan_spacing
        self.get_logger().info(f"map {grid.name!r} received ({grid.width} x {grid.height} "
                               f"cells); {p.method} planner built in {ms:.0f} ms{warm}"
                               + (f"; re-plans keep a waypoint per {spacing:g} m left to the "
                                  f"goal (replan_spacing)" if spacing else ""))
        self._ready_pub.publish(String(data=json.dumps(
            {"map": grid.name, "method": p.method, "ms": round(ms, 1)})))
        if had_goal:
            self._step()  # plan again on the new map

    def _build_sd(self, grid, learnt) -> SparseDiffusion:
        """SD on ``grid`` with the model of ``learnt`` (the site's map; ``grid`` or an earlier
        version of it)."""
        from ecahd_core.model_zoo import load_sd

        p = self.params
        ckpt = load_sd(learnt, path=p.sd_model or None, footprint=self.footprint,
                       horizon=p.horizon)
        cost = (collision_cost(p, grid, self.footprint)
                if p.selection == "collision_aware" else None)
        return SparseDiffusion(ckpt, p.sparse_config(), cost=cost, grid=grid)

    def _build_fd(self, grid, learnt):
        from ecahd_core.model_zoo import load_model
        from ecahd_core.planning.full import FullDiffusion

        p = self.params
        ckpt = load_model("fd", learnt, path=p.fd_model or None, footprint=self.footprint)
        cost = collision_cost(p, grid, self.footprint) if p.fd_guidance else None
        return FullDiffusion(ckpt, guidance=p.fd_guidance, cost=cost,
                             num_steps=p.ddim_steps or None)

    def _on_goal(self, msg: PoseStamped) -> None:
        if not self.active:
            raise PlanningError("goal rejected: global_planner is not active (lifecycle: "
                                "activate it first)")
        check_frame(msg.header.frame_id, self.params.global_frame, "goal")
        try:
            x, y, _ = validate_pose((msg.pose.position.x, msg.pose.position.y, 0.0), "goal")
            yaw = heading_of(msg.pose.orientation)
            xy = np.array([x, y])
            if self.planning.grid is not None:
                xy = self.planning.grid.validate_point(xy, "goal")
        except EcahdError as exc:
            raise PlanningError(f"goal rejected: {exc}") from None
        if self.navigate is not None:
            self.navigate.end(0, "pre-empted by a goal on goal_pose")
        self._set_goal(xy, yaw)

    def _set_goal(self, xy: np.ndarray, yaw: float | None) -> None:
        """A validated goal (2,) [m] with its heading: planned now, or queued."""
        self.goal_yaw = yaw
        self.planning.set_goal(xy)
        if not self.planning.ready or self.pose is None:
            missing = " and ".join(n for n, ok in (("map", self.planning.ready),
                                                   ("odom", self.pose is not None)) if not ok)
            self.get_logger().info(f"goal ({xy[0]:.2f}, {xy[1]:.2f}) queued until {missing} "
                                   f"arrive(s)")
            return
        self._step()

    def _on_odom(self, msg: Odometry) -> None:
        p = self.params
        pose = placed_odometry(self, msg, self.tf.buffer, p.global_frame, p.transform_tolerance)
        if pose is None:
            return
        try:
            x, y, yaw = validate_pose(pose, "odometry pose")
        except PlanningError as exc:
            raise PlanningError(f"odometry ignored: {exc}") from None
        self.pose, self.robot_pose = np.array([x, y]), (x, y, yaw)
        self._step()

    def _on_local_costmap(self, msg: OccupancyGrid) -> None:
        check_frame(msg.header.frame_id, self.params.global_frame, "local_costmap")
        if self.planning.grid is not None:
            window = msg_to_grid(msg, name="local_costmap", unknown_is_occupied=False)
            self.planning.observe(window, self._now())

    def _on_replan(self, msg: String) -> None:
        """The refiner cannot follow the plan (a segment blocked by a scanned obstacle)."""
        try:
            reason = str(json.loads(msg.data).get("reason", "blocked"))
        except (ValueError, AttributeError):
            raise EcahdError(f"ecahd/replan ignored: not a JSON object: {msg.data[:80]!r}") \
                from None
        if self.goal is None:
            return
        self.planning.request_replan(reason)
        self._step()

    def _on_pending(self) -> None:
        if self.planning.runner.pending:
            self._step()

    def _step(self) -> None:
        """One call of the core at the current pose, and its result out."""
        if self.pose is None:
            return
        goal = self.goal
        try:
            outcome = self.planning.step(self.pose)
        except PlanningError as exc:
            mission = self.mission
            if mission is not None:
                mission.fail(str(exc), nav2_actions.NO_VALID_PATH)
            raise
        if outcome == "reached":
            self.get_logger().info(f"goal ({goal[0]:.2f}, {goal[1]:.2f}) reached")
        elif isinstance(outcome, PlanOutcome):
            self._publish(outcome)

    def _publish(self, out: PlanOutcome) -> None:
        """A plan out: ``plan``, ``plan_candidates`` (SD), ``ecahd/timing`` and a log line."""
        frame, runner = self.params.global_frame, self.planning.runner
        if out.request.reason == "timeout":
            self.get_logger().warning(
                f"no progress toward the next waypoint for {runner.stall_timeout:g} s: "
                f"replanning from the current pose (timeout replan {runner.stalls} in a row)")
        self._plan_ms.add(out.ms)
        self._plans += 1
        stamp = self.get_clock().now()
        plan = xy_to_path(out.waypoints, frame, stamp.to_msg())
        # the last pose carries the goal's heading for local_refiner; all zeros: any heading
        last = plan.poses[-1].pose
        if self.goal_yaw is None:
            no_heading(last)
        else:
            last.orientation = pose_from_xy_yaw(0.0, 0.0, self.goal_yaw).orientation
        self._plan_pub.publish(plan)
        mission = self.mission
        if mission is not None:
            mission.planned(out.waypoints)
        if out.sparse is not None:
            self._cand_pub.publish(candidate_markers(out.sparse, frame, stamp.to_msg()))
        self._timing_pub.publish(timing_message(out.method, out.ms, stamp.nanoseconds * 1e-9,
                                                horizon=len(out.waypoints)))
        goal = out.waypoints[-1]
        line = (f"{out.method} plan of {len(out.waypoints)} points to ({goal[0]:.2f}, "
                f"{goal[1]:.2f}) in {out.ms:.1f} ms{out.detail}")
        if out.method == "fallback_astar":
            self.get_logger().warning(line)
        else:
            self.get_logger().info(line)

    # --------------------------------------------------------------- Nav2's actions' side
    def goal_pose_in(self, msg: PoseStamped, *, tf_error: int | None = None,
                     what: str = "goal") -> tuple[float, float, float | None]:
        """A PoseStamped's (x, y, yaw or None) in ``global_frame`` (GoalError naming the
        problem, ``tf_error`` when tf cannot join its frame)."""
        p = self.params
        return pose_in_frame(msg, p.global_frame, self.tf.buffer, p.transform_tolerance, what,
                             nav2_actions.TF_ERROR if tf_error is None else tf_error)

    def start_mission(self, x: float, y: float, yaw: float | None) -> Mission:
        """navigate_to_pose's goal: checked on the map (GoalError with Nav2's code), planned
        as a goal_pose is, followed by a Mission."""
        xy = np.array([x, y])
        if self.grid is not None:
            xy = check_point(self.grid, xy, "goal", nav2_actions.GOAL_OUTSIDE_MAP,
                             nav2_actions.GOAL_OCCUPIED)
        self.mission = Mission(xy, yaw, self.now(), self.params.mission_config())
        try:
            self._set_goal(xy, yaw)  # the plans made now count for the mission
        except PlanningError as exc:
            self.mission = None
            self.planning.cancel()
            raise GoalError(nav2_actions.NO_VALID_PATH, str(exc)) from None
        return self.mission

    def stop_goal(self) -> None:
        """Drop the goal and stop the robot (an empty plan: local_refiner stops)."""
        if self.planning is not None:
            self.planning.cancel()
        self.goal_yaw = None
        self._plan_pub.publish(xy_to_path(np.zeros((0, 2)), self.params.global_frame,
                                          self.get_clock().now().to_msg()))

    def dense_path(self, start: np.ndarray, goal: np.ndarray):
        """compute_path_to_pose's path from ``start`` to ``goal`` (2,) [m]: a DensePath."""
        import torch

        from ecahd_core.planning.dense_path import DensePath, DensePathPlanner

        p = self.params
        if p.method == "astar":
            t0 = time.perf_counter()
            path = self.planning.astar.plan(start, goal)
            return DensePath(path=path, safe=True, rule="astar", reason="",
                             ms=(time.perf_counter() - t0) * 1e3)
        if p.method != "sd" or self._sd is None:
            raise GoalError(nav2_actions.PATH_UNKNOWN,
                            f"compute_path_to_pose serves methods sd and astar, not "
                            f"{p.method!r}")
        if self._dense is None:  # the DD model and the net, once per map
            self._dense = DensePathPlanner.for_map(self.grid, self.footprint, self._sd,
                                                   dd_model=p.dd_model or None,
                                                   learnt=self._site)
        return self._dense.plan(start, goal,
                                generator=torch.Generator().manual_seed(p.seed))

    def _publish_diagnostics(self) -> None:
        """This node's health on /diagnostics: planner and map, goal, plan latency, fallbacks."""
        p, planning = self.params, self.planning
        goal = self.goal
        values = {
            "method": p.method, "model": (p.sd_model or p.fd_model or f"shipped for {p.map_name}")
            if p.method != "astar" else "A*",
            "map": planning.grid.name if planning.grid is not None else "none",
            "map_age_s": self._now() - self._map_time if self._map_time is not None else math.nan,
            "map_changed_share": self.map_changed,
            "goal": "none" if goal is None else f"{goal[0]:.2f}, {goal[1]:.2f}",
            "plans": self._plans, "plan_ms_p50": self._plan_ms.quantile(0.5),
            "plan_ms_p99": self._plan_ms.quantile(0.99), "fallbacks": planning.fallbacks,
            "replan_spacing_m": planning.replan_spacing or "off"}
        if not self.active:
            level, message = "warn", "inactive (lifecycle): goals are not planned"
        elif not planning.ready:
            level, message = "warn", "waiting for a map"
        elif goal is not None and self.pose is None:
            level, message = "warn", "a goal waits for odometry"
        else:
            level, message = "ok", "planning" if goal is not None else "ready, no goal"
        self._diag_pub.publish(diagnostic_array(
            [node_status("global_planner", level, message, values)],
            self.get_clock().now().to_msg()))

def main(args=None) -> None:
    spin_node(GlobalPlanner, args, name="global_planner")


if __name__ == "__main__":
    main()
