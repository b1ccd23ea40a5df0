"""Do the SD candidates of a circling re-plan loop contain one that makes geodesic progress?"""
import sys, time, numpy as np, torch
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import load_map
from ecahd_core.problems import make_problems
from ecahd_core.astar import planner_for, clearance_for_footprint
from ecahd_core.collision import segment_collisions
from ecahd_core import planner as P
import count6_lib as L
torch.set_num_threads(1)
mp, seed, n, robot, k = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], int(sys.argv[5])
grid, fp = load_map(mp), make_footprint(robot)
hd = L.build(grid, fp)
prob = make_problems(grid, n, seed=seed)[k]
t0 = time.perf_counter()
ap = planner_for(grid, clearance_for_footprint(fp), landmarks=0)
print('build', time.perf_counter() - t0)
r, c = grid.world_to_cell(np.asarray(prob.goal))
t0 = time.perf_counter(); dist = ap._dijkstra(int(ap.labels[int(r), int(c)])) * grid.resolution; print('dijkstra', time.perf_counter() - t0, ap.num_nodes)
def g(xy):
    xy = np.atleast_2d(xy); rr, cc = grid.world_to_cell(xy); rr = np.clip(rr.astype(int), 0, grid.data.shape[0]-1); cc = np.clip(cc.astype(int), 0, grid.data.shape[1]-1)
    nd = ap.labels[rr, cc]; out = np.full(len(xy), np.inf); ok = nd >= 0
    out[ok] = dist[nd[ok]] + np.linalg.norm(xy[ok] - ap.rep_xy[nd[ok]], axis=1); return out
rec = []
orig = P.SparseDiffusion.plan
def wrap(self, start, goal, **kw):
    sp = orig(self, start, goal, **kw); rec.append((np.asarray(start), sp)); return sp
P.SparseDiffusion.plan = wrap
plan = hd.plan(prob.start, prob.goal, generator=torch.Generator().manual_seed(0))
col = segment_collisions(plan.trajectory, fp, grid)
print('colliding', col.any(), 'iters', len(plan.global_plans), 'sd calls', len(rec))
for i, (s, sp) in enumerate(rec):
    gs = g(s)[0]; cw = sp.candidates; first = g(cw[:, 1]); chosen = g(sp.waypoints[1])[0]
    print(f"{i:3d} S=({s[0]:.1f},{s[1]:.1f}) g(S)={gs:6.1f} eucl={np.linalg.norm(s-prob.goal):5.1f} chosen g={chosen:6.1f} cands g min={np.min(first):6.1f} n_progress={(first < gs - 0.5).sum()}/{len(first)} fl={sp.first_leg}")
