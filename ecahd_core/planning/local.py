"""The online Algorithm 1's local half (paper Sec. III-A, lines 13-18, and the controller) as
runtime classes with no rclpy: local_refiner only converts messages and calls them.

:class:`LocalRunner`: the global plan's segments W[k-1] -> W[k] (the first from the robot's
    pose when the plan arrived) go to a ``refine`` function (J check, DD when c^l > c_th,
    polishing, the exact check: :class:`SegmentRefiner` over the same local stage as the
    offline planner, :meth:`~ecahd_core.planning.dense.DenseStage.local_stage`)
    that runs on a worker thread, ``prepare_ahead`` segments ahead of the robot, so the control
    tick never waits for DD. :meth:`LocalRunner.tick` is bounded work: pure pursuit on the
    current segment's local plan (resampled once, searched in a window around the robot's
    progress), the next segment's local plan taken over when the robot reaches its waypoint
    and the plan is ready. With nothing safe to follow (the segment not refined yet, or refined
    but still in collision by the exact checker) the command is zero velocity.

Poses are (x [m], y [m], yaw [rad]); plans are (P, 2) [m] in the global frame; ``now`` is a
clock reading in seconds (sim time or wall time, the caller's choice).
"""
from __future__ import annotations

import math
import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from ecahd_core.controller import PathTracker, pure_pursuit
from ecahd_core.errors import EcahdError
from ecahd_core.validation import simplify, validate_plan, validate_pose

WAITING_END_DISTANCE = 0.05  # [m] at the end of the local plan with nothing next: stop
ALIGN_GAIN = 1.5  # [1/s] turning in place to the goal's heading: w = gain * heading error
MIN_ALIGN_W = 0.2  # [rad/s] ... but at least this fast (within max_w)
PASSED_REACH = 1.0  # [m] a plan's waypoint counts as passed by the robot only this near it


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
    shaped: bool = False  # moved onto the lanes learnt from demonstrations (ecahd_core.lanes)


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
    yaw_goal_tolerance: float = 0.25  # [rad] a goal with a heading: turned to within this
    stale_timeout: float = 1.0  # [s]
    plan_timeout: float = 0.0  # [s], 0 = never
    prepare_ahead: int = 2  # segments refined ahead of the one being followed
    # precise tracking: with less room than precise_room [m] beside the robot or at the
    # waypoint it heads for (LocalRunner.room), pure pursuit uses precise_lookahead and the
    # take-over waypoint_tolerance precise_tolerance (0 = off)
    precise_room: float = 0.05  # [m]
    precise_lookahead: float = 0.1  # [m]
    precise_tolerance: float = 0.15  # [m]

    def __post_init__(self) -> None:
        if not (math.isfinite(self.precise_room) and self.precise_room >= 0):
            raise EcahdError(f"precise_room must be a finite number >= 0, got "
                             f"{self.precise_room!r}")
        for name in ("control_period", "max_v", "max_w", "max_accel", "lookahead",
                     "waypoint_tolerance", "goal_tolerance", "yaw_goal_tolerance",
                     "stale_timeout", "precise_lookahead", "precise_tolerance"):
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
    segment still being refined, "blocked" by a segment the exact checker finds in collision,
    "aligning": turning in place to the goal's heading, "heading_blocked": turning in place
    would hit something, so the goal ends at its position)."""

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
        self.goal_yaw: float | None = None  # [rad] the plan's goal heading (None: any)
        self.waypoints_passed = 0  # plans' waypoints the robot had passed when they arrived
        # (x, y, yaw) -> the robot may turn in place there (None: always)
        self.can_turn: Callable[[tuple[float, float, float]], bool] | None = None
        # (N, 2) [m] -> (N,) [m] room beside the footprint there (None: always room; precise
        # tracking off)
        self.room: Callable[[np.ndarray], np.ndarray] | None = None
        self.precise_ticks = 0  # control ticks that tracked precisely

    # ----------------------------------------------------------------------------- inputs
    def set_pose(self, pose, now: float) -> None:
        """The robot's (x, y, yaw) at ``now`` [s]; PlanningError if not finite."""
        self.pose = validate_pose(pose, "odometry pose")
        self.pose_time = now

    def set_plan(self, waypoints, now: float,
                 bounds: tuple[float, float, float, float] | None = None,
                 goal_yaw: float | None = None) -> None:
        """A new global plan (P, 2) [m]: validated (see :func:`validate_plan`), simplified, its
        first ``prepare_ahead`` + 1 segments submitted for refinement. An empty plan stops.
        ``goal_yaw`` [rad]: at the goal the robot turns in place to this heading (None: any)."""
        if goal_yaw is not None and not math.isfinite(goal_yaw):
            raise EcahdError(f"the goal's heading is not finite: {goal_yaw!r}")
        xy = np.asarray(waypoints, dtype=np.float64).reshape(-1, 2)
        if len(xy) == 0:
            self.clear_plan()
            return
        xy = simplify(validate_plan(xy, bounds))
        if len(xy) == 1:
            xy = np.concatenate([xy, xy])
        passed = self.passed_waypoints(xy)
        if passed:  # planned from where the robot was: do not send it back to them
            xy = np.concatenate([xy[:1], xy[1 + passed:]])
            self.waypoints_passed += passed
        for job in self._jobs.values():
            job.cancel()
        self.generation += 1
        self.waypoints, self.plan_time, self._jobs, self._reported = xy, now, {}, set()
        self.goal_yaw = goal_yaw
        self._starts = {1: np.array(self.pose[:2]) if self.pose is not None else xy[0]}
        self._target = 1  # the next segment to take over (the followed one stays meanwhile)
        self._submit_ahead()

    def passed_waypoints(self, xy: np.ndarray) -> int:
        """How many of plan xy's (P, 2) [m] first interior waypoints the robot has already
        passed: a plan made from an earlier pose arrives while the robot drives on (SD's time,
        a late message). W[k] is passed when the robot, within PASSED_REACH of it, lies beyond
        it along W[k-1] -> W[k]; the goal never is. 0 without a pose."""
        if self.pose is None:
            return 0
        p = np.array(self.pose[:2])
        k = 1
        while k < len(xy) - 1:
            a, b = xy[k - 1], xy[k]
            ab = b - a
            beyond = float((p - a) @ ab) >= float(ab @ ab)  # projection past b
            if not (beyond and np.linalg.norm(p - b) <= PASSED_REACH):
                break
            k += 1
        return k - 1

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
            turn = self._align()
            if turn is not None:
                return turn
            self.clear_plan()
            self.events.append(("goal_reached", None))
            return self._stop("goal_reached")
        # take over the next segment: the first one of a new plan at once, a later one when
        # the robot reaches the waypoint the followed one ends at
        k = self._target
        lookahead, tolerance = self._tracking(xy, k)
        due = (self.tracker is None or self.segment != k - 1 or k == 1
               or np.linalg.norm(self.waypoints[k - 1] - xy) < tolerance)
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
        target, remaining = self.tracker.lookahead(xy, lookahead)
        if remaining < WAITING_END_DISTANCE and self.segment < len(self.waypoints) - 1:
            return self._stop("waiting")  # at the end of the followed plan, the next not ready
        v, w = pure_pursuit(self.pose, target, goal_distance, self.v, c.control_period, c)
        self.v = v
        return Command(v, w, "follow")

    def _tracking(self, xy: np.ndarray, k: int) -> tuple[float, float]:
        """(lookahead [m], take-over tolerance [m]) for this tick: the precise ones where the
        robot or the waypoint W[k-1] it heads for has less than ``precise_room`` beside the
        footprint. Pure pursuit with a 0.25 m lookahead that takes a segment over 0.3 m before
        its waypoint swings 2-3 cm wide of a sharp turn: enough to graze the jamb of a door
        5 cm wider than the robot (docs/RESULTS.md, closed loop)."""
        c = self.config
        if self.room is None or c.precise_room <= 0 or self.waypoints is None:
            return c.lookahead, c.waypoint_tolerance
        here = np.stack([xy, self.waypoints[min(max(k - 1, 0), len(self.waypoints) - 1)]])
        if float(np.min(self.room(here))) >= c.precise_room:
            return c.lookahead, c.waypoint_tolerance
        self.precise_ticks += 1
        return min(c.lookahead, c.precise_lookahead), min(c.waypoint_tolerance,
                                                           c.precise_tolerance)

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
    def _align(self) -> Command | None:
        """At the goal's position: a turn in place towards the goal's heading, or None when
        there is none to make (no heading, within ``yaw_goal_tolerance``, or turning here would
        hit something: then a "heading_blocked" event, and the goal ends at its position)."""
        if self.goal_yaw is None:
            return None
        yaw = self.pose[2]
        error = (self.goal_yaw - yaw + math.pi) % (2.0 * math.pi) - math.pi
        if abs(error) <= self.config.yaw_goal_tolerance:
            return None
        if self.can_turn is not None and not self.can_turn(self.pose):
            self.events.append(("heading_blocked", error))
            return None
        max_w = self.config.max_w
        w = math.copysign(min(max(abs(ALIGN_GAIN * error), min(MIN_ALIGN_W, max_w)), max_w),
                          error)
        self.v = 0.0
        return Command(0.0, w, "aligning")

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
    (:meth:`~ecahd_core.planning.dense.DenseStage.local_stage`: the straight LocalPlan, J,
    DD above c_th, keep-better, polishing; both ends fixed) judged by the exact checker.

    When the refined plan still collides by the exact checker: the straight plan if the exact
    checker finds it free (J's c_th is only a trigger), else the cheapest of ``retries`` fresh
    DD samples (one batch, polished) that it finds free; else the segment is blocked.
    A local plan that starts in contact (the robot already touches a wall) is safe when it goes
    no deeper than its start: it leads out. With ``exact`` False every plan counts as safe (the
    paper's ablations, which follow straight segments whatever they hit).

    Args:
        planner: a DenseStage (or a HierarchicalPlanner: its local stage).
        grid: the GridMap the exact checker judges on; footprint: the robot.
        generator: the DD sampler's torch.Generator (a seed reproduces the plans).
        lanes: a LaneField (``ecahd lanes``) or None: a safe local plan is then moved sideways
            onto where the robot was driven in its direction (``lanes.shape_path``: its ends
            fixed, never into collision by the exact checker on the current grid).
    """

    def __init__(self, planner, grid, footprint, *, generator=None, exact: bool = True,
                 retries: int = 8, lanes=None) -> None:
        self.planner, self.grid, self.footprint = planner, grid, footprint
        self.generator = generator
        self.lanes = lanes
        self.retries = retries  # fresh DD samples when the refined plan still collides
        self.exact = exact  # False: every plan counts as safe (the paper's ablations)

    def set_world(self, grid, costmap) -> None:
        """Judge on ``grid`` and guide DD / polishing by ``costmap`` from now on (the static map
        fused with what the scans see: :class:`ecahd_core.sensing.LocalWorld`)."""
        self.grid, self.planner.costmap = grid, costmap

    def can_turn(self, pose) -> bool:
        """The footprint may turn in place at ``pose`` (x, y, yaw): every wall is at least its
        circumscribed radius from the position (a circle always may where it stands free)."""
        from ecahd_core.collision import wall_distance

        if self.footprint.is_circle:  # turning sweeps nothing new
            return True
        xy = np.asarray(pose[:2], dtype=np.float64).reshape(1, 2)
        return bool(wall_distance(self.grid, xy)[0] >= self.footprint.circumscribed_radius)

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
        shaped = False
        if safe and self.exact and self.lanes is not None:
            from ecahd_core.lanes import shape_path

            moved = shape_path(plan, self.lanes, self.grid, self.footprint)
            plan, shaped = (moved.path, True) if moved.shaped else (plan, False)
        return SegmentResult(plan=plan, c_before=stage.c_before, c_after=c_after,
                             stage="dd" if stage.dd_used else "j_check", safe=safe,
                             ms=(time.perf_counter() - t0) * 1e3, polished=stage.polished,
                             shaped=shaped)

    @staticmethod
    def _exact_ends(plan, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        out = plan.detach().numpy().astype(np.float64)
        out[0], out[-1] = a, b  # exact ends (the models work in float32)
        return out


def judge_items(items: list[tuple], judge: Callable[[np.ndarray], bool]) -> list[tuple]:
    """:meth:`LocalRunner.recheck_items` -> the (item, safe) verdicts
    :meth:`LocalRunner.apply_recheck` takes; an item with no plan to judge counts as safe."""
    return [(item, True if item[-1] is None else judge(item[-1])) for item in items]

