import sys, time, numpy as np
from ecahd_core.maps import load_map
from ecahd_core.footprint import make_footprint
from ecahd_core.placement import WaypointPlacer
grid = load_map("maps/warehouse2.yaml")
rng = np.random.default_rng(0)
res = {}
for robot in ["humanoid", "circle"]:
    pl = WaypointPlacer(grid, make_footprint(robot))
    a = rng.uniform([2, 2], [28, 48], size=(2,)); b = a + rng.uniform(-5, 5, size=(64, 2))
    pl.wall_length(a, b)
    t0 = time.perf_counter()
    for _ in range(300): w = pl.wall_length(a, b)
    print(robot, "%.3f ms" % ((time.perf_counter() - t0) / 300 * 1e3), w[:4])
