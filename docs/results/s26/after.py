"""One office-1 problem planned with the subgoal rule off and on (the same SD draws up to the
first subgoal), beside A*: python after.py MAP SEED N ROBOT K OUT.png (ECAHD_MODELS=M)"""
import sys, numpy as np, torch
import matplotlib; matplotlib.use("Agg"); import matplotlib.pyplot as plt
from ecahd_core.astar import astar_path, clearance_for_footprint
from ecahd_core.collision import segment_collisions
from ecahd_core.cost import CollisionCost
from ecahd_core.collision import exact_check_for
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import load_map
from ecahd_core.model_zoo import load_model
from ecahd_core.navigation import auto_replan_spacing
from ecahd_core.placement import placer_for
from ecahd_core.planner import DenseConfig, HierarchicalPlanner, SparseConfig, SparseDiffusion
from ecahd_core.problems import make_problems
torch.set_num_threads(1)
mp, seed, n, robot, k, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], int(sys.argv[5]), sys.argv[6]
grid, fp = load_map(mp), make_footprint(robot)
cost = CollisionCost.build(grid, fp).as_tuple()
sd = SparseDiffusion(load_model("sd", grid, footprint=fp), SparseConfig(selection="collision_aware", precision="auto"), cost=cost, placer=placer_for(grid, fp, None))
prob = make_problems(grid, n, seed=seed)[k]
occ = (grid.data >= 65) | (grid.data < 0)
ex = [grid.origin[0], grid.origin[0] + occ.shape[1] * grid.resolution, grid.origin[1], grid.origin[1] + occ.shape[0] * grid.resolution]
ap = astar_path(grid, prob.start, prob.goal, clearance_for_footprint(fp))
fig, axes = plt.subplots(1, 2, figsize=(13, 6.5))
for ax, sub in zip(axes, (False, True)):
    hd = HierarchicalPlanner(sd, load_model("dd", grid, footprint=fp), costmap=cost[0], footprint_points=cost[1], cost_config=cost[2], dense=DenseConfig(), exact_check=exact_check_for(grid, fp), replan_spacing=auto_replan_spacing(grid, sd.expert_spacing), backtracks=2, subgoals=sub)
    plan = hd.plan(prob.start, prob.goal, generator=torch.Generator().manual_seed(0))
    traj = plan.trajectory; col = segment_collisions(traj, fp, grid)
    ax.imshow(occ, origin='lower', extent=ex, cmap='Greys', interpolation='nearest')
    ax.plot(ap[:, 0], ap[:, 1], 'g-', lw=2, label='A* (reference)')
    ax.plot(traj[:, 0], traj[:, 1], 'b-', lw=1.2, label='ECAHD')
    for i in np.nonzero(col)[0]: ax.plot(traj[i:i+2, 0], traj[i:i+2, 1], 'r-', lw=3)
    subs = [g[-2] for g, f in zip(plan.global_plans, plan.first_leg) if f == 'subgoal']
    if subs: s_ = np.array(subs); ax.plot(s_[:, 0], s_[:, 1], 'mx', ms=8, label='subgoals')
    ax.plot(*prob.start, 'g^', ms=10); ax.plot(*prob.goal, 'r*', ms=14)
    c = np.vstack([traj[-40:], [prob.goal]]).mean(0)
    ax.set_xlim(prob.goal[0] - 15, prob.goal[0] + 3); ax.set_ylim(prob.goal[1] - 7, prob.goal[1] + 5)
    ax.set_title(f"subgoal rule {'on' if sub else 'off'}: {len(plan.global_plans)} iterations, "
                 f"{'COLLIDES' if col.any() else 'collision-free'}" + (f", {plan.subgoals} subgoal re-plans" if sub else ""))
    ax.legend(loc='lower right', fontsize=8)
fig.tight_layout(); fig.savefig(out, dpi=70)
