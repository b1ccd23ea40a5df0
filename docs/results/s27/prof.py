"""Profile a planning bench: per-stage times of every ECAHD plan (HierarchicalPlanner.plan's
timings_ms), summed over the problems; argv after the script go to `ecahd` unchanged."""
import sys, time, collections, json
import numpy as np
from ecahd_core import planner as P
recs = []
orig = P.HierarchicalPlanner.plan
def plan(self, *a, **k):
    r = orig(self, *a, **k)
    recs.append((dict(r.timings_ms), len(r.global_plans), r.subgoals, r.backtracked))
    return r
P.HierarchicalPlanner.plan = plan
from ecahd_ros.cli import main
rc = main(sys.argv[1:])
tot = collections.Counter()
for t, *_ in recs:
    tot.update(t)
n = len(recs)
print(f"{n} plans; mean iterations {np.mean([r[1] for r in recs]):.1f}; median total "
      f"{np.median([r[0]['total'] for r in recs]):.0f} ms")
for k, v in sorted(tot.items(), key=lambda kv: -kv[1]):
    print(f"  {k:12s} mean {v / n:7.1f} ms")
