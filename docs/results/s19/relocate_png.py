"""Leg repair with and without relocation on one SD-like first leg (expert corner waypoints
perturbed by N(0, 2^2 m^2), docs/results/s19/proxy.py's setting) of office 2.
usage: python relocate_png.py office2.yaml PAIR OUT.png"""
import sys, numpy as np, torch
torch.set_num_threads(1)
import matplotlib; matplotlib.use("Agg"); import matplotlib.pyplot as plt
from ecahd_core.maps import load_map
from ecahd_core.dataset import generate_dataset
from ecahd_core.footprint import make_footprint
from ecahd_core.placement import WaypointPlacer
mp, pair, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
grid, fp = load_map(mp), make_footprint("circle")
ds = generate_dataset(grid, pairs=pair + 1, seed=99, workers=1, progress=False)
rng = np.random.default_rng(0)
for i in range(pair + 1):  # the same draws as proxy.py
    w = ds.sparse[i].astype(np.float64).copy()
    w[1:-1] += rng.normal(0, 2.0, w[1:-1].shape)
    w = np.clip(w, np.array(grid.bounds[:2]) + 0.05, np.array(grid.bounds[2:]) - 0.05)
img = np.where(grid.occupied, 0.0, np.where(grid.data < 0, 0.6, 1.0))
x0, y0 = grid.origin[:2]
ext = [x0, x0 + grid.width * grid.resolution, y0, y0 + grid.height * grid.resolution]
fig, axes = plt.subplots(1, 2, figsize=(12, 6))
for ax, relocate in zip(axes, (False, True)):
    placer = WaypointPlacer(grid, fp, relocate=relocate)
    xy, _ = placer(w, legs=1)
    n = len(xy) - (len(w) - 1)  # the legs the first leg became
    walls = placer.leg_walls(xy)[:n]
    ax.imshow(img, cmap="gray", origin="lower", extent=ext, vmin=0, vmax=1)
    ax.plot(ds.full[pair][:, 0], ds.full[pair][:, 1], "g-", lw=1, label="expert (A*)")
    ax.plot(w[:2, 0], w[:2, 1], "c--", lw=1.5, label="SD-like first leg")
    ax.plot(xy[:n + 1, 0], xy[:n + 1, 1], "b-", lw=1.5, label="after repair")
    for j in np.flatnonzero(walls > 0):
        ax.plot(xy[j:j + 2, 0], xy[j:j + 2, 1], "r-", lw=2.5)
    for p in xy[:n + 1]:
        ax.add_patch(plt.Circle(p, fp.circumscribed_radius, fill=False, lw=0.6))
    c = xy[0]
    span = max(4.0, np.abs(np.vstack([xy[:n + 1], w[:2]]) - c).max() + 1.5)
    ax.set_xlim(c[0] - span, c[0] + span); ax.set_ylim(c[1] - span, c[1] + span)
    ax.set_title(("with relocation" if relocate else "bends only (before)")
                 + f": {int((walls > 0).sum())} leg(s) crossing a wall (red)")
    ax.legend(fontsize=8, loc="lower left")
fig.suptitle(f"office 2, pair {pair}: an SD-like waypoint behind the wall beside a door (0.8 m circle robot)")
fig.tight_layout(rect=(0, 0, 1, 0.95)); fig.savefig(out, dpi=80)
