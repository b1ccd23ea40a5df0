"""Demonstrations: training data from the robot's own driving (issue 41, item 1).

A recorded pose stream (time, x, y, yaw in the map frame, from a rosbag: see
``ecahd_ros.dataset_bags``) is cut into demonstrations, each a path from where the robot set
off to where it stopped, and these become an :class:`~ecahd_core.dataset.ExpertDataset` in
exactly the views of the A* expert data (:func:`~ecahd_core.dataset.expert_sample`: P^g = 10
sparse waypoints, P^l = 4 point dense segments, 100 points), so ``ecahd train`` trains SD / DD
on them unchanged. Start and goal of a demonstration are the robot's own: where it started
moving and where it stopped.

The stream is cut (:func:`cut_demonstrations`), each cut counted by its reason (``REASONS``):

1. ``pose_gap``: no pose for longer than ``max_gap`` [s] (a recorder pause, a dropped topic).
2. ``teleport``: between two poses the robot moved farther than ``max_speed`` x dt +
   ``jump_tolerance`` [m] (a relocalisation, a pose reset).
3. ``stop`` / ``turn_in_place``: the robot stayed within ``stop_radius`` [m] of one point for
   longer than ``stop_time`` [s] (a stop), or turned by more than ``turn_angle`` [rad] while
   doing so, however briefly (a turn in place: a learnt path has no heading, so the two sides
   of the turn are two demonstrations). The still poses belong to no demonstration.

Each moving stretch between two cuts is then judged, and dropped pieces counted:

4. ``collision``: the exact checker (:func:`~ecahd_core.collision.check_collision`, the
   robot's footprint at the recorded headings) finds the footprint in an occupied cell; the
   colliding poses are cut out, the free pieces on either side judged on their own.
5. ``too_short``: path length below ``min_distance`` (3 m, the expert's minimum).
6. ``looping``: the path comes back within ``loop_radius`` of a point it had passed (default:
   the footprint's circumscribed radius, so the robot's footprint overlaps where it had been)
   after more than ``loop_length`` m (3 m, the shortest demonstration) of driving, measured on
   points every ``loop_spacing`` m: a circle, a drive up a dead end and back, a patrol back
   and forth. Passes on the two sides of a wall are at least twice that radius apart, so
   hairpins round a wall, U-turns and corners stay (on 1 h of A* routes in a generated
   office none is dropped, where "longer than 3 x the straight distance + 2 m" dropped 11%);
   the rule is ours (the paper has no demonstrations).

A stream whose poses put the footprint in a wall for more than ``mismatch_share`` of the run
is refused (:func:`check_map_matches`): the map does not belong to the bag.

Coverage (:func:`coverage`): the share of the map's free cells within ``coverage_radius``
(1 m) of a kept path, the part of the map the demonstrations teach SD something about.

Units: metres, seconds, radians, map frame. No rclpy, no rosbags here.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from ecahd_core.errors import DatasetError

# the cut and drop reasons, in the order they are reported
CUT_REASONS = ("pose_gap", "teleport", "stop", "turn_in_place")
DROP_REASONS = ("collision", "too_short", "looping")
REASONS = CUT_REASONS + DROP_REASONS


@dataclass(frozen=True)
class DemoConfig:
    """How a pose stream is cut into demonstrations (module docstring, rules 1-6)."""

    min_distance: float = 3.0  # [m] shortest demonstration kept (the A* expert's)
    max_gap: float = 0.5  # [s] a longer time without a pose cuts
    max_speed: float = 2.0  # [m/s] fastest the robot drives
    jump_tolerance: float = 0.25  # [m] pose noise and small relocalisations allowed on top
    stop_radius: float = 0.1  # [m] the robot is still while within this of one point
    stop_time: float = 2.0  # [s] still for longer than this: a stop
    turn_angle: float = math.radians(45.0)  # [rad] turning more than this while still
    loop_radius: float = 0.0  # [m] back this close to an earlier point loops; 0: the
    #                           footprint's circumscribed radius
    loop_length: float = 3.0  # [m] ... after more driving than this
    loop_spacing: float = 0.1  # [m] points of the loop test
    mismatch_share: float = 0.5  # refuse a stream with more of its poses in walls
    coverage_radius: float = 1.0  # [m]

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise DatasetError(f"{name} must be a finite number >= 0, got {value!r}")
        for name in ("max_gap", "stop_radius", "loop_spacing"):
            if getattr(self, name) <= 0:
                raise DatasetError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if self.mismatch_share > 1:
            raise DatasetError(f"mismatch_share must be in [0, 1], got {self.mismatch_share!r}")


@dataclass(frozen=True)
class PoseStream:
    """The robot's recorded poses: t (N,) [s], xy (N, 2) [m], yaw (N,) [rad], map frame;
    ``source`` names where they came from (a bag)."""

    t: np.ndarray
    xy: np.ndarray
    yaw: np.ndarray
    source: str = ""

    @classmethod
    def from_records(cls, records, source: str = "") -> "PoseStream":
        """From rows (t [s], x [m], y [m], yaw [rad]) (N, 4), in any order: sorted by time,
        a pose repeating the previous one's time dropped, non-finite rows dropped."""
        a = np.asarray(records, dtype=np.float64).reshape(-1, 4)
        a = a[np.all(np.isfinite(a), axis=1)]
        a = a[np.argsort(a[:, 0], kind="stable")]
        if len(a):
            a = a[np.concatenate([[True], np.diff(a[:, 0]) > 0])]
        return cls(t=a[:, 0], xy=a[:, 1:3], yaw=a[:, 3], source=source)

    def __len__(self) -> int:
        return len(self.t)

    @property
    def duration(self) -> float:
        """[s] from the first pose to the last."""
        return float(self.t[-1] - self.t[0]) if len(self.t) else 0.0


@dataclass(frozen=True)
class Piece:
    """A stretch of the stream: poses [first, last] of ``source``; xy (n, 2) [m], yaw (n,)."""

    xy: np.ndarray
    yaw: np.ndarray
    source: str
    reason: str | None = None  # None: kept; else one of DROP_REASONS

    @property
    def length(self) -> float:
        return float(np.linalg.norm(np.diff(self.xy, axis=0), axis=1).sum())


@dataclass
class CutResult:
    """What :func:`cut_demonstrations` made of one or more streams."""

    kept: list = field(default_factory=list)  # [Piece]
    dropped: list = field(default_factory=list)  # [Piece], reason set
    counts: dict = field(default_factory=lambda: dict.fromkeys(REASONS, 0))
    poses: int = 0
    seconds: float = 0.0  # [s] of recorded driving (sum of the streams' durations)

    def extend(self, other: "CutResult") -> None:
        self.kept += other.kept
        self.dropped += other.dropped
        for k, v in other.counts.items():
            self.counts[k] += v
        self.poses += other.poses
        self.seconds += other.seconds

    def summary(self) -> str:
        """One line: kept, and each reason's count."""
        return (f"kept {len(self.kept)} demonstrations ({sum(p.length for p in self.kept):.0f} m)"
                f" from {self.poses} poses ({self.seconds / 60:.1f} min); cuts: "
                + ", ".join(f"{self.counts[r]} {r.replace('_', ' ')}" for r in CUT_REASONS)
                + "; dropped: "
                + ", ".join(f"{self.counts[r]} {r.replace('_', ' ')}" for r in DROP_REASONS))


# ---------------------------------------------------------------------------------- cutting
def cut_demonstrations(stream: PoseStream, grid, footprint,
                       config: DemoConfig = DemoConfig()) -> CutResult:
    """Cut one pose stream into demonstrations (module docstring): the kept pieces, the
    dropped ones with their reason, and the count of every cut and drop."""
    out = CutResult(poses=len(stream), seconds=stream.duration)
    if len(stream) < 2:
        return out
    for lo, hi in _continuous_runs(stream, config, out.counts):
        for a, b in _moving_stretches(stream, lo, hi, config, out.counts):
            _judge(stream, a, b, grid, footprint, config, out)
    return out


def _continuous_runs(s: PoseStream, c: DemoConfig, counts: dict) -> list[tuple[int, int]]:
    """[lo, hi) index ranges without a pose gap or a teleport inside (rules 1, 2)."""
    dt = np.diff(s.t)  # (N-1,) > 0
    step = np.linalg.norm(np.diff(s.xy, axis=0), axis=1)
    gap = dt > c.max_gap
    jump = ~gap & (step > c.max_speed * dt + c.jump_tolerance)
    counts["pose_gap"] += int(gap.sum())
    counts["teleport"] += int(jump.sum())
    cuts = np.flatnonzero(gap | jump) + 1
    bounds = np.concatenate([[0], cuts, [len(s)]])
    return [(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:]) if b - a >= 2]


def _moving_stretches(s: PoseStream, lo: int, hi: int, c: DemoConfig,
                      counts: dict) -> list[tuple[int, int]]:
    """Inclusive [a, b] index ranges of run [lo, hi) between stops and turns in place
    (rule 3). Anchors: the first pose, then each pose at least stop_radius from the previous
    anchor; the poses from one anchor up to the next are within stop_radius of it (a dwell).
    A dwell longer than stop_time, or turning more than turn_angle, is a cut."""
    x, y = s.xy[lo:hi, 0].tolist(), s.xy[lo:hi, 1].tolist()
    r2 = c.stop_radius ** 2
    anchors = [0]
    ax, ay = x[0], y[0]
    for i in range(1, len(x)):
        if (x[i] - ax) ** 2 + (y[i] - ay) ** 2 >= r2:
            anchors.append(i)
            ax, ay = x[i], y[i]
    anchors = np.asarray(anchors) + lo
    ends = np.append(anchors[1:] - 1, hi - 1)  # last pose of each dwell
    dwell = s.t[ends] - s.t[anchors]
    turn = np.zeros(len(anchors))
    long = np.flatnonzero(ends > anchors)
    if len(long):  # the yaw swept during each dwell of more than one pose
        yaw = np.unwrap(s.yaw[lo:hi])
        for k in long:
            w = yaw[anchors[k] - lo:ends[k] - lo + 1]
            turn[k] = w.max() - w.min()
    is_turn = turn > c.turn_angle
    is_stop = ~is_turn & (dwell > c.stop_time)
    inner = np.zeros(len(anchors), dtype=bool)  # a still start or end of a run is no cut
    inner[1:-1] = True
    counts["turn_in_place"] += int((is_turn & inner).sum())
    counts["stop"] += int((is_stop & inner).sum())
    out, start = [], int(lo)
    for k in np.flatnonzero(is_turn | is_stop):
        if anchors[k] > start:
            out.append((start, int(anchors[k])))  # drove from `start`, stopped at the anchor
        start = int(ends[k])  # sets off from the dwell's last pose
    if hi - 1 > start:
        out.append((start, hi - 1))
    return out


def _judge(s: PoseStream, a: int, b: int, grid, footprint, c: DemoConfig,
           out: CutResult) -> None:
    """Rules 4-6 on poses [a, b]: collisions cut out, then too short, then looping."""
    xy, yaw = s.xy[a:b + 1], s.yaw[a:b + 1]
    bad = colliding_poses(xy, yaw, footprint, grid)
    if bad.any():
        edges = np.flatnonzero(np.diff(np.concatenate([[0], bad.astype(np.int8), [0]])))
        for lo, hi in zip(edges[::2], edges[1::2]):  # each colliding stretch [lo, hi)
            out.counts["collision"] += 1
            w = slice(max(lo - 1, 0), min(hi + 1, len(xy)))  # drawn joined to its neighbours
            out.dropped.append(Piece(xy[w], yaw[w], s.source, "collision"))
        free = np.flatnonzero(np.diff(np.concatenate([[1], bad.astype(np.int8), [1]])))
        pieces = [(lo, hi) for lo, hi in zip(free[::2], free[1::2]) if hi - lo >= 1]
    else:
        pieces = [(0, len(xy))]
    for lo, hi in pieces:
        piece = Piece(xy[lo:hi], yaw[lo:hi], s.source)
        if hi - lo < 2 or piece.length < c.min_distance:
            reason = "too_short"
        elif loops(piece.xy, radius=c.loop_radius or footprint.circumscribed_radius,
                   length=c.loop_length, spacing=c.loop_spacing):
            reason = "looping"
        else:
            out.kept.append(piece)
            continue
        out.counts[reason] += 1
        out.dropped.append(Piece(piece.xy, piece.yaw, s.source, reason))


def colliding_poses(xy, yaw, footprint, grid) -> np.ndarray:
    """(n,) bool: the recorded pose i, or the path from it to a neighbour, puts the footprint
    in an occupied cell, by one :func:`~ecahd_core.collision.check_collision` of the whole
    path at the recorded headings (dense poses mapped back to segments as ``densify`` lays
    them out; a colliding segment spoils both its end poses)."""
    from ecahd_core.collision import check_collision

    xy = np.asarray(xy, dtype=np.float64)
    yaw = np.asarray(yaw, dtype=np.float64)
    n = len(xy)
    bad = np.zeros(n, dtype=bool)
    if n == 0:
        return bad
    grid.free_distance  # noqa: B018  (built once: poses far from every wall pass at once)
    report = check_collision(xy, footprint, grid, headings=yaw)
    if report.collision_free:
        return bad
    if n == 1:
        return report.colliding.copy()
    # densify's layout (collision.densify): segment i gives n_i poses, the last pose closes
    step = grid.resolution / 4
    turn_radius = 0.0 if footprint.is_circle else footprint.circumscribed_radius
    length = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    turn = np.abs(np.angle(np.exp(1j * np.diff(yaw))))
    count = np.maximum(1, np.ceil(np.maximum(length, turn * turn_radius) / step - 1e-9))
    seg_of = np.append(np.repeat(np.arange(n - 1), count.astype(np.int64)), n - 2)
    if len(seg_of) != len(report.colliding):  # not that layout: the poses alone
        from ecahd_core.collision import DEFAULT_TOLERANCE, pose_depths

        return pose_depths(np.column_stack([xy, yaw]), footprint, grid) > DEFAULT_TOLERANCE
    seg_bad = np.zeros(n - 1, dtype=bool)
    seg_bad[seg_of[report.colliding]] = True
    bad[:-1] |= seg_bad
    bad[1:] |= seg_bad
    return bad


def loops(xy, *, radius: float, length: float = DemoConfig.loop_length,
          spacing: float = DemoConfig.loop_spacing) -> bool:
    """Rule 6: two points of the path (N, 2) [m], taken every ``spacing`` m of arc length,
    lie within ``radius`` [m] of each other with more than ``length`` [m] of path between
    them."""
    from ecahd_core.dataset import cumulative_arclength, points_at_arclength

    total = cumulative_arclength(xy)[-1]
    if total <= length:
        return False
    s = np.linspace(0.0, total, max(2, int(math.ceil(total / spacing)) + 1))
    p = points_at_arclength(xy, s)  # (M, 2)
    rows = max(1, (1 << 22) // len(s))  # bound the (rows, M) block
    for i in range(0, len(s), rows):
        near = np.linalg.norm(p[i:i + rows, None, :] - p[None, :, :], axis=-1) < radius
        far_along = s[None, :] - s[i:i + rows, None] > length  # (r, M)
        if np.any(near & far_along):
            return True
    return False


# ------------------------------------------------------------------------------ map checks
def wall_share(stream: PoseStream, grid, footprint) -> float:
    """Share in [0, 1] of the stream's poses whose footprint overlaps an occupied cell (off
    the map counts as occupied), by the exact checker's pose test."""
    from ecahd_core.collision import DEFAULT_TOLERANCE, far_passed_depths

    if not len(stream):
        return 0.0
    grid.free_distance  # noqa: B018
    poses = np.column_stack([stream.xy, stream.yaw])
    return float(np.mean(far_passed_depths(poses, footprint, grid) > DEFAULT_TOLERANCE))


def check_map_matches(stream: PoseStream, grid, footprint,
                      config: DemoConfig = DemoConfig()) -> float:
    """The stream's :func:`wall_share`; DatasetError when above ``config.mismatch_share``."""
    share = wall_share(stream, grid, footprint)
    if share > config.mismatch_share:
        raise DatasetError(
            f"{stream.source or 'the pose stream'}: {100 * share:.0f}% of its {len(stream)} "
            f"poses put robot {footprint.name!r} in a wall of map {grid.name!r}: the map does "
            f"not match the bag (another map, or poses in another frame?)")
    return share


def coverage(grid, paths, radius: float = DemoConfig.coverage_radius) -> tuple[float, np.ndarray]:
    """Share of the map's free cells whose centre lies within ``radius`` [m] of a path, and
    the (H, W) bool mask of those cells. paths: list of (N, 2) [m]."""
    import cv2

    from ecahd_core.dataset import resample_by_arclength

    free = ~grid.occupied
    on_path = np.zeros(grid.data.shape, dtype=bool)
    for xy in paths:
        xy = np.asarray(xy, dtype=np.float64)
        total = float(np.linalg.norm(np.diff(xy, axis=0), axis=1).sum()) if len(xy) > 1 else 0
        pts = resample_by_arclength(xy, max(2, int(total / (0.5 * grid.resolution)) + 2))
        rows, cols = grid.world_to_cell(pts)
        ok = (rows >= 0) & (rows < grid.height) & (cols >= 0) & (cols < grid.width)
        on_path[rows[ok], cols[ok]] = True
    if not on_path.any():
        return 0.0, np.zeros_like(free)
    # distance [cells] from each cell centre to the nearest path cell's centre
    dist = cv2.distanceTransform((~on_path).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    covered = free & (dist * grid.resolution <= radius)
    return float(covered.sum()) / max(int(free.sum()), 1), covered


# ------------------------------------------------------------------------------- dataset
def demonstrations_dataset(result: CutResult, grid, *, footprint_spec: str = "circle",
                           padding: float = 0.0, config: DemoConfig = DemoConfig(),
                           sparse_horizon: int = 10, dense_points: int = 4,
                           full_points: int = 100, max_spacing: float | None = None,
                           waypoints: str = "auto", sources: list | None = None,
                           extra: dict | None = None):
    """The kept demonstrations as an :class:`~ecahd_core.dataset.ExpertDataset` (the A*
    expert's views, :func:`~ecahd_core.dataset.expert_sample`; ``max_spacing`` and
    ``waypoints`` as in :func:`~ecahd_core.dataset.generate_dataset`); ``params`` records the
    sources, the configuration, every count and the coverage. DatasetError when none was
    kept."""
    from ecahd_core import __version__
    from ecahd_core.astar import clearance_for_footprint
    from ecahd_core.dataset import (DATASET_KIND, DATASET_VERSION, DTYPE, WAYPOINT_RULES,
                                    ExpertDataset, chunk_count, expert_sample,
                                    split_by_arclength, waypoint_rule_for,
                                    with_corner_waypoints)
    from ecahd_core.footprint import make_footprint

    if not result.kept:
        raise DatasetError("no demonstration was kept (" + result.summary() + ")")
    if waypoints != "auto" and waypoints not in WAYPOINT_RULES:
        raise DatasetError(f"waypoints must be 'auto' or one of {list(WAYPOINT_RULES)}, "
                           f"got {waypoints!r}")
    footprint = make_footprint(footprint_spec)
    views = dict(sparse_horizon=sparse_horizon, dense_points=dense_points,
                 full_points=full_points)
    samples, split = [], 0
    for piece in result.kept:
        k = chunk_count(piece.length, sparse_horizon, max_spacing)
        split += k > 1
        parts = [piece.xy] if k == 1 else split_by_arclength(piece.xy, k)
        samples += [expert_sample(p, **views) for p in parts]
    if waypoints == "auto":
        waypoints = waypoint_rule_for([x.length for x in samples], sparse_horizon)
    if waypoints == "corners":
        samples = [with_corner_waypoints(x) for x in samples]
    share, _ = coverage(grid, [p.xy for p in result.kept], config.coverage_radius)
    params = {
        "kind": DATASET_KIND,
        "version": DATASET_VERSION,
        "source": "demonstrations",
        "bags": list(sources or []),
        "footprint_spec": footprint_spec,
        "footprint": footprint.name,
        "padding": float(padding),
        "clearance": clearance_for_footprint(footprint, padding=padding),
        "min_distance": float(config.min_distance),
        "pairs": len(samples),
        "sparse_horizon": int(sparse_horizon),
        "dense_points": int(dense_points),
        "full_points": int(full_points),
        **({"waypoints": waypoints} if waypoints != "arclength" else {}),
        **({"max_spacing": float(max_spacing), "split_paths": split}
           if max_spacing is not None else {}),
        "demonstrations": len(result.kept),
        "counts": dict(result.counts),
        "poses": int(result.poses),
        "seconds": round(float(result.seconds), 3),
        "coverage": round(share, 6),
        "cut_config": asdict(config),
        **(extra or {}),
        "ecahd_version": __version__,
        "map": {"frame_id": grid.frame_id, "unknown_is_occupied": grid.unknown_is_occupied,
                "occupied_threshold": grid.occupied_threshold},
    }
    return ExpertDataset(
        sparse=np.stack([x.sparse for x in samples]).astype(DTYPE),
        sparse_h={h: np.stack([x.sparse_h[h] for x in samples]).astype(DTYPE)
                  for h in range(2, sparse_horizon + 1)},
        dense=np.concatenate([x.dense for x in samples]).astype(DTYPE),
        full=np.stack([x.full for x in samples]).astype(DTYPE),
        starts=np.stack([x.sparse[0] for x in samples]).astype(DTYPE),
        goals=np.stack([x.sparse[-1] for x in samples]).astype(DTYPE),
        lengths=np.array([x.length for x in samples], dtype=DTYPE),
        map_data=np.array(grid.data, dtype=np.int8),
        map_resolution=grid.resolution,
        map_origin=grid.origin,
        map_name=grid.name,
        map_fingerprint=grid.fingerprint(),
        params=params,
    )
