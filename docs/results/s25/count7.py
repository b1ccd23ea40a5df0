"""count6.py that also saves each plan: python count7.py MAP SEED N ROBOT OUT.npz
(ECAHD_MODELS=M, PYTHONPATH=code:/tmp/s25)"""
import sys, time, numpy as np, torch
from ecahd_core.collision import segment_collisions, check_collision
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import load_map
from ecahd_core.problems import make_problems
import count6_lib as L
torch.set_num_threads(1)
mp, seed, n, robot, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], sys.argv[5]
grid, fp = load_map(mp), make_footprint(robot)
hd = L.build(grid, fp)
gen = torch.Generator().manual_seed(0)
bad, ts, saved = [], [], {}
for k, prob in enumerate(make_problems(grid, n, seed=seed)):
    t0 = time.perf_counter(); plan = hd.plan(prob.start, prob.goal, generator=gen); ts.append(time.perf_counter() - t0)
    traj = np.asarray(plan.trajectory); saved[f"p{k}"] = traj
    if segment_collisions(traj, fp, grid).any():
        rep = check_collision(traj, fp, grid); bad.append(k)
        print('DEPTH', k, f'{rep.max_depth:.4f}', int(rep.colliding.sum()), flush=True)
np.savez(out, **saved)
print(f"{mp} s{seed} {robot}: colliding {len(bad)}/{n} {bad} median {1e3*np.median(ts):.0f} ms max {1e3*np.max(ts):.0f} ms mean {1e3*np.mean(ts):.0f} ms", flush=True)
