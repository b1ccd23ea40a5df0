"""Benchmark problems: seeded start/goal pairs in free space with their A* reference paths.

A problem's start and goal keep ``clearance`` [m] from obstacles (default 0.4 m, the largest
preset robot, so every preset robot can stand there) and are at least ``min_distance`` [m]
apart along the A* path (paper Sec. IV-A: "random point pairs"). Benchmarks draw them with a
seed different from the training data's (default 2026 vs. 0), so they are held out.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ecahd_core.astar import AStarPlanner, path_length
from ecahd_core.dataset import sample_endpoint
from ecahd_core.errors import PlanningError
from ecahd_core.maps import GridMap

DEFAULT_SEED = 2026
DEFAULT_CLEARANCE = 0.4  # [m]
DEFAULT_MIN_DISTANCE = 3.0  # [m] along the A* path


@dataclass(frozen=True)
class Problem:
    """Attributes:
        start, goal: (2,) [m] in the map frame.
        astar_path: (N, 2) [m] the A* reference path (clearance-respecting, smoothed).
        astar_length: its length [m].
    """

    start: np.ndarray
    goal: np.ndarray
    astar_path: np.ndarray
    astar_length: float


def make_problems(grid: GridMap, n: int, *, seed: int = DEFAULT_SEED,
                  clearance: float = DEFAULT_CLEARANCE,
                  min_distance: float = DEFAULT_MIN_DISTANCE) -> list[Problem]:
    """``n`` seeded problems on ``grid`` (deterministic for a seed)."""
    if n < 1:
        raise PlanningError(f"need at least one problem, got {n}")
    rng = np.random.default_rng(seed)
    planner = AStarPlanner(grid, clearance, smooth=True)
    problems: list[Problem] = []
    for _ in range(100 * n + 100):
        if len(problems) == n:
            return problems
        start, goal = sample_endpoint(rng, planner), sample_endpoint(rng, planner)
        try:
            path = planner.plan(start, goal)
        except PlanningError:
            continue
        length = path_length(path)
        if length >= min_distance:
            problems.append(Problem(start=start, goal=goal, astar_path=path, astar_length=length))
    raise PlanningError(f"found only {len(problems)} of {n} problems on map {grid.name!r} with "
                        f"clearance {clearance} m and min_distance {min_distance} m")
