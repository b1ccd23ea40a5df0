import sys, time, numpy as np, torch
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import load_map
from ecahd_core.problems import make_problems
from ecahd_core import planner as P
import count6_lib as L
torch.set_num_threads(1)
grid, fp = load_map(sys.argv[1]), make_footprint(sys.argv[2])
hd = L.build(grid, fp)
stats = {"checks": 0, "alt": 0, "near_goal_alt": 0, "kept": 0}
orig_plan = P.SparseDiffusion.plan
inside = [False]
def tg(self, S, G, sparse, p, times, gen):
    stats["checks"] += 1
    n0 = stats["alt"]
    inside[0] = (S, G, sparse)
    out = orig_tg(self, S, G, sparse, p, times, gen)
    inside[0] = False
    if stats["alt"] > n0:
        if np.allclose(sparse.waypoints[1], G): stats["near_goal_alt"] += 1
        if out is not sparse: stats["kept"] += 1
    return out
def plan(self, *a, **k):
    if inside[0]: stats["alt"] += 1
    return orig_plan(self, *a, **k)
orig_tg = P.HierarchicalPlanner._toward_subgoal
P.HierarchicalPlanner._toward_subgoal = tg
P.SparseDiffusion.plan = plan
gen = torch.Generator().manual_seed(0)
ts = []
for prob in make_problems(grid, int(sys.argv[3]), seed=2044):
    t0 = time.perf_counter(); hd.plan(prob.start, prob.goal, generator=gen); ts.append(time.perf_counter() - t0)
print(stats, f"median {1e3*np.median(ts):.0f} ms")
