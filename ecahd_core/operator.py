"""A scripted operator with habits A* does not have, its driving, and the habit metric
(issue 41, items 3 and 4).

Demonstrations are only worth learning from if they carry something the A* expert does not.
The operator here plans each route with A* and then applies a site's habit:

* **keep right**: in every corridor wider than twice the robot it drives in the right-hand
  half, relative to its direction of travel;
* **no-go zones**: it never enters a marked polygon of free floor (``zones:`` in the scenario
  file, :func:`ecahd_core.scenario.read_zones`).

Corridors and their right half (the definition the metric and the operator share)
---------------------------------------------------------------------------------
At a point p of a path, travelling in the unit direction t (the direction of the path's
segment through p; the operator's smoothed tangent), the *cross-section* is the line through
p along the left normal n = rot90(t). d_L and d_R [m] are the distances from p along +n and
-n to the first occupied cell of the map (unknown and off the map count as occupied),
sampled every half cell (so exact to half a cell). The point is **in a corridor** when

    2 x (robot's circumscribed diameter) < w = d_L + d_R <= ``max_corridor_width`` (4 m)

(wider cross-sections are open floor: rooms, lobbies, docks; narrower ones leave the robot no
half to keep to), and **on the right half** when d_R < d_L. The right-half share of a set of
paths is the length on the right half over the length in corridors, both summed over all paths
(:func:`habit_metrics`); A*'s shortest paths, which hug whichever wall the route turns round,
score about 50% (measured in test/test_operator.py).

A path **enters a zone** when one of its points, taken every quarter cell along it, lies inside
the zone's polygon (the robot's centre; the operator itself keeps its whole footprint out).

How the operator keeps right (the choice)
-----------------------------------------
A*'s path is offset sideways, not searched with a direction-dependent cost: A* over (cell,
heading) states would multiply the search by 8 and its cost would need a weight to tune, while
the offset states the habit directly and reuses the expert's planner. Steps
(:meth:`Operator.keep_right`):

1. A* (:func:`~ecahd_core.astar.planner_for`) with the zones drawn into the map as occupied
   cells, the expert's clearance (the footprint's circumscribed radius r: with r + margin
   the 0.9 m doors of a generated office close for the 0.4 m circle), then the path
   resampled every ``spacing`` m with a tangent smoothed over +-``tangent_reach`` m.
2. At each point in a corridor (above, on the map without the zones) the lateral shift that puts
   it at d_R = max(``lane`` x w, r + margin) (``lane`` 0.25: the middle of the right half), never
   closer to the right wall than r + margin. Elsewhere no shift; gaps of at most ``gap_fill`` m between
   corridor points (a door or a side corridor opening on one side) take the shift of their
   ends, interpolated, so the route does not swerve at each door.
3. The shift is smoothed (moving average over ``ramp`` m) and faded to 0 over ``ramp`` m at
   the start and the goal, which stay exactly where they are (0.5 m: on 3 generated offices
   86.5 / 72.5 / 88.9% of the corridor length on the right half, 1.0 m: 79.4 / 63.2 / 82.7%,
   the lane going over after each door more slowly).
4. Safety: where a shifted point has less clearance than r + margin / 2 (or than A*'s point
   had, if less) on the map with the zones (``maps.signed_distance``), or the exact checker
   (:func:`~ecahd_core.collision.check_collision`, the footprint along the path) finds the
   shifted path in an occupied cell, the shift there and within ``ramp`` m is halved, up to
   ``repairs`` times, then set to 0 there (A*'s own path); a path still colliding is replaced
   by A*'s (counted: ``Route.offset`` False).

Driving (:func:`drive_route`): pure pursuit (:func:`~ecahd_core.controller.pure_pursuit`, the
local_refiner's controller and limits) on the unicycle kinematics of the simulator
(:func:`~ecahd_core.controller.unicycle_step`), ticking at the recording rate; the robot stands
``stop_time`` s at each goal (longer than ``DemoConfig.stop_time``, so the demonstrations are
cut there). Simulated time, no real-time wait.

Units: metres, seconds, radians, map frame. No rclpy, no rosbags here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ecahd_core.errors import EcahdError

HABITS = ("keep-right", "zone")  # keep-right: the right half of corridors; zone: zones only
MAX_CORRIDOR_WIDTH = 4.0  # [m] a wider cross-section is open floor, not a corridor
CORRIDOR_ROBOTS = 2.0  # a corridor is wider than this many robot diameters
_RAY_BLOCK = 1 << 22  # bound on (points x ray samples) per vectorised block


class OperatorError(EcahdError):
    """A zone or route the operator cannot use."""


# --------------------------------------------------------------------------- corridors
def cross_sections(grid, xy, direction, *, reach: float = MAX_CORRIDOR_WIDTH
                   ) -> tuple[np.ndarray, np.ndarray]:
    """(d_L, d_R) [m], each (M,): distance from each point xy (M, 2) [m] along the left normal
    of ``direction`` (M, 2) (any length > 0) and along its opposite to the first occupied cell
    (off the map counts as occupied), sampled every half cell; ``inf`` when none within
    ``reach`` [m]."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    t = np.asarray(direction, dtype=np.float64).reshape(-1, 2)
    t = t / np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    n = np.column_stack([-t[:, 1], t[:, 0]])  # (M, 2) left normal
    h = grid.resolution / 2
    steps = np.arange(1, int(math.ceil(reach / h)) + 1) * h  # (K,) [m]
    occ = grid.occupied
    ox, oy = grid.origin
    out = []
    for sign in (1.0, -1.0):
        dist = np.full(len(xy), np.inf)
        rows_per = max(1, _RAY_BLOCK // len(steps))
        for i in range(0, len(xy), rows_per):
            p = xy[i:i + rows_per, None, :] + sign * steps[None, :, None] * n[i:i + rows_per, None]
            col = np.floor((p[..., 0] - ox) / grid.resolution).astype(np.int64)  # (m, K)
            row = np.floor((p[..., 1] - oy) / grid.resolution).astype(np.int64)
            inside = (row >= 0) & (row < grid.height) & (col >= 0) & (col < grid.width)
            hit = ~inside
            hit[inside] = occ[row[inside], col[inside]]
            first = np.argmax(hit, axis=1)  # (m,) first occupied sample (0 if none)
            any_hit = hit[np.arange(len(first)), first]
            dist[i:i + rows_per] = np.where(any_hit, steps[first], np.inf)
        out.append(dist)
    return out[0], out[1]


def corridor_bounds(footprint, *, max_width: float = MAX_CORRIDOR_WIDTH) -> tuple[float, float]:
    """(narrowest, widest) cross-section [m] that counts as a corridor (module docstring):
    more than 2 robot diameters, at most ``max_width``."""
    return CORRIDOR_ROBOTS * 2.0 * footprint.circumscribed_radius, float(max_width)


@dataclass(frozen=True)
class HabitMetrics:
    """What :func:`habit_metrics` measured over a set of paths.

    Attributes:
        paths: how many paths.
        length: [m] their total length.
        corridor_length: [m] of it in corridors wider than twice the robot.
        right_length: [m] of that on the right half.
        zone_entries: paths entering a zone (0 when no zone was given).
    """

    paths: int
    length: float
    corridor_length: float
    right_length: float
    zone_entries: int

    @property
    def right_share(self) -> float:
        """Share of the corridor length on the right half, in [0, 1]; nan without corridors."""
        return self.right_length / self.corridor_length if self.corridor_length else math.nan

    @property
    def zone_share(self) -> float:
        """Share of the paths entering a zone, in [0, 1]; nan without paths."""
        return self.zone_entries / self.paths if self.paths else math.nan

    def summary(self) -> str:
        return (f"{self.paths} paths, {self.length:.0f} m, {self.corridor_length:.0f} m in "
                f"corridors, {100 * self.right_share:.1f}% of it on the right half, "
                f"{self.zone_entries} ({100 * self.zone_share:.1f}%) entering a zone")


def habit_metrics(paths, grid, robot, zones=None, *, max_width: float = MAX_CORRIDOR_WIDTH,
                  spacing: float = 0.05) -> HabitMetrics:
    """The habit measures of issue 41 (module docstring) over ``paths`` [(N, 2) [m]] on
    ``grid`` for the Footprint ``robot``: each segment is cut into pieces of at most
    ``spacing`` m, each piece judged at its midpoint in the segment's direction.
    ``zones``: [:class:`~ecahd_core.scenario.Zone`] or None."""
    lo, hi = corridor_bounds(robot, max_width=max_width)
    total = corridor = right = 0.0
    entries = 0
    count = 0
    for path in paths:
        xy = np.asarray(path, dtype=np.float64).reshape(-1, 2)
        count += 1
        if len(xy) < 2:
            continue
        mid, direction, weight = _pieces(xy, spacing)
        total += float(weight.sum())
        if len(mid):
            d_left, d_right = cross_sections(grid, mid, direction, reach=hi)
            width = d_left + d_right
            inside = (width > lo) & (width <= hi)
            corridor += float(weight[inside].sum())
            right += float(weight[inside & (d_right < d_left)].sum())
        if zones and path_enters(xy, zones, step=grid.resolution / 4):
            entries += 1
    return HabitMetrics(paths=count, length=total, corridor_length=corridor,
                        right_length=right, zone_entries=entries)


def _pieces(xy: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Segments of xy (N, 2) cut into pieces of at most ``spacing`` m -> (midpoints (S, 2),
    their segment's direction (S, 2), lengths (S,) [m]); zero-length segments dropped."""
    seg = np.diff(xy, axis=0)
    length = np.linalg.norm(seg, axis=1)
    keep = length > 1e-9
    a, seg, length = xy[:-1][keep], seg[keep], length[keep]
    k = np.maximum(1, np.ceil(length / spacing)).astype(np.int64)  # pieces per segment
    idx = np.repeat(np.arange(len(k)), k)
    j = np.arange(len(idx)) - np.repeat(np.cumsum(k) - k, k)  # piece index within its segment
    frac = (j + 0.5) / k[idx]
    mid = a[idx] + frac[:, None] * seg[idx]
    return mid, seg[idx], (length / k)[idx]


def path_enters(xy, zones, *, step: float) -> bool:
    """Whether a point of the path (N, 2) [m], taken every ``step`` m, lies in a zone."""
    from ecahd_core.controller import resample

    pts = resample(np.asarray(xy, dtype=np.float64).reshape(-1, 2), step)
    return any(bool(z.contains(pts).any()) for z in zones)


# ---------------------------------------------------------------------------- operator
@dataclass(frozen=True, kw_only=True)
class OperatorConfig:
    """How the operator plans (module docstring, steps 1-4).

    Attributes:
        keep_right: apply the keep-right habit (False: A* round the zones only).
        margin: [m] the keep-right lane keeps r + margin from the right wall, and a shift
            never brings a point closer than r + margin / 2 to a wall or zone.
        max_corridor_width: [m] the widest cross-section that is a corridor.
        spacing: [m] between the points of an operator's path.
        tangent_reach: [m] the tangent at a point is the chord over +-this much path.
        gap_fill: [m] a non-corridor gap this short between corridor points keeps the shift.
        ramp: [m] the shift's smoothing window and its fade at the start and goal.
        lane: the lane's distance from the right wall as a share of the corridor's width
            (0.25: the middle of the right half), never below r + margin.
        repairs: how often the shift is halved where a shifted path lacks clearance.
    """

    keep_right: bool = True
    margin: float = 0.1
    max_corridor_width: float = MAX_CORRIDOR_WIDTH
    spacing: float = 0.1
    tangent_reach: float = 0.3
    gap_fill: float = 1.5
    ramp: float = 0.5
    lane: float = 0.25
    repairs: int = 6

    def __post_init__(self) -> None:
        for name in ("margin", "max_corridor_width", "spacing", "tangent_reach", "gap_fill",
                     "ramp", "lane"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise OperatorError(f"operator {name} must be a finite number >= 0, "
                                    f"got {value!r}")
        for name in ("spacing", "max_corridor_width", "ramp"):
            if getattr(self, name) <= 0:
                raise OperatorError(f"operator {name} must be > 0, got {getattr(self, name)!r}")
        if self.lane >= 0.5:
            raise OperatorError(f"operator lane must be < 0.5 (the right half), got {self.lane!r}")
        if not (isinstance(self.repairs, int) and self.repairs >= 0):
            raise OperatorError(f"operator repairs must be an integer >= 0, got {self.repairs!r}")


@dataclass(frozen=True)
class Route:
    """One planned route: the operator's path and A*'s (the same start and goal, the map
    without the zones, the robot's clearance without margin), both (N, 2) [m]; ``offset``:
    the keep-right shift was applied (False: off, or given up for safety)."""

    path: np.ndarray
    astar: np.ndarray
    offset: bool


def zone_grid(grid, zones):
    """The map with every cell whose centre lies in a zone occupied (a GridMap named as the
    map). OperatorError for a zone with no free cell of the map inside (off the map, or on
    walls only: a zone marks free floor)."""
    from dataclasses import replace

    if not zones:
        return grid
    data = np.array(grid.data, dtype=np.int8)
    rows, cols = np.mgrid[0:grid.height, 0:grid.width]
    centres = grid.cell_to_world(rows.ravel(), cols.ravel())  # (H W, 2)
    free = ~grid.occupied.ravel()
    for z in zones:
        lo, hi = z.polygon.min(axis=0), z.polygon.max(axis=0)
        box = np.all((centres >= lo) & (centres <= hi), axis=1)
        inside = np.zeros(len(centres), dtype=bool)
        inside[box] = z.contains(centres[box])
        if not (inside & free).any():
            raise OperatorError(f"zone {z.name!r} covers no free cell of map {grid.name!r}: "
                                f"a zone marks free floor the operator avoids")
        data.reshape(-1)[inside] = 100
    return replace(grid, data=data)


class Operator:
    """Plans routes with the habits of :class:`OperatorConfig` on one map for one footprint
    (module docstring).

    Attributes:
        grid: the map; ``planning_grid``: with the zones occupied.
        footprint, zones, config: as given.
        planner: A* on ``planning_grid`` with clearance r (starts and goals are
            sampled from its mask).
        astar: A* on ``grid`` with clearance r (the expert; its paths are what the habit is
            measured against).
    """

    def __init__(self, grid, footprint, zones=(), config: OperatorConfig = OperatorConfig()
                 ) -> None:
        from ecahd_core.astar import clearance_for_footprint, planner_for
        from ecahd_core.maps import signed_distance

        self.grid, self.footprint, self.zones, self.config = grid, footprint, list(zones), config
        self.planning_grid = zone_grid(grid, self.zones)
        r = clearance_for_footprint(footprint)
        self.clearance = r + config.margin
        self.planner = planner_for(self.planning_grid, r)
        self.astar = planner_for(grid, r)
        self._sdf = signed_distance(self.planning_grid)  # (H, W) [m]
        self.planning_grid.free_distance  # noqa: B018  (the exact checker's fast path)

    @property
    def mask(self) -> np.ndarray:
        """(H, W) bool: cells a route may start or end in (the operator's A* mask, its largest
        connected region)."""
        labels = self.planner.components
        counts = np.bincount(labels.ravel())
        counts[0] = 0
        return labels == int(np.argmax(counts))

    def plan(self, start, goal) -> Route:
        """A route from ``start`` to ``goal`` [m] (PlanningError as A*'s)."""
        path = self.planner.plan(start, goal)
        astar = self.astar.plan(start, goal)
        if not self.config.keep_right:
            return Route(path=path, astar=astar, offset=False)
        shifted = self.keep_right(path)
        return Route(path=shifted if shifted is not None else path, astar=astar,
                     offset=shifted is not None)

    def keep_right(self, path) -> np.ndarray | None:
        """A* path (N, 2) [m] -> the keep-right path (M, 2) [m] with the same start and goal
        (module docstring, steps 1-4); None when no safe shift was found."""
        from ecahd_core.collision import check_collision
        from ecahd_core.controller import resample

        c = self.config
        pts = resample(np.asarray(path, dtype=np.float64), c.spacing)  # (M, 2)
        M = len(pts)
        if M < 3:
            return pts
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
        total = s[-1]
        # 1. tangents: chords over +-tangent_reach of arc length
        ahead = np.searchsorted(s, s + c.tangent_reach).clip(max=M - 1)
        behind = np.searchsorted(s, s - c.tangent_reach).clip(min=0)
        tangent = pts[ahead] - pts[behind]
        tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-12)
        normal = np.column_stack([-tangent[:, 1], tangent[:, 0]])  # (M, 2) left
        # 2. the shift to the right lane, in corridors of the map (zones are floor here)
        lo, hi = corridor_bounds(self.footprint, max_width=c.max_corridor_width)
        d_left, d_right = cross_sections(self.grid, pts, tangent, reach=hi)
        width = d_left + d_right
        corridor = (width > lo) & (width <= hi)
        with np.errstate(invalid="ignore"):  # inf - inf off corridors
            target = np.maximum(c.lane * width, self.clearance)
            shift = np.where(corridor, d_right - target, 0.0)  # (M,) [m] > 0: to the right
        shift = _fill_gaps(shift, corridor, s, c.gap_fill)
        # 3. smoothed, faded in and out at the ends
        shift = _moving_average(shift, s, c.ramp)
        shift *= np.clip(np.minimum(s, total - s) / c.ramp, 0.0, 1.0)
        # 4. safety: halve the shift round points without clearance / with a collision
        near = int(math.ceil(c.ramp / c.spacing))
        floor = np.minimum(self.clearance - c.margin / 2, self._clearance_at(pts))
        for attempt in range(c.repairs + 2):
            out = pts - shift[:, None] * normal
            bad = self._clearance_at(out) < floor - 1e-9
            if not bad.any():
                report = check_collision(out, self.footprint, self.planning_grid)
                if report.collision_free:
                    return out
                bad = _poses_to_points(report.colliding, len(out))
            spread = np.convolve(bad.astype(float), np.ones(2 * near + 1), mode="same") > 0
            # halved `repairs` times, then gone there (A*'s own path)
            shift[spread] *= 0.5 if attempt < c.repairs else 0.0
        return None

    def _clearance_at(self, xy: np.ndarray) -> np.ndarray:
        rows, cols = self.planning_grid.world_to_cell(xy)
        inside = ((rows >= 0) & (rows < self.grid.height) & (cols >= 0)
                  & (cols < self.grid.width))
        out = np.full(len(xy), -np.inf)
        out[inside] = self._sdf[rows[inside], cols[inside]]
        return out


def _fill_gaps(shift: np.ndarray, corridor: np.ndarray, s: np.ndarray, gap: float) -> np.ndarray:
    """Non-corridor runs of at most ``gap`` m of arc length between two corridor points take
    the shift interpolated between their ends."""
    out = shift.copy()
    idx = np.flatnonzero(corridor)
    for a, b in zip(idx[:-1], idx[1:]):
        if b - a > 1 and s[b] - s[a] <= gap:
            out[a + 1:b] = np.interp(s[a + 1:b], [s[a], s[b]], [shift[a], shift[b]])
    return out


def _moving_average(x: np.ndarray, s: np.ndarray, window: float) -> np.ndarray:
    """Mean of x over the points within +-window/2 of arc length s (points evenly spaced)."""
    step = float(np.median(np.diff(s))) if len(s) > 1 else 1.0
    k = max(1, int(round(window / max(step, 1e-9))) | 1)  # odd
    pad = np.pad(x, k // 2, mode="edge")
    return np.convolve(pad, np.ones(k) / k, mode="valid")


def _poses_to_points(colliding: np.ndarray, n: int) -> np.ndarray:
    """The path points (n,) near the dense poses the exact checker found colliding, by their
    proportional place along the dense poses (enough to say where to halve the shift)."""
    bad = np.zeros(n, dtype=bool)
    hits = np.flatnonzero(colliding)
    bad[np.clip(np.round(hits * (n - 1) / max(len(colliding) - 1, 1)).astype(np.int64),
                0, n - 1)] = True
    return bad


# ------------------------------------------------------------------------------ driving
@dataclass(frozen=True, kw_only=True)
class DriveConfig:
    """The simulated robot's control and recording (defaults: the local_refiner's limits and
    rate, ``ecahd_ros.local_refiner_params``).

    Attributes:
        rate: [Hz] control ticks = recorded poses per second.
        max_v: [m/s], max_w: [rad/s], max_accel: [m/s^2] limits; lookahead: [m] pure pursuit's.
        goal_tolerance: [m] a route ends this close to its goal.
        stop_time: [s] standing still at each goal.
        timeout_factor: a route gives up after this many times its length / max_v (+ 10 s).
    """

    rate: float = 20.0
    max_v: float = 0.5
    max_w: float = 1.5
    max_accel: float = 1.0
    lookahead: float = 0.25
    goal_tolerance: float = 0.05
    stop_time: float = 3.0
    timeout_factor: float = 4.0

    def __post_init__(self) -> None:
        for name in ("rate", "max_v", "max_w", "max_accel", "lookahead", "goal_tolerance",
                     "stop_time", "timeout_factor"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise OperatorError(f"drive {name} must be a finite number > 0, got {value!r}")


@dataclass
class Drive:
    """One route driven: poses (N, 3) (x [m], y [m], yaw [rad]) and twists (N, 2) (v [m/s],
    w [rad/s]) at each tick, the stop included; whether the goal was reached."""

    poses: np.ndarray
    twists: np.ndarray
    reached: bool
    moving_ticks: int = field(default=0)


def drive_route(path, pose: tuple[float, float, float], config: DriveConfig = DriveConfig()
                ) -> Drive:
    """Drive ``path`` (N, 2) [m] from ``pose`` (x, y, yaw) with pure pursuit on the unicycle
    (module docstring), then stand ``stop_time`` s. Returns the poses after each tick (the
    starting pose not repeated)."""
    from ecahd_core.controller import PathTracker, pure_pursuit, unicycle_step

    c = config
    dt = 1.0 / c.rate
    tracker = PathTracker(np.asarray(path, dtype=np.float64))
    goal = tracker.end
    length = float(tracker._arc[-1])
    ticks_max = int(math.ceil((c.timeout_factor * length / c.max_v + 10.0) * c.rate))
    x, y, yaw = (float(v) for v in pose)
    v = 0.0
    poses, twists = [], []
    reached = False
    for _ in range(ticks_max):
        xy = np.array([x, y])
        to_goal = math.hypot(goal[0] - x, goal[1] - y)
        if to_goal <= c.goal_tolerance:
            reached = True
            break
        target, remaining = tracker.lookahead(xy, c.lookahead)
        v, w = pure_pursuit((x, y, yaw), target, max(remaining, to_goal), v, dt, c)
        x, y, yaw = unicycle_step(x, y, yaw, v, w, dt)
        yaw = math.atan2(math.sin(yaw), math.cos(yaw))
        poses.append((x, y, yaw))
        twists.append((v, w))
    moving = len(poses)
    for _ in range(int(round(c.stop_time * c.rate))):
        poses.append((x, y, yaw))
        twists.append((0.0, 0.0))
    return Drive(poses=np.array(poses, dtype=np.float64).reshape(-1, 3),
                 twists=np.array(twists, dtype=np.float64).reshape(-1, 2), reached=reached,
                 moving_ticks=moving)
