import json, glob, sys, re
pat = sys.argv[1] if len(sys.argv) > 1 else '*'
rows = {}
for f in sorted(glob.glob(f'/tmp/s25/res/{pat}.json')):
    tag = f.split('/')[-1][:-5]
    d = json.load(open(f))
    for c in d['cells']:
        print(f"{tag:28s} {c['robot']:9s} free {c['collision_free']:5.1f} fb {c['net_fallback_rate']:4.1f} rs {c['net_resample_rate']:4.1f} bt {c['backtrack_rate']:4.1f} med {c['time_ms_median']:6.0f} mean {c['time_ms_mean']:6.0f} p95 {c['time_ms_p95']:6.0f}")
