"""local_refiner: ECAHD's local stage as a node (paper Algorithm 1 lines 13-18, Algorithm 2) with a
pure-pursuit controller that follows the result. A thin shell over
:class:`ecahd_core.planning.local.LocalRunner` (the online logic, unit-tested without ROS); a
lifecycle node (``ecahd_ros.lifecycle``: it drives only while active).

Each segment of the global plan (the first from the robot's pose when the plan arrived, then
waypoint to waypoint) gets the straight local plan of P^l points, its collision cost c^l of J
(surface sweep of the footprint) and, when c^l > c_th, a Dense Diffusion sample guided by J; a DD
plan still above c_th is polished by descending J (``polish_steps``, ours). The exact
swept-footprint checker judges the result: a local plan it finds in collision is never followed
(zero velocity, a "blocked" warning). This work runs on a worker thread, ``prepare_ahead``
segments ahead of the robot, so cmd_vel goes out at ``control_rate`` while DD runs: the control
tick only tracks the current local plan (bounded work, whatever the plan's length) and takes
over the next one when the robot reaches its waypoint. With nothing safe to follow (not refined
yet, or blocked) the command is zero velocity.

A map's cost J, DD model and local costmap are built, and each scan is fused into the local
costmap and the prepared plans re-judged, on two more worker threads (ecahd_core.worker; the
newest map or scan wins over one still waiting), so neither a 2000 x 2000 map nor a scan
fusion on it holds the control timer back.

With ``dd_enabled`` false ("ECAHD w/o DD" of Table III, and the baselines' "no local planner")
J is still evaluated on each straight plan (the timing records keep c_before), DD never runs and
no DD model is loaded; the exact check still applies.

Controller (every 1 / control_rate s of ``control_clock``: steady wall time by default, as
Nav2's controller_server; the tick reads the node's clock, sim time with use_sim_time): pure
pursuit within max_v, max_w and max_accel. Zero velocity with no plan, odometry older than
``stale_timeout`` (or a plan older than ``plan_timeout`` when that is > 0), and once the goal
(the plan's last point) is within ``goal_tolerance`` and, when the plan's last pose has an
orientation (the goal's heading; all zeros: any), the robot has turned in place to it within
``yaw_goal_tolerance`` (not where turning would sweep the footprint into a wall: then a warning);
the plan is then dropped until a new one arrives.

Every message is validated before it changes state: a plan in another frame, with non-finite or
off-map poses or more than 100 000 poses, NaN odometry, a malformed map: one error line, the
message is dropped, the node keeps running (and keeps the last valid plan).

Parameters: see :data:`PARAMETERS` (``max_v``, ``max_w``, ``max_accel``, ``lookahead``,
``waypoint_tolerance``, ``goal_tolerance``, ``stale_timeout`` and ``plan_timeout`` can be changed
at run time; the rest are read-only).

Subscribes:
    plan (nav_msgs/Path; reliable, transient_local, depth 1): the global plan, frame
        ``global_frame``; an empty path stops the robot; the last pose's orientation is the
        goal's heading (all zeros: any).
    odom (nav_msgs/Odometry; reliable, depth 10): the robot's pose, in ``global_frame`` or in a
        frame /tf joins to it (REP-105's odom: ``transform_tolerance``).
    /tf, /tf_static (tf2_msgs/TFMessage): map -> odom from the localisation, base_link ->
        the scanner (scans are placed by it; scan_offset_* where tf does not say).
    scan (sensor_msgs/LaserScan; sensor data QoS; with ``use_scan``): fused into the local
        costmap and the collision monitor.
    map (nav_msgs/OccupancyGrid; reliable, transient_local, depth 1): builds J's cost map and
        loads the DD model (in its own callback group: control goes on meanwhile); without a
        map the straight local plans are followed unchecked.
Publishes:
    /diagnostics (diagnostic_msgs/DiagnosticArray; every second): this node's health
        (``ecahd_ros.diagnostics``); inputs stamped by another clock are also said in the log.
    cmd_vel (geometry_msgs/Twist, or TwistStamped with ``enable_stamped_cmd_vel``; reliable,
        depth 10) at ``control_rate``.
    local_plan (nav_msgs/Path; reliable, depth 1): the dense local plan being followed.
    local_plan_footprints (visualization_msgs/MarkerArray; reliable, depth 1): the footprint
        outline at each local plan point (blue; red when the segment is blocked).
    ecahd/timing (std_msgs/String; reliable, depth 10): JSON {"stage": "j_check" | "dd", "ms",
        "c_before", "c_after", "safe", "stamp"} per segment ("dd" when DD ran; ms = the local
        stage on the worker), and {"stage": "control", "ms", "reason", "monitor",
        "map_ready", "wall", "stamp"} after every control tick (``wall``: time.time() [s] at
        publishing, for the inter-publish jitter; ``monitor``: none / slowdown / stop /
        yield): the tick's wall time (``ecahd eval-bag`` reports its p50 / p99 apart from
        inference time).
"""
from __future__ import annotations

import math
import threading
import time
from functools import partial

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Twist, TwistStamped
from nav_msgs.msg import OccupancyGrid, Odometry, Path
from sensor_msgs.msg import LaserScan
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.clock import Clock, ClockType
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from ecahd_core.collision_monitor import CollisionMonitor, MonitorResult
from ecahd_core.errors import EcahdError
from ecahd_core.frames import FrameError
from ecahd_core.model_zoo import learnt_map
from ecahd_core.planning.local import LocalRunner, SegmentResult, judge_items
from ecahd_core.planning.dense import DenseConfig, DenseStage
from ecahd_core.sensing import PoseHistory
from ecahd_core.worker import LatestWorker
from ecahd_ros.callbacks import check_frame, guard, now_seconds
from ecahd_ros.clock_check import StampCheck
from ecahd_ros.conversions import (footprint_markers, heading_of, layout_to_msg, msg_to_grid,
                                   path_to_xy, timing_message, xy_to_path)
from ecahd_ros.diagnostics import (DIAGNOSTICS_PERIOD, Latencies, RateMeter, diagnostic_array,
                                   node_status)
from ecahd_ros.lifecycle import ManagedNode
from ecahd_ros.local_refiner_params import DYNAMIC, PARAMETERS, LocalRefinerParams
from ecahd_ros.params import (collision_cost, declare_parameters, lanes_for, load_lanes, make_robot,
                              on_parameter_change, read_parameters)
from ecahd_ros.qos import MAP_QOS, PLAN_QOS, SCAN_QOS, STREAM_QOS, VIZ_QOS
from ecahd_ros.spin import spin_node
from ecahd_ros.tf_listener import TfListener, placed_odometry

POSE_HISTORY = 1.0  # [s] of odometry poses kept to place scans by their stamps
SCAN_POSE_WAIT = 0.2  # [s] a scan waits at most this long for the odometry of its stamp
SCAN_TOLERANCE = 1.0  # [s] a scan older than this is said to be stale (monitor off)


class LocalRefiner(ManagedNode):
    """The node: parameters in, plans, odometry and scans in, :class:`~ecahd_core.planning.
    local.LocalRunner` (segments refined ahead, the bounded control tick), cmd_vel out. A
    lifecycle node (``ecahd_ros.lifecycle``): configured and activated at start-up unless
    ``autostart`` is false; it drives only while active and stops the robot when deactivated."""

    def __init__(self, **kwargs) -> None:
        super().__init__("local_refiner", **kwargs)
        declare_parameters(self, PARAMETERS, dynamic=DYNAMIC)
        self.params: LocalRefinerParams | None = None  # once configured
        self.runner: LocalRunner | None = None
        on_parameter_change(self, PARAMETERS, lambda: self.params, self._apply_params)
        # configuration errors raise with autostart: spin_node exits non-zero with one line
        self.start(self.get_parameter("autostart").value)

    def configure(self) -> None:
        """Parameters, the model check, the runner, workers, topics and timers (lifecycle
        configure)."""
        self.params = read_parameters(self, PARAMETERS, LocalRefinerParams)
        p = self.params
        self.footprint = make_robot(p)
        self.judged = make_robot(p, margin=p.clearance_margin)  # what plans and commands clear
        if p.dd_enabled:  # an unreadable or mismatched model fails now, not at the first map
            from ecahd_core.model_zoo import check_model

            check_model("dd", p.map_name, path=p.dd_model or None, footprint=self.footprint)
        from ecahd_core.model_zoo import is_general

        # the segment-frame DD refines segments on any map: another extent is taken at once
        self._general = p.dd_enabled and is_general("dd", p.dd_model, p.map_name)
        self._lanes = load_lanes(p.lanes)  # an unreadable lane field fails now
        from ecahd_core.threads import set_torch_threads

        import torch

        set_torch_threads(p.torch_threads)
        self.generator = torch.Generator().manual_seed(p.seed)
        self.grid = None
        self._site = None  # the map the DD model was loaded for (updates of it keep it)
        self.map_changed = 0.0  # share of the map's cells changed since the model's map
        self.planner = None  # DenseStage (the local stage) once a map arrives
        self._lock = threading.Lock()  # the runner is shared by the callback threads
        self._world_lock = threading.Lock()  # the local costmap: scan worker vs publisher
        # long work off the executor thread (ecahd_core.worker): maps, scan fusion
        report = lambda exc: self.get_logger().error(str(exc))  # noqa: E731 (guard logs)
        self._map_worker = LatestWorker(guard(self, self._build_world), name="map",
                                        on_error=report, nice=p.worker_nice)
        self._scan_worker = LatestWorker(guard(self, self._fuse_scan), name="scan",
                                         on_error=report, nice=p.worker_nice)
        self.runner = LocalRunner(p.runner_config(), worker_nice=p.worker_nice)
        self._poses = PoseHistory(POSE_HISTORY)  # odometry by stamp, to place the scans
        # inputs stamped by another clock (a simulator's /clock without use_sim_time) are said
        self._stamps = StampCheck(self.get_parameter("use_sim_time").value)
        self._pending_scan = None  # (Scan, monotonic time) waiting for its stamp's odometry
        self._scan_frame = ""  # the scans' frame (placed on the base by tf when it knows it)
        self.tf = None  # TfListener: odometry in odom placed in global_frame through /tf
        self.world = None  # ecahd_core.sensing.LocalWorld once a map arrives (use_scan)
        self.refiner = None  # ecahd_core.planning.local.SegmentRefiner once a map arrives
        self.monitor = CollisionMonitor(self.footprint, p.monitor_config()) \
            if p.collision_monitor else None
        # the static guard: no command into the map's walls (a monitor without scan points)
        self.guard = CollisionMonitor(self.footprint, p.monitor_config())
        self._static = None  # StaticClearance of the current map (the guard's depths)
        self.counters = {"monitor_stop": 0, "monitor_slowdown": 0, "monitor_yield": 0,
                         "guard_stop": 0,
                         "blocked": 0,
                         "rechecks_invalidated": 0, "scans": 0, "scans_unsynced": 0}
        self._cmd_type = TwistStamped if p.enable_stamped_cmd_vel else Twist
        lifecycle = self.create_lifecycle_publisher
        self._cmd_pub = self.made(lifecycle(self._cmd_type, "cmd_vel", STREAM_QOS))
        self._local_pub = self.made(lifecycle(Path, "local_plan", VIZ_QOS))
        self._fp_pub = self.made(lifecycle(MarkerArray, "local_plan_footprints", VIZ_QOS))
        self._timing_pub = self.made(lifecycle(String, "ecahd/timing", STREAM_QOS))
        self._replan_pub = self.made(lifecycle(String, "ecahd/replan", STREAM_QOS))
        self._costmap_pub = self.made(lifecycle(OccupancyGrid, "local_costmap", VIZ_QOS))
        # health also while inactive
        self._diag_pub = self.made(self.create_publisher(DiagnosticArray, "/diagnostics",
                                                          STREAM_QOS))
        self._control_ms = Latencies()  # the last control ticks' wall times
        self._ticks = RateMeter()  # the control loop's measured rate
        self._map_time: float | None = None  # [s, node clock] when the map's world was built
        self._mismatches_seen = 0  # StampCheck.mismatches at the last /diagnostics
        inputs, maps = MutuallyExclusiveCallbackGroup(), MutuallyExclusiveCallbackGroup()
        control = MutuallyExclusiveCallbackGroup()
        self.made(self.create_subscription(Path, "plan", guard(self, self._on_plan), PLAN_QOS,
                                            callback_group=inputs))
        self.made(self.create_subscription(Odometry, "odom", guard(self, self._on_odom),
                                            STREAM_QOS, callback_group=inputs))
        self.tf = TfListener(self, callback_group=inputs)
        for sub in self.tf.subscriptions:
            self.made(sub)
        self.made(self.create_subscription(OccupancyGrid, "map", guard(self, self._on_map),
                                            MAP_QOS, callback_group=maps))
        # steady: the sim steps /clock by 1 / rate_hz (20 ms), so a 20 Hz timer on sim time
        # fires 40 or 60 ms apart; the robot's base wants commands evenly spaced
        clock = Clock(clock_type=ClockType.STEADY_TIME) if p.control_clock == "steady" else None
        self._timer = self.made(self.create_timer(
            1.0 / p.control_rate, guard(self, self._on_control), callback_group=control,
            clock=clock))
        if p.use_scan:
            sensing = MutuallyExclusiveCallbackGroup()
            self.made(self.create_subscription(LaserScan, "scan", guard(self, self._on_scan),
                                                SCAN_QOS, callback_group=sensing))
            self.made(self.create_timer(1.0 / p.local_costmap_rate,
                                         guard(self, self._publish_costmap),
                                         callback_group=sensing))
        self.made(self.create_timer(DIAGNOSTICS_PERIOD, guard(self, self._publish_diagnostics),
                                     callback_group=maps))
        self._last_reason = None
        dd = f"DD above c_th={p.c_th:g}" if p.dd_enabled else "DD disabled"
        self.get_logger().info(f"local refiner configured: {dd}, "
                               f"{p.control_rate:g} Hz, robot {self.footprint.name!r}")

    # reading the runner's state (tests, the demo)
    @property
    def waypoints(self):
        return self.runner.waypoints

    @property
    def dd_calls(self) -> int:
        return self.runner.dd_calls

    def _apply_params(self, params: LocalRefinerParams) -> None:
        with self._lock:
            self.params = params
            self.runner.config = params.runner_config()
            if self.monitor is not None:  # its slowdown cap follows max_v / max_w
                self.monitor = CollisionMonitor(self.footprint, params.monitor_config())
            self.guard = CollisionMonitor(self.footprint, params.monitor_config())
        self.get_logger().info("parameters updated")

    def _now(self) -> float:
        return now_seconds(self)

    # ------------------------------------------------------------------------- callbacks
    def _on_map(self, msg: OccupancyGrid) -> None:
        """Validate the map here; build its cost J, DD and local costmap on the map worker
        (seconds on a 2000 x 2000 map: the control timer keeps its rate meanwhile)."""
        p = self.params
        check_frame(msg.header.frame_id, p.global_frame, "map")
        self._map_worker.submit(msg_to_grid(msg, name=p.map_name))

    def _build_world(self, grid) -> None:
        """(map worker) Everything the local stage needs on ``grid``, swapped in at once."""
        from ecahd_core.model_zoo import load_dd
        from ecahd_core.planning.local import SegmentRefiner

        p = self.params
        # with a per-map model, an update of the site's map keeps it (MapError: another extent)
        learnt, changed = (learnt_map(self._site, grid) if p.dd_enabled and not self._general
                           else (grid, 0.0))
        ckpt = (load_dd(learnt, path=p.dd_model or None, footprint=self.footprint)
                if p.dd_enabled else None)
        cost = collision_cost(p, grid, self.footprint)
        # Algorithm 1's local stage, the offline planner's own (DenseStage)
        planner = DenseStage(
            ckpt, costmap=cost.costmap, footprint_points=cost.footprint_points,
            cost_config=cost.config,
            dense=DenseConfig(c_th=p.c_th, enabled=p.dd_enabled,
                              polish_steps=p.polish_steps))
        refiner = SegmentRefiner(planner, grid, self.judged,
                                 generator=self.generator, exact=p.exact_check,
                                 lanes=lanes_for(self._lanes, grid, self.get_logger()))
        from ecahd_core.sensing import StaticClearance

        world, static = None, StaticClearance(grid)
        if p.use_scan:
            from ecahd_core.sensing import LocalWorld

            world = LocalWorld(grid, cost, p.local_costmap_config(), offset=p.scan_offset,
                               mark_moving=p.mark_moving_obstacles,
                               shuttles=p.monitor_shuttles)
            static = world.static_clearance
        self._map_time = self._now()
        self._site, self.map_changed = learnt, changed
        if learnt is not grid and changed > p.map_change_warn:
            self.get_logger().warning(
                f"map updated: {100 * changed:.2f}% of its cells changed since the map the DD "
                f"model learnt (map_change_warn {100 * p.map_change_warn:g}%): J, DD's guidance "
                "and the exact checker use the new map; consider training again")
        with self._lock, self._world_lock:
            self.grid, self.planner, self.refiner, self.world = grid, planner, refiner, world
            self._static = static
            self.runner.refine = refiner
            self.runner.can_turn = refiner.can_turn  # turning in place to the goal's heading
            # precise tracking in tight places, by the static map (its distances are kept)
            self.runner.room = partial(static.room, footprint=self.footprint)
            self.runner.reset_costs()  # the current plan's segments are refined on this map
        self.get_logger().info(f"map {grid.name!r} received; "
                               f"{'DD model and ' if p.dd_enabled else ''}cost J ready, "
                               f"P^l={planner.dense.points}")

    def _on_plan(self, msg: Path) -> None:
        p = self.params
        check_frame(msg.header.frame_id, p.global_frame, "plan")
        xy = path_to_xy(msg)
        try:  # the last pose's orientation: the goal's heading (all zeros: any)
            yaw = heading_of(msg.poses[-1].pose.orientation) if msg.poses else None
        except EcahdError as exc:
            raise EcahdError(f"plan ignored: its last pose's {exc}") from None
        with self._lock:
            if len(xy) == 0:
                self.get_logger().info("empty plan: stopping")
            bounds = self.grid.bounds if self.grid is not None else None
            try:
                self.runner.set_plan(xy, self._now(), bounds, goal_yaw=yaw)
            except EcahdError as exc:
                raise EcahdError(f"plan ignored: {exc}") from None

    def _on_odom(self, msg: Odometry) -> None:
        p = self.params
        xyyaw = placed_odometry(self, msg, self.tf.buffer, p.global_frame, p.transform_tolerance)
        if xyyaw is None:
            return
        with self._lock:
            try:
                self.runner.set_pose(xyyaw, self._now())
            except EcahdError as exc:
                raise EcahdError(f"odometry ignored: {exc}") from None
        # the poses of the last second by their stamps: a scan is placed with the pose at its
        # own stamp, not the latest one the robot has moved on from
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        self._check_stamp("odometry", stamp, self.params.stale_timeout)
        self._poses.add(stamp, self.runner.pose)
        pending = self._pending_scan
        if pending is not None and (self._poses.covers(pending[0].stamp)
                                    or time.monotonic() - pending[1] > SCAN_POSE_WAIT):
            self._pending_scan = None
            self._submit_scan(pending[0])

    def _check_stamp(self, what: str, stamp: float, tolerance: float) -> None:
        """Warn (at most every few seconds) when ``what``'s stamp [s] disagrees with the node's
        clock by more than ``tolerance`` [s], naming the likely cause and the fix."""
        line = self._stamps.check(what, stamp, self._now(), tolerance)
        if line is not None:
            self.get_logger().warning(line)

    def _submit_scan(self, scan) -> None:
        """Fuse ``scan`` on the scan worker with the odometry pose at its stamp (interpolated;
        the newest pose when odometry never reached the stamp within SCAN_POSE_WAIT, counted
        as ``scans_unsynced``)."""
        if not self._poses.covers(scan.stamp):
            self.counters["scans_unsynced"] += 1
        pose = self._poses.at(scan.stamp) or self.runner.pose
        self._scan_worker.submit((pose, scan, self._mounting(self._scan_frame)))

    def _mounting(self, frame: str) -> tuple[float, float, float]:
        """The scanner's (x [m], y [m], yaw [rad]) on robot_base_frame: from /tf_static (or
        /tf) where the tree joins ``frame`` to the base, else the scan_offset_* parameters."""
        p = self.params
        try:
            return self.tf.buffer.lookup(p.robot_base_frame, frame).xy_yaw()
        except FrameError:
            return p.scan_offset

    def _on_scan(self, msg: LaserScan) -> None:
        """Validate the scan and place it with the odometry pose at its stamp here; fuse it
        on the scan worker (:meth:`_fuse_scan`)."""
        from ecahd_core.sensing import Scan

        if self.world is None or self.runner.pose is None:
            return
        self._scan_frame = msg.header.frame_id.lstrip("/")
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        try:
            scan = Scan(ranges=msg.ranges, angle_min=msg.angle_min,
                        angle_increment=msg.angle_increment, range_min=msg.range_min,
                        range_max=msg.range_max, stamp=stamp)
        except EcahdError as exc:
            raise EcahdError(f"scan ignored: {exc}") from None
        self._check_stamp("scan", stamp, self.params.monitor_source_timeout or SCAN_TOLERANCE)
        if self._poses.covers(stamp):
            self._submit_scan(scan)
        else:  # odometry of its stamp not here yet: wait for it (a newer scan replaces it)
            self._pending_scan = (scan, time.monotonic())

    def _fuse_scan(self, item) -> None:
        """(scan worker) Fuse a scan into the local costmap; re-judge the followed and prepared
        local plans on the fused map (a newly blocked one is refined again, guided by the
        fused J). A scan that waited while another was fused is dropped for the newer one."""
        pose, scan, offset = item
        with self._world_lock:
            world = self.world
            if world is None:
                return
            world.add_scan(pose, scan, offset)
            self.counters["scans"] += 1
            if not (self.params.scan_in_plans and world.stale):
                return
            grid, costmap = world.fused()
        with self._lock:
            if self.world is not world:  # a new map arrived meanwhile
                return
            self.refiner.set_world(grid, costmap)
            items = self.runner.recheck_items()
            judge = self.refiner.judge
        # the exact checker without the lock: the control tick never waits for it
        verdicts = judge_items(items, judge)
        with self._lock:
            if self.world is not world:
                return
            invalid = self.runner.apply_recheck(verdicts)
        if invalid:
            self.counters["rechecks_invalidated"] += invalid
            self.get_logger().info(f"scan: {invalid} local plan(s) now in collision with a "
                                   "scanned obstacle: refining again")

    def _publish_costmap(self) -> None:
        with self._world_lock:
            if self.world is None:
                return
            layout = self.world.window.to_occupancy(self.params.global_frame)
        self._costmap_pub.publish(layout_to_msg(layout, self.get_clock().now().to_msg()))

    def _on_control(self) -> None:
        """The control tick: the runner's bounded tick, cmd_vel, then what happened (while
        active)."""
        if not self.active:
            return
        t0 = time.perf_counter()
        now = self._now()
        with self._lock:
            cmd = self.runner.tick(now)
            events = self.runner.pop_events()
            pose = self.runner.pose
        v, w, action = cmd.v, cmd.w, "none"
        world = self.world
        seen = None if world is None else world.seen
        if self.monitor is not None and seen is not None and pose is not None:
            # the last line of defence, once scans flow
            guarded = self.monitor.filter(pose, v, w, seen.points, seen.stamp, now,
                                          velocities=seen.velocities, bounds=seen.bounds,
                                          depths=partial(world.depths, footprint=self.judged))
            v, w, action = guarded.v, guarded.w, guarded.action
            if action != "none":
                self.counters[f"monitor_{action}"] += 1
                self.runner.v = v  # the controller ramps up from what was really commanded
        static = self._static
        if static is not None and pose is not None and action not in ("stop", "yield"):
            v, w = self._keep_off_map(pose, v, w, static)
        self._publish_cmd(v, w)
        ms = (time.perf_counter() - t0) * 1e3
        self._control_ms.add(ms)
        self._ticks.tick()
        stamp = self.get_clock().now()
        for kind, what in events:
            self._on_event(kind, what, stamp)
        if cmd.reason != self._last_reason and cmd.reason in ("blocked", "goal_reached"):
            self.get_logger().info(f"control: {cmd.reason}")
        self._last_reason = cmd.reason
        self._timing_pub.publish(timing_message("control", ms, stamp.nanoseconds * 1e-9,
                                                reason=cmd.reason, monitor=action,
                                                map_ready=self.planner is not None,
                                                wall=time.time()))

    def _keep_off_map(self, pose, v: float, w: float, static) -> tuple[float, float]:
        """The static guard (``static_guard_horizon``): (v, w) unless, held, it would bring
        the real footprint into the map's walls; then the turn on the spot or a stop (counted,
        a throttled warning naming the command)."""
        guarded = self.guard.keep_off_map(
            pose, MonitorResult(v, w, "none", math.inf, ""),
            partial(static.depths, footprint=self.footprint),
            horizon=self.params.static_guard_horizon)
        if guarded.action == "none":
            return v, w
        self.counters["guard_stop"] += 1
        self.runner.v = guarded.v
        self.get_logger().warning(f"static guard at ({pose[0]:.2f}, {pose[1]:.2f}): "
                                  f"{guarded.reason}", throttle_duration_sec=2.0)
        return guarded.v, guarded.w

    def _on_event(self, kind: str, what, stamp) -> None:
        p = self.params
        if kind == "error":
            self.get_logger().error(what)
            return
        if kind == "goal_reached":
            self.get_logger().info("goal reached")
            return
        if kind == "heading_blocked":
            self.get_logger().warning(
                f"at the goal, {math.degrees(what):+.0f} deg from its heading: turning in place "
                "here would hit a wall; the goal ends at its position")
            return
        result: SegmentResult = what
        if kind == "blocked":
            self.counters["blocked"] += 1
            self.get_logger().warning(
                "segment blocked: its local plan (after DD and polishing) is in collision by "
                "the exact checker; stopped, asking global_planner for a new plan")
            import json

            x, y = (float(v) for v in result.plan[0])
            self._replan_pub.publish(String(data=json.dumps(
                {"reason": "blocked", "x": x, "y": y, "stamp": stamp.nanoseconds * 1e-9})))
        self._local_pub.publish(xy_to_path(result.plan, p.global_frame, stamp.to_msg()))
        self._fp_pub.publish(footprint_markers(self.footprint, result.plan, p.global_frame,
                                               stamp.to_msg(), colliding=not result.safe))
        if result.c_before is not None:
            self._timing_pub.publish(timing_message(
                result.stage, result.ms, stamp.nanoseconds * 1e-9, c_before=result.c_before,
                c_after=result.c_after, safe=result.safe))

    def _publish_cmd(self, v: float, w: float) -> None:
        msg = self._cmd_type()
        twist = msg.twist if isinstance(msg, TwistStamped) else msg
        twist.linear.x, twist.angular.z = float(v), float(w)
        if isinstance(msg, TwistStamped):
            msg.header.stamp = self.get_clock().now().to_msg()
            msg.header.frame_id = "base_link"
        self._cmd_pub.publish(msg)

    def on_deactivate(self, state):
        """Stop the robot (one zero velocity) before the publishers stop."""
        if self.active and self.runner is not None:
            self._publish_cmd(0.0, 0.0)
        return super().on_deactivate(state)

    def release(self) -> None:
        """Undo :meth:`configure` (lifecycle cleanup and shutdown): workers stopped, topics and
        timers destroyed."""
        if self.runner is not None:
            self._map_worker.close()
            self._scan_worker.close()
            self.runner.close()
        self.destroy_made()
        self.runner = self.params = self.tf = self.world = self.planner = self.grid = None
        self._site = None

    def destroy_node(self) -> None:
        self.release()
        super().destroy_node()


    def _publish_diagnostics(self) -> None:
        """This node's health on /diagnostics: map and DD, the control loop's rate and tick
        latency, the collision monitor's actions, inputs from another clock."""
        p, c = self.params, self.counters
        rate = self._ticks.rate()
        waypoints = self.runner.waypoints
        values = {
            "map": self.grid.name if self.grid is not None else "none",
            "map_age_s": self._now() - self._map_time if self._map_time is not None else math.nan,
            "map_changed_share": self.map_changed,
            "dd": ("ready" if self.planner is not None and self.planner.dd is not None
                   else "disabled" if not p.dd_enabled else "loading"),
            "plan_points": 0 if waypoints is None else len(waypoints),
            "waypoints_passed": self.runner.waypoints_passed,
            "control_rate_hz": rate, "control_rate_target_hz": p.control_rate,
            "control_ms_p50": self._control_ms.quantile(0.5),
            "control_ms_p99": self._control_ms.quantile(0.99), "dd_calls": self.dd_calls,
            "monitor_stops": c["monitor_stop"], "monitor_slowdowns": c["monitor_slowdown"],
            "monitor_yields": c["monitor_yield"], "guard_stops": c["guard_stop"],
            "precise_ticks": self.runner.precise_ticks, "scans": c["scans"],
            "stamps_from_another_clock": self._stamps.mismatches,
            "stale_stamps": self._stamps.stale}
        mismatched = self._stamps.mismatches > self._mismatches_seen
        self._mismatches_seen = self._stamps.mismatches
        if not self.active:
            level, message = "warn", "inactive (lifecycle): not driving"
        elif self.grid is None:
            level, message = "warn", "waiting for a map"
        elif mismatched:
            level, message = "warn", ("inputs stamped by another clock (use_sim_time?): see the "
                                      "log")
        elif len(self._control_ms) >= 10 and rate < 0.8 * p.control_rate:
            level, message = "warn", f"control loop at {rate:.1f} Hz of {p.control_rate:g}"
        else:
            level, message = "ok", "following a plan" if waypoints is not None else "ready"
        self._diag_pub.publish(diagnostic_array(
            [node_status("local_refiner", level, message, values)],
            self.get_clock().now().to_msg()))

def main(args=None) -> None:
    # one executor thread: the local stage has its own worker (see ecahd_ros.spin)
    spin_node(LocalRefiner, args, name="local_refiner")


if __name__ == "__main__":
    main()
