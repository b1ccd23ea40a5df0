"""A* detours round what the robot knows (the static map fused with the obstacles its scans
found): the fallback when SD cannot get round a blockage, and the A* baseline's re-plans."""
from __future__ import annotations

import numpy as np

from ecahd_core.errors import PlanningError

DETOUR_MARGIN = 8.0  # [m] detour's first search: the box round start and goal grown by this
DETOUR_BOX_MAX = 0.5  # a box holding more than this part of the map's cells is not searched first
# [m] detour's room to spare: a path keeping this much more than the footprint's clearance is
# taken where it is at most SPARE_STRETCH times as long as the tightest one. A* paths touch the
# clearance wherever they turn round a corner, and the robot that follows one with pure pursuit
# grazed a furniture block in the closed loop (docs/RESULTS.md, 2026-12-07).
DETOUR_SPARE = 0.1
SPARE_STRETCH = 1.25


def detour(grid, footprint, start, goal, *, reach: float = 0.6,
           margin: float | None = DETOUR_MARGIN, coarse: bool = True,
           spare: float = DETOUR_SPARE) -> np.ndarray:
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
    ``ecahd bench replan``); False: exact A* on every grid. ``spare`` [m]: a second search
    with that much more clearance; its path is returned where one exists and is at most
    SPARE_STRETCH times as long as the tight one (0: the tight path only)."""
    start, goal = (np.asarray(p, dtype=np.float64).reshape(2) for p in (start, goal))
    tight = _search(grid, footprint, start, goal, reach, margin, coarse, 0.0)
    if not spare > 0:
        return tight
    try:
        roomy = _search(grid, footprint, start, goal, reach, margin, coarse, float(spare))
    except PlanningError:
        return tight
    return roomy if _length(roomy) <= SPARE_STRETCH * _length(tight) else tight


def _length(path: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())


def _search(grid, footprint, start: np.ndarray, goal: np.ndarray, reach: float,
            margin: float | None, coarse: bool, extra: float) -> np.ndarray:
    """:func:`detour`'s search with the footprint's clearance + ``extra`` [m]: the box first
    (``margin``), then the whole map."""
    if margin is not None:
        lo, hi = np.minimum(start, goal) - margin, np.maximum(start, goal) + margin
        box = grid.crop(lo[0], lo[1], hi[0], hi[1])
        if box is not grid and box.height * box.width <= DETOUR_BOX_MAX * grid.height * grid.width:
            try:
                return _detour(box, footprint, start, goal, reach, coarse, extra)
            except PlanningError:
                pass
    return _detour(grid, footprint, start, goal, reach, coarse, extra)


def _detour(grid, footprint, start: np.ndarray, goal: np.ndarray, reach: float,
            coarse: bool, extra: float = 0.0) -> np.ndarray:
    """:func:`detour` on ``grid`` as it is, with the footprint's clearance + ``extra`` [m]."""
    from ecahd_core.astar import AStarPlanner, clearance_for_footprint, planner_for

    clearance = clearance_for_footprint(footprint, padding=extra)
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
