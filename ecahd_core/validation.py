"""Checks of poses and plans that arrive from outside (messages, files): finite, within sane
bounds, not absurdly long, with errors that name the problem; and the plan simplification the
local refiner applies before it refines a plan segment by segment."""
from __future__ import annotations

import math

import numpy as np

from ecahd_core.errors import PlanningError

COORDINATE_LIMIT = 1e6  # [m] |x|, |y| beyond this is absurd whatever the map
MAX_PLAN_POINTS = 100_000  # a plan with more poses is rejected
PLAN_MARGIN = 1.0  # [m] plan points may lie this far outside the map's bounds
SIMPLIFY_TOLERANCE = 0.005  # [m] interior plan points this close to the chord are dropped


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

