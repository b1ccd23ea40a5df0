import sys, numpy as np, torch
import cv2
from ecahd_core.collision import exact_check_for, segment_collisions
from ecahd_core.cost import CollisionCost, CostConfig
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import load_map
from ecahd_core.model_zoo import load_model
from ecahd_core.placement import placer_for
from ecahd_core.planner import DenseConfig, HierarchicalPlanner, SparseConfig, SparseDiffusion
from ecahd_core.problems import make_problems
torch.set_num_threads(1)
mp, spacing, n, robot = sys.argv[1], float(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
grid, fp = load_map(mp), make_footprint(robot)
occ = grid.occupied
nlab, lab = cv2.connectedComponents(occ.astype(np.uint8), connectivity=8)
sizes = np.bincount(lab.ravel())
cost = CollisionCost.build(grid, fp, CostConfig()).as_tuple()
sd = SparseDiffusion(load_model("sd", grid, footprint=fp), SparseConfig(selection="collision_aware", precision="auto"), cost=cost, placer=placer_for(grid, fp, None))
hd = HierarchicalPlanner(sd, load_model("dd", grid, footprint=fp), costmap=cost[0], footprint_points=cost[1], cost_config=cost[2], dense=DenseConfig(), exact_check=exact_check_for(grid, fp), replan_spacing=spacing)
gen = torch.Generator().manual_seed(0)
x0, y0 = grid.origin[0], grid.origin[1]; res = grid.resolution
R = fp.circumscribed_radius
for k, prob in enumerate(make_problems(grid, n, seed=2026)):
    plan = hd.plan(prob.start, prob.goal, generator=gen)
    traj = np.asarray(plan.trajectory)
    bad = np.flatnonzero(segment_collisions(traj, fp, grid))
    if not len(bad): continue
    comps = set()
    for j in bad:
        a, b = traj[j], traj[j+1]
        for t in np.linspace(0, 1, 20):
            p = a + t*(b-a)
            c0 = int((p[0]-x0)/res); r0 = int((p[1]-y0)/res); w = int(R/res)+1
            sub = lab[max(r0-w,0):r0+w+1, max(c0-w,0):c0+w+1]
            rr, cc = np.mgrid[max(r0-w,0):r0+w+1, max(c0-w,0):c0+w+1]
            d = np.hypot((cc+0.5)*res+x0-p[0], (rr+0.5)*res+y0-p[1])
            comps |= set(sub[(d <= R) & (sub > 0)].tolist())
    print(k, "collides with components of sizes", sorted(int(sizes[c]) for c in comps))
