"""What the robot knows beyond the static map (issue 11): scans turned into world points, a
rolling :class:`~ecahd_core.local_costmap.LocalCostmap`, and the static map fused with it, both
as a GridMap (for the exact checker) and as a CostMap (for J). No rclpy.

There is no TF tree here: a scan's pose is the odometry pose at its stamp composed with the fixed
mounting offset (x [m], y [m], yaw [rad]) of the sensor on base_link, the same parameters on the
simulator and the refiner.
"""
from __future__ import annotations

import bisect
import math
import time
from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from ecahd_core.errors import EcahdError, TrajectoryError
from ecahd_core.local_costmap import LocalCostmap, LocalCostmapConfig
from ecahd_core.maps import GridMap
from ecahd_core.tracking import MotionTracker, TrackerConfig

SCAN_MAX_BEAMS = 100_000  # a scan with more beams is rejected
MOVER_MEMORY = 1.0  # [s] a return near one that moved this recently is not marked (LocalWorld)
MOVER_GAP = 0.3  # [m] ... "near": the tracker's cluster gap
# [s] moving returns kept to find where a mover turns round: a whole back-and-forth of a 3 m
# run at 0.3 m/s (20 s). 12 s forgot a depot mover's turn just before it came back into the
# robot; 30 s x 8 returns a scan: shuttle_bounds 3.6 ms a scan (12 s x 16: 3.0; RESULTS.md)
SHUTTLE_MEMORY = 30.0
SHUTTLE_ANGLE = 30.0  # [deg] a trail return moving at most this far off a line moved along it
SHUTTLE_POINTS = 8  # at most this many moving returns of a scan are kept for that
SHUTTLE_CUT_SLACK = 1.0  # [s] a trail whose oldest return is this near the memory was cut off
MEMORY_TILE = 128  # [cells] remembered obstacles are added to J's cost map tile by tile
RECENT_OBSTACLES = 2.0  # [s] a detour that the whole memory blocks tries what was seen lately


@dataclass(frozen=True)
class Scan:
    """One sensor_msgs/LaserScan's numbers: ranges (N,) [m] (REP-117: +inf no return, -inf too
    close, NaN invalid), angle_min, angle_increment [rad], range_min, range_max [m], stamp [s]."""

    ranges: np.ndarray
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    stamp: float

    def __post_init__(self) -> None:
        r = np.asarray(self.ranges, dtype=np.float64).reshape(-1)
        if not 0 < len(r) <= SCAN_MAX_BEAMS:
            raise EcahdError(f"scan must have 1..{SCAN_MAX_BEAMS} ranges, got {len(r)}")
        for name in ("angle_min", "angle_increment", "range_min", "range_max", "stamp"):
            if not math.isfinite(getattr(self, name)):
                raise EcahdError(f"scan {name} is not finite: {getattr(self, name)}")
        if not 0 <= self.range_min < self.range_max:
            raise EcahdError(f"scan needs 0 <= range_min < range_max, got {self.range_min}, "
                             f"{self.range_max}")
        object.__setattr__(self, "ranges", r)


def sensor_pose(pose, offset) -> tuple[float, float, float]:
    """base_link pose (x, y, yaw) composed with the sensor offset (x, y, yaw)."""
    x, y, yaw = pose
    ox, oy, oyaw = offset
    c, s = math.cos(yaw), math.sin(yaw)
    return x + c * ox - s * oy, y + s * ox + c * oy, yaw + oyaw


def valid_beams(scan: Scan) -> np.ndarray:
    """(M,) indices of the scan's valid returns (finite, within [range_min, range_max]), in
    beam order: the rows of :func:`scan_points`."""
    r = scan.ranges
    with np.errstate(invalid="ignore"):
        return np.flatnonzero(np.isfinite(r) & (r >= scan.range_min) & (r <= scan.range_max))


def scan_points(pose, scan: Scan, offset=(0.0, 0.0, 0.0)) -> np.ndarray:
    """World (x, y) [m] of the scan's valid returns (finite, within [range_min, range_max]):
    (M, 2), in beam order."""
    sx, sy, syaw = sensor_pose(pose, offset)
    beams = valid_beams(scan)
    a = syaw + scan.angle_min + scan.angle_increment * beams
    rv = scan.ranges[beams]
    return np.stack([sx + rv * np.cos(a), sy + rv * np.sin(a)], axis=1)


class PoseHistory:
    """Odometry poses by their stamps, to place a scan with the pose at its own stamp (there is
    no TF tree here). A scan stamped after the newest pose must wait for the next odometry:
    placed with an older pose, a robot turning at 1.5 rad/s puts returns 8 m away 0.24 m off
    the wall per 20 ms of difference, marks that narrow every door (measured on a 60 x 60 m
    office, docs/RESULTS.md).

    Args:
        horizon: [s] of poses kept.
    """

    def __init__(self, horizon: float = 1.0) -> None:
        self.horizon = float(horizon)
        self._stamps: list[float] = []
        self._poses: list[tuple[float, float, float]] = []

    def add(self, stamp: float, pose) -> None:
        """One odometry pose (x, y, yaw) at ``stamp`` [s]; an older stamp than the newest
        resets the history (a restarted clock)."""
        if self._stamps and stamp < self._stamps[-1]:
            self._stamps.clear()
            self._poses.clear()
        self._stamps.append(float(stamp))
        self._poses.append(tuple(float(v) for v in pose))
        while len(self._stamps) > 2 and self._stamps[-1] - self._stamps[0] > self.horizon:
            del self._stamps[0], self._poses[0]

    @property
    def newest(self) -> float | None:
        """[s] the newest pose's stamp (None: no pose yet)."""
        return self._stamps[-1] if self._stamps else None

    def covers(self, stamp: float) -> bool:
        """A pose at or after ``stamp`` [s] is known."""
        return bool(self._stamps) and self._stamps[-1] >= stamp

    def at(self, stamp: float):
        """(x, y, yaw) at ``stamp`` [s]: interpolated between the poses either side of it (yaw
        the short way round); the oldest or newest pose outside the history; None if empty."""
        if not self._stamps:
            return None
        i = bisect.bisect_left(self._stamps, stamp)
        if i == 0:
            return self._poses[0]
        if i == len(self._stamps):
            return self._poses[-1]
        t0, t1 = self._stamps[i - 1], self._stamps[i]
        (x0, y0, a0), (x1, y1, a1) = self._poses[i - 1], self._poses[i]
        f = 0.0 if t1 <= t0 else (stamp - t0) / (t1 - t0)
        da = math.atan2(math.sin(a1 - a0), math.cos(a1 - a0))
        yaw = a0 + f * da
        return (x0 + f * (x1 - x0), y0 + f * (y1 - y0), math.atan2(math.sin(yaw), math.cos(yaw)))


def fuse_grid(static: GridMap, mask: np.ndarray, origin: tuple[float, float]) -> GridMap:
    """The static map with a window's marked cells occupied (100): what the exact checker
    judges with. mask: (h, w) bool, row 0 at the lowest y; origin: world (x, y) [m] of its
    cell (0, 0), on the static map's cell lattice (LocalCostmap.for_map)."""
    if not mask.any():
        return static
    ox, oy = origin
    c0 = int(round((ox - static.origin[0]) / static.resolution))
    r0 = int(round((oy - static.origin[1]) / static.resolution))
    h, w = mask.shape
    rs, re = max(0, r0), min(static.height, r0 + h)
    cs, ce = max(0, c0), min(static.width, c0 + w)
    if rs >= re or cs >= ce:
        return static
    data = static.data.copy()
    sub = mask[rs - r0:re - r0, cs - c0:ce - c0]
    data[rs:re, cs:ce][sub] = 100
    fused = GridMap(data, static.resolution, static.origin, name=static.name,
                    frame_id=static.frame_id, unknown_is_occupied=static.unknown_is_occupied,
                    occupied_threshold=static.occupied_threshold)
    rows, cols = np.nonzero(sub)
    if len(rows):
        fused.__dict__["free_distance"] = _fused_free_distance(static, rows + rs, cols + cs)
    return fused


FUSED_DISTANCE_REACH = 2.0  # [m] beyond the marks' box, fused distances are capped (below)


def _fused_free_distance(static: GridMap, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """A lower bound of the fused grid's ``free_distance`` (static map + the marked cells
    (rows, cols) (K,)), for the exact checker's far-pose pass, in a few ms instead of a
    distance transform of the whole map (~80 ms on 2000 x 2000 cells): the static map's
    (computed once per map) and, in the marks' box grown by ``FUSED_DISTANCE_REACH`` m, the
    exact distance to the marks; outside that box the marks are at least that far, so the
    distance is capped there (a footprint reaching farther gets every pose tested). A lower
    bound only makes the checker test more poses cell by cell (a pose is passed only when it
    is farther from every occupied cell than its footprint reaches), so its verdicts stay
    exact."""
    import cv2

    g = int(math.ceil(FUSED_DISTANCE_REACH / static.resolution))  # [cells]
    H, W = static.height, static.width
    r_lo, r_hi = max(int(rows.min()) - g, 0), min(int(rows.max()) + 1 + g, H)
    c_lo, c_hi = max(int(cols.min()) - g, 0), min(int(cols.max()) + 1 + g, W)
    free = np.ones((r_hi - r_lo, c_hi - c_lo), dtype=np.uint8)
    free[rows - r_lo, cols - c_lo] = 0
    marks = cv2.distanceTransform(free, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    dist = np.minimum(static.free_distance, np.float32(g * static.resolution))
    box = dist[r_lo:r_hi, c_lo:c_hi]
    np.minimum(box, (marks * static.resolution).astype(np.float32), out=box)
    dist.setflags(write=False)
    return dist


@dataclass(frozen=True)
class SeenObstacles:
    """The latest scan's returns that are not on (or next to) the static map's obstacles, in
    the world frame, with their estimated velocities: the collision monitor's input.

    Attributes:
        points: (M, 2) [m]; velocities: (M, 2) [m/s] (0: static or unknown);
        stamp: [s] the scan's time.
        bounds: (M, 2) [m] or None: where a moving point will turn round, as offsets (behind
            <= 0 <= ahead) along its direction of motion (-inf, inf: no turn known; see
            :func:`shuttle_bounds`); None: none known for any point.
    """

    points: np.ndarray
    velocities: np.ndarray
    stamp: float
    bounds: np.ndarray | None = None


class StaticClearance:
    """Is a pose clear of a GridMap? The exact checker's answer, fast far from walls
    (``collision.far_passed_depths`` on the map's ``free_distance``, built on first use).

    Args:
        grid: the map (its ``occupied`` cells; beyond its edge counts as occupied).
    """

    def __init__(self, grid: GridMap) -> None:
        self.grid = grid

    def depths(self, poses, footprint) -> np.ndarray:
        """(N, 3) poses -> (N,) the exact checker's overlap depth [m] of ``footprint`` with the
        map (<= 0 or -inf: free). A pose whose cell lies farther than the circumscribed radius
        + 2 half cell diagonals from every occupied cell is free whatever its heading (-inf, a
        lookup's cost); the exact checker judges the rest (near walls)."""
        from ecahd_core.collision import far_passed_depths

        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        if not np.all(np.isfinite(poses)):
            raise TrajectoryError("poses must be finite")
        return far_passed_depths(poses, footprint, self.grid)

    def wall_distance(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) [m] -> (N,) [m] distance from each point's cell centre to the nearest
        occupied cell centre of the static map (off the map: 0; beyond the map's edge counts
        as occupied, as for the exact checker)."""
        from ecahd_core.collision import wall_distance

        return wall_distance(self.grid, np.asarray(xy, dtype=np.float64).reshape(-1, 2))

    def room(self, xy: np.ndarray, footprint) -> np.ndarray:
        """(N, 2) [m] -> (N,) [m] room beside ``footprint`` at each point: the distance to the
        nearest wall's edge (cell centres' distance less half a cell) less the footprint's
        inscribed radius; <= 0 where it cannot stand in any heading. The local runner's precise
        tracking reads it (``LocalRunner.room``)."""
        return self.wall_distance(xy) - 0.5 * self.grid.resolution - footprint.inscribed_radius


def shuttle_bounds(points: np.ndarray, velocities: np.ndarray, trail: np.ndarray,
                   trail_velocities: np.ndarray, trail_ages: np.ndarray, *,
                   memory: float = SHUTTLE_MEMORY, lateral: float = MOVER_GAP) -> np.ndarray:
    """Where each moving point will turn round, from where movers were seen before: a cart or
    a person going back and forth (issue 11's moving obstacles), whose turn a constant-velocity
    prediction misses.

    For a point p moving with velocity v, the trail points within ``lateral`` [m] of the line
    p + s v/|v| that moved along it (within ``SHUTTLE_ANGLE``) are the same mover's earlier
    returns along its way. If one of them moved the other way, the mover has turned round
    behind it: it shuttles over the stretch those trail points cover, [min s, max s], and p is
    predicted to turn round at its ends. Without such evidence the point keeps its
    straight-line prediction.

    The end ahead (max s) is trusted only when it is known: the trail holds the mover's turn
    there (a return ahead of p going p's way older than one ahead of p going back), or the
    trail reaches back to where the mover was first seen (its oldest return on the line is
    younger than ``memory`` less ``SHUTTLE_CUT_SLACK``, so the trail was not cut off). A
    trail cut off by ``memory`` covers only part of a long stretch, and its far end is where
    the memory began, not where the mover turns: a mover predicted to turn round "now" there
    drove into a robot standing 1 m further on its way (depot, docs/RESULTS.md). The end
    behind (min s), where it turned last, is known.

    Args:
        points, velocities: (M, 2) [m], [m/s] this scan's unmapped returns (velocity 0:
            static or unknown; those get no bounds).
        trail, trail_velocities: (K, 2) [m], [m/s] earlier moving returns (all moving).
        trail_ages: (K,) [s] how long before this scan each trail point was seen.
        memory: [s] how long trail points are kept (older ones were dropped).
        lateral: [m] how far off the line of motion a trail point may lie.

    Returns:
        (M, 2) [m] (behind <= 0, ahead >= 0) offsets along each point's direction of motion;
        -inf behind / inf ahead where no turn is known.
    """
    out = np.tile([-np.inf, np.inf], (len(points), 1))
    speed = np.hypot(velocities[:, 0], velocities[:, 1])  # (M,)
    moving = np.flatnonzero(speed > 0)
    if len(moving) == 0 or len(trail) == 0:
        return out
    u = velocities[moving] / speed[moving, None]  # (m, 2) unit directions
    p = points[moving]  # (m, 2)
    normal = np.stack([u[:, 1], -u[:, 0]], axis=1)  # (m, 2): (t - p) x u = (t - p) . normal
    # (m, K) [m] along the motion and off it: matrix products, no (m, K, 2) temporaries
    s = u @ trail.T - np.sum(p * u, axis=1)[:, None]
    off = np.abs(normal @ trail.T - np.sum(p * normal, axis=1)[:, None])
    along = u @ trail_velocities.T  # (m, K) [m/s] trail speed along u
    trail_speed = np.hypot(trail_velocities[:, 0], trail_velocities[:, 1])  # (K,)
    on = off <= lateral  # (m, K)
    # moved the other way along this line, within SHUTTLE_ANGLE of it: a second mover crossing
    # the line at 46 degrees counted as this one going back and forth (depot, RESULTS.md)
    parallel = np.abs(along) >= math.cos(math.radians(SHUTTLE_ANGLE)) * trail_speed[None, :]
    back = on & parallel & (along < 0)
    turned = back.any(axis=1)  # (m,)
    if not turned.any():
        return out
    ages = np.broadcast_to(np.asarray(trail_ages, dtype=np.float64)[None, :], on.shape)
    # a turn ahead is in the trail: the mover went this way ahead of p (older) before it came
    # back there (younger). Both ahead of p: a turn seen behind p, or a second mover's
    # returns, are not evidence of where the mover turns ahead
    ahead = s > 0.0
    same = on & parallel & (along > 0) & ahead  # went this way, ahead of p
    turn_ahead = np.where(same, ages, -np.inf).max(axis=1) > \
        np.where(back & ahead, ages, np.inf).min(axis=1)  # (m,)
    uncut = np.where(on, ages, -np.inf).max(axis=1) < memory - SHUTTLE_CUT_SLACK  # (m,)
    lo = np.where(on, s, np.inf).min(axis=1)  # (m,)
    hi = np.where(on, s, -np.inf).max(axis=1)
    rows = moving[turned]
    out[rows, 0] = np.minimum(lo[turned], 0.0)
    known = turned & (turn_ahead | uncut)
    out[moving[known], 1] = np.maximum(hi[known], 0.0)
    return out


def _near(points: np.ndarray, refs: np.ndarray, gap: float) -> np.ndarray:
    """(M,) bool: each of points (M, 2) [m] lies within ``gap`` [m] of one of refs (K, 2)."""
    near = np.zeros(len(points), dtype=bool)
    for chunk in range(0, len(refs), 256):  # (M, 256) distances at a time
        d2 = np.sum((points[:, None, :] - refs[None, chunk:chunk + 256, :]) ** 2, axis=-1)
        near |= d2.min(axis=1) <= gap * gap
    return near


class LocalWorld:
    """The static map, its cost J and the scans: :meth:`add_scan` updates the rolling window and
    the latest unmapped scan points with their velocities (:attr:`seen`, one object replaced
    whole, so a reader on another thread never sees points and velocities of two scans);
    :meth:`fused` gives (GridMap, CostMap) with the window's marks,
    recomputed only when a scan changed the window and at most every ``min_fuse_interval`` s
    (the CostMap costs about 75 ms on a 2000 x 2000 map).

    Args:
        grid: the static GridMap; cost: its :class:`~ecahd_core.cost.CollisionCost`.
        config: the window's LocalCostmapConfig.
        offset: the sensor's (x, y, yaw) on base_link.
        tracker: the MotionTracker settings for the unmapped points' velocities.
        mark_moving: returns on moving obstacles mark the window too. False (the default):
            they only clear their rays, and the collision monitor alone judges them by their
            predicted motion. Marked, a cylinder shuttling across a corridor is a wall there in
            J: the plan through it is "blocked" at every crossing, the planner detours, and
            with a second crosser on the detour the robot shuttled between the two routes for
            the whole episode (maze2d-large, docs/RESULTS.md). A return within
            ``MOVER_GAP`` of a moving one of the last ``MOVER_MEMORY`` s counts as moving too,
            so a mover is not marked during the scan or two in which it turns round and its
            velocity estimate passes through zero; so does a known return (on the map's
            walls) within MOVER_GAP of a moving one. Marks within MOVER_GAP of a moving return
            are removed: those a mover left in the first scans, before the tracker had an
            earlier scan to measure its motion against (0.3 s).
        shuttles: find where movers going back and forth turn round (:func:`shuttle_bounds`,
            ``seen.bounds``); False: ``seen.bounds`` stays None.
    """

    def __init__(self, grid: GridMap, cost, config: LocalCostmapConfig | None = None, *,
                 offset=(0.0, 0.0, 0.0), min_fuse_interval: float = 0.2,
                 tracker: TrackerConfig | None = None, mark_moving: bool = False,
                 shuttles: bool = False) -> None:
        self.grid, self.cost = grid, cost
        self.window = LocalCostmap.for_map(grid, config)
        self.offset = tuple(float(v) for v in offset)
        self.min_fuse_interval = min_fuse_interval
        self.tracker = MotionTracker(tracker)
        self.static_clearance = StaticClearance(grid)
        self.seen: SeenObstacles | None = None  # None until the first scan
        self._fused = (grid, cost.costmap)
        self._dirty = False
        self._fused_at = -math.inf
        self.fuse_ms = 0.0  # [ms] the last fusion's wall time
        self.mark_moving = bool(mark_moving)
        self.shuttles = bool(shuttles)
        self._movers: deque[tuple[float, np.ndarray]] = deque()  # (stamp, (K, 2) moving points)
        # (stamp, (K, 2) moving points, (K, 2) their velocities) of the last SHUTTLE_MEMORY s
        self._trail: deque[tuple[float, np.ndarray, np.ndarray]] = deque()

    def add_scan(self, pose, scan: Scan, offset=None) -> None:
        """A scan taken at ``pose`` (x, y, yaw) of base_link by a sensor mounted at ``offset``
        (x [m], y [m], yaw [rad]) on base_link (None: :attr:`offset`)."""
        offset = self.offset if offset is None else tuple(float(v) for v in offset)
        before = self.window.obstacle_mask().copy()
        beams = valid_beams(scan)  # (M,) indices of the returns
        every = scan_points(pose, scan, offset)  # (M, 2)
        # returns from the static map's obstacles are known: the planner and the exact checker
        # keep the footprint off them; the collision monitor guards against the rest
        unmapped = ~self.window.is_known(every)
        points = every[unmapped]
        velocities = self.tracker.update(points, scan.stamp)  # (M', 2)
        mark = None
        if not self.mark_moving:
            moving = self._moving(points, velocities, scan.stamp)  # (M',)
            # a known return beside a mover (one touching a wall) is not marked either: its
            # mark lands a little beyond the return, possibly off the known cells
            skip = np.zeros(len(every), dtype=bool)
            skip[unmapped] = moving
            if moving.any() and not unmapped.all():
                skip[~unmapped] = _near(every[~unmapped], points[moving], MOVER_GAP)
            mark = np.ones(len(scan.ranges), dtype=bool)
            mark[beams[skip]] = False
        self.window.update(pose, scan.ranges, angle_min=scan.angle_min,
                           angle_increment=scan.angle_increment, range_min=scan.range_min,
                           range_max=scan.range_max, stamp=scan.stamp,
                           sensor_offset=offset, mark=mark)
        if mark is not None and moving.any():  # marks it left before its motion was known
            self.window.forget(points[moving], MOVER_GAP)
        self.seen = SeenObstacles(points, velocities, scan.stamp,
                                  self._shuttles(points, velocities, scan.stamp)
                                  if self.shuttles else None)
        mask = self.window.obstacle_mask()
        if before.shape != mask.shape or not np.array_equal(before, mask) \
                or self.window.origin != self._window_origin:
            self._dirty = True
        self._window_origin = self.window.origin

    _window_origin: tuple[float, float] | None = None

    def _shuttles(self, points: np.ndarray, velocities: np.ndarray, stamp: float
                  ) -> np.ndarray | None:
        """:func:`shuttle_bounds` of this scan's unmapped returns against the moving returns
        of the last SHUTTLE_MEMORY s; then this scan's moving returns join them. None when
        nothing moves."""
        while self._trail and (self._trail[0][0] < stamp - SHUTTLE_MEMORY
                               or self._trail[0][0] > stamp):  # old, or the clock went back
            self._trail.popleft()
        moving = np.any(velocities != 0.0, axis=1)
        bounds = None
        if moving.any() and self._trail:
            bounds = shuttle_bounds(points, velocities,
                                    np.concatenate([p for _, p, _ in self._trail]),
                                    np.concatenate([v for _, _, v in self._trail]),
                                    np.concatenate([np.full(len(p), stamp - t)
                                                    for t, p, _ in self._trail]))
        if moving.any():
            keep = np.flatnonzero(moving)
            keep = keep[np.linspace(0, len(keep) - 1, min(len(keep), SHUTTLE_POINTS)
                                    ).astype(np.int64)]
            self._trail.append((float(stamp), points[keep], velocities[keep]))
        return bounds

    def _moving(self, points: np.ndarray, velocities: np.ndarray, stamp: float) -> np.ndarray:
        """(M,) bool: the unmapped returns (M, 2) [m] that move ((M, 2) [m/s] velocities
        not 0) or lie within MOVER_GAP of a return that moved in the last MOVER_MEMORY s."""
        while self._movers and (self._movers[0][0] < stamp - MOVER_MEMORY
                                or self._movers[0][0] > stamp):  # old, or the clock went back
            self._movers.popleft()
        moving = np.any(velocities != 0.0, axis=1)  # (M,)
        if self._movers and len(points):
            moving |= _near(points, np.concatenate([p for _, p in self._movers]), MOVER_GAP)
        if moving.any():
            self._movers.append((float(stamp), points[np.any(velocities != 0.0, axis=1)]))
        return moving

    def depths(self, poses, footprint) -> np.ndarray:
        """:meth:`StaticClearance.depths` on the static map: the collision monitor's check of
        every command and of its escapes against what the map knows (the unmapped obstacles
        are the monitor's own points)."""
        return self.static_clearance.depths(poses, footprint)

    @property
    def marked(self) -> bool:
        """Any cell of the window marked now."""
        return bool(self.window.obstacle_mask().any())

    def fused(self, *, force: bool = False) -> tuple[GridMap, object]:
        """(fused GridMap, fused CostMap); the cached pair when nothing changed or the last
        fusion is younger than ``min_fuse_interval`` (unless ``force``)."""
        now = time.monotonic()
        if self._dirty and (force or now - self._fused_at >= self.min_fuse_interval):
            t0 = time.perf_counter()
            if self.marked:
                self._fused = (fuse_grid(self.grid, self.window.obstacle_mask(),
                                         self.window.origin),
                               self.window.fused_costmap(self.cost.costmap, self.cost.config))
            else:
                self._fused = (self.grid, self.cost.costmap)
            self._dirty, self._fused_at = False, now
            self.fuse_ms = (time.perf_counter() - t0) * 1e3
        return self._fused

    @property
    def stale(self) -> bool:
        """A scan changed the window since the last fusion."""
        return self._dirty


class ObstacleMemory:
    """The global planner's memory of obstacles the scans found (local costmap windows pasted
    onto the static map's lattice): a marked cell is remembered for ``persistence`` seconds
    unless a later window sees it free, so a detour does not lead back into a blockage that
    has left the robot's rolling window. No rclpy.

    Args:
        grid: the static GridMap; persistence: [s] how long a mark outlives its last sighting.
    """

    def __init__(self, grid: GridMap, persistence: float = 60.0) -> None:
        self.grid = grid
        self.persistence = float(persistence)
        self._last = np.full(grid.data.shape, -np.inf)  # (H, W) [s] last time marked
        self._cost_cache = None  # (key of the static cost and the marks, the fused J tuple)
        # (H, W) walls of the map the models never learnt (an update of the site's map): held
        # for good, so SD's plans that cross them are detoured as a scanned blockage is
        self.unlearnt = np.zeros(grid.data.shape, dtype=bool)

    def learnt_from(self, learnt: GridMap) -> int:
        """The models learnt ``learnt``, an earlier map of this site: the walls added since
        (occupied here, free there) are remembered for good. Returns how many cells."""
        learnt.changed_share(self.grid)  # MapError when it is another extent
        self.unlearnt = self.grid.occupied & ~learnt.occupied
        return int(self.unlearnt.sum())

    def update(self, window: GridMap, now: float) -> None:
        """A window (its ``data``: 100 marked, 0 seen free, -1 not seen) at time ``now`` [s]."""
        if abs(window.resolution - self.grid.resolution) > 1e-9:
            raise EcahdError(f"local costmap resolution {window.resolution} differs from the "
                             f"map's {self.grid.resolution}")
        c0 = int(round((window.origin[0] - self.grid.origin[0]) / self.grid.resolution))
        r0 = int(round((window.origin[1] - self.grid.origin[1]) / self.grid.resolution))
        h, w = window.data.shape
        H, W = self.grid.data.shape
        rs, re, cs, ce = max(0, r0), min(H, r0 + h), max(0, c0), min(W, c0 + w)
        if rs >= re or cs >= ce:
            return
        sub = window.data[rs - r0:re - r0, cs - c0:ce - c0]
        last = self._last[rs:re, cs:ce]
        last[sub >= window.occupied_threshold] = now
        last[sub == 0] = -np.inf  # seen free: whatever was there has gone

    def mask(self, now: float, within: float | None = None) -> np.ndarray:
        """(H, W) bool cells remembered as blocked at ``now`` (marked in the last ``within``
        seconds; default the persistence), and the walls the models never learnt."""
        return (self._last >= now - (self.persistence if within is None else within)) \
            | self.unlearnt

    def fused(self, now: float, within: float | None = None) -> GridMap:
        """The static map with the remembered cells occupied."""
        return fuse_grid(self.grid, self.mask(now, within), self.grid.origin)

    def fused_cost(self, now: float, static_cost):
        """J's CollisionCost with the remembered cells as obstacles:
        ``static_cost`` (built on :attr:`grid`) with them added on the tiles of
        ``MEMORY_TILE`` cells that hold them (``costmap.add_obstacles``; in free space the
        same cost as a cost map built from :meth:`fused`, 2-3x faster on a 2000 x 2000 map,
        ``ecahd bench replan``), kept until the remembered cells change; ``static_cost``
        itself when nothing is remembered."""
        from ecahd_core.costmap import add_obstacles

        mask = self.mask(now) & ~self.grid.occupied  # remembered, not on the map
        if not mask.any():
            return static_cost
        key = (id(static_cost), mask.tobytes())
        if self._cost_cache is None or self._cost_cache[0] != key:
            rows, cols = np.nonzero(mask)
            occupied = self.grid.occupied
            costmap = add_obstacles(static_cost.costmap, rows, cols,
                                    lambda r, c: occupied[r, c], tile=MEMORY_TILE,
                                    name="remembered")
            self._cost_cache = (key, replace(static_cost, costmap=costmap))
        return self._cost_cache[1]

    def detour(self, footprint, start, goal, now: float) -> tuple[np.ndarray, int]:
        """A path round what is known (``navigation.detour``): on the static map with every
        remembered cell, else with only those marked in the last ``RECENT_OBSTACLES`` s (a
        moving obstacle's trail in the memory can close every way). Never the static map
        alone: a path through what the scans see now is not given.

        Returns (path (N, 2) [m], how many of the two maps were tried). Raises PlanningError
        naming both when neither holds a way."""
        from ecahd_core.errors import PlanningError
        from ecahd_core.planning.detour import detour

        grids = (self.fused(now), self.fused(now, within=RECENT_OBSTACLES))
        for i, grid in enumerate(grids):
            try:
                return detour(grid, footprint, start, goal), i + 1
            except PlanningError as exc:
                if i == len(grids) - 1:
                    raise PlanningError(f"no way round the obstacles the scans found (also "
                                        f"with only those of the last {RECENT_OBSTACLES:g} s): "
                                        f"{exc}") from None

    def crosses(self, path, footprint, now: float) -> bool:
        """Whether the footprint swept along the straight legs of ``path`` (P, 2) [m] meets a
        remembered cell (the static map's walls are not judged here). The exact checker runs
        on the remembered cells alone with their distance transform, so it passes the poses
        far from every mark (about 9x faster on a 2000 x 2000 map, the transform included,
        ``ecahd bench replan``)."""
        from ecahd_core.collision import check_collision

        mask = self.mask(now)
        if not mask.any():
            return False
        g = self.grid
        only = GridMap(np.where(mask, 100, 0).astype(np.int8), g.resolution, g.origin,
                       name=g.name, frame_id=g.frame_id)
        only.free_distance  # computed now: check_collision uses it where a grid holds it
        return not check_collision(path, footprint, only).collision_free
