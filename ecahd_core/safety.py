"""The safety net (ours, beyond the paper): no path the exact checker finds in collision is handed
out as the plan to follow.

ECAHD's rules (collision-aware best of N, keep-better, polishing) act on the cost J, a smoothed
surrogate; the referee is the exact swept-footprint checker (``collision.py``). When the referee
still finds the plan in collision, the net acts in this order and reports which rule acted:

1. ``retry``: every local segment the checker finds in collision is sampled again by Dense
   Diffusion, a fresh batch of ``samples`` candidates per round (polished like any DD plan), for
   at most ``retries`` rounds; the shortest candidate the checker finds free replaces the segment
   (its end points stay, so neighbouring segments stay joined). Needs the HierarchicalPlanner
   and the plan's local segments; skipped otherwise (SD, FD, ECAHD w/o DD).
2. ``resample``: "more candidates first" for a route DD cannot bend: the whole plan is drawn
   again by the planner (SD's best of N and the local stage, fresh samples), up to ``resamples``
   times; the first plan the checker finds free is returned. A leg of SD's plan across a wall
   or shelf is what DD cannot repair, and another draw of SD often puts its waypoints on the
   right side. Needs the HierarchicalPlanner; skipped otherwise.
3. ``fallback``: A* with the footprint's clearance (``astar.clearance_for_footprint``) for each
   offending stretch only, from the last point before the collision that keeps that clearance
   to the first such point after it, spliced in (logged at WARNING). A stretch the checker still
   finds in collision is widened by one point on each side and planned again.
4. ``unsafe``: no A* path either (or the fallback is off): the result says so, with the reason;
   callers must not follow it (``ecahd plan`` exits 2).

``none``: the plan was collision-free as it came and is returned untouched.

Frames and units: map frame, metres.
"""
from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field

import numpy as np

from ecahd_core.collision import DEFAULT_TOLERANCE, check_collision, segment_collisions
from ecahd_core.errors import EcahdError, PlanningError
from ecahd_core.footprint import Footprint
from ecahd_core.maps import GridMap

log = logging.getLogger(__name__)

SAFETY_RULES = ("none", "retry", "resample", "fallback", "unsafe")
FALLBACKS = ("astar", "none")


@dataclass(frozen=True, kw_only=True)
class SafetyNetConfig:
    """Settings of the safety net.

    Attributes:
        retries: rounds of fresh Dense Diffusion samples for the colliding local segments
            (rule 1); 0 skips the rule.
        samples: DD candidates per colliding segment and round (one batch).
        resamples: whole plans drawn again (rule 2) before the fallback; 0 skips the rule.
        fallback: "astar" (rule 3: A* with the footprint's clearance for the offending
            stretches) or "none" (a plan still colliding after rules 1 and 2 is unsafe).
        padding: [m] added to the footprint's circumscribed radius for the fallback's A*.
        max_widen: how many times one stretch may be widened (one point each side) when its A*
            path still collides or cannot be planned.
        tolerance: [m] the exact checker's touching tolerance.
    """

    retries: int = 2
    samples: int = 8
    resamples: int = 2
    fallback: str = "astar"
    padding: float = 0.0
    max_widen: int = 4
    tolerance: float = DEFAULT_TOLERANCE

    def __post_init__(self) -> None:
        if self.fallback not in FALLBACKS:
            raise EcahdError(f"safety-net fallback {self.fallback!r} is not one of "
                             f"{list(FALLBACKS)}")
        if self.retries < 0 or self.samples < 1 or self.max_widen < 0 or self.resamples < 0:
            raise EcahdError(f"safety net needs retries >= 0, samples >= 1, resamples >= 0 and "
                             f"max_widen >= 0, got {self.retries}, {self.samples}, "
                             f"{self.resamples}, {self.max_widen}")
        if not (math.isfinite(self.padding) and self.padding >= 0):
            raise EcahdError(f"safety-net padding must be a finite number >= 0 m, "
                             f"got {self.padding!r}")


@dataclass(frozen=True)
class SafePlan:
    """Result of :meth:`SafetyNet.apply`.

    Attributes:
        path: (M, 2) [m] the plan to follow (when ``rule`` is "unsafe": the best the net got,
            for diagnosis only).
        rule: which rule acted last, one of SAFETY_RULES.
        collided_before: the exact checker found the input plan in collision.
        stretches: (first, last) indices into ``path`` (inclusive) of each A* stretch spliced in.
        retried_segments: local segments replaced by rule 1.
        resampled: whole plans drawn by rule 2.
        reason: why the plan is unsafe ("" otherwise).
        time_ms: wall time of the net (checks included).
    """

    path: np.ndarray
    rule: str
    collided_before: bool
    stretches: tuple = ()
    retried_segments: int = 0
    resampled: int = 0
    reason: str = ""
    time_ms: float = 0.0

    @property
    def safe(self) -> bool:
        """The exact checker finds ``path`` collision-free."""
        return self.rule != "unsafe"

    def stretch_paths(self) -> list[np.ndarray]:
        """Each spliced A* stretch as a (K, 2) [m] array."""
        return [self.path[a:b + 1] for a, b in self.stretches]


@dataclass
class _Work:
    """Mutable state of one :meth:`SafetyNet.apply` call."""

    path: np.ndarray
    stretches: list = field(default_factory=list)


class SafetyNet:
    """The safety net for one map and footprint; the fallback's A* planner (its clearance mask
    is the expensive part) is built once, on first need, and reused.

    Args:
        grid: the map the exact checker judges against.
        footprint: the robot.
        config: SafetyNetConfig.
        planner: a ``HierarchicalPlanner`` with DD, for rule 1 (None: rule 1 is skipped).
        astar: a ready ``AStarPlanner`` for ``grid`` with the fallback's clearance (optional).
    """

    def __init__(self, grid: GridMap, footprint: Footprint, config: SafetyNetConfig | None = None,
                 *, planner=None, astar=None) -> None:
        from ecahd_core.astar import clearance_for_footprint

        self.grid = grid
        grid.free_distance  # noqa: B018  once per map: the exact checks below pass far poses
        self.footprint = footprint
        self.config = config or SafetyNetConfig()
        self.planner = planner
        self.clearance = clearance_for_footprint(footprint, padding=self.config.padding)
        if astar is not None and (astar.grid is not grid
                                  or abs(astar.clearance - self.clearance) > 1e-9):
            raise EcahdError(f"the safety net's A* must plan on map {grid.name!r} with clearance "
                             f"{self.clearance:.3f} m, got clearance {astar.clearance:.3f} m")
        self._astar = astar

    @property
    def astar(self):
        """The fallback's AStarPlanner (built on first use)."""
        if self._astar is None:
            from ecahd_core.astar import planner_for

            self._astar = planner_for(self.grid, self.clearance)
        return self._astar

    def check(self, path: np.ndarray):
        """The referee: ``collision.check_collision`` with this net's footprint and map."""
        return check_collision(path, self.footprint, self.grid, tolerance=self.config.tolerance)

    # ---------------------------------------------------------------------------------- apply
    def apply(self, plan_path, *, segments=None, generator=None) -> SafePlan:
        """Judge ``plan_path`` (N, 2) [m] by the exact checker and repair it if it collides.

        Args:
            plan_path: (N, 2) [m] the plan (e.g. ``HierarchicalPlan.trajectory``).
            segments: the plan's local segments, each (P^l, 2) [m], joined end to start into
                ``plan_path`` (``HierarchicalPlan.segments``); needed by rule 1.
            generator: torch.Generator for the samples of rules 1 and 2.

        Returns:
            SafePlan; ``rule`` says which rule acted ("unsafe": do not follow ``path``).
        """
        t0 = time.perf_counter()
        path = np.array(plan_path, dtype=np.float64)
        if path.ndim != 2 or path.shape[1] != 2 or len(path) < 1:
            raise EcahdError(f"the safety net needs a (N, 2) path, got shape {path.shape}")
        report = self.check(path)

        resampled = 0

        def done(rule, p, *, stretches=(), retried=0, reason=""):
            return SafePlan(path=p, rule=rule, collided_before=not report.collision_free,
                            stretches=tuple(stretches), retried_segments=retried,
                            resampled=resampled, reason=reason,
                            time_ms=(time.perf_counter() - t0) * 1e3)

        if report.collision_free:
            return done("none", path)
        retried = 0
        if self.config.retries and segments is not None and self._can_replan():
            segs = [np.array(s, dtype=np.float64) for s in segments]
            retried = self._retry(segs, generator)
            if retried:
                path = np.concatenate([segs[0]] + [s[1:] for s in segs[1:]])
                if self.check(path).collision_free:
                    log.info("safety net: %d local segment(s) sampled again by DD, now "
                             "collision-free", retried)
                    return done("retry", path, retried=retried)
        if self.config.resamples and self._can_replan():
            for resampled in range(1, self.config.resamples + 1):
                again = np.array(self.planner.plan(path[0], path[-1], generator=generator
                                                   ).trajectory, dtype=np.float64)
                if self.check(again).collision_free:
                    log.info("safety net: plan drawn again (%d of at most %d), now "
                             "collision-free", resampled, self.config.resamples)
                    return done("resample", again, retried=retried)
        if self.config.fallback == "none":
            return done("unsafe", path, retried=retried,
                        reason="the plan collides and the A* fallback is off")
        work = _Work(path=path)
        reason = self._fallback(work)
        if reason:
            log.warning("safety net: no safe plan: %s", reason)
            return done("unsafe", work.path, stretches=work.stretches, retried=retried,
                        reason=reason)
        return done("fallback", work.path, stretches=work.stretches, retried=retried)

    # ---------------------------------------------------------------------- rule 1: retries
    def _can_replan(self) -> bool:
        return self.planner is not None and getattr(self.planner, "dd", None) is not None

    def _retry(self, segs: list[np.ndarray], generator) -> int:
        """Replace colliding local segments (in place) by fresh DD samples the checker finds free.
        Returns how many were replaced."""
        import torch

        bad = [k for k, s in enumerate(segs) if not self.check(s).collision_free]
        replaced = 0
        for _ in range(self.config.retries):
            still = []
            for k in bad:
                a = torch.as_tensor(segs[k][0], dtype=torch.float32)
                b = torch.as_tensor(segs[k][-1], dtype=torch.float32)
                cands, _ = self.planner.resample_segment(a, b, samples=self.config.samples,
                                                         generator=generator)
                cands = cands.numpy().astype(np.float64)
                cands[:, 0], cands[:, -1] = segs[k][0], segs[k][-1]  # exact joins (not float32)
                free = [c for c in cands if self.check(c).collision_free]
                if free:
                    segs[k] = min(free, key=lambda c: float(
                        np.linalg.norm(np.diff(c, axis=0), axis=1).sum()))
                    replaced += 1
                else:
                    still.append(k)
            bad = still
            if not bad:
                break
        return replaced

    # --------------------------------------------------------------------- rule 2: fallback
    def _anchor(self, xy: np.ndarray, *, exact: bool = True) -> bool:
        """A point A* may start or end a stretch at: its cell is traversable and (``exact``) the
        exact distance to the nearest obstacle square keeps the clearance, so the footprint is
        free there at any heading."""
        if not bool(self.grid.in_bounds(np.asarray(xy)[None])[0]):
            return False
        astar = self.astar
        row, col = (int(v) for v in self.grid.world_to_cell(xy))
        if not astar.mask[row, col]:
            return False
        return not exact or astar.point_clearance(xy) >= self.clearance - 1e-6

    def _fallback(self, work: _Work) -> str:
        """Splice A* stretches over every collision of ``work.path``, left to right. Returns ""
        on success, else the reason the plan is unsafe."""
        from ecahd_core.astar import plan_from_pose

        done_until = 0  # path index before which everything is judged or spliced
        for _ in range(4 * len(work.path) + 8):  # bound: every pass consumes >= 1 point
            path = work.path
            bad_seg = self._bad_segments(path)
            todo = np.flatnonzero(bad_seg[done_until:]) + done_until
            if not len(todo):
                return ""
            i = int(todo[0])  # the first colliding segment i -> i + 1
            j = i  # extend over the following colliding segments
            while j + 1 < len(bad_seg) and bad_seg[j + 1]:
                j += 1
            anchors = [k for k in range(len(path)) if self._anchor(path[k])]
            before = [k for k in anchors if done_until <= k <= i]
            after = [k for k in anchors if k >= j + 1]
            last = len(path) - 1  # the goal only needs a traversable cell (A*'s own rule)
            if (not after or after[-1] != last) and self._anchor(path[last], exact=False):
                after.append(last)
            s = before[-1] if before else (0 if done_until == 0 else None)
            if s is None or not after:
                return (f"no point keeping the clearance {self.clearance:.3f} m "
                        f"{'before' if s is None else 'after'} the collision at "
                        f"({path[i, 0]:.2f}, {path[i, 1]:.2f}) to plan A* from")
            e = after[0]
            stretch, last_error = None, ""
            for widen in range(self.config.max_widen + 1):
                try:
                    cand = plan_from_pose(self.astar, path[s], path[e])
                except PlanningError as exc:
                    last_error = str(exc)
                else:
                    if self.check(cand).collision_free:
                        stretch = cand
                        break
                    last_error = "its A* path still collides"
                earlier = [k for k in before if k < s]
                later = [k for k in after if k > e]
                if widen == self.config.max_widen or not (earlier or later):
                    break
                s = earlier[-1] if earlier else s
                e = later[0] if later else e
            if stretch is None:
                return (f"no A* path with clearance {self.clearance:.3f} m around the collision "
                        f"at ({path[i, 0]:.2f}, {path[i, 1]:.2f}) from "
                        f"({path[s, 0]:.2f}, {path[s, 1]:.2f}) to "
                        f"({path[e, 0]:.2f}, {path[e, 1]:.2f}): {last_error}")
            log.warning("safety net: fallback: A* stretch of %d points spliced in from "
                        "(%.2f, %.2f) to (%.2f, %.2f) over a collision the diffusion plan kept",
                        len(stretch), path[s, 0], path[s, 1], path[e, 0], path[e, 1])
            work.path = np.concatenate([path[:s], stretch, path[e + 1:]])
            work.stretches.append((s, s + len(stretch) - 1))
            done_until = s + len(stretch) - 1
        return "the fallback did not converge"

    def _bad_segments(self, path: np.ndarray) -> np.ndarray:
        """(N, 2) path -> (N - 1,) bool: ``collision.segment_collisions`` with this net's
        footprint, map and tolerance."""
        return segment_collisions(path, self.footprint, self.grid,
                                  tolerance=self.config.tolerance)
