"""Leg repair on SD-like plans without SD: expert corner waypoints, interior ones perturbed by
N(0, sigma^2); how often the repaired plan still has a leg crossing a wall.
usage: python proxy.py MAP PAIRS SIGMA [all|first] [key=value placer overrides]"""
import sys, time, numpy as np, torch
torch.set_num_threads(1)
from ecahd_core.maps import load_map
from ecahd_core.dataset import generate_dataset
from ecahd_core.footprint import make_footprint
import ecahd_core.placement as P
mp, pairs, sigma, mode = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
over = dict(kv.split("=") for kv in sys.argv[5:])
for k, v in over.items():
    if hasattr(P, k): setattr(P, k, type(getattr(P, k))(v))
grid = load_map(mp); fp = make_footprint("circle")
ds = generate_dataset(grid, pairs=pairs, seed=99, workers=1, progress=False)
placer = P.placer_for(grid, fp, None)
for k, v in over.items():
    if hasattr(placer, k): setattr(placer, k, type(getattr(placer, k))(int(v)))
rng = np.random.default_rng(0)
bad_before = bad_after = 0; t = 0.0; added = 0; n = 0
for i in range(ds.num_pairs):
    w = ds.sparse[i].astype(np.float64).copy()
    w[1:-1] += rng.normal(0, sigma, w[1:-1].shape)
    w = np.clip(w, np.array(grid.bounds[:2]) + 0.05, np.array(grid.bounds[2:]) - 0.05)
    legs = 1 if mode == "first" else None
    wb = placer.leg_walls(w)
    t0 = time.perf_counter(); xy, k = placer(w, legs=legs); t += time.perf_counter() - t0
    # the legs that replace the first (mode first) / all legs
    walls = placer.leg_walls(xy)
    if mode == "first":
        # the legs the first became (with legs=1 the later waypoints stay as they were)
        nfirst = len(xy) - (len(w) - 1)
        walls = walls[:nfirst]
        bad_before += wb[0] > 0
    else:
        bad_before += (wb > 0).any()
    bad_after += (walls > 0).any(); added += k; n += 1
print(f"{mp.split('/')[-1]} sigma {sigma} {mode} {' '.join(sys.argv[5:])}: {n} plans, crossing before {bad_before}, after repair {bad_after} ({100*bad_after/n:.1f}%), added {added}, {1000*t/n:.0f} ms/plan")
