import cProfile, pstats, sys, time, torch, numpy as np
torch.set_num_threads(1)
from ecahd_core.maps import load_map
from ecahd_core.footprint import make_footprint
from ecahd_core.problems import make_problems
from ecahd_core.commands import plan as _p
grid, fp = load_map(sys.argv[1]), make_footprint("humanoid")
import count6_lib as L
hd = L.build(grid, fp)
probs = make_problems(grid, 16, seed=2040)
gen = torch.Generator().manual_seed(0)
hd.plan(probs[0].start, probs[0].goal, generator=gen)
pr = cProfile.Profile(); t0=time.perf_counter(); pr.enable()
for p in probs: hd.plan(p.start, p.goal, generator=gen)
pr.disable(); print("total", time.perf_counter()-t0)
pstats.Stats(pr).sort_stats("cumtime").print_stats(25)
