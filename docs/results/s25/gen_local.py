"""Office dataset where a share of the pairs' goals lie 1-8 m (straight) from the start:
python gen_local.py MAP OUT.npz [SHARE]"""
import sys, math, numpy as np
from ecahd_core import dataset as D
from ecahd_core.maps import load_map
SHARE = float(sys.argv[3]) if len(sys.argv) > 3 else 0.5
LO, HI = 1.0, 8.0
orig = D._coarse_attempt
def local_attempt(task, index):
    coarse, cells, seed, min_distance, views = task
    rng = np.random.default_rng([seed, index, 7])
    if rng.random() >= SHARE:
        return orig(task, index)
    fine = coarse.fine
    start = D._sample_in_cells(rng, fine, cells)
    g = fine.grid
    for _ in range(200):
        r, a = rng.uniform(LO, HI), rng.uniform(0, 2 * math.pi)
        goal = start + r * np.array([math.cos(a), math.sin(a)])
        col = int(math.floor((goal[0] - g.origin[0]) / g.resolution))
        row = int(math.floor((goal[1] - g.origin[1]) / g.resolution))
        if 0 <= row < g.height and 0 <= col < g.width and fine.mask[row, col] \
                and fine.point_clearance(goal) >= fine.clearance - D.SDF_TOLERANCE:
            return D._plan_attempt(coarse, start, goal, min_distance, views)
    return ("unreachable",)
D._coarse_attempt = local_attempt
grid = load_map(sys.argv[1])
ds = D.generate_dataset(grid, pairs=5000, seed=0, footprint_spec="circle", waypoints="corners")
ds.save(sys.argv[2])
L = np.asarray(ds.lengths); e = np.linalg.norm(np.asarray(ds.goals) - np.asarray(ds.starts), axis=1)
print("median length %.1f m, euclid<8 m %.0f%%, expert_spacing %.2f m" % (np.median(L), 100 * np.mean(e < 8), D.expert_spacing(ds)), ds.params)
