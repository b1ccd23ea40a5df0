"""Velocities of the obstacles a LiDAR sees that are not on the map (issue 11), so the collision
monitor can predict where a moving one will be instead of treating it as a wall. No rclpy.

Each scan's unmapped returns (world frame) are grouped into clusters (points closer than
``cluster_gap`` chain together). A cluster's velocity comes from aligning it with the returns of
an earlier scan, ``baseline`` seconds before (the earliest kept scan at least that old, at
most ``max_baseline``):

1. The earlier points within ``max_speed * dt + cluster_gap`` of the cluster are its candidates
   in the earlier scan; none -> velocity unknown (0: a new object is judged as static).
2. Two initial shifts: 0 (standing still) and centroid(cluster) - centroid(candidates).
3. From each, a translation-only, trimmed ICP refines t: each cluster point is matched to the
   nearest point of the candidates' polyline (consecutive returns joined, so shifts finer than
   the beam spacing count) shifted by t, the worst ``1 - trim`` of the matches are dropped, and
   t moves by the mean residual; ``iterations`` times. The shift from the centroids wins only
   if its residual is clearly (``tie_rms``) smaller: along a flat face no shift is observable.
4. v = t / dt; |v| < ``min_speed`` -> 0 (sensor noise and view changes on static objects); |v|
   above ``max_speed`` is clipped.

Why ICP and not the centroid alone: as the robot drives past a box the faces it sees change,
and the centroid of the visible points moves although the box does not (up to a few tenths of a
metre per second). The points themselves stay on the same faces, so aligning them gives a shift
near zero for the box and the true displacement for a cylinder or a person.

Shapes: points (M, 2) [m] world frame, velocities (M, 2) [m/s], stamps [s].
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from ecahd_core.errors import EcahdError
from ecahd_core.local_costmap import check_real

_OWNER = "motion tracker"
MAX_POINTS = 2000  # more unmapped points than this per scan are subsampled for tracking
ALIGN_POINTS = 24  # a cluster is aligned with at most this many of its points (evenly picked)
CONVERGED = 2e-4  # [m] an ICP step shorter than this ends the iterations


def _thin(points: np.ndarray, n: int) -> np.ndarray:
    """At most n of the points (M, 2), evenly spaced in their order (beam order kept)."""
    if len(points) <= n:
        return points
    return points[np.linspace(0, len(points) - 1, n).astype(np.int64)]


@dataclass(frozen=True, kw_only=True)
class TrackerConfig:
    """Settings of :class:`MotionTracker` (one place defines each default).

    Attributes:
        cluster_gap: [m] returns closer than this belong to one object.
        baseline: [s] the scan a cluster is aligned with is at least this much older.
        max_baseline: [s] ... and at most this much (older scans are forgotten).
        min_speed: [m/s] slower estimates count as static.
        max_speed: [m/s] the fastest obstacle expected (search radius; estimates are clipped).
        trim: fraction of the nearest matches the ICP keeps, in (0, 1].
        iterations: ICP iterations.
        tie_rms: [m] the ICP started from the centroids' shift is taken over the one started
            from standing still only when its residual is smaller by more than this.
    """

    cluster_gap: float = 0.3
    baseline: float = 0.3
    max_baseline: float = 0.8
    min_speed: float = 0.12
    max_speed: float = 1.5
    trim: float = 0.7
    iterations: int = 8
    tie_rms: float = 0.003

    def __post_init__(self) -> None:
        for name in ("cluster_gap", "baseline", "max_baseline", "max_speed", "trim", "tie_rms"):
            check_real(_OWNER, name, getattr(self, name), zero_ok=False)
        check_real(_OWNER, "min_speed", self.min_speed, zero_ok=True)
        if self.max_baseline < self.baseline:
            raise EcahdError(f"{_OWNER}: max_baseline ({self.max_baseline} s) must be >= "
                             f"baseline ({self.baseline} s)")
        if self.trim > 1:
            raise EcahdError(f"{_OWNER}: trim must be in (0, 1], got {self.trim!r}")
        if isinstance(self.iterations, bool) or not isinstance(self.iterations, int) \
                or self.iterations < 1:
            raise EcahdError(f"{_OWNER}: iterations must be an integer >= 1, "
                             f"got {self.iterations!r}")


def clusters(points: np.ndarray, gap: float) -> np.ndarray:
    """Breakpoint segmentation of a scan: (M, 2) returns [m] in beam order -> (M,) int labels
    0..C-1. A new cluster starts wherever two consecutive returns are ``gap`` [m] or more apart
    (the last and the first return close the circle of a 360-degree scan)."""
    m = len(points)
    if m < 2:
        return np.zeros(m, dtype=np.int64)
    jump = np.hypot(*np.diff(points, axis=0).T) >= gap  # (M-1,)
    labels = np.concatenate([[0], np.cumsum(jump)])  # (M,)
    if labels[-1] > 0 and np.hypot(*(points[0] - points[-1])) < gap:
        labels[labels == labels[-1]] = 0  # the circle closes: last cluster joins the first
        _, labels = np.unique(labels, return_inverse=True)
    return labels


def align(moved: np.ndarray, before: np.ndarray, shift: np.ndarray, *, trim: float,
          iterations: int, gap: float = math.inf) -> tuple[np.ndarray, float]:
    """Translation-only trimmed ICP, point to segment: the shift t (2,) [m] with moved ~
    before + t. moved: (A, 2) [m]; before: (B, 2) [m] in beam order (consecutive points
    closer than ``gap`` [m] are joined by a segment, so a shift finer than the beam spacing is
    resolved; a lone point is a segment of length 0); shift: (2,) initial guess.
    -> (t, rms [m] of the kept matches' residuals after the last step)."""
    t = np.asarray(shift, dtype=np.float64).copy()
    ax, ay = before[:, 0], before[:, 1]  # (B,) segment starts
    if len(before) > 1:
        bx, by = np.roll(ax, -1), np.roll(ay, -1)  # (B,) ends
        lone = np.hypot(bx - ax, by - ay) >= gap
        lone[-1] = True  # the last point starts no segment (the circle is not closed here)
        bx, by = np.where(lone, ax, bx), np.where(lone, ay, by)
    else:
        bx, by = ax, ay
    ex, ey = bx - ax, by - ay  # (B,) segment vectors
    e2 = np.maximum(ex * ex + ey * ey, 1e-18)
    mx, my = moved[:, 0:1], moved[:, 1:2]  # (A, 1)
    rows = np.arange(len(moved))
    keep = max(1, int(math.ceil(trim * len(moved))))
    rms = math.inf
    for it in range(iterations + 1):
        px, py = mx - (ax + t[0]), my - (ay + t[1])  # (A, B) from each segment start
        u = np.clip((px * ex + py * ey) / e2, 0.0, 1.0)
        dx, dy = px - u * ex, py - u * ey  # (A, B) from the nearest point of each segment
        d2 = dx * dx + dy * dy
        nearest = np.argmin(d2, axis=1)  # (A,)
        best_d2 = d2[rows, nearest]
        best = np.argpartition(best_d2, keep - 1)[:keep] if keep < len(moved) else rows
        rms = float(np.sqrt(best_d2[best].mean()))
        if it == iterations:
            break
        step = (dx[rows, nearest][best].mean(), dy[rows, nearest][best].mean())
        t += step
        if step[0] * step[0] + step[1] * step[1] < CONVERGED * CONVERGED:
            iterations = it + 1  # one more pass for the residual at the final shift
    return t, rms


class MotionTracker:
    """Per-point velocities of unmapped scan returns (see the module docstring).

    Args:
        config: TrackerConfig (default TrackerConfig()).
    """

    def __init__(self, config: TrackerConfig | None = None) -> None:
        self.config = TrackerConfig() if config is None else config
        self._history: deque[tuple[float, np.ndarray]] = deque()  # (stamp [s], (M, 2))

    def reset(self) -> None:
        """Forget the earlier scans (e.g. after the clock jumped back)."""
        self._history.clear()

    def update(self, points, stamp: float) -> np.ndarray:
        """Add one scan's unmapped returns and estimate their velocities.

        Args:
            points: (M, 2) world x, y [m] of the scan's returns that are not on the map.
            stamp: [s] the scan's time.

        Returns:
            (M, 2) velocity [m/s] of each point (0 where static or unknown).
        """
        cfg = self.config
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if not math.isfinite(stamp):
            raise EcahdError(f"{_OWNER}: stamp must be finite, got {stamp!r}")
        if self._history and stamp < self._history[-1][0]:
            self.reset()  # time went back (a restarted simulation)
        velocities = np.zeros_like(pts)
        picked = np.unique(np.linspace(0, len(pts) - 1, min(len(pts), MAX_POINTS)
                                       ).astype(np.int64))  # (T,) beam order kept
        tracked = pts[picked]
        earlier = self._earlier(stamp)
        if earlier is not None and len(tracked) and len(earlier[1]):
            dt = stamp - earlier[0]
            velocities = self._velocities(tracked, earlier[1], dt)
            if len(tracked) < len(pts):  # each point: the velocity of the tracked one before it
                velocities = velocities[np.searchsorted(picked, np.arange(len(pts)),
                                                        side="right") - 1]
        self._history.append((float(stamp), tracked))
        while self._history and stamp - self._history[0][0] > cfg.max_baseline:
            self._history.popleft()
        return velocities

    def _earlier(self, stamp: float) -> tuple[float, np.ndarray] | None:
        """The latest kept scan at least ``baseline`` older than ``stamp``, if any."""
        cfg = self.config
        found = None
        for when, pts in self._history:
            if cfg.baseline - 1e-9 <= stamp - when <= cfg.max_baseline + 1e-9:
                found = (when, pts)
        return found

    def _velocities(self, tracked: np.ndarray, before: np.ndarray, dt: float) -> np.ndarray:
        """(T, 2) returns now, (B, 2) returns dt [s] earlier -> (T, 2) velocities [m/s]."""
        cfg = self.config
        labels = clusters(tracked, cfg.cluster_gap)  # (T,)
        reach = cfg.max_speed * dt + cfg.cluster_gap  # [m]
        cluster_v = np.zeros((labels.max(initial=-1) + 1, 2))  # (C, 2)
        for c in range(len(cluster_v)):
            mine = _thin(tracked[labels == c], ALIGN_POINTS)  # (A, 2)
            d2 = np.sum((before[:, None, :] - mine[None, :, :]) ** 2, axis=-1).min(axis=1)
            cand = _thin(before[d2 <= reach * reach], 2 * ALIGN_POINTS)  # (B', 2)
            if len(cand) == 0:
                continue
            # from standing still and from the centroids' shift; standing still wins unless the
            # other aligns clearly better (along a flat face a shift is not observable, and the
            # centroid moves with the view: starting there would invent a velocity)
            still, still_rms = align(mine, cand, np.zeros(2), trim=cfg.trim,
                                     iterations=cfg.iterations, gap=cfg.cluster_gap)
            guess = mine.mean(axis=0) - cand.mean(axis=0)
            t = still
            if np.hypot(*(guess - still)) > CONVERGED:  # a second start that can differ
                moved, moved_rms = align(mine, cand, guess, trim=cfg.trim,
                                         iterations=cfg.iterations, gap=cfg.cluster_gap)
                t = moved if moved_rms < still_rms - cfg.tie_rms else still
            v = t / dt
            speed = float(np.hypot(*v))
            if speed < cfg.min_speed:
                continue
            cluster_v[c] = v * min(1.0, cfg.max_speed / speed)
        return cluster_v[labels]
