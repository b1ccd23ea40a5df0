"""Run `ecahd bench planning ...` (argv) and, for every ECAHD plan the exact checker finds in
collision, print which iterations' local plans collide and what made them: settled part or not,
the leg's wall length by the leg test, DD, polishing, the exact rule."""
import sys, pickle
import numpy as np
from ecahd_core import planner as P
recs = []
orig = P.HierarchicalPlanner.plan
def plan(self, start, goal, **k):
    r = orig(self, start, goal, **k)
    recs.append((self, np.asarray(start), np.asarray(goal), r))
    return r
P.HierarchicalPlanner.plan = plan
from ecahd_ros.cli import main
main(sys.argv[1:])
from ecahd_core.collision import check_collision
out = []
for i, (hd, s, g, r) in enumerate(recs):
    fp = hd.sparse.placer.footprint
    grid = hd.sparse.placer.grid
    if check_collision(r.trajectory, fp, grid).collision_free:
        continue
    bad = [j for j, seg in enumerate(r.segments) if not check_collision(seg, fp, grid).collision_free]
    print(f"plan {i}: iterations {len(r.global_plans)}, settled {r.settled}, subgoals {r.subgoals}, "
          f"backtracked {r.backtracked}, colliding iterations {bad}")
    for j in bad:
        w = r.global_plans[j]
        leg = hd.sparse.placer.leg_walls(w[:2])[0]
        print(f"   it {j}: first_leg {r.first_leg[j]!r} leg_wall {leg:.2f} m, leg length "
              f"{np.linalg.norm(w[1]-w[0]):.2f} m, dd {r.dd_segments[j]}, polished {r.polished[j]}, "
              f"exact_kept {r.exact_kept[j]}, cost {r.local_costs[j]}")
    out.append((i, s, g, r))
pickle.dump([(i, s, g, r) for i, s, g, r in out], open(sys.argv[-1] + ".pkl", "wb")) if sys.argv[-1].startswith("/tmp") else None
