"""The online Algorithm 1's global half (paper Sec. III-A) as runtime classes driven by poses
and a clock, with no rclpy: global_planner only converts messages and calls them (Nav2's
planner_server / planner plugin split), and unit tests drive them with fake clocks and poses.

:class:`GlobalRunner`: when to ask for a plan. A goal asks for a plan of horizon P^g at once;
    each time the robot comes within ``waypoint_tolerance`` of the plan's next waypoint, the
    p-th replan asks for horizon P^g - p (Algorithm 1 lines 2-11, ``replan`` "every_waypoint";
    with ``replan_spacing``, ours, at least what the distance left needs,
    :func:`~ecahd_core.planning.horizon.replan_horizon`); with ``replan`` "once" (ours, and the
    Table III baselines A* and FD) one plan serves the whole goal. Beyond the paper, a robot
    that makes no progress toward its next waypoint for ``replan_timeout`` seconds replans from
    where it is, and goals that arrive faster than ``min_plan_interval`` are coalesced (the
    latest wins), so the planning work does not grow with the goal rate.

Poses are (x [m], y [m], yaw [rad]); plans are (P, 2) [m] in the global frame; ``now`` is a
clock reading in seconds (sim time or wall time, the caller's choice).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from ecahd_core.errors import EcahdError, PlanningError
from ecahd_core.placement import LEG_ROUNDS
from ecahd_core.planning.horizon import (REPLAN_POLICIES, SNAP_DISTANCE, check_replan_spacing,
                                         replan_horizon, replan_spacing_for)
from ecahd_core.planning.rules import STALL_PLANS, SparseStage, stalled

MAX_STALL_DOUBLINGS = 3  # GlobalRunnerConfig.replan_timeout grows at most 8-fold
# [m] coming this much nearer the next waypoint than ever since it became the next one is
# progress: it restarts replan_timeout's clock (a 6.5 m office leg takes 13 s at 0.5 m/s)
PROGRESS_STEP = 0.25


@dataclass(frozen=True, kw_only=True)
class GlobalRunnerConfig:
    """Settings of :class:`GlobalRunner` (units in brackets).

    Attributes:
        horizon: P^g, waypoints of a goal's first plan.
        waypoint_tolerance: [m] reaching the next waypoint this close replans; the goal this
            close is reached.
        replan_timeout: [s] no waypoint reached and no progress toward the next one (coming
            PROGRESS_STEP nearer it than before) for this long replans; 0 = never. Each
            further timeout replan with no progress in between doubles it (at most
            2^MAX_STALL_DOUBLINGS times): on a slow or busy CPU a local stage that takes longer
            than the timeout would otherwise be restarted by every replan, and the robot would
            never move (seen on a 2-core machine at 4x real time).
        replan: "every_waypoint" (Algorithm 1) or "once" (one plan per goal).
        min_plan_interval: [s] goals closer in time than this are coalesced.
        replan_spacing: [m] re-plans keep enough waypoints for the distance left to the goal
            (:func:`replan_horizon`; ours; None: Algorithm 1's P^g - p).
    """

    horizon: int = 10
    waypoint_tolerance: float = 0.3
    replan_timeout: float = 5.0
    replan: str = "every_waypoint"
    min_plan_interval: float = 0.05
    replan_spacing: float | None = None

    def __post_init__(self) -> None:
        if self.horizon < 2:
            raise EcahdError(f"horizon must be >= 2, got {self.horizon}")
        if not self.waypoint_tolerance > 0:
            raise EcahdError(f"waypoint_tolerance must be > 0 m, got {self.waypoint_tolerance}")
        if not self.replan_timeout >= 0 or not self.min_plan_interval >= 0:
            raise EcahdError("replan_timeout and min_plan_interval must be >= 0 s")
        if self.replan not in REPLAN_POLICIES:
            raise EcahdError(f"replan {self.replan!r} is not one of {list(REPLAN_POLICIES)}")
        check_replan_spacing(self.replan_spacing)


@dataclass(frozen=True)
class PlanRequest:
    """Plan from ``start`` (2,) to ``goal`` (2,) [m] with ``horizon`` waypoints; ``reason`` is
    "goal", "waypoint" or "timeout" (or the local stage's, e.g. "blocked"); ``iteration`` is
    Algorithm 1's p, the waypoints reached since the goal arrived."""

    start: np.ndarray
    goal: np.ndarray
    horizon: int
    reason: str
    iteration: int = 0
    stalled: bool = False  # the goal's last plans all started near here (rules.stalled)


class GlobalRunner:
    """Algorithm 1's outer loop online (see the module docstring).

    Call :meth:`set_goal` for a goal, :meth:`step` with each pose; a :class:`PlanRequest` it
    returns is planned by the caller, who hands the result to :meth:`accept` (or reports a
    failure with :meth:`fail`). :meth:`step` returns "reached" once when the goal is reached.
    """

    def __init__(self, config: GlobalRunnerConfig) -> None:
        self.config = config
        self.goal: np.ndarray | None = None  # (2,) [m]
        self.waypoints: np.ndarray | None = None  # (P, 2) [m] the current plan
        self._next = 1  # index of the waypoint whose reach asks for the next plan
        self.iteration = 0  # p of Algorithm 1: waypoints reached since the goal arrived
        self._pending = False  # the goal still needs its first plan
        self._last_plan = -math.inf  # [s] when the last plan was accepted
        self._last_request = -math.inf  # [s] when the last goal plan was requested
        self._forced: str | None = None  # a replan asked for by the local stage
        self.blocked_count = 0  # "blocked" replans asked for since the goal arrived
        self._hold = False  # the current goal's plan is followed to the end (a fallback)
        self._follow_to = 1  # index of the waypoint whose reach asks for a re-plan (settle)
        self._last_progress = -math.inf  # [s] of the last progress (PROGRESS_STEP)
        self._closest = math.inf  # [m] nearest the robot came to the next waypoint
        self.stalls = 0  # timeout replans since a waypoint was last reached
        self._starts: list = []  # (2,) [m] where the goal's last plans were asked for
        self.stall_timeout = config.replan_timeout  # [s] the last timeout replan's wait

    @property
    def active(self) -> bool:
        return self.goal is not None

    @property
    def pending(self) -> bool:
        """A goal waits for its first plan (e.g. coalesced in a burst)."""
        return self.goal is not None and self._pending

    @property
    def next_index(self) -> int | None:
        """Index in :attr:`waypoints` of the waypoint the robot heads for (None: no plan)."""
        return None if self.waypoints is None else self._next

    def set_goal(self, goal) -> None:
        """A new goal (2,) [m] pre-empts the current one."""
        g = np.asarray(goal, dtype=np.float64).reshape(2)
        if not np.all(np.isfinite(g)):
            raise PlanningError(f"goal is not finite: {g.tolist()}")
        self.goal, self.waypoints, self.iteration, self._pending = g, None, 0, True
        self._starts = []
        self._forced, self.blocked_count, self._hold, self.stalls = None, 0, False, 0
        self._follow_to = 1

    def cancel(self) -> None:
        self.goal, self.waypoints, self._pending, self._forced = None, None, False, None
        self.blocked_count = 0

    def request_replan(self, reason: str) -> None:
        """The local stage cannot follow the plan (e.g. "blocked" by an unmapped obstacle):
        the next :meth:`step` asks for a new plan from the robot's pose (same horizon)."""
        if self.goal is not None:
            self._forced = reason
            self.blocked_count += reason == "blocked"

    def step(self, xy, now: float) -> PlanRequest | str | None:
        """The robot is at ``xy`` (2,) [m] at ``now`` [s]: a PlanRequest, "reached" or None."""
        c = self.config
        if self.goal is None:
            return None
        xy = np.asarray(xy, dtype=np.float64).reshape(2)
        if not np.all(np.isfinite(xy)):
            raise PlanningError(f"robot position is not finite: {xy.tolist()}")
        if now < self._last_request or now < self._last_plan or now < self._last_progress:
            # the clock jumped back (a restarted simulator)
            self._last_request = self._last_plan = self._last_progress = -math.inf
        if self._pending:
            if now - self._last_request < c.min_plan_interval:
                return None  # coalesce a burst of goals: the latest is planned next time
            self._last_request = now
            self._starts = [xy.copy()]
            return PlanRequest(xy, self.goal.copy(), c.horizon, "goal")
        if self.waypoints is None:
            return None
        if float(np.linalg.norm(xy - self.goal)) < c.waypoint_tolerance:
            self.cancel()
            return "reached"
        if self._forced is not None:
            reason, self._forced = self._forced, None
            return self._request(xy, reason)
        if c.replan == "once" or self._hold:
            return None
        nxt = self._next
        dist = float(np.linalg.norm(xy - self.waypoints[nxt]))
        if len(self.waypoints) > nxt + 1 and dist < c.waypoint_tolerance:
            self.iteration += 1  # MoveAgent reached t^g_p[1]: replan with P^g - p
            self.stalls = 0
            if nxt < self._follow_to:  # the settle rule: follow on to the next waypoint
                self._next, self._last_progress = nxt + 1, now
                self._closest = float(np.linalg.norm(xy - self.waypoints[nxt + 1]))
                return None
            return self._request(xy, "waypoint")
        if dist < self._closest - PROGRESS_STEP:  # nearer the next waypoint: not stalled
            self._closest, self._last_progress, self.stalls = dist, now, 0
        timeout = c.replan_timeout * 2 ** min(self.stalls, MAX_STALL_DOUBLINGS)
        if c.replan_timeout > 0 and now - max(self._last_plan, self._last_progress) > timeout:
            self._last_plan = now  # one timeout replan per period even if planning fails
            self.stalls, self.stall_timeout = self.stalls + 1, timeout
            return self._request(xy, "timeout")
        return None

    def _request(self, xy: np.ndarray, reason: str) -> PlanRequest:
        """A re-plan from ``xy`` (2,) [m] now, for ``reason``."""
        self._starts = self._starts[-(STALL_PLANS - 1):] + [xy.copy()]
        return PlanRequest(xy, self.goal.copy(), self._horizon(xy), reason, self.iteration,
                           stalled=stalled(self._starts))

    def _horizon(self, xy: np.ndarray) -> int:
        """The horizon of a re-plan from ``xy`` (2,) [m] now (:func:`replan_horizon`)."""
        c = self.config
        return replan_horizon(c.horizon, self.iteration, xy, self.goal, c.replan_spacing)

    def accept(self, waypoints: np.ndarray, now: float, *, hold: bool = False,
               follow: int = 1) -> None:
        """The plan (P, 2) [m] made for the last request; ``hold``: follow it to the goal with
        no waypoint or timeout replans (a fallback path round a blockage), for the rest of the
        goal; ``follow``: the waypoint whose reach asks for the next re-plan, those before it
        are passed without one (the settle rule, ``HierarchicalPlanner``'s ``settle``: P - 1
        follows the whole plan; timeout and local-stage replans still act; 1: Algorithm 1)."""
        self.waypoints = np.asarray(waypoints, dtype=np.float64)
        # the waypoint to reach next: the first after the start that lies beyond
        # waypoint_tolerance of it. One the robot already stands at would count as reached at
        # once and ask for the next plan from the same pose; leg repair can put one there in
        # every plan, and on the office that made ~25 plans a second for 16 s (seed 5).
        near = np.linalg.norm(self.waypoints[1:-1] - self.waypoints[0], axis=1) \
            < self.config.waypoint_tolerance
        self._next = 1 + int(np.argmin(near)) if not near.all() else len(self.waypoints) - 1
        self._pending = False
        self._last_plan = now
        # goals that queued up while this plan was made are coalesced from its end on
        self._last_request = max(self._last_request, now)
        self._hold = self._hold or hold
        self._follow_to = int(follow)
        self._closest = float(np.linalg.norm(self.waypoints[self._next] - self.waypoints[0]))

    def fail(self) -> None:
        """Planning for the goal failed for good (an unreachable goal): drop it."""
        self.cancel()



# ------------------------------------------------------------------ what the robot plans
METHODS = ("sd", "astar", "fd")  # ECAHD's Sparse Diffusion; the Table III baselines' planners
ASTAR_SPACING = 0.25  # [m] most distance between consecutive points of a published A* path
BLOCKED_BEFORE_FALLBACK = 2  # "blocked" re-plans SD makes before the A* fallback takes over


@dataclass(frozen=True, kw_only=True)
class OnlinePlannerConfig:
    """Settings of :class:`OnlinePlanner` (global_planner's parameters of the same names).

    Attributes:
        method: one of METHODS: "sd" (ECAHD, re-planned by the GlobalRunner), "astar" or "fd"
            (one whole path per goal).
        place_reach: [m] sd: SD's waypoints in a wall (map + remembered obstacles) move at most
            this far and legs crossing a wall get a placed midpoint; -1: by the map
            (``placement.auto_reach``: on for building maps); <= SNAP_DISTANCE: off.
        leg_repair: rounds of leg repair while placement is on.
        repair_reach: [m] leg repair's reach; -1: the placer's default.
        replan_spacing: [m] -1: by the map and the SD model (``auto_replan_spacing``); 0: off
            (Algorithm 1's P^g - p); else the spacing.
        subgoals, settle: the subgoal and settle rules (``rules.SparseStage``).
        obstacle_memory: [s] obstacles the local costmap found are avoided for this long
            unless seen gone.
    """

    method: str = "sd"
    place_reach: float = -1.0
    leg_repair: int = LEG_ROUNDS
    repair_reach: float = -1.0
    replan_spacing: float = -1.0
    subgoals: bool = True
    settle: bool = True
    obstacle_memory: float = 60.0

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise EcahdError(f"method {self.method!r} is not one of {list(METHODS)}")
        if not (self.place_reach >= 0 or self.place_reach == -1):
            raise EcahdError(f"place_reach must be >= 0 m or -1 (by the map), got "
                             f"{self.place_reach}")
        if not (self.replan_spacing >= 0 or self.replan_spacing == -1):
            raise EcahdError(f"replan_spacing must be >= 0 m or -1 (by the map), got "
                             f"{self.replan_spacing}")

    def spacing_on(self, grid, expert_spacing: float | None = None, *,
                   general: bool = False) -> float | None:
        """[m] the re-plans' spacing on ``grid`` for an SD model whose expert waypoints lie
        ``expert_spacing`` [m] apart (``replan_spacing`` -1: by both,
        :func:`~ecahd_core.planning.horizon.auto_replan_spacing`; 0: None, off)."""
        return replan_spacing_for(grid, None if self.replan_spacing == -1
                                  else self.replan_spacing, expert_spacing, general=general)


@dataclass(frozen=True)
class PlanOutcome:
    """A plan :meth:`OnlinePlanner.step` made and the runner accepted.

    Attributes:
        waypoints: (P, 2) [m] the plan to publish, the robot's position first, the goal last.
        method: "sd", "astar", "fd" or "fallback_astar" (A* round remembered obstacles).
        ms: [ms] planning wall time.
        request: the runner's PlanRequest it answers (its ``reason``: "goal", "waypoint",
            "timeout", "blocked", ...).
        follow: index of the waypoint whose reach asks for the next re-plan (GlobalStep's).
        sparse: SD's plan with its N candidates (method "sd"), else None.
        detail: what the rules did, for the log.
    """

    waypoints: np.ndarray
    method: str
    ms: float
    request: PlanRequest
    follow: int = 1
    sparse: object = None
    detail: str = ""


class OnlinePlanner:
    """The online Algorithm 1's global half: the GlobalRunner decides *when* to plan, this
    decides *what*, with the offline planner's own :class:`~ecahd_core.planning.rules.
    SparseStage` for every SD plan; global_planner converts messages and calls it.

    Beyond the offline planner, online (ours): SD weighs its candidates by J and places its
    waypoints on the static map fused with the obstacles the scans found (``observe``); an SD
    plan that still crosses one, or a third "blocked" re-plan, is replaced by A* round what is
    known (the fallback, followed to the goal); a goal that the footprint does not fit moves
    at most SNAP_DISTANCE; where placement is off (maze2d-large) SD's waypoints in a wall snap
    out by at most SNAP_DISTANCE, since local_refiner refines each segment with its ends fixed
    (the offline planner's joined polishing may move them).

    Args:
        config: OnlinePlannerConfig.
        runner: the GlobalRunner's settings (its replan_spacing is decided per map).
        footprint: the Footprint waypoints must clear (with global_planner's clearance margin).
        clock: () -> now [s]: sim time or wall time, or a fake one in tests.
        generator: SD's and FD's random numbers (a seed reproduces a plan sequence).
    """

    def __init__(self, config: OnlinePlannerConfig, runner: GlobalRunnerConfig, footprint, *,
                 clock, generator=None) -> None:
        self.config = config
        # the baselines plan one whole path per goal: no re-plans, no timeout
        if config.method != "sd":
            runner = replace(runner, replan="once", replan_timeout=0.0)
        self.runner = GlobalRunner(runner)
        self.footprint = footprint
        self.clock = clock
        self.generator = generator
        self.grid = None
        self.stage = None  # rules.SparseStage (method sd)
        self.astar = None  # astar.AStarPlanner (method astar)
        self.fd = None  # full.FullDiffusion (method fd)
        self.memory = None  # sensing.ObstacleMemory of the scanned obstacles
        self.fallbacks = 0  # A* fallbacks so far
        self._placers: dict = {}  # (kind, fused grid key) -> WaypointPlacer
        self._reach = 0.0  # [m] placement's reach on the current map
        self._tried = 0  # maps the last fallback tried

    # ---------------------------------------------------------------------------- inputs
    @property
    def ready(self) -> bool:
        """A map arrived and the planner of ``method`` is built on it."""
        return any(x is not None for x in (self.stage, self.astar, self.fd))

    @property
    def replan_spacing(self) -> float | None:
        return self.runner.config.replan_spacing

    def set_map(self, grid, *, sd=None, astar=None, fd=None, learnt=None, lanes=None) -> None:
        """A new map with the planner of ``method`` built on it (``sd``: a SparseDiffusion
        without a placer; ``astar``: an AStarPlanner with the footprint's clearance; ``fd``: a
        FullDiffusion). Builds the placers and the subgoal rule's graph now, so no re-plan pays
        for them; an active goal is planned again. ``learnt``: the map of this site the models
        learnt when ``grid`` is an update of it: walls added since are treated as a scanned
        blockage that never leaves (SD's plans crossing one are detoured by A*). ``lanes``: a
        LaneField of this map (``ecahd lanes``) or None: SD's waypoints are moved onto it
        (``lanes.WaypointLanes``); EcahdError when it does not belong to ``grid``."""
        from ecahd_core.placement import auto_reach
        from ecahd_core.sensing import ObstacleMemory

        c = self.config
        self.grid, self._placers = grid, {}
        self.memory = ObstacleMemory(grid, c.obstacle_memory)
        if learnt is not None and learnt is not grid:
            self.memory.learnt_from(learnt)
        self.astar, self.fd, self.stage = astar, fd, None
        spacing = (c.spacing_on(grid, sd.expert_spacing, general=sd.general)
                   if sd is not None else None)
        self.runner.config = replace(self.runner.config, replan_spacing=spacing)
        if sd is not None:
            self._reach = (auto_reach(grid, general=sd.general) if c.place_reach < 0
                           else c.place_reach)
            placer = self._placer(grid, "place") if self.placement_on else None
            self.stage = SparseStage(sd.on(placer=placer), replan=self.runner.config.replan,
                                     replan_spacing=spacing, subgoals=c.subgoals,
                                     settle=c.settle)
            if self.stage.subgoaling():
                self.stage.subgoal_rule().field.graph  # the cost-to-go's graph, built now
            if lanes is not None:
                from ecahd_core.lanes import WaypointLanes

                self.stage.lanes = WaypointLanes(lanes, grid, self.footprint)
        if self.runner.goal is not None:
            self.runner.set_goal(self.runner.goal)  # plan again on the new map

    @property
    def placement_on(self) -> bool:
        """Whether placement (``place_reach``) moves SD's waypoints farther than the goal
        snap."""
        return self._reach > SNAP_DISTANCE

    def set_goal(self, goal) -> None:
        """A new goal (2,) [m], already validated, pre-empts the current one."""
        self.runner.set_goal(goal)

    def request_replan(self, reason: str) -> None:
        """The local stage cannot follow the plan (``reason``, e.g. "blocked")."""
        self.runner.request_replan(reason)

    def cancel(self) -> None:
        """Drop the goal and its plan: nothing is planned until the next goal."""
        self.runner.cancel()

    def observe(self, window, now: float) -> None:
        """A local costmap window (GridMap): its obstacles are remembered for re-plans."""
        if self.memory is not None:
            self.memory.update(window, now)

    # --------------------------------------------------------------------------- the call
    def step(self, xy) -> PlanOutcome | str | None:
        """The robot is at ``xy`` (2,) [m]: "reached" once when the goal is reached, a
        PlanOutcome when a plan was made (and accepted by the runner), else None. Raises
        PlanningError naming the problem when no plan can be made (a goal that cannot be
        reached is dropped)."""
        if not self.ready:
            return None
        event = self.runner.step(xy, self.clock())
        if isinstance(event, PlanRequest):
            return self._plan(event)
        return event

    def _plan(self, request: PlanRequest) -> PlanOutcome:
        try:
            goal = self.grid.validate_point(request.goal, "goal")
            start = self.grid.validate_point(request.start, "robot pose")
        except PlanningError as exc:
            if str(exc).startswith("goal"):
                self.runner.fail()
            raise PlanningError(f"cannot plan: {exc}") from None
        method, sparse, follow, detail = self.config.method, None, 1, ""
        t0 = time.perf_counter()
        if request.reason == "blocked" and (
                method != "sd" or self.runner.blocked_count >= BLOCKED_BEFORE_FALLBACK):
            method = "fallback_astar"  # SD could not get round it: A* on what is known
            waypoints = self._fallback(start, goal)
            detail = self._fallback_detail()
        elif method == "sd":
            waypoints, sparse, follow, detail = self._plan_sd(request, start, goal)
            if self._crosses_remembered(waypoints):  # SD cannot see round it: detour now
                method, sparse, follow = "fallback_astar", None, 1
                waypoints = self._fallback(start, goal)
                detail = (" (SD's best crossed an obstacle the scans found or a wall added "
                          "since the map its model learnt)" + self._fallback_detail())
        elif method == "astar":
            waypoints = self._astar(start, goal)
        else:
            waypoints = self.fd.plan(start, goal, generator=self.generator)
            waypoints[0], waypoints[-1] = start, goal  # exact ends (the model works in float32)
        ms = (time.perf_counter() - t0) * 1e3
        self.runner.accept(waypoints, self.clock(), hold=method == "fallback_astar",
                           follow=follow)
        return PlanOutcome(waypoints=waypoints, method=method, ms=ms, request=request,
                           follow=follow, sparse=sparse, detail=detail)

    def _plan_sd(self, request: PlanRequest, start: np.ndarray, goal: np.ndarray):
        """SparseStage.step for ``request`` on what is known now -> (waypoints (P, 2) [m],
        SparsePlan, follow, detail)."""
        now = self.clock()
        fused = self._fused(now)  # built once a plan: a whole grid on a big map
        goal = self._snap_goal(start, goal, fused)
        stage = self.stage
        sd = stage.sd
        if fused is not self.grid:  # J and placement see the remembered obstacles too
            sd = sd.on(cost=self.memory.fused_cost(now, sd.cost) if sd.cost is not None
                       else None,
                       placer=self._placer(fused, "place") if sd.placer is not None else None)
        # a re-plan at a reached waypoint may start from the rest of the current plan
        # (warm_fraction; from noise when 0, bit for bit)
        previous = self.runner.waypoints if request.reason == "waypoint" else None
        step = stage.step(start, goal, previous, iteration=request.iteration,
                          horizon=request.horizon, sd=sd, generator=self.generator,
                          stalled=request.stalled)
        waypoints = step.waypoints.copy()
        waypoints[0], waypoints[-1] = start, goal  # exact ends (the model works in float32)
        detail = (" (toward a subgoal on the shortest route"
                  + (", stalled: the goal's last plans started within a metre)"
                     if request.stalled else ")")
                  if step.sparse.first_leg == "subgoal"
                  else f" (candidate {step.sparse.best} of {len(step.sparse.candidates)})")
        if step.sparse.placed:
            detail += f", {step.sparse.placed} waypoint(s) moved out of or added round walls"
        if not self.placement_on and len(waypoints) > 2:
            waypoints, moved = self._placer(fused, "snap")(waypoints,
                                                           last_reach=SNAP_DISTANCE)
            if moved:
                detail += f", {moved} waypoint(s) snapped out of walls"
        if step.settled:
            detail += ", every leg free: followed whole (settle rule)"
        elif step.follow > 1 and not step.forced:
            detail += (f", legs free up to the subgoal: followed to waypoint {step.follow} "
                       "(settle rule)")
        elif step.forced:
            detail += ", out of iterations: the last plan followed whole"
        return waypoints, step.sparse, step.follow, detail

    def _snap_goal(self, start: np.ndarray, goal: np.ndarray, grid) -> np.ndarray:
        """``goal`` moved at most SNAP_DISTANCE to where the footprint fits on ``grid`` (the
        static or fused map; itself if it fits or nothing within reach does)."""
        placed, _ = self._placer(grid, "snap")(np.stack([start, goal]),
                                               last_reach=SNAP_DISTANCE)
        return placed[-1]

    def _fused(self, now: float):
        """The static map with the obstacles the scans found (remembered for
        ``obstacle_memory`` s unless seen gone), or the static map itself."""
        if self.memory is None or not self.memory.mask(now).any():
            return self.grid
        return self.memory.fused(now)

    def _placer(self, grid, kind: str):
        """The WaypointPlacer of ``kind`` ("place": placement and leg repair with the
        configured reach; "snap": SNAP_DISTANCE, no leg repair) on ``grid`` (the static map or
        a fused one), its distance transform built once per grid."""
        from ecahd_core.placement import WaypointPlacer

        key = (kind, None if grid is self.grid else grid.occupied.tobytes())
        if key not in self._placers:
            c = self.config
            if len(self._placers) > 8:  # fused grids come and go with the scans
                self._placers = {k: v for k, v in self._placers.items() if k[1] is None}
            self._placers[key] = (
                WaypointPlacer(grid, self.footprint, reach=self._reach, leg_rounds=c.leg_repair,
                               repair_reach=c.repair_reach if c.repair_reach > 0 else None)
                if kind == "place" else
                WaypointPlacer(grid, self.footprint, reach=SNAP_DISTANCE, leg_rounds=0))
        return self._placers[key]

    def _crosses_remembered(self, waypoints: np.ndarray) -> bool:
        """Whether the straight legs of ``waypoints`` (P, 2) [m] sweep the footprint over an
        obstacle the scans found and the memory still holds (the static map's walls are DD's
        and polishing's business; a scanned blockage is not in what SD learnt)."""
        return self.memory is not None and self.memory.crosses(waypoints, self.footprint,
                                                               self.clock())

    def _fallback(self, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """A* with the footprint's clearance round the remembered obstacles
        (``ObstacleMemory.detour``), resampled ASTAR_SPACING apart -> (N, 2) [m]."""
        from ecahd_core.controller import resample

        try:
            path, self._tried = self.memory.detour(self.footprint, start, goal, self.clock())
        except PlanningError as exc:
            raise PlanningError(f"{exc}; the robot waits for a way to open") from None
        self.fallbacks += 1
        return resample(path, ASTAR_SPACING)

    def _fallback_detail(self) -> str:
        return (f" (A* fallback after {self.runner.blocked_count} blocked segment(s), "
                f"{int(self.memory.mask(self.clock()).sum())} remembered obstacle cells, tried "
                f"{self._tried} of 2 maps, {self.fallbacks} fallback(s) so far)")

    def _astar(self, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """A* from ``start`` to ``goal`` -> (N, 2) [m], ASTAR_SPACING apart at most. An
        unreachable goal or one without clearance is dropped."""
        from ecahd_core.astar import plan_from_pose
        from ecahd_core.controller import resample

        try:
            path = plan_from_pose(self.astar, start, goal)
        except PlanningError as exc:  # the pose was validated: the goal is the problem
            self.runner.fail()
            raise PlanningError(f"goal rejected: {exc}") from None
        return resample(path, ASTAR_SPACING)
