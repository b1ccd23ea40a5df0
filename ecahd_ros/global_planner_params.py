"""global_planner's parameters, each declared once (:data:`PARAMETERS`: name, default from
the core config it sets, description) and read into :class:`GlobalPlannerParams`, which
validates them and hands the core its configs. ``config/ecahd.yaml`` and docs/parameters.md are
rendered from this list (``ecahd config``)."""
from __future__ import annotations

from ecahd_core.planning.horizon import REPLAN_POLICIES
from ecahd_core.planning.mission import MissionConfig
from ecahd_core.planning.online import METHODS, GlobalRunnerConfig, OnlinePlannerConfig
from ecahd_core.planning.sparse import SELECTION_RULES, SparseConfig
from ecahd_core.threads import PRECISION_CHOICES
from ecahd_ros.params import (ParamSpec, parameters_dataclass, require, require_cost_margin,
                              require_non_negative, require_positive, shared)


# the defaults live in the core configs the parameters set (one home for each)
_ONLINE, _RUNNER, _SPARSE = OnlinePlannerConfig(), GlobalRunnerConfig(), SparseConfig()
_MISSION = MissionConfig()

PARAMETERS = [
    ParamSpec("method", _ONLINE.method, f"global planner: {list(METHODS)} (sd: ECAHD, replanned at each "
                              "waypoint; astar, fd: one whole path per goal)"),
    ParamSpec("sd_model", "", "SD checkpoint path; '' = the shipped model for map_name; "
                              "'general' = the shipped map-conditioned generalist (any map, "
                              "and a new map is planned on at once)"),
    ParamSpec("fd_model", "", "FD checkpoint path (method fd); '' = the shipped model"),
    ParamSpec("fd_guidance", False, "method fd: guide the Full Diffusion sample by J"),
    *shared("map_name"),
    ParamSpec("num_candidates", _SPARSE.num_candidates, "N, candidate global plans sampled in one batch"),
    ParamSpec("horizon", _RUNNER.horizon, "P^g, waypoints of the first global plan"),
    ParamSpec("max_spacing", 0.0, "[m] sd: waypoint spacing by distance, legs of a plan longer "
                                  "than this re-sampled by SD between their ends (for big "
                                  "maps); 0 = off (the paper's fixed P^g)"),
    ParamSpec("place_reach", _ONLINE.place_reach, "[m] sd: SD's waypoints that lie in a wall (map + remembered "
                                   "obstacles) move into free space at most this far, and legs "
                                   "crossing a wall get a placed midpoint (leg_repair); -1 = by "
                                   "the map: 1.0 on maps over 50 000 cells, else off; off (or "
                                   "<= 0.2): waypoints and the goal move at most 0.2 m"),
    ParamSpec("leg_repair", _ONLINE.leg_repair, "sd: rounds of leg repair while place_reach is on (> 0.2 m); "
                               "0 = off"),
    ParamSpec("repair_reach", _ONLINE.repair_reach, "[m] sd: leg repair looks this far from a leg's middle for "
                                    "its new waypoint (at most half the leg); -1 = the larger "
                                    "of place_reach and 3.0"),
    ParamSpec("leg_batches", _SPARSE.leg_batches, "sd, every_waypoint, with place_reach on: when the "
                                          "chosen candidate's first leg still crosses a wall "
                                          "after leg repair, the first of the other candidates "
                                          "whose first leg does not, else up to this many more "
                                          "batches of N (one waypoint more each); 0 = the "
                                          "other candidates only; -1 = off"),
    ParamSpec("ddim_steps", 0, "DDIM steps of SD or FD; 0 = the checkpoint's"),
    ParamSpec("epsilon", _SPARSE.epsilon, "[m] goal-reaching radius of the best-of-N rule"),
    ParamSpec("selection", "collision_aware", f"best-of-N rule: {list(SELECTION_RULES)} "
                                              "(shortest_reaching: Sec. III-A's)"),
    *shared("robot", "footprint", "footprint_padding", "global_frame", "transform_tolerance",
            "clearance_margin", "cost_margin"),
    ParamSpec("waypoint_tolerance", _RUNNER.waypoint_tolerance, "[m] reaching the next waypoint this close replans "
                                         "with horizon P^g - p (sd); the goal this close is "
                                         "reached"),
    ParamSpec("replan", _RUNNER.replan, f"sd: {list(REPLAN_POLICIES)} (every_waypoint: "
                                          "Algorithm 1; once: one SD plan per goal)"),
    ParamSpec("replan_spacing", _ONLINE.replan_spacing, "[m] sd, every_waypoint: each re-plan keeps at least "
                                      "ceil(D / this) + 1 waypoints (at most P^g) for the "
                                      "straight distance D left to the goal, instead of "
                                      "Algorithm 1's P^g - p, whose last plan is a straight "
                                      "line to the goal wherever the robot is; -1 = by the "
                                      "map and model: on maps over 50 000 cells the SD "
                                      "model's expert waypoint spacing, at least 3.0, else "
                                      "off; 0 = off"),
    ParamSpec("subgoals", _ONLINE.subgoals, "sd, every_waypoint, with a replan spacing and the free-first-"
                                "leg rule on (building maps): a re-plan past P^g - 1 waypoints, "
                                "or one the robot asks for within 1 m of where it asked for the "
                                "goal's last two (stalled, ecahd_core.planning.rules.stalled), "
                                "whose first leg makes no progress by the goal's cost-to-go "
                                "plans toward a point on the shortest route (the subgoal rule, "
                                "ecahd_core.progress.SubgoalRule; docs/rules.md, subgoals)"),
    ParamSpec("settle", _ONLINE.settle, "sd, every_waypoint, with a replan spacing and the free-first-leg "
                              "rule on (building maps): a plan whose every straight leg is free "
                              "by the leg test is followed whole, not re-planned at each "
                              "waypoint, and a plan toward a subgoal whose legs up to it are "
                              "free is followed to the subgoal (the settle rule)"),
    ParamSpec("replan_timeout", _RUNNER.replan_timeout, "[s] sd: with no progress toward the next waypoint (reaching "
                                     "it, or coming 0.25 m nearer it than before) for this long, "
                                     "replan from the current pose (same horizon); doubles with "
                                     "each further such replan (at most 8x) until the robot "
                                     "progresses again; 0 = never"),
    ParamSpec("warm_fraction", -1.0, "sd, every_waypoint: a re-plan at a reached waypoint starts "
                                    "from the rest of the current plan noised to the last F "
                                    "(0..1) of SD's DDIM schedule, and one whose first leg "
                                    "crosses a wall is drawn again from noise; 0 = from noise "
                                    "(Algorithm 1 as written); -1 = by the map: 0.3 where "
                                    "waypoint placement acts (building maps: median plans "
                                    "1.2-2.3x faster, p95 1.9-4.1x, as collision-free), else 0 "
                                    "(docs/RESULTS.md)"),
    ParamSpec("obstacle_memory", _ONLINE.obstacle_memory, "[s] obstacles the local costmap found are avoided "
                                       "by re-plans for this long unless seen gone"),
    ParamSpec("inference_precision", "auto", f"sd: the SD Transformer computes in one of "
                                             f"{list(PRECISION_CHOICES)} (auto: bf16 where the "
                                             f"CPU has native bfloat16, AVX512-BF16 or AMX)"),
    ParamSpec("nice", 0, "nice increment of the thread that plans, so that planning yields "
                         "the CPU to the controller on a busy computer; 0 = unchanged (5 "
                         "changed no closed-loop figure, docs/RESULTS.md)"),
    *shared("dd_model", "map_change_warn", "yaw_goal_tolerance", "lanes"),
    ParamSpec("heading_timeout", _MISSION.align_timeout, "[s] navigate_to_pose: a goal whose position is reached but "
                                 "not its heading within this fails (turning in place "
                                 "blocked)"),
    *shared("seed", "torch_threads", "autostart"),
]


@parameters_dataclass(PARAMETERS)
class GlobalPlannerParams:
    """The node's validated parameters (see the module docstring for units)."""

    def __post_init__(self) -> None:
        require_positive(self, "num_candidates", "epsilon", "waypoint_tolerance",
                         "yaw_goal_tolerance", "heading_timeout", "torch_threads")
        require(0 <= self.nice <= 19, "nice", self.nice, "in 0..19")
        require(self.inference_precision in PRECISION_CHOICES, "inference_precision",
                self.inference_precision, f"one of {list(PRECISION_CHOICES)}")
        require_non_negative(self, "ddim_steps", "footprint_padding", "seed", "replan_timeout",
                             "transform_tolerance",
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
        require(0.0 <= self.warm_fraction <= 1.0 or self.warm_fraction == -1, "warm_fraction",
                self.warm_fraction, "in 0..1 (0: off), or -1 (by the map)")

    def runner_config(self) -> GlobalRunnerConfig:
        """The GlobalRunner's settings (its replan spacing is decided per map by
        :meth:`~ecahd_core.planning.online.OnlinePlanner.set_map`)."""
        return GlobalRunnerConfig(horizon=self.horizon, waypoint_tolerance=self.waypoint_tolerance,
                                  replan_timeout=self.replan_timeout, replan=self.replan)

    def online_config(self) -> OnlinePlannerConfig:
        return OnlinePlannerConfig(method=self.method, place_reach=self.place_reach,
                                   leg_repair=self.leg_repair, repair_reach=self.repair_reach,
                                   replan_spacing=self.replan_spacing, subgoals=self.subgoals,
                                   settle=self.settle, obstacle_memory=self.obstacle_memory)

    def mission_config(self) -> MissionConfig:
        """When a navigate_to_pose goal is reached: the position within waypoint_tolerance
        (the planner's own "reached"), the heading within yaw_goal_tolerance."""
        return MissionConfig(xy_tolerance=self.waypoint_tolerance,
                             yaw_tolerance=self.yaw_goal_tolerance,
                             align_timeout=self.heading_timeout)

    def sparse_config(self) -> SparseConfig:
        return SparseConfig(num_candidates=self.num_candidates, horizon=self.horizon,
                            epsilon=self.epsilon, selection=self.selection,
                            num_steps=self.ddim_steps or None,
                            max_spacing=self.max_spacing or None,
                            warm_fraction=self.warm_fraction,
                            precision=self.inference_precision, leg_batches=self.leg_batches)
