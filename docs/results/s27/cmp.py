"""Compare the settle arm against session 26's main runs (rates, medians, length, settle %)."""
import json, glob, os, sys
pat = sys.argv[1] if len(sys.argv) > 1 else "/tmp/s27/dev/res/settle_*.json"
base_dir = sys.argv[2] if len(sys.argv) > 2 else "/tmp/s26/held/res"
base_prefix = sys.argv[3] if len(sys.argv) > 3 else "new_"
tot = [0, 0, 0, 0, 0]
for f in sorted(glob.glob(pat)):
    name = os.path.basename(f).split("_", 1)[1]
    b = os.path.join(base_dir, base_prefix + name)
    if not os.path.exists(b):
        print("no base for", name); continue
    x, y = json.load(open(b))["cells"][0], json.load(open(f))["cells"][0]
    n = x["problems"]
    print(f"{name:32s} free {x['collision_free']:5.1f} -> {y['collision_free']:5.1f}  "
          f"fallback {x['net_fallback_rate']:4.1f} -> {y['net_fallback_rate']:4.1f}  "
          f"net {y['net_collision_free']:5.1f}  median {x['time_ms_median']:6.0f} -> {y['time_ms_median']:6.0f}  "
          f"length {x['length_ratio']:.3f} -> {y['length_ratio']:.3f}  settle {y.get('settle_rate')}")
    tot[0] += n; tot[1] += round(x['collision_free'] * n / 100); tot[2] += round(y['collision_free'] * n / 100)
    tot[3] += round(x['net_fallback_rate'] * n / 100); tot[4] += round(y['net_fallback_rate'] * n / 100)
print(f"total {tot[0]} plans: free {tot[1]} -> {tot[2]}  fallback {tot[3]} -> {tot[4]}")
