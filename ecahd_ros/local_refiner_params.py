"""local_refiner's parameters, each declared once (:data:`PARAMETERS`: name, default, from the
core config it sets where there is one, and description; :data:`DYNAMIC`: those settable at run
time) and read into :class:`LocalRefinerParams`, which validates them and hands the core its
configs. ``config/ecahd.yaml`` and docs/parameters.md are rendered from them (``ecahd config``)."""
from __future__ import annotations

from ecahd_core.collision_monitor import SLOWDOWN_PROFILES, CollisionMonitorConfig
from ecahd_core.planning.local import LocalRunnerConfig
from ecahd_core.planning.dense import DenseConfig
from ecahd_ros.params import (ParamSpec, parameters_dataclass, require, require_cost_margin,
                              require_non_negative, require_positive, shared)


# the monitor's defaults live in CollisionMonitorConfig (one home for each)
_MONITOR = CollisionMonitorConfig()

PARAMETERS = [
    *shared("dd_model", "map_change_warn", "lanes"),
    *shared("map_name", "robot", "footprint", "footprint_padding", "global_frame",
            "transform_tolerance", "clearance_margin", "cost_margin"),
    ParamSpec("c_th", DenseConfig().c_th, "DD refines a local plan whose collision cost c^l "
                                          "exceeds this"),
    ParamSpec("dd_enabled", True, "run Dense Diffusion at all; false: follow the straight local "
                                  "plans (ECAHD w/o DD; J still checked for the diagnostics)"),
    ParamSpec("polish_steps", DenseConfig().polish_steps,
              "J-descent steps on a DD local plan still above c_th (ours); 0 = the paper"),
    ParamSpec("exact_check", True, "never follow a local plan the exact checker finds in "
                                   "collision (ours); false: the paper's ablations (ECAHD w/o "
                                   "DD, FD without a local planner) drive straight segments "
                                   "into walls"),
    ParamSpec("control_rate", 20.0, "[Hz] cmd_vel rate (Nav2's controller_frequency default)"),
    ParamSpec("control_clock", "steady", "clock of the control timer: 'steady' (monotonic wall "
                                         "time, as Nav2's controller_server loop: ticks stay "
                                         "evenly spaced however /clock arrives) or 'ros' (the "
                                         "node's clock, /clock with use_sim_time: for a "
                                         "simulation running faster or slower than real "
                                         "time). Either way the controller reads the node's "
                                         "clock"),
    ParamSpec("prepare_ahead", 2, "segments refined ahead of the one being followed"),
    ParamSpec("worker_nice", 0, "nice increment of the worker threads (local stage, scan "
                                "fusion, map), so that their work yields the CPU to the control "
                                "timer; 0 = the process's priority (5 changed no closed-loop "
                                "figure, docs/RESULTS.md)"),
    ParamSpec("max_v", 0.5, "[m/s] limit on |linear velocity| (dynamic)"),
    ParamSpec("max_w", 1.5, "[rad/s] limit on |angular velocity| (dynamic)"),
    ParamSpec("max_accel", 1.0, "[m/s^2] limit on |linear acceleration| (dynamic)"),
    ParamSpec("lookahead", 0.25, "[m] pure-pursuit lookahead distance (0.4 cut corners: 3.7% "
                                 "of sim steps in wall contact over 5 demo episodes, 0.25: 0%; "
                                 "dynamic)"),
    ParamSpec("waypoint_tolerance", 0.3, "[m] reaching a waypoint this close starts the next "
                                         "segment (dynamic)"),
    ParamSpec("precise_room", 0.05, "[m] precise tracking: where the robot, or the waypoint it "
                                   "heads for, has less room than this beside its footprint "
                                   "(a door a little wider than the robot), pure pursuit uses "
                                   "precise_lookahead and precise_waypoint_tolerance, so a "
                                   "sharp turn before a tight door does not swing wide into "
                                   "its jamb; 0 = off (dynamic)"),
    ParamSpec("precise_lookahead", 0.1, "[m] pure pursuit's lookahead in tight places "
                                        "(precise_room; dynamic)"),
    ParamSpec("precise_waypoint_tolerance", 0.15, "[m] waypoint_tolerance in tight places "
                                                  "(precise_room; dynamic)"),
    ParamSpec("goal_tolerance", 0.25, "[m] the goal (last plan point) counts as reached "
                                      "(dynamic)"),
    ParamSpec("stale_timeout", 1.0, "[s] odometry older than this stops the robot (dynamic)"),
    ParamSpec("plan_timeout", 0.0, "[s] a plan older than this stops the robot; 0 = never "
                                   "(dynamic)"),
    ParamSpec("enable_stamped_cmd_vel", False, "publish geometry_msgs/TwistStamped on cmd_vel"),
    ParamSpec("use_scan", True, "fuse 'scan' into a rolling local costmap that J and the exact "
                                "check read (obstacles not on the map)"),
    ParamSpec("scan_in_plans", True, "the local costmap feeds J and the exact check (false: "
                                     "scans reach only the collision monitor)"),
    ParamSpec("local_costmap_size", 6.0, "[m] side of the rolling local costmap window"),
    ParamSpec("obstacle_persistence", 2.0, "[s] a scanned obstacle not seen again for this long "
                                           "is forgotten; 0 = until a ray clears it"),
    ParamSpec("local_costmap_rate", 2.0, "[Hz] publishing rate of 'local_costmap'"),
    ParamSpec("mark_moving_obstacles", False, "returns on obstacles the tracker sees moving "
                                              "mark the local costmap too (false: they only "
                                              "clear, and the collision monitor judges them "
                                              "by their predicted motion, so a person crossing "
                                              "a corridor does not block the plan through it)"),
    *shared("scan_offset_x", "scan_offset_y", "scan_offset_yaw"),
    ParamSpec("robot_base_frame", "base_link", "the robot's base frame (Nav2's name): scans are "
                                               "placed on it by the tf of their own frame "
                                               "(/tf_static), the scan_offset_* parameters "
                                               "where tf does not join them"),
    ParamSpec("collision_monitor", True, "stop / slow down any cmd_vel whose footprint, swept "
                                         "over monitor_time_to_collision, hits a scan point "
                                         "that is not on the static map"),
    ParamSpec("static_guard_horizon", 0.5, "[s] every cmd_vel, held this long, must keep the "
                                           "robot's footprint off the map's walls (nor deeper "
                                           "into them than now), else the robot turns on the "
                                           "spot if that is clear, or stops; with or without "
                                           "scans; 0 = off"),
    ParamSpec("monitor_time_to_collision", _MONITOR.time_to_collision, "[s] horizon of the collision monitor"),
    ParamSpec("monitor_stop_margin", _MONITOR.stop_margin, "[m] footprint growth that stops the robot"),
    ParamSpec("monitor_slowdown_margin", _MONITOR.slowdown_margin, "[m] footprint growth that slows the robot down"),
    ParamSpec("monitor_slowdown_ratio", _MONITOR.slowdown_ratio, "slowing down caps |v| and |w| at this times "
                                             "max_v and max_w (at the stop margin with the "
                                             "linear profile)"),
    ParamSpec("monitor_slowdown_profile", _MONITOR.slowdown_profile, "'linear': the slowdown's ratio rises "
                                                    "from monitor_slowdown_ratio at the stop "
                                                    "margin to 1 at the slowdown margin with "
                                                    "the obstacle's least clearance; 'step': "
                                                    "monitor_slowdown_ratio whenever within "
                                                    "the margin (Nav2)"),
    ParamSpec("monitor_source_timeout", _MONITOR.source_timeout, "[s] scans older than this (after the first) stop "
                                             "the robot"),
    ParamSpec("monitor_yield", True, "when the monitor stops the robot where a moving obstacle "
                                     "(tracked from the scans) would hit it, drive the escape "
                                     "command that stays clear longest (static map checked)"),
    ParamSpec("monitor_yield_horizon", _MONITOR.yield_horizon, "[s] how far ahead moving obstacles are predicted "
                                            "for yielding"),
    ParamSpec("monitor_prediction_growth", _MONITOR.prediction_growth, "[m/s] a moving obstacle predicted t s ahead "
                                                "counts as this times min(t, "
                                                "monitor_time_to_collision) closer (its "
                                                "velocity is an estimate); 0 trusts it"),
    ParamSpec("monitor_shuttles", True, "movers seen going back and forth are predicted "
                                        "turning round at the ends of their stretch (false: "
                                        "straight on; moving-contact episodes 2 of 20 with, "
                                        "6-10 without, docs/RESULTS.md)"),
    ParamSpec("monitor_beat_horizon", 0.0, "[s] with monitor_shuttles: a command that meets a "
                                           "mover going back and forth within this horizon "
                                           "is stopped (the robot does not start across its "
                                           "beat); 0 = off (3 s: the robot waited for "
                                           "crossers, 10 of 20 reached against 14)"),
    *shared("yaw_goal_tolerance", "seed", "torch_threads", "autostart"),
]
CONTROL_CLOCKS = ("steady", "ros")
DYNAMIC = ("max_v", "max_w", "max_accel", "lookahead", "waypoint_tolerance", "goal_tolerance",
           "precise_room", "precise_lookahead", "precise_waypoint_tolerance",
           "yaw_goal_tolerance", "stale_timeout", "plan_timeout")


@parameters_dataclass(PARAMETERS)
class LocalRefinerParams:
    """The node's validated parameters (see :data:`PARAMETERS` for units)."""

    def __post_init__(self) -> None:
        require_positive(self, "control_rate", "max_v", "max_w", "max_accel", "lookahead",
                         "waypoint_tolerance", "goal_tolerance", "yaw_goal_tolerance",
                         "precise_lookahead", "precise_waypoint_tolerance",
                         "stale_timeout", "torch_threads")
        require_cost_margin(self)
        require_non_negative(self, "c_th", "footprint_padding", "plan_timeout", "seed",
                             "transform_tolerance",
                             "clearance_margin", "precise_room",
                             "polish_steps", "prepare_ahead", "obstacle_persistence",
                             "monitor_prediction_growth", "monitor_beat_horizon",
                             "static_guard_horizon")
        require_positive(self, "local_costmap_size", "local_costmap_rate",
                         "monitor_time_to_collision", "monitor_source_timeout",
                         "monitor_yield_horizon")
        require(self.control_clock in CONTROL_CLOCKS, "control_clock", self.control_clock,
                f"one of {list(CONTROL_CLOCKS)}")
        require(0 <= self.worker_nice <= 19, "worker_nice", self.worker_nice, "in 0..19")
        require(0 < self.monitor_slowdown_ratio <= 1, "monitor_slowdown_ratio",
                self.monitor_slowdown_ratio, "in (0, 1]")
        require(self.monitor_slowdown_profile in SLOWDOWN_PROFILES, "monitor_slowdown_profile",
                self.monitor_slowdown_profile, f"one of {list(SLOWDOWN_PROFILES)}")
        require(0 <= self.monitor_stop_margin <= self.monitor_slowdown_margin,
                "monitor_stop_margin", self.monitor_stop_margin,
                ">= 0 and <= monitor_slowdown_margin")
        require(bool(self.global_frame), "global_frame", self.global_frame, "non-empty")
        require(bool(self.robot_base_frame), "robot_base_frame", self.robot_base_frame,
                "non-empty")

    def runner_config(self) -> LocalRunnerConfig:
        return LocalRunnerConfig(
            control_period=1.0 / self.control_rate, max_v=self.max_v, max_w=self.max_w,
            max_accel=self.max_accel, lookahead=self.lookahead,
            waypoint_tolerance=self.waypoint_tolerance, goal_tolerance=self.goal_tolerance,
            yaw_goal_tolerance=self.yaw_goal_tolerance, stale_timeout=self.stale_timeout, plan_timeout=self.plan_timeout,
            prepare_ahead=self.prepare_ahead, precise_room=self.precise_room,
            precise_lookahead=self.precise_lookahead,
            precise_tolerance=self.precise_waypoint_tolerance)

    def local_costmap_config(self):
        from ecahd_core.local_costmap import LocalCostmapConfig

        return LocalCostmapConfig(size=self.local_costmap_size,
                                  persistence=self.obstacle_persistence)

    def monitor_config(self):
        from ecahd_core.collision_monitor import CollisionMonitorConfig

        return CollisionMonitorConfig(
            time_to_collision=self.monitor_time_to_collision,
            stop_margin=self.monitor_stop_margin, slowdown_margin=self.monitor_slowdown_margin,
            slowdown_ratio=self.monitor_slowdown_ratio,
            slowdown_profile=self.monitor_slowdown_profile,
            source_timeout=self.monitor_source_timeout,
            # the controller ramps from the command sent: cap, do not scale again each tick
            slowdown_limits=(self.max_v, self.max_w),
            escape_limits=(self.max_v, self.max_w) if self.monitor_yield else None,
            yield_horizon=self.monitor_yield_horizon,
            prediction_growth=self.monitor_prediction_growth,
            beat_horizon=self.monitor_beat_horizon)

    @property
    def scan_offset(self) -> tuple[float, float, float]:
        return self.scan_offset_x, self.scan_offset_y, self.scan_offset_yaw
