"""python one.py MAP SEED ROBOT K OUT.png: re-plan problem K of a --per-problem-seeds bench alone
(the bench's own planner, seed problem_seed(0, K)) and draw it: map, trajectory (red where the
exact checker finds collisions), the goal's shortest route, subgoal iterations."""
import sys
import numpy as np, torch
import matplotlib; matplotlib.use("Agg"); import matplotlib.pyplot as plt
from ecahd_core import planner as P
from ecahd_core.bench import planning as B
mp, seed, robot, k, out = sys.argv[1], int(sys.argv[2]), sys.argv[3], int(sys.argv[4]), sys.argv[5]
got = {}
orig = P.HierarchicalPlanner.plan
def plan(self, s, g, **kw):
    r = orig(self, s, g, **kw); got.setdefault("r", (self, s, g, r)); raise KeyboardInterrupt
P.HierarchicalPlanner.plan = plan
from ecahd_core.problems import make_problems
from ecahd_core.maps import load_map
grid = load_map(mp)
probs = make_problems(grid, k + 1, seed=seed)
orig_mp = B.make_problems if hasattr(B, "make_problems") else None
import ecahd_core.problems as PR
PR.make_problems = lambda g, n, seed: [probs[k]]
orig_ps = B.problem_seed
B.problem_seed = lambda s, i: orig_ps(s, k)
try:
    B.run_planning_benchmark(B.PlanningBenchSettings(map=mp, problems=1, seed=seed, robots=(robot,), methods=("hd",), ablation=False, precision="auto", guidance="on", per_problem_seeds=True), progress=False)
except KeyboardInterrupt:
    pass
hd, s, g, r = got["r"]
from ecahd_core.collision import segment_collisions
from ecahd_core.progress import GoalField
fp = hd.sparse.placer.footprint
traj = r.trajectory
col = segment_collisions(traj, fp, grid)
print("iterations", len(r.global_plans), "settled", r.settled, "subgoals", r.subgoals, "backtracked", r.backtracked, "colliding segs", int(col.sum()))
print("first_leg", r.first_leg)
to_go = GoalField(grid, fp).to(g)
route = to_go.route(s, 200.0)
lo = np.minimum(traj.min(0), route.min(0)) - 3; hi = np.maximum(traj.max(0), route.max(0)) + 3
fig, ax = plt.subplots(figsize=(9, 9))
x0, y0 = grid.origin[:2]; res = grid.resolution
ax.imshow(grid.occupied, origin="lower", cmap="Greys", extent=[x0, x0 + grid.width * res, y0, y0 + grid.height * res])
ax.plot(route[:, 0], route[:, 1], "g-", lw=1, label="shortest route (coarse graph)")
ax.plot(traj[:, 0], traj[:, 1], "-", color="purple", lw=1, label="ECAHD trajectory")
for i in np.flatnonzero(col):
    ax.plot(traj[i:i + 2, 0], traj[i:i + 2, 1], "r-", lw=3)
wps = np.array([w[0] for w in r.global_plans])
ax.plot(wps[:, 0], wps[:, 1], "o", ms=3, color="orange", label="iteration starts")
sub = [i for i, f in enumerate(r.first_leg) if f == "subgoal"]
if sub:
    ax.plot(wps[sub, 0], wps[sub, 1], "s", ms=5, mfc="none", color="blue", label="subgoal re-plans")
ax.plot(*s, "g^", ms=10); ax.plot(*g, "r*", ms=14)
ax.set_xlim(lo[0], hi[0]); ax.set_ylim(lo[1], hi[1]); ax.legend(loc="best", fontsize=8)
ax.set_title(f"{grid.name} {robot} seed {seed} problem {k}: {len(r.global_plans)} iterations, {r.subgoals} subgoal")
fig.savefig(out, dpi=90, bbox_inches="tight")
