"""Table of the subgoal rule's held-out run: python held_tab.py [DIR] (default: subgoal/ beside
this file; files base_MAP_ROBOT_sSEED.json and new_..., from held.sh)."""
import glob, json, os, sys
D = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(os.path.abspath(__file__)), 'subgoal')
cells = {}
for f in glob.glob(f'{D}/*.json'):
    arm, m, r, s = os.path.basename(f)[:-5].split('_')
    cells[(arm, m, r, s)] = json.load(open(f))['cells'][0]
keys = sorted({k[1:] for k in cells}, key=lambda k: (k[0].startswith('w'), k))
tot = {}
print('| map, robot, seed | alone, main | **alone, subgoal rule** | subgoal % | A* fallback (plans) | median [ms] | mean [ms] | p95 [ms] |')
print('|---|---:|---:|---:|---:|---:|---:|---:|')
for m, r, s in keys:
    b, n = cells.get(('base', m, r, s)), cells.get(('new', m, r, s))
    if b is None or n is None:
        continue
    N = b['problems']
    fb = lambda c: round(N * c['net_fallback_rate'] / 100)
    bad = lambda c: round(N * (100 - c['collision_free']) / 100)
    fam = 'offices' if m.startswith('office') else 'warehouses'
    t = tot.setdefault(fam, [0, 0, 0, 0, 0])
    t[0] += N; t[1] += bad(b); t[2] += bad(n); t[3] += fb(b); t[4] += fb(n)
    assert b['net_collision_free'] == 100.0 and n['net_collision_free'] == 100.0
    print(f"| {m}, {r}, s{s[1:]} | {b['collision_free']:.1f}% | {n['collision_free']:.1f}% | {n['subgoal_rate']:.1f} | {fb(b)} -> {fb(n)} | "
          f"{b['time_ms_median']:.0f} -> {n['time_ms_median']:.0f} | {b['time_ms_mean']:.0f} -> {n['time_ms_mean']:.0f} | {b['time_ms_p95']:.0f} -> {n['time_ms_p95']:.0f} |")
for fam, (N, b, n, fb, fn) in tot.items():
    print(f"| **{fam}, {N} plans** | {100*(N-b)/N:.1f}% ({N-b}) | **{100*(N-n)/N:.1f}% ({N-n})** | | {fb} -> {fn} ({100*fb/N:.1f}% -> {100*fn/N:.1f}%) | | | |")
