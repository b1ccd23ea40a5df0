"""python tab.py DIR [DIR ...]: Table I-style rows of one-arm `bench planning --json` files
(name MAP_ROBOT_sSEED.json), a total per family (office / warehouse / depot)."""
import glob, json, os, sys
rows, fam = [], {}
for d in sys.argv[1:]:
    for f in sorted(glob.glob(os.path.join(d, "*.json"))):
        m, robot, seed = os.path.basename(f)[:-5].split("_")
        c = json.load(open(f))["cells"][0]
        n = c["problems"]
        free, fb = round(c["collision_free"] * n / 100), round(c["net_fallback_rate"] * n / 100)
        net = round(c["net_collision_free"] * n / 100)
        rows.append(f"| {m}, {robot}, {seed} | {c['collision_free']:.1f}% | {c['net_fallback_rate']:.1f}% "
                    f"| **{c['net_collision_free']:.1f}%** | {c['settle_rate']:.0f} | {c['subgoal_rate']:.0f} "
                    f"| {c['time_ms_median']:.0f} | {c['time_ms_p95']:.0f} | {c['length_ratio']:.3f} |")
        t = fam.setdefault(m.rstrip("0123456789"), [0, 0, 0, 0])
        for i, v in enumerate((n, free, fb, net)):
            t[i] += v
print("| map, robot, seed | ECAHD alone collision-free | A* fallback | with the net | settle % "
      "| subgoal % | median ms | p95 ms | length / A* |")
print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
print("\n".join(rows))
for k, (n, free, fb, net) in fam.items():
    print(f"| **{k}s, {n} plans** | **{100 * free / n:.1f}%** ({free}) | {100 * fb / n:.1f}% ({fb}) "
          f"| **{100 * net / n:.1f}%** ({net}) | | | | | |")
