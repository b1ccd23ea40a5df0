"""Paired table of the held-out run: settle off vs on per map and robot, from the benches' JSON
(--per-problem-seeds: problem k drew from the same seed in both arms)."""
import json, glob, os, sys
import numpy as np
d = sys.argv[1]
fam = sys.argv[2] if len(sys.argv) > 2 else "office"
rows, tot = [], dict(n=0, off=0, on=0, lost=0, won=0, fb_off=0, fb_on=0)
print("| map, robot | alone, off | **alone, settle** | lost / won | settle % | A* fallback (plans) | median [ms] | mean [ms] | length / A* |")
print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
for f in sorted(glob.glob(f"{d}/on_{fam}*_s*.json")):
    name = os.path.basename(f)[3:-5]
    g = f"{d}/off_{name}.json"
    if not os.path.exists(g):
        continue
    a, b = json.load(open(g))["cells"][0], json.load(open(f))["cells"][0]
    fa, fb = np.array(a["free_by_problem"]), np.array(b["free_by_problem"])
    n = len(fa)
    lost, won = int((fa & ~fb).sum()), int((~fa & fb).sum())
    xa, xb = round(a["net_fallback_rate"] * n / 100), round(b["net_fallback_rate"] * n / 100)
    tot["n"] += n; tot["off"] += int(fa.sum()); tot["on"] += int(fb.sum())
    tot["lost"] += lost; tot["won"] += won; tot["fb_off"] += xa; tot["fb_on"] += xb
    print(f"| {name.replace('_', ', ')} | {a['collision_free']:.1f}% | **{b['collision_free']:.1f}%** | {lost} / {won} | "
          f"{b['settle_rate']:.1f} | {xa} -> {xb} | {a['time_ms_median']:.0f} -> {b['time_ms_median']:.0f} | "
          f"{a['time_ms_mean']:.0f} -> {b['time_ms_mean']:.0f} | {a['length_ratio']:.3f} -> {b['length_ratio']:.3f} |")
n = tot["n"]
if n:
    print(f"| **{fam}s, {n} plans** | {100*tot['off']/n:.1f}% ({tot['off']}) | **{100*tot['on']/n:.1f}% ({tot['on']})** | "
          f"{tot['lost']} / {tot['won']} | | {tot['fb_off']} -> {tot['fb_on']} ({100*tot['fb_off']/n:.1f}% -> {100*tot['fb_on']/n:.1f}%) | | | |")
