"""Exact swept-footprint collision checking for evaluation (paper Sec. IV, "collision-free rate").

This is the referee, not the guide: it is not differentiable and shares nothing with the cost J
(``cost.py``), so a planner cannot score well here by exploiting the cost map's smoothing.

A trajectory is interpolated densely by arc length; at every dense pose the footprint is placed
exactly and tested against every occupied cell near it:

- circles: the distance from the centre to the cell square is < radius - tolerance;
- polygons: the separating axis theorem (SAT) between the convex footprint and the axis-aligned
  cell square finds an overlap deeper than ``tolerance`` on every axis. A non-convex footprint
  is split into triangles by ear clipping and each triangle is tested.

Touching (overlap depth <= tolerance) is not a collision. Everything off the map is occupied.

Frames and units: map frame, metres, radians; a cell (row, col) is the square
[ox + col*res, ox + (col+1)*res] x [oy + row*res, oy + (row+1)*res] with row 0 at the lowest y
(see ``maps.py``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple, Sequence

import numpy as np

from ecahd_core.errors import FootprintError, TrajectoryError
from ecahd_core.footprint import Footprint, signed_area
from ecahd_core.maps import GridMap

DEFAULT_TOLERANCE = 1e-6  # [m] overlaps up to this deep count as touching, not colliding
_ZERO_LENGTH = 1e-9  # [m] segments shorter than this have no direction of their own
_CHUNK_ELEMENTS = 1 << 21  # bound on (poses x cells x axes) per vectorised block


@dataclass(frozen=True)
class CollisionReport:
    """Result of :func:`check_collision`.

    Attributes:
        collision_free: no dense pose collides.
        penetration_fraction: fraction of the N dense poses whose footprint overlaps an
            occupied cell, in [0, 1].
        max_depth: the worst pose's penetration depth [m]; 0.0 if collision free.
        first_collision_index: index into ``dense_poses`` of the first colliding pose, or None.
        dense_poses: (N, 3) x [m], y [m], heading [rad] of the checked poses.
        colliding: (N,) bool, the pose collides.
        depths: (N,) penetration depth [m] of each pose, 0.0 where it does not collide. A pose's
            depth is the largest, over the occupied cells it overlaps, of the minimum
            translation that separates the footprint (for non-convex footprints: one of its
            triangles) from that one cell; for a circle, radius - distance(centre, cell).
    """

    collision_free: bool
    penetration_fraction: float
    max_depth: float
    first_collision_index: int | None
    dense_poses: np.ndarray
    colliding: np.ndarray
    depths: np.ndarray


class CollisionRate(NamedTuple):
    """Result of :func:`collision_free_rate`; unpacks as ``rate, mean_penetration``."""

    rate: float  # fraction of trajectories that are collision free, in [0, 1]
    mean_penetration_fraction: float  # mean of the reports' penetration_fraction


# ------------------------------------------------------------------------------ public API
def check_collision(traj, footprint: Footprint, grid: GridMap, *, step: float | None = None,
                    headings=None, tolerance: float = DEFAULT_TOLERANCE) -> CollisionReport:
    """Check a trajectory's swept footprint against the occupied cells of ``grid``.

    Args:
        traj: (P, 2) waypoints x, y [m] in the map frame, P >= 1.
        footprint: the robot shape (an exact circle or a polygon in the robot frame).
        grid: the occupancy grid; off-map space counts as occupied.
        step: dense interpolation step [m] (default ``grid.resolution / 4``). Along a segment
            neither the centre nor (when headings turn) any footprint point moves more than
            ``step`` between consecutive dense poses.
        headings: optional (P,) per-waypoint headings [rad] (e.g. the simulator's yaw),
            interpolated along the shortest turn between waypoints. Default: the direction of
            the segment each pose lies on (see :func:`densify`).
        tolerance: overlap depth [m] that still counts as touching (not a collision).

    Returns:
        CollisionReport over the N dense poses.

    Raises:
        TrajectoryError: wrong shape, no points, non-finite values, bad step or tolerance.
        FootprintError: a polygon footprint that cannot be triangulated.
    """
    tolerance = _as_number(tolerance, "collision tolerance")
    if not (math.isfinite(tolerance) and tolerance >= 0):
        raise TrajectoryError(f"collision tolerance must be a finite number >= 0 m, "
                              f"got {tolerance!r}")
    if step is None:
        step = grid.resolution / 4
    # a circle looks the same at every heading: turning on the spot needs no extra poses
    turn_radius = 0.0 if footprint.is_circle else footprint.circumscribed_radius
    poses = densify(traj, step=step, headings=headings, turn_radius=turn_radius)
    # a grid whose free_distance its users built (safety net, placement, the monitor's static
    # map) passes far poses; one without it (e.g. fused with a scan) is not given one here
    depths = (far_passed_depths if "free_distance" in grid.__dict__ else _pose_depths)(
        poses, footprint, grid)  # (N,)
    colliding = depths > tolerance
    depths = np.where(colliding, depths, 0.0)
    hits = np.flatnonzero(colliding)
    for arr in (poses, colliding, depths):
        arr.setflags(write=False)
    return CollisionReport(
        collision_free=not hits.size,
        penetration_fraction=float(hits.size) / len(poses),
        max_depth=float(depths.max()),
        first_collision_index=int(hits[0]) if hits.size else None,
        dense_poses=poses,
        colliding=colliding,
        depths=depths,
    )


def collision_free_rate(trajs: Sequence, footprint: Footprint, grid: GridMap, *,
                        step: float | None = None,
                        tolerance: float = DEFAULT_TOLERANCE) -> CollisionRate:
    """Collision-free rate of a batch of trajectories.

    Args:
        trajs: a list of (P_i, 2) waypoint arrays [m] (lengths may differ), or a (B, P, 2) array.
        footprint, grid, step, tolerance: as in :func:`check_collision`.

    Returns:
        CollisionRate(rate, mean_penetration_fraction), both in [0, 1].
    """
    if len(trajs) == 0:
        raise TrajectoryError("collision_free_rate needs at least one trajectory")
    reports = [check_collision(t, footprint, grid, step=step, tolerance=tolerance) for t in trajs]
    free = sum(r.collision_free for r in reports)
    return CollisionRate(free / len(reports),
                         float(np.mean([r.penetration_fraction for r in reports])))


def segment_collisions(traj, footprint: Footprint, grid: GridMap, *,
                       tolerance: float = DEFAULT_TOLERANCE) -> np.ndarray:
    """Which segments of a trajectory collide, by one :func:`check_collision` of the whole of it.

    Args:
        traj: (N, 2) waypoints [m], N >= 1.
        footprint, grid, tolerance: as in :func:`check_collision` (default step, no headings).

    Returns:
        (N - 1,) bool: a dense pose of segment i -> i + 1 (its end poses included) collides.
        The dense poses are mapped back to segments by :func:`densify`'s counts
        (n_i = max(1, ceil(length_i / step))); a colliding waypoint pose spoils both segments
        that meet there.
    """
    path = _as_trajectory(traj)
    if len(path) < 2:
        return np.zeros(0, dtype=bool)
    report = check_collision(path, footprint, grid, tolerance=tolerance)
    bad = np.zeros(len(path) - 1, dtype=bool)
    if report.collision_free:
        return bad
    step = grid.resolution / 4  # check_collision's default
    length = np.linalg.norm(np.diff(path, axis=0), axis=1)
    n = np.maximum(1, np.ceil(length / step - 1e-9)).astype(np.int64)
    if int(n.sum()) + 1 != len(report.colliding):  # not densify's layout: judge one by one
        return np.array([not check_collision(path[k:k + 2], footprint, grid,
                                             tolerance=tolerance).collision_free
                         for k in range(len(path) - 1)])
    seg_of = np.append(np.repeat(np.arange(len(path) - 1), n), len(path) - 2)
    hits = np.flatnonzero(report.colliding)
    bad[seg_of[hits]] = True
    # a colliding waypoint pose also spoils the segment that ends there
    first = np.concatenate([[0], np.cumsum(n)])  # dense index of each waypoint
    at_wp = np.flatnonzero(report.colliding[first[1:-1]]) if len(path) > 2 else []
    bad[np.asarray(at_wp, dtype=np.int64)] = True
    return bad


def exact_check_for(grid: GridMap, footprint: Footprint, *,
                    tolerance: float = DEFAULT_TOLERANCE):
    """The exact checker as ``HierarchicalPlanner``'s ``exact_check``: a function of a path
    (N, 2) [m] giving :func:`segment_collisions` (N - 1,) bool. Builds ``grid.free_distance``
    (once per map) so that poses far from every wall pass at once."""
    grid.free_distance  # noqa: B018

    def exact_check(path) -> np.ndarray:
        return segment_collisions(path, footprint, grid, tolerance=tolerance)

    return exact_check


def densify(traj, *, step: float, headings=None, turn_radius: float = 0.0) -> np.ndarray:
    """Interpolate waypoints densely by arc length.

    Every waypoint is a dense pose; segment i (waypoint i -> i+1) contributes n_i poses at
    t = k / n_i, k = 0..n_i-1, with
    n_i = max(1, ceil(max(length_i, |turn_i| * turn_radius) / step)),
    and the last waypoint closes the list.

    Headings without ``headings``: each pose takes the direction (atan2) of the segment it
    lies on, the last waypoint that of the last segment. A zero-length segment keeps the
    previous segment's heading; zero-length segments at the start take the first real
    segment's heading (the robot faces where it is about to go); 0.0 if the trajectory has no
    real segment at all.

    Args:
        traj: (P, 2) waypoints [m], P >= 1.
        step: largest spacing [m] between consecutive poses, > 0.
        headings: optional (P,) per-waypoint headings [rad]; interpolated along the shortest turn.
        turn_radius: [m] the footprint's circumscribed radius, so turning on the spot is also
            sampled every ``step`` of footprint-point travel.

    Returns:
        (N, 3) poses x [m], y [m], heading [rad] in (-pi, pi].
    """
    pts = _as_trajectory(traj)
    step = _as_number(step, "interpolation step")
    if not (math.isfinite(step) and step > 0):
        raise TrajectoryError(f"interpolation step must be a finite number > 0 m, got {step!r}")
    P = len(pts)
    if headings is None:
        wp_heading = None
    else:
        wp_heading = np.asarray(headings, dtype=np.float64)
        if wp_heading.shape != (P,):
            raise TrajectoryError(f"headings must have shape ({P},) to match the trajectory, "
                                  f"got {wp_heading.shape}")
        if not np.all(np.isfinite(wp_heading)):
            raise TrajectoryError("headings contain NaN or inf")
    if P == 1:
        h0 = 0.0 if wp_heading is None else float(wp_heading[0])
        return np.array([[pts[0, 0], pts[0, 1], _wrap(h0)]])

    seg = np.diff(pts, axis=0)  # (P-1, 2)
    length = np.hypot(seg[:, 0], seg[:, 1])  # (P-1,)
    if wp_heading is None:
        seg_heading = _segment_headings(seg, length)  # (P-1,)
        turn = np.zeros(P - 1)
        start_heading = seg_heading
        end_heading = seg_heading[-1]
    else:
        turn = _wrap(np.diff(wp_heading))  # (P-1,) shortest turn
        start_heading = wp_heading[:-1]
        end_heading = wp_heading[-1]
    travel = np.maximum(length, np.abs(turn) * max(float(turn_radius), 0.0))
    n = np.maximum(1, np.ceil(travel / step - 1e-9)).astype(np.int64)  # (P-1,)
    seg_of = np.repeat(np.arange(P - 1), n)  # (N-1,) segment of each pose
    first = np.concatenate([[0], np.cumsum(n)[:-1]])
    t = (np.arange(len(seg_of)) - first[seg_of]) / n[seg_of]  # (N-1,) in [0, 1)
    xy = pts[seg_of] + t[:, None] * seg[seg_of]
    th = start_heading[seg_of] + t * turn[seg_of]
    poses = np.empty((len(seg_of) + 1, 3))
    poses[:-1, :2], poses[:-1, 2] = xy, th
    poses[-1] = (pts[-1, 0], pts[-1, 1], end_heading)
    poses[:, 2] = _wrap(poses[:, 2])
    return poses


def convex_pieces(polygon: np.ndarray) -> list[np.ndarray]:
    """Split a simple CCW polygon (V, 2) into convex pieces: the polygon itself if it is convex,
    else triangles by ear clipping. Duplicate and collinear vertices are dropped first."""
    poly = _clean_polygon(np.asarray(polygon, dtype=np.float64))
    if len(poly) < 3:
        raise FootprintError("footprint polygon degenerates to fewer than 3 distinct vertices")
    if signed_area(poly) < 0:
        poly = poly[::-1].copy()
    a, b, c = poly, np.roll(poly, -1, axis=0), np.roll(poly, -2, axis=0)
    if np.all(_cross(b - a, c - b) >= 0):
        return [poly]
    return [poly[list(tri)] for tri in _ear_clip(poly)]


# -------------------------------------------------------------------------------- internals
def _as_trajectory(traj) -> np.ndarray:
    """Validate waypoints -> (P, 2) float64."""
    try:
        pts = np.asarray(traj, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TrajectoryError(f"trajectory must be a numeric (P, 2) array: {exc}") from exc
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise TrajectoryError(f"trajectory must have shape (P, 2), got {pts.shape}")
    if pts.shape[0] < 1:
        raise TrajectoryError("trajectory has no points")
    if not np.all(np.isfinite(pts)):
        bad = int(np.flatnonzero(~np.isfinite(pts).all(axis=1))[0])
        raise TrajectoryError(f"trajectory has NaN or inf coordinates (first at waypoint {bad})")
    return pts


def _as_number(value, what: str) -> float:
    try:
        return float(value)
    except (TypeError, ValueError) as exc:
        raise TrajectoryError(f"{what} must be a number, got {value!r}") from exc


def _segment_headings(seg: np.ndarray, length: np.ndarray) -> np.ndarray:
    """(S, 2), (S,) -> (S,) direction of each segment; zero-length segments keep the previous
    heading (leading ones the first real one; 0 if none is real)."""
    real = length > _ZERO_LENGTH
    if not real.any():
        return np.zeros(len(seg))
    heading = np.arctan2(seg[:, 1], seg[:, 0])
    last_real = np.maximum.accumulate(np.where(real, np.arange(len(seg)), -1))
    last_real = np.where(last_real < 0, np.argmax(real), last_real)
    return heading[last_real]


def _wrap(angle):
    """Angles [rad] -> (-pi, pi], same shape."""
    return np.pi - np.mod(np.pi - angle, 2 * np.pi)


def pose_depths(poses, footprint: Footprint, grid: GridMap) -> np.ndarray:
    """The exact overlap depth of single poses: (N, 3) x [m], y [m], heading [rad] -> (N,)
    [m], > ``DEFAULT_TOLERANCE`` where the footprint placed there overlaps an occupied cell
    (<= 0 or -inf: free). The same test :func:`check_collision` applies to every dense pose."""
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    if not np.all(np.isfinite(poses)):
        raise TrajectoryError("poses must be finite")
    return _pose_depths(poses, footprint, grid)


def far_passed_depths(poses: np.ndarray, footprint: Footprint, grid: GridMap) -> np.ndarray:
    """:func:`pose_depths` of (N, 3) poses, fast far from walls: a pose whose cell lies farther
    than the circumscribed radius + sqrt(2) cells from every occupied cell (``grid``'s
    ``free_distance``, built on first use) gets -inf without its cells being tested. Exact: a
    pose is within half a cell diagonal of its cell's centre and an occupied square's points
    within half a diagonal of theirs, so such a pose's footprint is at least that far from
    every occupied square (free)."""
    near = wall_distance(grid, poses[:, :2]) - math.sqrt(2.0) * grid.resolution \
        <= footprint.circumscribed_radius  # (N,)
    out = np.full(len(poses), -np.inf)
    if near.any():
        out[near] = _pose_depths(poses[near], footprint, grid)
    return out


def wall_distance(grid: GridMap, xy: np.ndarray) -> np.ndarray:
    """(N, 2) [m] -> (N,) [m] distance from each point's cell centre to the nearest occupied
    cell centre (``grid.free_distance``; off the map: 0, beyond its edge counts as occupied)."""
    rows, cols = grid.world_to_cell(xy)
    inside = (rows >= 0) & (rows < grid.height) & (cols >= 0) & (cols < grid.width)
    out = np.zeros(len(xy))
    out[inside] = grid.free_distance[rows[inside], cols[inside]]
    return out


def _pose_depths(poses: np.ndarray, footprint: Footprint, grid: GridMap) -> np.ndarray:
    """(N, 3) poses -> (N,) largest overlap depth [m] with any occupied cell (<= 0: none)."""
    res = grid.resolution
    half = res / 2
    r_c = footprint.circumscribed_radius
    K = int(math.ceil(2 * r_c / res)) + 2  # window side [cells] covering the circumscribed disc
    if footprint.is_circle:
        axes_per_pose = 1
        pieces = []
    else:
        pieces = [_piece_axes(p) for p in convex_pieces(footprint.polygon)]
        axes_per_pose = sum(len(p[1]) + 2 for p in pieces)
    chunk = max(1, _CHUNK_ELEMENTS // (K * K * axes_per_pose))
    out = np.full(len(poses), -np.inf)
    for s in range(0, len(poses), chunk):
        block = poses[s:s + chunk]
        centres, occ = _window(block[:, :2], r_c, K, grid)  # (n, K, K, 2), (n, K, K)
        # distance from the pose centre to each cell square: a lower bound for any footprint
        rel = np.abs(centres - block[:, None, None, :2]) - half
        dist = np.hypot(np.maximum(rel[..., 0], 0.0), np.maximum(rel[..., 1], 0.0))  # (n, K, K)
        if footprint.is_circle:
            depth = np.where(occ, footprint.radius - dist, -np.inf)
            out[s:s + len(block)] = depth.reshape(len(block), -1).max(axis=1)
            continue
        cand = occ & (dist < r_c)  # cells the circumscribed disc reaches
        active = np.flatnonzero(cand.reshape(len(block), -1).any(axis=1))
        if not active.size:
            continue
        sub = block[active]
        best = np.full(cand[active].shape, -np.inf)  # (m, K, K)
        for verts, normals, lo, hi in pieces:
            best = np.maximum(best, _sat_depth(sub, centres[active], half, verts, normals, lo, hi))
        best = np.where(cand[active], best, -np.inf)
        out[s + active] = best.reshape(len(active), -1).max(axis=1)
    return out


def _window(xy: np.ndarray, r: float, K: int, grid: GridMap) -> tuple[np.ndarray, np.ndarray]:
    """The K x K cells around each point that cover the square of half-side r around it.

    xy: (n, 2) [m] -> centres (n, K, K, 2) [m], occupied (n, K, K) bool (off-map: True).
    """
    ox, oy = grid.origin
    res = grid.resolution
    c0 = np.floor((xy[:, 0] - r - ox) / res).astype(np.int64)  # (n,)
    r0 = np.floor((xy[:, 1] - r - oy) / res).astype(np.int64)
    k = np.arange(K)
    rows = r0[:, None, None] + k[None, :, None]  # (n, K, 1)
    cols = c0[:, None, None] + k[None, None, :]  # (n, 1, K)
    rows, cols = np.broadcast_arrays(rows, cols)  # (n, K, K)
    inside = (rows >= 0) & (rows < grid.height) & (cols >= 0) & (cols < grid.width)
    occ = grid.occupied[np.clip(rows, 0, grid.height - 1), np.clip(cols, 0, grid.width - 1)]
    occ = np.where(inside, occ, True)
    centres = np.stack([ox + (cols + 0.5) * res, oy + (rows + 0.5) * res], axis=-1)
    return centres, occ


def _piece_axes(piece: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Convex CCW piece (V, 2) [robot frame] -> its vertices (V, 2), outward unit edge normals
    (V, 2) and the piece's projection interval [lo, hi] (V,) on each normal."""
    edges = np.roll(piece, -1, axis=0) - piece
    normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    proj = piece @ normals.T  # (V_vertices, V_axes)
    return piece, normals, proj.min(axis=0), proj.max(axis=0)


def _sat_depth(poses: np.ndarray, centres: np.ndarray, half: float, verts: np.ndarray,
               normals: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """SAT overlap depth between a convex piece placed at each pose and the cell squares.

    poses: (m, 3); centres: (m, K, K, 2) cell centres [m]; half: half cell side [m];
    verts, normals, lo, hi: from :func:`_piece_axes` (robot frame).

    Returns (m, K, K) [m]: the minimum over the candidate axes (the piece's edge normals and the
    world x and y axes) of the shorter push that separates the two projections, i.e. the
    minimum translation distance when > 0; <= 0 means separated or touching.
    """
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    # piece edge normals in the world: R(theta) n; the piece's interval shifts by p . n_world
    nx = c[:, None] * normals[:, 0] - s[:, None] * normals[:, 1]  # (m, A)
    ny = s[:, None] * normals[:, 0] + c[:, None] * normals[:, 1]
    shift = poses[:, 0:1] * nx + poses[:, 1:2] * ny  # (m, A)
    cx, cy = centres[..., 0:1], centres[..., 1:2]  # (m, K, K, 1)
    sq_mid = cx * nx[:, None, None, :] + cy * ny[:, None, None, :]  # (m, K, K, A)
    sq_half = half * (np.abs(nx) + np.abs(ny))[:, None, None, :]
    p_lo = (lo + shift)[:, None, None, :]
    p_hi = (hi + shift)[:, None, None, :]
    depth = np.minimum(p_hi - (sq_mid - sq_half), (sq_mid + sq_half) - p_lo)
    depth = depth.min(axis=-1)  # (m, K, K)
    # the square's own axes (world x and y): the piece's world bounding box
    wx = poses[:, 0:1] + c[:, None] * verts[:, 0] - s[:, None] * verts[:, 1]  # (m, V)
    wy = poses[:, 1:2] + s[:, None] * verts[:, 0] + c[:, None] * verts[:, 1]
    for w, cc in ((wx, centres[..., 0]), (wy, centres[..., 1])):
        w_lo = w.min(axis=1)[:, None, None]
        w_hi = w.max(axis=1)[:, None, None]
        depth = np.minimum(depth, np.minimum(w_hi - (cc - half), (cc + half) - w_lo))
    return depth


def _clean_polygon(poly: np.ndarray) -> np.ndarray:
    """Drop consecutive duplicate vertices and vertices on a straight line."""
    keep = list(poly)
    changed = True
    while changed and len(keep) >= 3:
        changed = False
        for i in range(len(keep)):
            a, b, c = keep[i - 1], keep[i], keep[(i + 1) % len(keep)]
            if np.hypot(*(b - a)) <= _ZERO_LENGTH or abs(_cross(b - a, c - b)) <= 1e-12:
                del keep[i]
                changed = True
                break
    return np.array(keep).reshape(-1, 2)


def _ear_clip(poly: np.ndarray) -> list[tuple[int, int, int]]:
    """Triangulate a simple CCW polygon (V, 2) -> V-2 index triples."""
    idx = list(range(len(poly)))
    tris: list[tuple[int, int, int]] = []
    while len(idx) > 3:
        for k in range(len(idx)):
            ia, ib, ic = idx[k - 1], idx[k], idx[(k + 1) % len(idx)]
            a, b, c = poly[ia], poly[ib], poly[ic]
            turn = _cross(b - a, c - b)
            if abs(turn) <= 1e-12:  # collinear after earlier clips: a zero-area ear, drop it
                del idx[k]
                break
            if turn < 0:  # reflex vertex
                continue
            others = poly[[j for j in idx if j not in (ia, ib, ic)]]
            if len(others) and np.any(_in_triangle(others, a, b, c)):
                continue
            tris.append((ia, ib, ic))
            del idx[k]
            break
        else:
            raise FootprintError("footprint polygon cannot be triangulated "
                                 "(is it self-intersecting?)")
    tris.append((idx[0], idx[1], idx[2]))
    return tris


def _in_triangle(p: np.ndarray, a, b, c) -> np.ndarray:
    """(n, 2) points inside or on the CCW triangle a, b, c -> (n,) bool."""
    return ((_cross(b - a, p - a) >= -1e-12) & (_cross(c - b, p - b) >= -1e-12)
            & (_cross(a - c, p - c) >= -1e-12))


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """z component of u x v for (..., 2) arrays."""
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


