"""The exact collision checker with and without the grid's free_distance: time for the A*
paths of 6 seeded problems (docs/RESULTS.md, 2026-12-02).

    python scripts/bench_exact_checker.py MAP.yaml
"""
import sys
import time

import numpy as np

from ecahd_core.astar import clearance_for_footprint, planner_for
from ecahd_core.collision import check_collision
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import load_map
from ecahd_core.problems import make_problems

plain, fast = load_map(sys.argv[1]), load_map(sys.argv[1])
t = time.perf_counter()
fast.free_distance
print(f"free_distance: {(time.perf_counter() - t) * 1e3:.0f} ms")
astar = planner_for(plain, clearance_for_footprint(make_footprint("circle")))
paths = [astar.plan(p.start, p.goal) for p in make_problems(plain, 6, seed=7)]
metres = sum(np.linalg.norm(np.diff(p, axis=0), axis=1).sum() for p in paths)
for robot in ("circle", "quadruped"):
    fp = make_footprint(robot)
    for grid, name in ((plain, "every pose tested"), (fast, "far poses passed")):
        t = time.perf_counter()
        v = [check_collision(p, fp, grid).collision_free for p in paths]
        print(f"{robot}, {name}: {(time.perf_counter() - t) * 1e3:.0f} ms for {metres:.0f} m, {v}")
