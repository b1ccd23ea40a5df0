"""alone-rate on N problems: ECAHD_MODELS=M python count.py MAP SEED N ROBOT"""
import json, os, sys, time, numpy as np, torch
from ecahd_core.collision import exact_check_for, segment_collisions, check_collision
from ecahd_core.cost import CollisionCost
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import load_map
from ecahd_core.model_zoo import load_model
from ecahd_core.placement import placer_for
from ecahd_core import planner as PL
from ecahd_core.planner import DenseConfig, HierarchicalPlanner, SparseConfig, SparseDiffusion
from ecahd_core.navigation import auto_replan_spacing
from ecahd_core.problems import make_problems
torch.set_num_threads(1)
mp, seed, n, robot = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
grid, fp = load_map(mp), make_footprint(robot)
cost = CollisionCost.build(grid, fp).as_tuple()
sd = SparseDiffusion(load_model("sd", grid, footprint=fp), SparseConfig(selection="collision_aware", precision="auto"), cost=cost, placer=placer_for(grid, fp, None))
spacing = auto_replan_spacing(grid, sd.expert_spacing)
hd = HierarchicalPlanner(sd, load_model("dd", grid, footprint=fp), costmap=cost[0], footprint_points=cost[1], cost_config=cost[2], dense=DenseConfig(**json.loads(os.environ.get("DENSE", "{}"))), exact_check=exact_check_for(grid, fp), replan_spacing=spacing, backtracks=int(os.environ.get("BT", "2")))
gen = torch.Generator().manual_seed(0)
bad, ts = [], []
for k, prob in enumerate(make_problems(grid, n, seed=seed)):
    t0 = time.perf_counter(); plan = hd.plan(prob.start, prob.goal, generator=gen); ts.append(time.perf_counter() - t0)
    print('BT', k, getattr(plan, 'backtracked', '-'), flush=True)
    if segment_collisions(np.asarray(plan.trajectory), fp, grid).any():
        bad.append(k)
        rep = check_collision(np.asarray(plan.trajectory), fp, grid); print('DEPTH', k, f'{rep.max_depth:.4f}', int(rep.colliding.sum()), flush=True)
        segbad = [i for i, sg in enumerate(plan.segments) if segment_collisions(sg, fp, grid).any()]
        print(k, "iters", len(plan.segments), "bad", [(i, len(plan.global_plans[i]), plan.first_leg[i] or "-", "dd" if plan.dd_segments[i] else "", "kept" if plan.exact_kept[i] else "", f"wall={sd.placer.leg_walls(plan.global_plans[i][:2])[0]:.2f}", f"len={np.linalg.norm(plan.global_plans[i][1]-plan.global_plans[i][0]):.1f}") for i in segbad], flush=True)
print(f"{mp} s{seed} {robot}: colliding {len(bad)}/{n} {bad} median {1e3*np.median(ts):.0f} ms max {1e3*np.max(ts):.0f} ms mean {1e3*np.mean(ts):.0f} ms", getattr(PL, "PROTO_STATS", None), flush=True)
