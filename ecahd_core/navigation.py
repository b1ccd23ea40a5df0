"""The online Algorithm 1 (paper Sec. III-A) as two runtime classes driven by poses and a clock,
with no rclpy: the ROS nodes only convert messages and call them (Nav2's controller_server /
controller plugin split), and unit tests drive them with fake clocks and poses.

:class:`GlobalRunner` (global_planner): when to ask the Sparse Diffusion planner for a plan.
    A goal asks for a plan of horizon P^g at once; each time the robot comes within
    ``waypoint_tolerance`` of the plan's next waypoint, the p-th replan asks for horizon
    P^g - p (Algorithm 1 lines 2-11, ``replan`` "every_waypoint"; with ``replan_spacing``, ours,
    at least what the distance left needs, :func:`replan_horizon`); with ``replan`` "once" (ours,
    and the Table III baselines A* and FD) one plan serves the whole goal. Beyond the paper, a
    robot that makes no progress toward its next waypoint for ``replan_timeout`` seconds replans
    from where it is, and goals that arrive faster than ``min_plan_interval`` are coalesced (the
    latest wins), so the planning work does not grow with the goal rate.

:class:`LocalRunner` (local_refiner): Algorithm 1 lines 13-18 and the controller.
    The global plan's segments W[k-1] -> W[k] (the first from the robot's pose when the plan
    arrived) go to a ``refine`` function (J check, DD when c^l > c_th, polishing, the exact
    check) that runs on a worker thread, ``prepare_ahead`` segments ahead of the robot, so the
    control tick never waits for DD. :meth:`LocalRunner.tick` is bounded work: pure pursuit on
    the current segment's local plan (resampled once, searched in a window around the robot's
    progress), the next segment's local plan taken over when the robot reaches its waypoint
    and the plan is ready. With nothing safe to follow (the segment not refined yet, or refined
    but still in collision by the exact checker) the command is zero velocity.

Poses are (x [m], y [m], yaw [rad]); plans are (P, 2) [m] in the global frame; ``now`` is a
clock reading in seconds (sim time or wall time, the caller's choice).
"""
from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from ecahd_core.controller import PathTracker, pure_pursuit
from ecahd_core.errors import EcahdError, PlanningError

log = logging.getLogger("ecahd.navigation")

REPLAN_POLICIES = ("every_waypoint", "once")
REPLAN_SPACING = 3.0  # [m] the least replan spacing chosen on a big map (auto_replan_spacing)
COORDINATE_LIMIT = 1e6  # [m] |x|, |y| beyond this is absurd whatever the map
MAX_PLAN_POINTS = 100_000  # a plan with more poses is rejected
PLAN_MARGIN = 1.0  # [m] plan points may lie this far outside the map's bounds
SIMPLIFY_TOLERANCE = 0.005  # [m] interior plan points this close to the chord are dropped
WAITING_END_DISTANCE = 0.05  # [m] at the end of the local plan with nothing next: stop


def auto_replan_spacing(grid, expert_spacing: float | None = None) -> float | None:
    """[m] the replan spacing (:func:`replan_horizon`) chosen by the map and the SD model: on
    maps over ``astar.COARSE_ABOVE_CELLS`` cells (buildings) the model's ``expert_spacing``
    (``SparseDiffusion.expert_spacing``, the median spacing of the waypoints it learnt), at
    least REPLAN_SPACING; None (Algorithm 1's P^g - p) on smaller maps, so maze2d-large keeps
    the paper's rule.

    Measured (docs/RESULTS.md): 3 m fits the warehouses (expert spacing 2.6-2.7 m); on the
    60 x 60 m office (6.5 m) 3 m asked for twice the waypoints SD learnt and 6.5 m beat it on
    ECAHD alone, fallbacks and time."""
    from ecahd_core.astar import COARSE_ABOVE_CELLS

    if grid.width * grid.height <= COARSE_ABOVE_CELLS:
        return None
    return max(REPLAN_SPACING, expert_spacing or 0.0)


def replan_spacing_for(grid, value: float | None,
                       expert_spacing: float | None = None) -> float | None:
    """A replan-spacing setting [m] as the commands take it: None by the map and the model
    (:func:`auto_replan_spacing`), 0 off, else ``value``."""
    if value is None:
        return auto_replan_spacing(grid, expert_spacing)
    if not (math.isfinite(value) and value >= 0):
        raise EcahdError(f"replan spacing must be >= 0 m (0: off), got {value}")
    return value or None


def check_replan_spacing(spacing: float | None) -> float | None:
    """``spacing`` [m] if it is None (off) or a finite number > 0, else EcahdError."""
    if spacing is not None and not (math.isfinite(spacing) and spacing > 0):
        raise EcahdError(f"replan_spacing must be None (off) or a finite number > 0 m, "
                         f"got {spacing}")
    return spacing


def replan_horizon(horizon: int, iteration: int, start, goal,
                   spacing: float | None = None) -> int:
    """The horizon of Algorithm 1's p-th SD plan: P^g - p, at least 2 (line 2).

    With ``spacing`` [m] (ours, for big maps; None: the paper's rule) at least
    ceil(D / spacing) + 1 and at most P^g, for the straight distance D [m] from ``start`` (2,)
    to ``goal`` (2,): the horizon shrinks with the distance left, not with the count of
    waypoints reached. Algorithm 1 as written ends with a plan of horizon 2, the straight line
    to the goal, after P^g - 2 re-plans wherever the robot then is; on a building SD's first
    waypoints often lie close together, and that last straight leg crossed shelf rows for
    8-35 m (every colliding circle-robot plan on a generated warehouse, docs/RESULTS.md)."""
    h = max(2, horizon - iteration)
    if spacing is not None:
        d = float(np.linalg.norm(np.asarray(goal, dtype=np.float64)
                                 - np.asarray(start, dtype=np.float64)))
        h = max(h, min(horizon, int(math.ceil(d / spacing - 1e-9)) + 1))
    return h


# --------------------------------------------------------------------------- input checks
def validate_pose(pose, what: str = "pose") -> tuple[float, float, float]:
    """(x, y, yaw) finite and within COORDINATE_LIMIT, else PlanningError naming ``what``."""
    x, y, yaw = (float(v) for v in pose)
    if not all(math.isfinite(v) for v in (x, y, yaw)):
        raise PlanningError(f"{what} is not finite: ({x}, {y}, {yaw})")
    if abs(x) > COORDINATE_LIMIT or abs(y) > COORDINATE_LIMIT:
        raise PlanningError(f"{what} ({x:g}, {y:g}) is absurdly far (> {COORDINATE_LIMIT:g} m)")
    return x, y, yaw


def validate_plan(xy, bounds: tuple[float, float, float, float] | None = None) -> np.ndarray:
    """A plan (P, 2) [m] that can be followed, else PlanningError saying why: non-empty, at most
    MAX_PLAN_POINTS, finite, and within ``bounds`` (xmin, ymin, xmax, ymax) [m] widened by
    PLAN_MARGIN (or within COORDINATE_LIMIT without a map)."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    P = len(xy)
    if P == 0:
        raise PlanningError("plan has no poses")
    if P > MAX_PLAN_POINTS:
        raise PlanningError(f"plan has {P} poses, more than {MAX_PLAN_POINTS}")
    if not np.all(np.isfinite(xy)):
        bad = int(np.flatnonzero(~np.isfinite(xy).all(axis=1))[0])
        raise PlanningError(f"plan pose {bad} is not finite: {xy[bad].tolist()}")
    if bounds is None:
        lo, hi = np.full(2, -COORDINATE_LIMIT), np.full(2, COORDINATE_LIMIT)
    else:
        lo = np.array(bounds[:2]) - PLAN_MARGIN
        hi = np.array(bounds[2:]) + PLAN_MARGIN
    outside = np.flatnonzero(((xy < lo) | (xy > hi)).any(axis=1))
    if len(outside):
        i = int(outside[0])
        raise PlanningError(f"plan pose {i} ({xy[i, 0]:.4g}, {xy[i, 1]:.4g}) lies off the map "
                            f"(x in [{lo[0]:.4g}, {hi[0]:.4g}], y in [{lo[1]:.4g}, {hi[1]:.4g}])")
    return xy


def simplify(xy: np.ndarray, tolerance: float = SIMPLIFY_TOLERANCE) -> np.ndarray:
    """(P, 2) -> (Q, 2), Q <= P: consecutive duplicates and interior points within
    ``tolerance`` [m] of the chord between their kept neighbours dropped (Ramer-Douglas-Peucker,
    iterative), ends kept. A 10 000-pose straight plan becomes 2 points, so the number of
    segments (each one J check) follows the plan's shape, not its sampling."""
    keep_d = np.ones(len(xy), dtype=bool)
    keep_d[1:] = np.linalg.norm(np.diff(xy, axis=0), axis=1) > 1e-9
    xy = xy[keep_d]
    if len(xy) <= 2:
        return xy
    keep = np.zeros(len(xy), dtype=bool)
    keep[0] = keep[-1] = True
    stack = [(0, len(xy) - 1)]
    while stack:
        i, j = stack.pop()
        if j - i < 2:
            continue
        a, b = xy[i], xy[j]
        seg = b - a
        pts = xy[i + 1:j] - a
        n = float(np.hypot(*seg))
        d = (np.abs(seg[0] * pts[:, 1] - seg[1] * pts[:, 0]) / n if n > 1e-12
             else np.linalg.norm(pts, axis=1))
        k = int(np.argmax(d))
        if d[k] > tolerance:
            m = i + 1 + k
            keep[m] = True
            stack += [(i, m), (m, j)]
    return xy[keep]


# ----------------------------------------------------------------------------- global stage
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
        self.stall_timeout = config.replan_timeout  # [s] the last timeout replan's wait

    @property
    def active(self) -> bool:
        return self.goal is not None

    @property
    def pending(self) -> bool:
        """A goal waits for its first plan (e.g. coalesced in a burst)."""
        return self.goal is not None and self._pending

    def set_goal(self, goal) -> None:
        """A new goal (2,) [m] pre-empts the current one."""
        g = np.asarray(goal, dtype=np.float64).reshape(2)
        if not np.all(np.isfinite(g)):
            raise PlanningError(f"goal is not finite: {g.tolist()}")
        self.goal, self.waypoints, self.iteration, self._pending = g, None, 0, True
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
        return PlanRequest(xy, self.goal.copy(), self._horizon(xy), reason, self.iteration)

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


# ------------------------------------------------------------------------------ local stage
@dataclass(frozen=True)
class SegmentResult:
    """One segment's local stage as the refiner follows it.

    Attributes:
        plan: (P^l, 2) [m] the local plan.
        c_before, c_after: J's collision cost of the straight plan and of ``plan`` (None
            without a map).
        stage: "straight" (no map), "j_check" (J below c_th), "dd" (DD ran).
        safe: the exact checker finds ``plan`` collision-free (True without a map).
        ms: [ms] wall time of the whole local stage.
        polished: polishing ran.
    """

    plan: np.ndarray
    c_before: float | None = None
    c_after: float | None = None
    stage: str = "straight"
    safe: bool = True
    ms: float = 0.0
    polished: bool = False


@dataclass(frozen=True, kw_only=True)
class LocalRunnerConfig:
    """Settings of :class:`LocalRunner` (units in brackets; the node's parameters)."""

    control_period: float = 0.05  # [s]
    max_v: float = 0.5  # [m/s]
    max_w: float = 1.5  # [rad/s]
    max_accel: float = 1.0  # [m/s^2]
    lookahead: float = 0.25  # [m]
    waypoint_tolerance: float = 0.3  # [m]
    goal_tolerance: float = 0.25  # [m]
    stale_timeout: float = 1.0  # [s]
    plan_timeout: float = 0.0  # [s], 0 = never
    prepare_ahead: int = 2  # segments refined ahead of the one being followed

    def __post_init__(self) -> None:
        for name in ("control_period", "max_v", "max_w", "max_accel", "lookahead",
                     "waypoint_tolerance", "goal_tolerance", "stale_timeout"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise EcahdError(f"{name} must be a finite number > 0, got {value!r}")
        if not (math.isfinite(self.plan_timeout) and self.plan_timeout >= 0):
            raise EcahdError(f"plan_timeout must be >= 0 s, got {self.plan_timeout!r}")
        if self.prepare_ahead < 0:
            raise EcahdError(f"prepare_ahead must be >= 0, got {self.prepare_ahead}")


@dataclass(frozen=True)
class Command:
    """One control tick's output: v [m/s], w [rad/s] and why (``reason``: "follow",
    "no_odom", "stale_odom", "no_plan", "plan_timeout", "goal_reached", "waiting" for a
    segment still being refined, "blocked" by a segment the exact checker finds in collision)."""

    v: float
    w: float
    reason: str


RefineFn = Callable[[np.ndarray, np.ndarray], SegmentResult]


def _run_now(fn: Callable[[], SegmentResult]) -> Future:
    """A ``submit`` that runs the job at once (tests, and no worker thread)."""
    future: Future = Future()
    try:
        future.set_result(fn())
    except Exception as exc:  # noqa: BLE001 (reported through the future)
        future.set_exception(exc)
    return future


class LocalRunner:
    """The local stage and the controller online (see the module docstring).

    Args:
        config: LocalRunnerConfig.
        refine: (start (2,), end (2,)) [m] -> SegmentResult; None follows straight segments.
        submit: runs a job, returning a Future; None = a worker thread of this runner
            (``synchronous=True``: run jobs inside the call that submits them).
        worker_nice: that worker thread's nice value is raised by this much
            (``threads.lower_priority``): DD yields the CPU to the control ticks.
    Thread safety: :meth:`set_plan`, :meth:`set_pose`, :meth:`tick` are called from one
    thread (or under the caller's lock); jobs finish on the worker.
    """

    def __init__(self, config: LocalRunnerConfig, refine: RefineFn | None = None, *,
                 submit: Callable[[Callable[[], SegmentResult]], Future] | None = None,
                 synchronous: bool = False, worker_nice: int = 0) -> None:
        from ecahd_core.threads import lower_priority

        self.config = config
        self.refine = refine
        self._pool = None
        if submit is None and not synchronous:
            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="local_stage",
                                            initializer=lower_priority,
                                            initargs=(worker_nice,))
            submit = self._pool.submit
        self._submit = submit or _run_now
        self._lock = threading.Lock()
        self.pose: tuple[float, float, float] | None = None
        self.pose_time: float | None = None
        self.waypoints: np.ndarray | None = None  # (P, 2) the simplified global plan
        self.plan_time: float | None = None
        self.generation = 0  # increases with every plan
        self.segment = 0  # index of the waypoint the followed local plan ends at
        self.tracker: PathTracker | None = None  # the followed local plan
        self.current: SegmentResult | None = None
        self._starts: dict[int, np.ndarray] = {}  # segment k -> its start when not W[k-1]
        self._jobs: dict[int, Future] = {}  # segment k of this generation -> its job
        self._reported: set[int] = set()  # segments of this generation whose result was reported
        self.v = 0.0  # [m/s] the last command
        self.events: list[tuple[str, object]] = []  # ("segment", SegmentResult), ("blocked",
        #   SegmentResult), ("goal_reached", None), ("error", str): drained by the caller
        self.dd_calls = 0

    # ----------------------------------------------------------------------------- inputs
    def set_pose(self, pose, now: float) -> None:
        """The robot's (x, y, yaw) at ``now`` [s]; PlanningError if not finite."""
        self.pose = validate_pose(pose, "odometry pose")
        self.pose_time = now

    def set_plan(self, waypoints, now: float,
                 bounds: tuple[float, float, float, float] | None = None) -> None:
        """A new global plan (P, 2) [m]: validated (see :func:`validate_plan`), simplified, its
        first ``prepare_ahead`` + 1 segments submitted for refinement. An empty plan stops."""
        xy = np.asarray(waypoints, dtype=np.float64).reshape(-1, 2)
        if len(xy) == 0:
            self.clear_plan()
            return
        xy = simplify(validate_plan(xy, bounds))
        if len(xy) == 1:
            xy = np.concatenate([xy, xy])
        for job in self._jobs.values():
            job.cancel()
        self.generation += 1
        self.waypoints, self.plan_time, self._jobs, self._reported = xy, now, {}, set()
        self._starts = {1: np.array(self.pose[:2]) if self.pose is not None else xy[0]}
        self._target = 1  # the next segment to take over (the followed one stays meanwhile)
        self._submit_ahead()

    def clear_plan(self) -> None:
        for job in self._jobs.values():
            job.cancel()
        self.generation += 1
        self.waypoints, self.tracker, self.current, self._jobs = None, None, None, {}
        self._reported = set()

    def reset_costs(self) -> None:
        """The map changed: every segment of the current plan is refined again."""
        if self.waypoints is not None:
            self.set_plan(self.waypoints, self.plan_time if self.plan_time is not None else 0.0)

    # ------------------------------------------------------------------------------ tick
    def tick(self, now: float) -> Command:
        """One control period: bounded work, never waits for a refinement."""
        c = self.config
        if self.pose is None:
            return self._stop("no_odom")
        if now - self.pose_time > c.stale_timeout:
            return self._stop("stale_odom")
        if self.waypoints is None:
            return self._stop("no_plan")
        if c.plan_timeout > 0 and now - self.plan_time > c.plan_timeout:
            return self._stop("plan_timeout")
        xy = np.array(self.pose[:2])
        goal_distance = float(np.linalg.norm(self.waypoints[-1] - xy))
        if goal_distance < c.goal_tolerance:
            self.clear_plan()
            self.events.append(("goal_reached", None))
            return self._stop("goal_reached")
        # take over the next segment: the first one of a new plan at once, a later one when
        # the robot reaches the waypoint the followed one ends at
        k = self._target
        due = (self.tracker is None or self.segment != k - 1 or k == 1
               or np.linalg.norm(self.waypoints[k - 1] - xy) < c.waypoint_tolerance)
        if k < len(self.waypoints) and due:
            result = self._result(k)
            if result is not None:
                if not result.safe:
                    self.tracker = self.current = None  # nothing safe to follow
                    self._target = k  # stays blocked until a new plan
                    return self._stop("blocked")
                self.tracker, self.current, self.segment = PathTracker(result.plan), result, k
                self._target = k + 1
                self._submit_ahead()
        if self.tracker is None:
            return self._stop("waiting")
        target, remaining = self.tracker.lookahead(xy, c.lookahead)
        if remaining < WAITING_END_DISTANCE and self.segment < len(self.waypoints) - 1:
            return self._stop("waiting")  # at the end of the followed plan, the next not ready
        v, w = pure_pursuit(self.pose, target, goal_distance, self.v, c.control_period, c)
        self.v = v
        return Command(v, w, "follow")

    def recheck(self, judge: Callable[[np.ndarray], bool]) -> int:
        """The world changed (a scan saw something): ``judge(plan (P, 2)) -> safe`` re-judges
        the rest of the followed local plan and every prepared one. A followed plan no longer
        safe is dropped (zero velocity) and its segment refined again from the robot's pose; a
        prepared one is refined again. Returns how many plans were invalidated.

        The same in two steps, so that a node judges without holding its lock (the exact
        checker takes tens of ms per plan on a 0.03 m map): :meth:`recheck_items` (under the
        lock), ``judge`` each item's plan (without it), :meth:`apply_recheck` (under it)."""
        return self.apply_recheck(judge_items(self.recheck_items(), judge))

    def recheck_items(self) -> list[tuple]:
        """What :meth:`recheck` judges: (kind, key, token, plan (P, 2) or None) for the rest of
        the followed plan ("followed"), each finished safe prepared plan ("prepared") and a
        blocked target segment ("blocked", retried when the world changed; nothing to judge)."""
        if self.waypoints is None:
            return []
        items: list[tuple] = []
        if self.tracker is not None and self.pose is not None:
            ahead = np.concatenate([np.array(self.pose[:2])[None],
                                    self.tracker.points[self.tracker.index:]])
            items.append(("followed", self.segment, self.tracker, ahead))
        for k, job in list(self._jobs.items()):
            if k < self._target or k == self.segment and self.tracker is not None:
                continue
            if not job.done() or job.cancelled() or job.exception() is not None:
                continue
            if job.result().safe:
                items.append(("prepared", k, job, job.result().plan))
            elif k == self._target and self.tracker is None and self.pose is not None:
                items.append(("blocked", k, job, None))
        return items

    def apply_recheck(self, verdicts: list[tuple[tuple, bool]]) -> int:
        """Act on ((kind, key, token, plan), safe) pairs from :meth:`recheck_items`; an item
        whose plan was replaced meanwhile (another tracker or job) is skipped. Returns how
        many plans were invalidated."""
        invalid = 0
        for (kind, k, token, _), safe in verdicts:
            if kind == "followed":
                if self.tracker is token and self.pose is not None and not safe:
                    invalid += 1
                    self.tracker = self.current = None
                    self._target = k
                    self._starts[k] = np.array(self.pose[:2])
                    self._resubmit(k)
            elif self._jobs.get(k) is not token:
                continue
            elif kind == "prepared" and not safe:
                invalid += 1
                self._resubmit(k)
            elif kind == "blocked" and k == self._target and self.tracker is None \
                    and self.pose is not None:  # blocked: the world changed, try again
                self._starts[k] = np.array(self.pose[:2])
                self._resubmit(k)
        return invalid

    def _resubmit(self, k: int) -> None:
        old = self._jobs.pop(k, None)
        if old is not None:
            old.cancel()
        self._reported.discard(k)
        a, b = self._segment_ends(k)
        self._jobs[k] = self._submit(self._job(a.copy(), b.copy()))

    def pop_events(self) -> list[tuple[str, object]]:
        events, self.events = self.events, []
        return events

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)

    # ---------------------------------------------------------------------------- helpers
    def _stop(self, reason: str) -> Command:
        self.v = 0.0
        return Command(0.0, 0.0, reason)

    def _segment_ends(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        return self._starts.get(k, self.waypoints[k - 1]), self.waypoints[k]

    def _submit_ahead(self) -> None:
        """Jobs for segments _target .. _target + prepare_ahead not yet submitted."""
        last = min(len(self.waypoints) - 1, self._target + self.config.prepare_ahead)
        for k in range(self._target, last + 1):
            if k not in self._jobs:
                a, b = self._segment_ends(k)
                self._jobs[k] = self._submit(self._job(a.copy(), b.copy()))

    def _job(self, a: np.ndarray, b: np.ndarray) -> Callable[[], SegmentResult]:
        refine = self.refine

        def run() -> SegmentResult:
            if refine is None:
                return SegmentResult(plan=np.stack([a, b]))
            return refine(a, b)
        return run

    def _result(self, k: int) -> SegmentResult | None:
        """Segment k's result if its job is done (a failed job counts as blocked)."""
        job = self._jobs.get(k)
        if job is None or not job.done() or job.cancelled():
            return None
        first = k not in self._reported  # each result is reported once
        self._reported.add(k)
        if job.exception() is not None:
            if first:
                self.events.append(("error", f"local stage of segment {k} failed: "
                                             f"{job.exception()}"))
            a, b = self._segment_ends(k)
            return SegmentResult(plan=np.stack([a, b]), safe=False)
        result = job.result()
        if first:
            self.events.append(("segment" if result.safe else "blocked", result))
            self.dd_calls += int(result.stage == "dd")
        return result


class SegmentRefiner:
    """The ``refine`` of a LocalRunner: one segment's local stage
    (:meth:`~ecahd_core.planner.HierarchicalPlanner.local_stage`: the straight LocalPlan, J,
    DD above c_th, keep-better, polishing; both ends fixed) judged by the exact checker.

    When the refined plan still collides by the exact checker: the straight plan if the exact
    checker finds it free (J's c_th is only a trigger), else the cheapest of ``retries`` fresh
    DD samples (one batch, polished) that it finds free; else the segment is blocked.
    A local plan that starts in contact (the robot already touches a wall) is safe when it goes
    no deeper than its start: it leads out. With ``exact`` False every plan counts as safe (the
    paper's ablations, which follow straight segments whatever they hit).

    Args:
        planner: a HierarchicalPlanner (only its local stage is used).
        grid: the GridMap the exact checker judges on; footprint: the robot.
        generator: the DD sampler's torch.Generator (a seed reproduces the plans).
    """

    def __init__(self, planner, grid, footprint, *, generator=None, exact: bool = True,
                 retries: int = 8) -> None:
        self.planner, self.grid, self.footprint = planner, grid, footprint
        self.generator = generator
        self.retries = retries  # fresh DD samples when the refined plan still collides
        self.exact = exact  # False: every plan counts as safe (the paper's ablations)

    def set_world(self, grid, costmap) -> None:
        """Judge on ``grid`` and guide DD / polishing by ``costmap`` from now on (the static map
        fused with what the scans see: :class:`ecahd_core.sensing.LocalWorld`)."""
        self.grid, self.planner.costmap = grid, costmap

    def judge(self, plan: np.ndarray) -> bool:
        """The exact checker's verdict on ``plan`` (P, 2): collision-free, or starting in contact
        and going no deeper (it leads out)."""
        from ecahd_core.collision import check_collision

        if not self.exact:
            return True
        report = check_collision(plan, self.footprint, self.grid)
        return bool(report.collision_free or (
            report.colliding[0] and float(report.depths[1:].max(initial=0.0))
            <= float(report.depths[0]) + 1e-6))

    def __call__(self, a: np.ndarray, b: np.ndarray) -> SegmentResult:
        """a, b: (2,) [m] -> SegmentResult (plan (P^l, 2) [m] float64)."""
        import time

        import torch

        t0 = time.perf_counter()
        stage = self.planner.local_stage(torch.as_tensor(a, dtype=torch.float32),
                                         torch.as_tensor(b, dtype=torch.float32),
                                         end_fixed=True, generator=self.generator)
        plan = self._exact_ends(stage.plan, a, b)
        safe = self.judge(plan)
        c_after = stage.c_after
        if not safe and (stage.dd_used or stage.polished):
            # the exact checker has the last word: a straight plan it finds free is never
            # replaced by a colliding DD plan, and fresh DD samples get a chance
            straight = np.linspace(a, b, len(plan))
            if self.judge(straight):
                plan, safe, c_after = straight, True, stage.c_before
            elif self.retries > 0 and self.planner.dd is not None:
                segs, costs = self.planner.resample_segment(
                    torch.as_tensor(a, dtype=torch.float32),
                    torch.as_tensor(b, dtype=torch.float32), samples=self.retries,
                    generator=self.generator)
                for i in np.argsort(costs.numpy()):
                    candidate = self._exact_ends(segs[i], a, b)
                    if self.judge(candidate):
                        plan, safe, c_after = candidate, True, float(costs[i])
                        break
        return SegmentResult(plan=plan, c_before=stage.c_before, c_after=c_after,
                             stage="dd" if stage.dd_used else "j_check", safe=safe,
                             ms=(time.perf_counter() - t0) * 1e3, polished=stage.polished)

    @staticmethod
    def _exact_ends(plan, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        out = plan.detach().numpy().astype(np.float64)
        out[0], out[-1] = a, b  # exact ends (the models work in float32)
        return out


def judge_items(items: list[tuple], judge: Callable[[np.ndarray], bool]) -> list[tuple]:
    """:meth:`LocalRunner.recheck_items` -> the (item, safe) verdicts
    :meth:`LocalRunner.apply_recheck` takes; an item with no plan to judge counts as safe."""
    return [(item, True if item[-1] is None else judge(item[-1])) for item in items]


DETOUR_MARGIN = 8.0  # [m] detour's first search: the box round start and goal grown by this
DETOUR_BOX_MAX = 0.5  # a box holding more than this part of the map's cells is not searched first


def detour(grid, footprint, start, goal, *, reach: float = 0.6,
           margin: float | None = DETOUR_MARGIN, coarse: bool = True) -> np.ndarray:
    """A path round what ``grid`` knows (e.g. the static map fused with the local costmap):
    A* with the footprint's clearance between the traversable cells nearest ``start`` and
    ``goal`` (within ``reach`` m, in one connected region), joined to both by a straight hop,
    so a pose or goal in a cell whose clearance A*'s grid rounds down still gets a path (the
    exact checker judges every hop). start, goal: (2,) [m] -> (N, 2) [m], start first, goal
    last. Raises PlanningError when no region holds both.

    On a big map the search first runs on the box round start and goal grown by ``margin`` m
    (outside it counts as occupied, so its paths are safe) unless that box holds most of the
    map, the whole map only if that finds none. None: the whole map at once. ``coarse``: on a
    grid of more than ``astar.COARSE_ABOVE_CELLS`` cells the search is the coarse A* (paths
    within about 1% of the shortest; 12x faster on a 60 x 60 m office at 0.03 m/cell,
    ``ecahd bench replan``); False: exact A* on every grid."""
    start, goal = (np.asarray(p, dtype=np.float64).reshape(2) for p in (start, goal))
    if margin is not None:
        lo, hi = np.minimum(start, goal) - margin, np.maximum(start, goal) + margin
        box = grid.crop(lo[0], lo[1], hi[0], hi[1])
        if box is not grid and box.height * box.width <= DETOUR_BOX_MAX * grid.height * grid.width:
            try:
                return _detour(box, footprint, start, goal, reach, coarse)
            except PlanningError:
                pass
    return _detour(grid, footprint, start, goal, reach, coarse)


def _detour(grid, footprint, start: np.ndarray, goal: np.ndarray, reach: float,
            coarse: bool) -> np.ndarray:
    """:func:`detour` on ``grid`` as it is."""
    from ecahd_core.astar import AStarPlanner, clearance_for_footprint, planner_for

    clearance = clearance_for_footprint(footprint)
    # a fresh planner per call (the grid changes with the scans), so no ALT landmarks
    planner = planner_for(grid, clearance, landmarks=0) if coarse \
        else AStarPlanner(grid, clearance)
    near_start, near_goal = (_cells_within(planner, p, reach) for p in (start, goal))
    best = None
    for label in np.unique(near_start[2]):
        ins, ing = near_start[2] == label, near_goal[2] == label
        if not ing.any():
            continue
        i = np.flatnonzero(ins)[np.argmin(near_start[1][ins])]
        j = np.flatnonzero(ing)[np.argmin(near_goal[1][ing])]
        if best is None or near_start[1][i] + near_goal[1][j] < best[0]:
            best = (near_start[1][i] + near_goal[1][j], near_start[0][i], near_goal[0][j])
    if best is None:
        raise PlanningError(f"no path with the footprint's clearance joins ({start[0]:.2f}, "
                            f"{start[1]:.2f}) and ({goal[0]:.2f}, {goal[1]:.2f}) on what is "
                            "known")
    _, a, b = best
    middle = planner.plan(a, b)
    return np.concatenate([start[None], middle, goal[None]])


def _cells_within(planner, xy: np.ndarray, reach: float):
    """The traversable cells of ``planner`` whose centres lie within ``reach`` m of ``xy``:
    (centres (K, 2) [m], distances (K,) [m], region labels (K,)), in row-major order."""
    grid = planner.grid
    r = int(np.ceil(reach / grid.resolution)) + 1
    row, col = (int(v) for v in grid.world_to_cell(xy))
    r0, c0 = max(row - r, 0), max(col - r, 0)
    window = planner.mask[r0:max(row + r + 1, 0), c0:max(col + r + 1, 0)]
    rows, cols = np.nonzero(window)
    rows, cols = rows + r0, cols + c0
    centres = grid.cell_to_world(rows, cols)
    d = np.linalg.norm(centres - xy, axis=1)
    keep = d <= reach
    return centres[keep], d[keep], planner.components[rows[keep], cols[keep]]


SNAP_DISTANCE = 0.2  # [m] a goal in collision moves at most this far (< waypoint_tolerance)
