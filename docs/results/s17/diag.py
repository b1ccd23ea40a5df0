"""Where ECAHD alone still collides: zoomed PNGs of colliding stretches + component sizes.
usage: ECAHD_MODELS=M python diag.py MAP SEED N ROBOT OUTPREFIX [spacing]"""
import sys, numpy as np, torch, cv2
import matplotlib; matplotlib.use("Agg"); import matplotlib.pyplot as plt
from ecahd_core.collision import exact_check_for, segment_collisions
from ecahd_core.cost import CollisionCost
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import load_map
from ecahd_core.model_zoo import load_model
from ecahd_core.placement import placer_for
from ecahd_core.planner import DenseConfig, HierarchicalPlanner, SparseConfig, SparseDiffusion
from ecahd_core.navigation import auto_replan_spacing
from ecahd_core.problems import make_problems
torch.set_num_threads(1)
mp, seed, n, robot, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], sys.argv[5]
grid, fp = load_map(mp), make_footprint(robot)
lab_n, lab = cv2.connectedComponents(grid.occupied.astype(np.uint8), connectivity=8)
sizes = np.bincount(lab.ravel())
cost = CollisionCost.build(grid, fp).as_tuple()
sdm = load_model("sd", grid, footprint=fp)
sd = SparseDiffusion(sdm, SparseConfig(selection="collision_aware", precision="auto"), cost=cost,
                     placer=placer_for(grid, fp, None))
spacing = float(sys.argv[6]) if len(sys.argv) > 6 else auto_replan_spacing(grid, sd.expert_spacing)
hd = HierarchicalPlanner(sd, load_model("dd", grid, footprint=fp), costmap=cost[0],
                         footprint_points=cost[1], cost_config=cost[2], dense=DenseConfig(),
                         exact_check=exact_check_for(grid, fp), replan_spacing=spacing)
gen = torch.Generator().manual_seed(0)
x0, y0, res = grid.origin[0], grid.origin[1], grid.resolution
R = fp.circumscribed_radius
img = np.where(grid.occupied, 0.0, np.where(grid.data < 0, 0.6, 1.0))
nbad = 0
for k, prob in enumerate(make_problems(grid, n, seed=seed)):
    plan = hd.plan(prob.start, prob.goal, generator=gen)
    traj = np.asarray(plan.trajectory)
    bad = np.flatnonzero(segment_collisions(traj, fp, grid))
    if not len(bad):
        continue
    nbad += 1
    comps = set()
    for j in bad:
        a, b = traj[j], traj[j + 1]
        for t in np.linspace(0, 1, 20):
            p = a + t * (b - a)
            c0 = int((p[0] - x0) / res); r0 = int((p[1] - y0) / res); w = int(R / res) + 1
            sub = lab[max(r0 - w, 0):r0 + w + 1, max(c0 - w, 0):c0 + w + 1]
            rr, cc = np.mgrid[max(r0 - w, 0):r0 + w + 1, max(c0 - w, 0):c0 + w + 1]
            d = np.hypot((cc + 0.5) * res + x0 - p[0], (rr + 0.5) * res + y0 - p[1])
            comps |= set(sub[(d <= R) & (sub > 0)].tolist())
    wps = np.asarray(plan.waypoints) if hasattr(plan, "waypoints") else None
    print(k, "colliding segments", len(bad), "components", sorted(int(sizes[c]) for c in comps), flush=True)
    ctr = traj[bad[0]]
    fig, ax = plt.subplots(1, 2, figsize=(12, 6))
    ext = [x0, x0 + grid.width * res, y0, y0 + grid.height * res]
    for a_, zoom in zip(ax, (None, 3.0)):
        a_.imshow(img, cmap="gray", origin="lower", extent=ext, vmin=0, vmax=1)
        a_.plot(traj[:, 0], traj[:, 1], "b-", lw=0.8)
        for j in bad:
            a_.plot(traj[j:j + 2, 0], traj[j:j + 2, 1], "r-", lw=2)
        a_.plot(*prob.start, "go"); a_.plot(*prob.goal, "m*")
        if zoom:
            a_.set_xlim(ctr[0] - zoom, ctr[0] + zoom); a_.set_ylim(ctr[1] - zoom, ctr[1] + zoom)
    ax[0].set_title(f"problem {k} ({robot})"); ax[1].set_title("first colliding stretch, 6 m")
    fig.savefig(f"{out}_{k}.png", dpi=80); plt.close(fig)
print("colliding plans", nbad, "of", n)
