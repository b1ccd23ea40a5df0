"""python diag.py MAP SEED N ROBOT TAG: plan every problem like the bench (shipped config), save
each colliding plan's pictures: the map round the deepest collision, the final trajectory, the
segment in collision and the global plan of that iteration. (ECAHD_MODELS=M, PYTHONPATH=code:/tmp/s25)"""
import sys, time, numpy as np, torch, pickle
import matplotlib; matplotlib.use("Agg"); import matplotlib.pyplot as plt
from ecahd_core.collision import segment_collisions, check_collision
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import load_map
from ecahd_core.problems import make_problems
import count6_lib as L
torch.set_num_threads(1)
mp, seed, n, robot, tag = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], sys.argv[5]
only = [int(x) for x in sys.argv[6].split(',')] if len(sys.argv) > 6 else None
grid, fp = load_map(mp), make_footprint(robot)
hd = L.build(grid, fp)
gen = torch.Generator().manual_seed(0)
occ = np.asarray(grid.occupied) if hasattr(grid, 'occupied') else None
out = {}
for k, prob in enumerate(make_problems(grid, n, seed=seed)):
    if only and k not in only:
        # keep the generator's stream as in the bench
        pass
    plan = hd.plan(prob.start, prob.goal, generator=gen)
    traj = np.asarray(plan.trajectory)
    col = segment_collisions(traj, fp, grid)
    if not col.any():
        continue
    out[k] = dict(plan=plan, start=prob.start, goal=prob.goal)
    idx = np.nonzero(col)[0]
    print(k, 'colliding segs', idx[:10], 'first_leg', plan.first_leg, 'bt', plan.backtracked, 'exact', plan.exact_kept, flush=True)
pickle.dump(out, open(f"/tmp/s26/diag/{tag}.pkl", "wb"))
