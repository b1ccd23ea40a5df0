"""global_planner: ECAHD's Sparse Diffusion global planner as a node (paper Sec. III-A,
Algorithm 1 lines 2-11 with its shrinking horizon), and the Table III baselines' global planners.

A goal becomes a plan here. The node is a thin shell over
:class:`ecahd_core.navigation.GlobalRunner` (when to plan, unit-tested without ROS). With
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

Parameters (read-only, declared in :data:`PARAMETERS`):
    method (str, "sd"): the global planner, one of METHODS ("sd", "astar", "fd").
    sd_model (str, ""): SD checkpoint path; "" = the shipped model for ``map_name``.
    fd_model (str, ""), fd_guidance (bool, false): the FD checkpoint ("" = shipped) and whether
        J guides it (method "fd").
    map_name (str, "maze2d-large"): the map's identity (an OccupancyGrid has no name); the
        checkpoint must have been trained for this name and the received grid's fingerprint.
    num_candidates (int, 10): N, candidates sampled in one batch.
    horizon (int, 10): P^g, waypoints of the first global plan.
    ddim_steps (int, 0): DDIM steps of SD or FD; 0 = the checkpoint's.
    epsilon (double, 1.0): [m] goal-reaching radius of the selection rule.
    selection (str, "collision_aware"): collision_aware (J weighs the candidates, as the paper's
        Table III runs do) or shortest_reaching (Sec. III-A's rule).
    robot (str, "circle"), footprint (str, ""), footprint_padding (double, 0.0 m): the robot.
    global_frame (str, "map"): frame of goals and plans.
    waypoint_tolerance (double, 0.3): [m] distance to the next waypoint that triggers a replan
        (sd); distance to the goal that ends it (all methods).
    replan (str, "every_waypoint"): sd: Algorithm 1's replanning at each waypoint, or "once".
    subgoals (bool, true), settle (bool, true): sd, every_waypoint, on maps where re-plans have
        a replan spacing and the free-first-leg rule acts (building maps): the subgoal rule (a
        re-plan past P^g - 1 waypoints whose first leg makes no progress by the goal's
        cost-to-go over the static map plans toward a point on the shortest route; the
        cost-to-go's graph is built when the map arrives) and the settle rule (a plan whose
        every straight leg is free by the leg test on the map and the remembered obstacles is
        followed whole: no re-plan at its waypoints; a plan toward a subgoal whose legs up to
        the subgoal are free, to the subgoal; timeout and blocked re-plans still act).
        As ``HierarchicalPlanner``'s ``subgoals`` and ``settle`` in ``ecahd bench planning``.
    replan_timeout (double, 5.0): [s] no progress toward the next waypoint (reaching it, or
        coming 0.25 m nearer it than before) for this long replans (sd); 0 = never.
        Doubles with each further such replan (at most 8x) until the robot progresses again.
    warm_fraction (double, 0.0): sd, every_waypoint: the re-plan at a reached waypoint starts
        from the rest of the current plan noised to where the last ``warm_fraction`` (0..1) of
        SD's DDIM schedule begins and runs only those steps (``SparseConfig.warm_fraction``,
        ours); 0 = from noise, Algorithm 1 as written. A goal's first plan, timeout and
        blocked re-plans always sample from noise.
    seed (int, 0): seed of the sampler's torch.Generator (a seed reproduces a plan sequence).
    torch_threads (int, 1): torch.set_num_threads.
    inference_precision (str, "auto"): fp32, bf16, or auto (bf16 where the CPU has native
        bfloat16): the SD Transformer's encoder layers (``SamplerConfig.precision``).
    nice (int, 0): the nice value of the thread that spins the node (and plans) is raised by
        this much at start-up, so that planning yields the CPU to the controller on a busy
        computer.
A parameter out of range, an unknown robot or an unreadable model ends the node at start-up
with one error line and exit code 1 (``ecahd_ros.spin``).

Subscribes:
    map (nav_msgs/OccupancyGrid; reliable, transient_local, depth 1): rebuilds the planner and
        replans when a goal is active.
    goal_pose (geometry_msgs/PoseStamped; reliable, depth 10): frame must be ``global_frame``;
        finite, on the map and free, else logged and ignored (the current plan stays). A new
        goal pre-empts the current one; a goal before map and odometry is queued.
    odom (nav_msgs/Odometry; reliable, depth 10): the robot's pose in ``global_frame``;
        non-finite or absurd poses are logged and ignored.
Publishes:
    plan (nav_msgs/Path; reliable, transient_local, depth 1): the selected sparse waypoints
        (sd) or the whole path (astar, fd), first = robot pose, last = the goal exactly.
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
import time
from dataclasses import dataclass

import numpy as np
from geometry_msgs.msg import Point, PoseStamped
from nav_msgs.msg import OccupancyGrid, Odometry, Path
from rclpy.node import Node
from std_msgs.msg import String
from visualization_msgs.msg import Marker, MarkerArray

from ecahd_core.errors import EcahdError, PlanningError
from ecahd_core.navigation import (REPLAN_POLICIES, SNAP_DISTANCE, GlobalRunner,
                                   GlobalRunnerConfig, PlanRequest, validate_pose)
from ecahd_core.placement import LEG_BATCHES
from ecahd_core.planner import SELECTION_RULES, SparseConfig, SparseDiffusion, SparsePlan
from ecahd_core.threads import PRECISION_CHOICES
from ecahd_ros.conversions import msg_to_grid, timing_message, xy_to_path
from ecahd_ros.params import (ParamSpec, collision_cost, declare_parameters, make_robot,
                              read_parameters, require, require_cost_margin,
                              require_non_negative, require_positive, shared)
from ecahd_ros.qos import MAP_QOS, PLAN_QOS, STREAM_QOS, VIZ_QOS
from ecahd_ros.spin import spin_node

METHODS = ("sd", "astar", "fd")  # ECAHD's Sparse Diffusion; the Table III baselines' planners
ASTAR_SPACING = 0.25  # [m] most distance between consecutive points of a published A* path

PARAMETERS = [
    ParamSpec("method", "sd", f"global planner: {list(METHODS)} (sd: ECAHD, replanned at each "
                              "waypoint; astar, fd: one whole path per goal)"),
    ParamSpec("sd_model", "", "SD checkpoint path; '' = the shipped model for map_name"),
    ParamSpec("fd_model", "", "FD checkpoint path (method fd); '' = the shipped model"),
    ParamSpec("fd_guidance", False, "method fd: guide the Full Diffusion sample by J"),
    *shared("map_name"),
    ParamSpec("num_candidates", 10, "N, candidate global plans sampled in one batch"),
    ParamSpec("horizon", 10, "P^g, waypoints of the first global plan"),
    ParamSpec("max_spacing", 0.0, "[m] sd: waypoint spacing by distance, legs of a plan longer "
                                  "than this re-sampled by SD between their ends (for big "
                                  "maps); 0 = off (the paper's fixed P^g)"),
    ParamSpec("place_reach", -1.0, "[m] sd: SD's waypoints that lie in a wall (map + remembered "
                                   "obstacles) move into free space at most this far, and legs "
                                   "crossing a wall get a placed midpoint (leg_repair); -1 = by "
                                   "the map: 1.0 on maps over 50 000 cells, else off; off (or "
                                   "<= 0.2): waypoints and the goal move at most 0.2 m"),
    ParamSpec("leg_repair", 3, "sd: rounds of leg repair while place_reach is on (> 0.2 m); "
                               "0 = off"),
    ParamSpec("repair_reach", -1.0, "[m] sd: leg repair looks this far from a leg's middle for "
                                    "its new waypoint (at most half the leg); -1 = the larger "
                                    "of place_reach and 3.0"),
    ParamSpec("leg_batches", LEG_BATCHES, "sd, every_waypoint, with place_reach on: when the "
                                          "chosen candidate's first leg still crosses a wall "
                                          "after leg repair, the first of the other candidates "
                                          "whose first leg does not, else up to this many more "
                                          "batches of N (one waypoint more each); 0 = the "
                                          "other candidates only; -1 = off"),
    ParamSpec("ddim_steps", 0, "DDIM steps of SD or FD; 0 = the checkpoint's"),
    ParamSpec("epsilon", 1.0, "[m] goal-reaching radius of the best-of-N rule"),
    ParamSpec("selection", "collision_aware", f"best-of-N rule: {list(SELECTION_RULES)} "
                                              "(shortest_reaching: Sec. III-A's)"),
    *shared("robot", "footprint", "footprint_padding", "global_frame", "clearance_margin",
            "cost_margin"),
    ParamSpec("waypoint_tolerance", 0.3, "[m] reaching the next waypoint this close replans "
                                         "with horizon P^g - p (sd); the goal this close is "
                                         "reached"),
    ParamSpec("replan", "every_waypoint", f"sd: {list(REPLAN_POLICIES)} (every_waypoint: "
                                          "Algorithm 1; once: one SD plan per goal)"),
    ParamSpec("replan_spacing", -1.0, "[m] sd, every_waypoint: each re-plan keeps at least "
                                      "ceil(D / this) + 1 waypoints (at most P^g) for the "
                                      "straight distance D left to the goal, instead of "
                                      "Algorithm 1's P^g - p, whose last plan is a straight "
                                      "line to the goal wherever the robot is; -1 = by the "
                                      "map and model: on maps over 50 000 cells the SD "
                                      "model's expert waypoint spacing, at least 3.0, else "
                                      "off; 0 = off"),
    ParamSpec("subgoals", True, "sd, every_waypoint, with a replan spacing and the free-first-"
                                "leg rule on (building maps): a re-plan past P^g - 1 waypoints "
                                "whose first leg makes no progress by the goal's cost-to-go "
                                "plans toward a point on the shortest route (the subgoal rule, "
                                "ecahd_core.progress.SubgoalRule)"),
    ParamSpec("settle", True, "sd, every_waypoint, with a replan spacing and the free-first-leg "
                              "rule on (building maps): a plan whose every straight leg is free "
                              "by the leg test is followed whole, not re-planned at each "
                              "waypoint, and a plan toward a subgoal whose legs up to it are "
                              "free is followed to the subgoal (the settle rule)"),
    ParamSpec("replan_timeout", 5.0, "[s] sd: with no progress toward the next waypoint (reaching "
                                     "it, or coming 0.25 m nearer it than before) for this long, "
                                     "replan from the current pose (same horizon); doubles with "
                                     "each further such replan (at most 8x) until the robot "
                                     "progresses again; 0 = never"),
    ParamSpec("warm_fraction", 0.0, "sd, every_waypoint: a re-plan at a reached waypoint starts "
                                    "from the rest of the current plan noised to the last F "
                                    "(0..1) of SD's DDIM schedule; 0 = from noise (Algorithm 1 "
                                    "as written; 0.3 took Algorithm 1 on maze2d-large from 177 "
                                    "to 115 ms per problem, docs/RESULTS.md)"),
    ParamSpec("obstacle_memory", 60.0, "[s] obstacles the local costmap found are avoided "
                                       "by re-plans for this long unless seen gone"),
    ParamSpec("inference_precision", "auto", f"sd: the SD Transformer computes in one of "
                                             f"{list(PRECISION_CHOICES)} (auto: bf16 where the "
                                             f"CPU has native bfloat16, AVX512-BF16 or AMX)"),
    ParamSpec("nice", 0, "nice increment of the thread that plans, so that planning yields "
                         "the CPU to the controller on a busy computer; 0 = unchanged (5 "
                         "changed no closed-loop figure, docs/RESULTS.md)"),
    *shared("seed", "torch_threads"),
]


@dataclass(frozen=True, kw_only=True)
class GlobalPlannerParams:
    """The node's validated parameters (see the module docstring for units)."""

    method: str
    sd_model: str
    fd_model: str
    fd_guidance: bool
    map_name: str
    num_candidates: int
    horizon: int
    max_spacing: float
    place_reach: float
    leg_repair: int
    repair_reach: float
    leg_batches: int
    ddim_steps: int
    epsilon: float
    selection: str
    robot: str
    footprint: str
    footprint_padding: float
    global_frame: str
    clearance_margin: float
    cost_margin: float
    waypoint_tolerance: float
    replan: str
    replan_spacing: float
    subgoals: bool
    settle: bool
    replan_timeout: float
    warm_fraction: float
    obstacle_memory: float
    seed: int
    torch_threads: int
    inference_precision: str
    nice: int

    def __post_init__(self) -> None:
        require_positive(self, "num_candidates", "epsilon", "waypoint_tolerance",
                         "torch_threads")
        require(0 <= self.nice <= 19, "nice", self.nice, "in 0..19")
        require(self.inference_precision in PRECISION_CHOICES, "inference_precision",
                self.inference_precision, f"one of {list(PRECISION_CHOICES)}")
        require_non_negative(self, "ddim_steps", "footprint_padding", "seed", "replan_timeout",
                             "obstacle_memory", "clearance_margin", "max_spacing", "leg_repair")
        require_cost_margin(self)
        require(self.repair_reach > 0 or self.repair_reach == -1, "repair_reach",
                self.repair_reach, "> 0 m, or -1 (the larger of place_reach and 3.0)")
        require(self.leg_batches >= -1, "leg_batches", self.leg_batches, ">= -1 (-1: off)")
        require(self.place_reach >= 0 or self.place_reach == -1, "place_reach",
                self.place_reach, ">= 0 m, or -1 (by the map's size)")
        require(self.replan_spacing >= 0 or self.replan_spacing == -1, "replan_spacing",
                self.replan_spacing, ">= 0 m, or -1 (by the map's size)")
        require(self.method in METHODS, "method", self.method, f"one of {list(METHODS)}")
        require(self.horizon >= 2, "horizon", self.horizon, ">= 2")
        require(self.selection in SELECTION_RULES, "selection", self.selection,
                f"one of {list(SELECTION_RULES)}")
        require(bool(self.global_frame), "global_frame", self.global_frame, "non-empty")
        require(bool(self.map_name), "map_name", self.map_name, "non-empty")
        require(self.replan in REPLAN_POLICIES, "replan", self.replan,
                f"one of {list(REPLAN_POLICIES)}")
        require(0.0 <= self.warm_fraction <= 1.0, "warm_fraction", self.warm_fraction,
                "in 0..1 (0: off)")

    def runner_config(self, grid=None, expert_spacing: float | None = None
                      ) -> GlobalRunnerConfig:
        """The runner's settings; ``replan_spacing`` -1 is decided by ``grid`` and the SD
        model's ``expert_spacing`` [m] (off without a grid, before the map arrives)."""
        from ecahd_core.navigation import auto_replan_spacing

        spacing = self.replan_spacing or None
        if spacing == -1:
            spacing = auto_replan_spacing(grid, expert_spacing) if grid is not None else None
        # the baselines plan one whole path per goal
        return GlobalRunnerConfig(horizon=self.horizon, waypoint_tolerance=self.waypoint_tolerance,
                                  replan_timeout=self.replan_timeout if self.method == "sd" else 0,
                                  replan=self.replan if self.method == "sd" else "once",
                                  replan_spacing=spacing)

    def sparse_config(self) -> SparseConfig:
        return SparseConfig(num_candidates=self.num_candidates, horizon=self.horizon,
                            epsilon=self.epsilon, selection=self.selection,
                            num_steps=self.ddim_steps or None,
                            max_spacing=self.max_spacing or None,
                            warm_fraction=self.warm_fraction,
                            precision=self.inference_precision, leg_batches=self.leg_batches)


def candidate_markers(plan: SparsePlan, frame_id: str, stamp) -> MarkerArray:
    """SparsePlan -> MarkerArray: DELETEALL, then one LINE_STRIP per candidate (id = its index),
    the chosen one purple and wider, the others translucent grey."""
    out = MarkerArray()
    clear = Marker()
    clear.action = Marker.DELETEALL
    out.markers.append(clear)
    for i, cand in enumerate(plan.candidates):
        m = Marker()
        m.header.frame_id, m.header.stamp = frame_id, stamp
        m.ns, m.id, m.type, m.action = "candidates", i, Marker.LINE_STRIP, Marker.ADD
        m.pose.orientation.w = 1.0
        chosen = i == plan.best
        m.scale.x = 0.08 if chosen else 0.03
        m.color.r, m.color.g, m.color.b, m.color.a = ((0.55, 0.2, 0.8, 1.0) if chosen
                                                      else (0.5, 0.5, 0.5, 0.6))
        for x, y in cand:
            m.points.append(Point(x=float(x), y=float(y), z=0.0))
        out.markers.append(m)
    return out


class GlobalPlanner(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("global_planner", **kwargs)
        declare_parameters(self, PARAMETERS)
        # configuration errors raise: spin_node exits non-zero with one line
        self.params: GlobalPlannerParams = read_parameters(self, PARAMETERS, GlobalPlannerParams)
        p = self.params
        self.footprint = make_robot(p)
        self.judged = make_robot(p, margin=p.clearance_margin)  # what waypoints must clear
        if p.method in ("sd", "fd"):  # an unreadable or mismatched model fails now
            from ecahd_core.model_zoo import check_model

            check_model(p.method, p.map_name,
                        path=(p.sd_model if p.method == "sd" else p.fd_model) or None,
                        footprint=self.footprint, horizon=p.horizon if p.method == "sd" else None)
        from ecahd_core.threads import lower_priority, set_torch_threads

        import torch

        set_torch_threads(p.torch_threads)
        lower_priority(p.nice)  # this thread spins the executor: SD and A* run on it
        self.generator = torch.Generator().manual_seed(p.seed)
        self.grid = None
        self.sparse: SparseDiffusion | None = None  # method sd
        self.astar = None  # method astar: ecahd_core.astar.AStarPlanner
        self.fd = None  # method fd: ecahd_core.planner.FullDiffusion
        self.pose: np.ndarray | None = None  # (2,) [m] latest valid odometry position
        self.runner = GlobalRunner(p.runner_config())
        self._plan_pub = self.create_publisher(Path, "plan", PLAN_QOS)
        self._cand_pub = self.create_publisher(MarkerArray, "plan_candidates", VIZ_QOS)
        self._timing_pub = self.create_publisher(String, "ecahd/timing", STREAM_QOS)
        self._ready_pub = self.create_publisher(String, "ecahd/planner_ready", MAP_QOS)
        self.create_subscription(OccupancyGrid, "map", self._guard(self._on_map), MAP_QOS)
        self.create_subscription(PoseStamped, "goal_pose", self._guard(self._on_goal),
                                 STREAM_QOS)
        self.create_subscription(Odometry, "odom", self._guard(self._on_odom), STREAM_QOS)
        self.create_subscription(OccupancyGrid, "local_costmap",
                                 self._guard(self._on_local_costmap), VIZ_QOS)
        self.create_subscription(String, "ecahd/replan", self._guard(self._on_replan),
                                 STREAM_QOS)
        self.memory = None  # ecahd_core.sensing.ObstacleMemory of the scanned obstacles
        self._static_cost = None  # J's tuple on the static map (collision-aware selection)
        self._placer_cache = None  # (key of the fused grid, its WaypointPlacer)
        self.subgoal_rule = None  # ecahd_core.progress.SubgoalRule on the static map
        self.fallbacks = 0  # A* fallbacks after repeated "blocked" replans
        # a goal coalesced in a burst is planned within one period even without odometry
        self.create_timer(p.runner_config().min_plan_interval, self._guard(self._on_pending))
        what = f"SD, N={p.num_candidates}, P^g={p.horizon}" if p.method == "sd" else p.method
        self.get_logger().info(f"global planner ready: {what}, robot {self.footprint.name!r}, "
                               "waiting for map and odom")

    @property
    def ready(self) -> bool:
        """A map arrived and the planner of ``method`` is built on it."""
        return any(x is not None for x in (self.sparse, self.astar, self.fd))

    @property
    def goal(self) -> np.ndarray | None:
        return self.runner.goal

    @property
    def waypoints(self) -> np.ndarray | None:
        return self.runner.waypoints

    # ------------------------------------------------------------------------- callbacks
    def _guard(self, callback):
        """Wrap a callback so no exception escapes: EcahdError is logged as an error, anything
        else with its traceback."""
        def wrapped(*msg) -> None:
            try:
                callback(*msg)
            except EcahdError as exc:
                self.get_logger().error(str(exc))
            except Exception:  # noqa: BLE001 (a node must survive a bug in one message)
                import traceback

                self.get_logger().error(f"{callback.__name__} failed:\n"
                                        f"{traceback.format_exc()}")
        return wrapped

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_map(self, msg: OccupancyGrid) -> None:
        p = self.params
        if msg.header.frame_id != p.global_frame:
            raise EcahdError(f"map in frame {msg.header.frame_id!r} ignored: expected "
                             f"{p.global_frame!r}")
        t0 = time.perf_counter()
        grid = msg_to_grid(msg, name=p.map_name)
        sparse = astar = fd = None
        warm = ""
        if p.method == "sd":
            sparse = self._build_sd(grid)
            x0, y0, x1, y1 = grid.bounds  # the first real plan then costs what later ones do
            warm = f", warm-up plan {sparse.warm_up((0.5 * (x0 + x1), 0.5 * (y0 + y1))):.0f} ms"
        elif p.method == "astar":
            from ecahd_core.astar import clearance_for_footprint, planner_for

            astar = planner_for(grid, clearance_for_footprint(self.judged))
        else:
            fd = self._build_fd(grid)
        self.grid, self.sparse, self.astar, self.fd = grid, sparse, astar, fd
        # replan_spacing may depend on the map and the model
        self.runner.config = p.runner_config(grid, sparse.expert_spacing if sparse else None)
        from ecahd_core.sensing import ObstacleMemory

        self.memory = ObstacleMemory(grid, p.obstacle_memory)
        self._static_cost = sparse.cost if sparse is not None else None
        self._placer_cache = None  # a new map: a new distance transform
        spacing = self.runner.config.replan_spacing
        self.subgoal_rule = None
        if self._rules_on() and p.subgoals:  # the cost-to-go's graph now, not on a re-plan
            from ecahd_core.progress import SubgoalRule

            self.subgoal_rule = SubgoalRule(grid, self.judged, spacing)
            self.subgoal_rule.field.graph
        ms = (time.perf_counter() - t0) * 1e3
        self.get_logger().info(f"map {grid.name!r} received ({grid.width} x {grid.height} "
                               f"cells); {p.method} planner built in {ms:.0f} ms{warm}"
                               + (f"; re-plans keep a waypoint per {spacing:g} m left to the "
                                  f"goal (replan_spacing)" if spacing else ""))
        self._ready_pub.publish(String(data=json.dumps(
            {"map": grid.name, "method": p.method, "ms": round(ms, 1)})))
        if self.runner.goal is not None:
            self.runner.set_goal(self.runner.goal)  # plan again on the new map
            self._step()

    def _build_sd(self, grid) -> SparseDiffusion:
        from ecahd_core.model_zoo import load_model

        p = self.params
        ckpt = load_model("sd", grid, path=p.sd_model or None, footprint=self.footprint,
                          horizon=p.horizon)
        cost = (collision_cost(p, grid, self.footprint).as_tuple()
                if p.selection == "collision_aware" else None)
        return SparseDiffusion(ckpt, p.sparse_config(), cost=cost)

    def _build_fd(self, grid):
        from ecahd_core.model_zoo import load_model
        from ecahd_core.planner import FullDiffusion

        p = self.params
        ckpt = load_model("fd", grid, path=p.fd_model or None, footprint=self.footprint)
        cost = collision_cost(p, grid, self.footprint).as_tuple() if p.fd_guidance else None
        return FullDiffusion(ckpt, guidance=p.fd_guidance, cost=cost,
                             num_steps=p.ddim_steps or None)

    def _on_goal(self, msg: PoseStamped) -> None:
        p = self.params
        frame = msg.header.frame_id
        if frame != p.global_frame:
            raise PlanningError(f"goal rejected: frame {frame!r} is not the global frame "
                                f"{p.global_frame!r}")
        try:
            x, y, _ = validate_pose((msg.pose.position.x, msg.pose.position.y, 0.0), "goal")
            xy = np.array([x, y])
            if self.grid is not None:
                xy = self.grid.validate_point(xy, "goal")
        except PlanningError as exc:
            raise PlanningError(f"goal rejected: {exc}") from None
        self.runner.set_goal(xy)
        if not self.ready or self.pose is None:
            missing = " and ".join(n for n, ok in (("map", self.ready),
                                                   ("odom", self.pose is not None)) if not ok)
            self.get_logger().info(f"goal ({xy[0]:.2f}, {xy[1]:.2f}) queued until {missing} "
                                   f"arrive(s)")
            return
        self._step()

    def _on_odom(self, msg: Odometry) -> None:
        if msg.header.frame_id and msg.header.frame_id != self.params.global_frame:
            raise PlanningError(f"odometry in frame {msg.header.frame_id!r}, expected "
                                f"{self.params.global_frame!r}: ignored")
        pos = msg.pose.pose.position
        try:
            x, y, _ = validate_pose((pos.x, pos.y, 0.0), "odometry pose")
        except PlanningError as exc:
            raise PlanningError(f"odometry ignored: {exc}") from None
        self.pose = np.array([x, y])
        self._step()

    def _on_local_costmap(self, msg: OccupancyGrid) -> None:
        if msg.header.frame_id != self.params.global_frame:
            raise EcahdError(f"local_costmap in frame {msg.header.frame_id!r} ignored: expected "
                             f"{self.params.global_frame!r}")
        if self.memory is None:
            return
        window = msg_to_grid(msg, name="local_costmap", unknown_is_occupied=False)
        self.memory.update(window, self._now())

    def _on_replan(self, msg: String) -> None:
        """The refiner cannot follow the plan (a segment blocked by a scanned obstacle)."""
        try:
            reason = str(json.loads(msg.data).get("reason", "blocked"))
        except (ValueError, AttributeError):
            raise EcahdError(f"ecahd/replan ignored: not a JSON object: {msg.data[:80]!r}") \
                from None
        if self.runner.goal is None:
            return
        self.runner.request_replan(reason)
        self._step()

    def _fused_grid(self):
        """The static map with the obstacles the scans found (remembered for
        ``obstacle_memory`` s unless seen gone), or the static map."""
        if self.memory is None:
            return self.grid
        return self.memory.fused(self._now())

    def _grid_key(self, grid):
        """What tells fused grids apart for the caches: None for the static map."""
        return None if grid is self.grid else grid.occupied.tobytes()

    def _rules_on(self) -> bool:
        """Whether the subgoal and settle rules can act: sd, every_waypoint, a replan spacing,
        placement on and the free-first-leg rule on (as in ``HierarchicalPlanner``)."""
        p = self.params
        return (p.method == "sd" and p.replan == "every_waypoint" and self.grid is not None
                and self.runner.config.replan_spacing is not None and self._placement_on()
                and p.leg_batches >= 0 and p.warm_fraction == 0)

    def _placement_on(self) -> bool:
        """Whether place_reach (-1: by the map) moves waypoints farther than the goal snap."""
        from ecahd_core.placement import auto_reach

        p = self.params
        return (auto_reach(self.grid) if p.place_reach < 0 else p.place_reach) > SNAP_DISTANCE

    def _placer(self):
        """The WaypointPlacer on :meth:`_fused_grid` (its distance transform is built once per
        fused grid)."""
        from ecahd_core.placement import WaypointPlacer, auto_reach

        grid = self._fused_grid()
        key = self._grid_key(grid)
        if self._placer_cache is None or self._placer_cache[0] != key:
            p = self.params
            reach = auto_reach(self.grid) if p.place_reach < 0 else p.place_reach
            on = self._placement_on()  # off: the 0.2 m snap, no waypoint added
            self._placer_cache = (key, WaypointPlacer(
                grid, self.judged, reach=reach if on else SNAP_DISTANCE,
                leg_rounds=p.leg_repair if on else 0,
                repair_reach=p.repair_reach if p.repair_reach > 0 else None))
        return self._placer_cache[1]

    def _fused_cost(self):
        """J's (costmap, footprint points, config) on the static map and the remembered
        obstacles (``ObstacleMemory.fused_cost``)."""
        return self.memory.fused_cost(self._now(), self._static_cost)

    def _on_pending(self) -> None:
        if self.runner.pending:
            self._step()

    def _step(self) -> None:
        """Ask the runner what to do at the current pose, and do it."""
        if not self.ready or self.pose is None:
            return
        goal = self.runner.goal
        event = self.runner.step(self.pose, self._now())
        if event == "reached":
            self.get_logger().info(f"goal ({goal[0]:.2f}, {goal[1]:.2f}) reached")
        elif isinstance(event, PlanRequest):
            if event.reason == "timeout":
                self.get_logger().warning(
                    f"no progress toward the next waypoint for {self.runner.stall_timeout:g} s: "
                    f"replanning from the current pose (timeout replan {self.runner.stalls} in a "
                    "row)")
            self._plan(event)

    # ----------------------------------------------------------------------------- planning
    def _plan(self, request: PlanRequest) -> None:
        """Plan for ``request`` and publish: SD best-of-N with its horizon, or the baseline's
        whole path. A goal that cannot be planned to is dropped."""
        try:
            goal = self.grid.validate_point(request.goal, "goal")
            start = self.grid.validate_point(request.start, "robot pose")
        except PlanningError as exc:
            if "goal" in str(exc).split(":")[0]:
                self.runner.fail()
            raise PlanningError(f"cannot plan: {exc}") from None
        method, result, detail = self.params.method, None, ""
        blocked = request.reason == "blocked"
        if blocked and (method != "sd" or self.runner.blocked_count >= 2):
            method = "fallback_astar"  # SD could not get round it: A* on what is known
            waypoints, ms = self._plan_fallback(start, goal)
        elif method == "sd":
            saved = self.sparse.cost
            if saved is not None:  # weigh the candidates by J with the scanned obstacles too
                self.sparse.cost = self._fused_cost()
            # the robot follows the first leg to the next re-plan: SD's rule for a free first
            # leg (leg_batches) judges it with the placer on the map and the remembered obstacles
            first_leg = self.params.replan == "every_waypoint" and self._placement_on()
            if first_leg:
                self.sparse.placer = self._placer()
            try:
                # a re-plan at a reached waypoint may start from the rest of the current plan
                # (warm_fraction; from noise when 0, bit for bit)
                previous = self.runner.waypoints if request.reason == "waypoint" else None
                t0 = time.perf_counter()
                result = self.sparse.replan(start, goal, previous, horizon=request.horizon,
                                            generator=self.generator,
                                            repair_legs=1 if first_leg else None)
                if (self.subgoal_rule is not None
                        and request.iteration >= self.params.horizon - 1):
                    result = self.subgoal_rule.apply(self.sparse, start, goal, result,
                                                     request.iteration,
                                                     generator=self.generator)
                    if result.first_leg == "subgoal":
                        detail = " (toward a subgoal on the shortest route)"
            finally:
                self.sparse.cost, self.sparse.placer = saved, None
            waypoints, ms = result.waypoints.copy(), (time.perf_counter() - t0) * 1e3
            detail = detail or f" (candidate {result.best} of {len(result.candidates)})"
            if self._crosses_remembered(waypoints):  # SD cannot see round it: detour now
                method, result = "fallback_astar", None
                waypoints, ms_fallback = self._plan_fallback(start, goal)
                ms += ms_fallback
                detail = " (SD's best crossed an obstacle the scans found)"
        elif method == "astar":
            waypoints, ms = self._plan_astar(start, goal)
        else:
            t0 = time.perf_counter()
            waypoints = self.fd.plan(start, goal, generator=self.generator)
            ms = (time.perf_counter() - t0) * 1e3
        waypoints[0], waypoints[-1] = start, goal  # exact ends (the models work in float32)
        if method == "sd":  # SD's waypoints in a wall move into free space (ours)
            waypoints, moved = self._placer()(waypoints, last_reach=SNAP_DISTANCE)
            if moved:
                detail += f", {moved} waypoint(s) moved out of or added round walls"
        follow = self._follow(waypoints, result) if method == "sd" else 1
        if follow == len(waypoints) - 1 > 1:
            detail += ", every leg free: followed whole (settle rule)"
        elif follow > 1:
            detail += f", legs free up to the subgoal: followed to waypoint {follow} (settle rule)"
        stamp = self.get_clock().now()
        self.runner.accept(waypoints, stamp.nanoseconds * 1e-9, hold=method == "fallback_astar",
                           follow=follow)
        self._plan_pub.publish(xy_to_path(waypoints, self.params.global_frame, stamp.to_msg()))
        if result is not None:
            self._cand_pub.publish(candidate_markers(result, self.params.global_frame,
                                                     stamp.to_msg()))
        self._timing_pub.publish(timing_message(method, ms, stamp.nanoseconds * 1e-9,
                                                horizon=len(waypoints)))
        self.get_logger().info(f"{method} plan of {len(waypoints)} points to "
                               f"({goal[0]:.2f}, {goal[1]:.2f}) in {ms:.1f} ms{detail}")

    def _follow(self, waypoints: np.ndarray, result: SparsePlan) -> int:
        """The settle rule (``settle``, as ``HierarchicalPlanner``'s): the index of the waypoint
        of the published ``waypoints`` (P, 2) [m] whose reach asks for the next re-plan: P - 1
        (none) when every straight leg is free by the leg test on the map and the remembered
        obstacles; for a plan toward a subgoal (``result``), the subgoal when every leg up to it
        is; else 1 (Algorithm 1)."""
        if not (self.params.settle and self._rules_on() and len(waypoints) > 2):
            return 1
        free = self._placer().leg_walls(waypoints) == 0  # (P - 1,)
        if free.all():
            return len(waypoints) - 1
        if result is not None and result.first_leg == "subgoal":
            at = np.flatnonzero(np.all(np.abs(waypoints - result.waypoints[-2]) < 1e-6, axis=1))
            if len(at) and at[0] > 1 and free[:at[0]].all():
                return int(at[0])
        return 1

    def _crosses_remembered(self, waypoints: np.ndarray) -> bool:
        """Whether the straight legs of ``waypoints`` (P, 2) [m] sweep the footprint over an
        obstacle the scans found and the memory still holds (the static map's walls are DD's
        and polishing's business; a scanned blockage is not in what SD learnt)."""
        return self.memory is not None and self.memory.crosses(waypoints, self.judged,
                                                               self._now())

    def _plan_fallback(self, start: np.ndarray, goal: np.ndarray) -> tuple[np.ndarray, float]:
        """A* with the footprint's clearance round the remembered obstacles
        (``ObstacleMemory.detour``), resampled -> (path (N, 2) [m], wall time [ms])."""
        from ecahd_core.controller import resample

        t0 = time.perf_counter()
        now = self._now()
        try:
            path, tried = self.memory.detour(self.judged, start, goal, now)
        except PlanningError as exc:
            raise PlanningError(f"{exc}; the robot waits for a way to open") from None
        path = resample(path, ASTAR_SPACING)
        self.fallbacks += 1
        self.get_logger().warning(
            f"replan after {self.runner.blocked_count} blocked segment(s): fallback to A* on "
            f"the map with {int(self.memory.mask(now).sum())} remembered obstacle cells, "
            f"tried {tried} of 2 maps ({self.fallbacks} fallback(s) so far)")
        return path, (time.perf_counter() - t0) * 1e3

    def _plan_astar(self, start: np.ndarray, goal: np.ndarray) -> tuple[np.ndarray, float]:
        """A* from ``start`` to ``goal`` -> (path (N, 2) [m], ASTAR_SPACING apart at most;
        wall time [ms]). An unreachable goal or one without clearance is dropped."""
        from ecahd_core.astar import plan_from_pose
        from ecahd_core.controller import resample

        t0 = time.perf_counter()
        try:
            path = plan_from_pose(self.astar, start, goal)
        except PlanningError as exc:  # the pose was validated: the goal is the problem
            self.runner.fail()
            raise PlanningError(f"goal rejected: {exc}") from None
        path = resample(path, ASTAR_SPACING)
        return path, (time.perf_counter() - t0) * 1e3


def main(args=None) -> None:
    spin_node(GlobalPlanner, args, name="global_planner")


if __name__ == "__main__":
    main()
