"""Zoomed PNGs of each colliding segment: SD plan of that iteration, DD segment, footprints.
usage: ECAHD_MODELS=M python diag4.py MAP SEED ROBOT OUT k1,k2,..."""
import sys, numpy as np, torch
import matplotlib; matplotlib.use("Agg"); import matplotlib.pyplot as plt
from ecahd_core.collision import exact_check_for, segment_collisions
from ecahd_core.cost import CollisionCost
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import load_map
from ecahd_core.model_zoo import load_model
from ecahd_core.placement import placer_for, headings
from ecahd_core.planner import DenseConfig, HierarchicalPlanner, SparseConfig, SparseDiffusion
from ecahd_core.navigation import auto_replan_spacing
from ecahd_core.problems import make_problems
torch.set_num_threads(1)
mp, seed, robot, out = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
want = [int(x) for x in sys.argv[5].split(",")]
grid, fp = load_map(mp), make_footprint(robot)
cost = CollisionCost.build(grid, fp).as_tuple()
sd = SparseDiffusion(load_model("sd", grid, footprint=fp), SparseConfig(selection="collision_aware", precision="auto"), cost=cost, placer=placer_for(grid, fp, None))
spacing = auto_replan_spacing(grid, sd.expert_spacing)
hd = HierarchicalPlanner(sd, load_model("dd", grid, footprint=fp), costmap=cost[0], footprint_points=cost[1], cost_config=cost[2], dense=DenseConfig(), exact_check=exact_check_for(grid, fp), replan_spacing=spacing)
gen = torch.Generator().manual_seed(0)
x0, y0, res = grid.origin[0], grid.origin[1], grid.resolution
img = np.where(grid.occupied, 0.0, np.where(grid.data < 0, 0.6, 1.0))
ext = [x0, x0 + grid.width * res, y0, y0 + grid.height * res]
poly = fp.polygon
for k, prob in enumerate(make_problems(grid, max(want) + 1, seed=seed)):
    plan = hd.plan(prob.start, prob.goal, generator=gen)
    if k not in want:
        continue
    segbad = [i for i, sg in enumerate(plan.segments) if segment_collisions(sg, fp, grid).any()]
    for i in segbad:
        sg = plan.segments[i]; gp = np.asarray(plan.global_plans[i])
        fig, ax = plt.subplots(figsize=(7, 7))
        ax.imshow(img, cmap="gray", origin="lower", extent=ext, vmin=0, vmax=1)
        traj = np.asarray(plan.trajectory)
        ax.plot(traj[:, 0], traj[:, 1], "c-", lw=0.8)
        ax.plot(gp[:, 0], gp[:, 1], "y.--", lw=0.8)
        ax.plot(sg[:, 0], sg[:, 1], "b.-", lw=1.5)
        dense = np.concatenate([np.linspace(sg[j], sg[j + 1], 6)[:-1] for j in range(len(sg) - 1)] + [sg[-1:]])
        hd_ = headings(dense)
        bad = segment_collisions(dense, fp, grid)
        for j, (p, h) in enumerate(zip(dense, hd_)):
            c, s = np.cos(h), np.sin(h)
            pg = poly @ np.array([[c, s], [-s, c]]) + p
            col = "r" if (j < len(bad) and bad[j]) or (j > 0 and bad[j - 1]) else "g"
            ax.fill(pg[:, 0], pg[:, 1], fill=False, ec=col, lw=0.5)
        ctr = sg.mean(0)
        ax.set_xlim(ctr[0] - 3, ctr[0] + 3); ax.set_ylim(ctr[1] - 3, ctr[1] + 3)
        ax.set_title(f"{robot} p{k} it{i} first_leg={plan.first_leg[i]} dd={plan.dd_segments[i]} kept={plan.exact_kept[i]}")
        fig.savefig(f"{out}_p{k}_it{i}.png", dpi=80); plt.close(fig)
        print(k, i, "seg", np.round(sg, 2).tolist(), "gp", np.round(gp[:3], 2).tolist(), flush=True)
