"""python pair.py OLD_DIR NEW_DIR FAMILY: paired table of two arms of one-arm `bench planning
--json` files with the same names (MAP_ROBOT_sSEED.json, --per-problem-seeds: problem k drew
from the same seed in both), one family (office / warehouse / depot)."""
import glob, json, os, sys
import numpy as np
old, new, fam = sys.argv[1:4]
tot = dict(n=0, a=0, b=0, lost=0, won=0, fa=0, fb=0, subgoal_a=0, subgoal_b=0)
print("| map, robot, seed | alone, main 1571b84 | **alone, route_sight** | lost / won | subgoal % | A* fallback (plans) | median [ms] | mean [ms] | length / A* |")
print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
for f in sorted(glob.glob(os.path.join(new, f"{fam}*_s*.json"))):
    g = os.path.join(old, os.path.basename(f))
    if not os.path.exists(g):
        continue
    a, b = json.load(open(g))["cells"][0], json.load(open(f))["cells"][0]
    fa, fb = np.array(a["free_by_problem"]), np.array(b["free_by_problem"])
    n = len(fa)
    lost, won = int((fa & ~fb).sum()), int((~fa & fb).sum())
    xa, xb = round(a["net_fallback_rate"] * n / 100), round(b["net_fallback_rate"] * n / 100)
    for k, v in dict(n=n, a=int(fa.sum()), b=int(fb.sum()), lost=lost, won=won, fa=xa, fb=xb).items():
        tot[k] += v
    name = os.path.basename(f)[:-5].replace("_", ", ")
    print(f"| {name} | {a['collision_free']:.1f}% | **{b['collision_free']:.1f}%** | {lost} / {won} | "
          f"{a['subgoal_rate']:.0f} -> {b['subgoal_rate']:.0f} | {xa} -> {xb} | "
          f"{a['time_ms_median']:.0f} -> {b['time_ms_median']:.0f} | "
          f"{a['time_ms_mean']:.0f} -> {b['time_ms_mean']:.0f} | "
          f"{a['length_ratio']:.3f} -> {b['length_ratio']:.3f} |")
n = tot["n"]
if n:
    print(f"| **{fam}s, {n} plans** | {100 * tot['a'] / n:.1f}% ({tot['a']}) | "
          f"**{100 * tot['b'] / n:.1f}% ({tot['b']})** | {tot['lost']} / {tot['won']} | | "
          f"{tot['fa']} -> {tot['fb']} ({100 * tot['fa'] / n:.1f}% -> {100 * tot['fb'] / n:.1f}%) | | | |")
