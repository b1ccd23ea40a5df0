import sys, numpy as np, torch
import matplotlib; matplotlib.use("Agg"); import matplotlib.pyplot as plt
from ecahd_core.collision import exact_check_for
from ecahd_core.cost import CollisionCost
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import load_map
from ecahd_core.model_zoo import load_model
from ecahd_core.placement import placer_for
from ecahd_core.planner import DenseConfig, HierarchicalPlanner, SparseConfig, SparseDiffusion
from ecahd_core.navigation import auto_replan_spacing
from ecahd_core.problems import make_problems
torch.set_num_threads(1)
mp, seed, robot, k_want = sys.argv[1], int(sys.argv[2]), sys.argv[3], int(sys.argv[4])
grid, fp = load_map(mp), make_footprint(robot)
cost = CollisionCost.build(grid, fp).as_tuple()
sd = SparseDiffusion(load_model("sd", grid, footprint=fp), SparseConfig(selection="collision_aware", precision="auto"), cost=cost, placer=placer_for(grid, fp, None))
spacing = auto_replan_spacing(grid, sd.expert_spacing)
hd = HierarchicalPlanner(sd, load_model("dd", grid, footprint=fp), costmap=cost[0], footprint_points=cost[1], cost_config=cost[2], dense=DenseConfig(), exact_check=exact_check_for(grid, fp), replan_spacing=spacing)
gen = torch.Generator().manual_seed(0)
for k, prob in enumerate(make_problems(grid, k_want + 1, seed=seed)):
    plan = hd.plan(prob.start, prob.goal, generator=gen)
S = np.array([g[0] for g in plan.global_plans])
for i, g in enumerate(plan.global_plans):
    print(i, len(g), np.round(g[0], 1), "->", np.round(g[1], 1), plan.first_leg[i], "dist", round(float(np.linalg.norm(g[0] - prob.goal)), 1))
x0, y0, res = grid.origin[0], grid.origin[1], grid.resolution
img = np.where(grid.occupied, 0.0, np.where(grid.data < 0, 0.6, 1.0))
fig, ax = plt.subplots(figsize=(9, 9))
ax.imshow(img, cmap="gray", origin="lower", extent=[x0, x0 + grid.width * res, y0, y0 + grid.height * res])
ax.plot(S[:, 0], S[:, 1], "b.-"); ax.plot(*prob.start, "go"); ax.plot(*prob.goal, "m*", ms=12)
for g in plan.global_plans[::5]:
    ax.plot(g[:, 0], g[:, 1], "y--", lw=0.6)
fig.savefig(f"runaway_{robot}_{seed}_{k_want}.png", dpi=70)
