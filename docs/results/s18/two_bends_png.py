"""The two-bend leg repair on warehouse 2 (seed 2028, problem 10's last legs): before / after.
usage: python two_bends_png.py warehouse2.yaml OUT.png"""
import sys
import numpy as np
import matplotlib; matplotlib.use("Agg"); import matplotlib.pyplot as plt
from ecahd_core.collision import segment_collisions
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import load_map
from ecahd_core.placement import WaypointPlacer

grid, fp = load_map(sys.argv[1]), make_footprint("circle")
legs = np.array([[12.99, 9.38], [11.99, 8.93], [11.39, 8.49]])  # SD's last waypoints, the goal
x0, y0, res = grid.origin[0], grid.origin[1], grid.resolution
img = np.where(grid.occupied, 0.0, np.where(grid.data < 0, 0.6, 1.0))
ext = [x0, x0 + grid.width * res, y0, y0 + grid.height * res]
fig, axs = plt.subplots(1, 2, figsize=(11, 5.5))
for ax, two in zip(axs, (False, True)):
    placer = WaypointPlacer(grid, fp, two_bends=two)
    path, added = placer.repair(legs)
    bad = segment_collisions(path, fp, grid)
    ax.imshow(img, cmap="gray", origin="lower", extent=ext, vmin=0, vmax=1)
    for k in range(len(path) - 1):
        ax.plot(path[k:k + 2, 0], path[k:k + 2, 1], "r-" if bad[k] else "b-", lw=2)
    for p in path:
        ax.add_patch(plt.Circle(p, fp.circumscribed_radius, fill=False, ec="0.4", lw=0.6))
    ax.plot(path[:, 0], path[:, 1], "ko", ms=3)
    ax.plot(*legs[-1], "m*", ms=14)
    ax.set_xlim(10.0, 15.5); ax.set_ylim(6.0, 11.0)
    ax.set_title(("leg repair, one bend" if not two else "with two bends") +
                 f": {added} added, {int(bad.sum())} leg(s) in collision")
fig.suptitle("warehouse 2: the way to the goal (magenta) round a block and a speckle cell "
             "(0.8 m circle robot; circles: footprint at the waypoints)")
fig.tight_layout()
fig.savefig(sys.argv[2], dpi=80)
