"""Table of the re-plan-spacing run: python agg.py [DIR] (default: spacing/ beside this file);
device files are TAG.json, this machine's here_TAG.json (device first where both ran)."""
import json, glob, os, sys
from collections import defaultdict
D = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(os.path.abspath(__file__)), 'spacing')
rows = {}
for pre, where in (('', 'device'), ('here_', 'here')):
    for f in glob.glob(f'{D}/{pre}*.json'):
        tag = os.path.basename(f)[len(pre):-5]
        if pre == '' and tag.startswith('here_'): continue
        if tag in rows: continue   # device first
        c = json.load(open(f))['cells'][0]
        n = c['problems']
        rows[tag] = dict(bad=round(n * (100 - c['collision_free']) / 100), fb=round(n * c['net_fallback_rate'] / 100), n=n,
                         med=c['time_ms_median'], where=where, net=c['net_collision_free'])
out = []
tot = defaultdict(lambda: [0, 0, 0])
for m in ('office1', 'office2', 'office3'):
    for r in ('circle', 'quadruped', 'humanoid'):
        cells = []
        for a in ('def', 'sp4'):
            b = f = n = 0; meds = []; wh = set()
            for s in (2042, 2043):
                x = rows.get(f'{a}_{m}_{r}_s{s}')
                if x is None: continue
                b += x['bad']; f += x['fb']; n += x['n']; meds.append(x['med']); wh.add(x['where'])
                assert x['net'] == 100.0, (a, m, r, s, x['net'])
            tot[(a, r)][0] += b; tot[(a, r)][1] += f; tot[(a, r)][2] += n
            cells.append((b, f, n, meds, wh))
        (b0, f0, n0, m0, w0), (b1, f1, n1, m1, w1) = cells
        out.append(f"| {m}, {r} | {n0-b0}/{n0} ({100*(n0-b0)/n0:.1f}%) | {n1-b1}/{n1} ({100*(n1-b1)/n1:.1f}%) | {f0} -> {f1} | {' / '.join(f'{v:.0f}' for v in m0)} -> {' / '.join(f'{v:.0f}' for v in m1)} | {'+'.join(sorted(w0))} |")
print('\n'.join(out))
for r in ('circle', 'quadruped', 'humanoid'):
    a, b = tot[('def', r)], tot[('sp4', r)]
    print(f"| **{r}, 192 plans** | {a[2]-a[0]}/{a[2]} ({100*(a[2]-a[0])/a[2]:.1f}%) | {b[2]-b[0]}/{b[2]} ({100*(b[2]-b[0])/b[2]:.1f}%) | {a[1]} -> {b[1]} | | |")
A = [sum(tot[('def', r)][i] for r in ('circle','quadruped','humanoid')) for i in range(3)]
B = [sum(tot[('sp4', r)][i] for r in ('circle','quadruped','humanoid')) for i in range(3)]
print(f"| **all, 576 plans** | {A[2]-A[0]}/{A[2]} ({100*(A[2]-A[0])/A[2]:.1f}%) | {B[2]-B[0]}/{B[2]} ({100*(B[2]-B[0])/B[2]:.1f}%) | {A[1]} -> {B[1]} | | |")
