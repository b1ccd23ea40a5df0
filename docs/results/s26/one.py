import sys, time, numpy as np, torch
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import load_map
from ecahd_core.problems import make_problems
from ecahd_core.collision import segment_collisions
import geo_lib as L
torch.set_num_threads(1)
mp, seed, n, robot = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
ks = [int(x) for x in sys.argv[5].split(',')]
grid, fp = load_map(mp), make_footprint(robot)
hd = L.build(grid, fp)
probs = make_problems(grid, n, seed=seed)
for k in ks:
    t0 = time.perf_counter()
    plan = hd.plan(probs[k].start, probs[k].goal, generator=torch.Generator().manual_seed(0))
    col = segment_collisions(plan.trajectory, fp, grid)
    print(k, 'colliding', bool(col.any()), 'iters', len(plan.global_plans), 'progress', plan.first_leg.count('progress'), f'{(time.perf_counter()-t0)*1e3:.0f} ms', {a: round(b) for a, b in plan.timings_ms.items()}, flush=True)
