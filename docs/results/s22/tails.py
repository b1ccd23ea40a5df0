import json, sys
for lab, files in (a.split('=') for a in sys.argv[1:]):
    cells = [c for f in files.split(',') for c in json.load(open(f))['cells']]
    m = [c['time_ms_mean'] for c in cells]; p = [c['time_ms_p95'] for c in cells]
    bt = [c.get('backtrack_rate') for c in cells]
    print(f"{lab}: mean {min(m):.0f}-{max(m):.0f} ms, p95 {min(p):.0f}-{max(p):.0f} ms, backtrack % {bt}")
