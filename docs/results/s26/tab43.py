"""Seed 2043: the subgoal rule (subgoal/new_*_s2043.json, s2043.sh) against the default arm of
the spacing run (spacing/def_* from the GPU machine's CPU, else spacing/here_def_*): rates only
(the two ran on different machines and loads)."""
import json, os
D = os.path.dirname(os.path.abspath(__file__))
def load(*names):
    for n in names:
        p = os.path.join(D, n)
        if os.path.exists(p):
            return json.load(open(p))['cells'][0]
tot = [0, 0, 0, 0, 0]
print('| map, robot, seed 2043 | alone, main (spacing run) | **alone, subgoal rule** | subgoal % | A* fallback (plans) |')
print('|---|---:|---:|---:|---:|')
for m in ('office1', 'office2', 'office3'):
    for r in ('circle', 'quadruped', 'humanoid'):
        b = load(f'spacing/def_{m}_{r}_s2043.json', f'spacing/here_def_{m}_{r}_s2043.json')
        n = load(f'subgoal/new_{m}_{r}_s2043.json')
        if b is None or n is None:
            continue
        N = b['problems']
        bad = lambda c: round(N * (100 - c['collision_free']) / 100)
        fb = lambda c: round(N * c['net_fallback_rate'] / 100)
        assert b['net_collision_free'] == 100.0 and n['net_collision_free'] == 100.0
        for i, v in enumerate((N, bad(b), bad(n), fb(b), fb(n))):
            tot[i] += v
        print(f"| {m}, {r} | {b['collision_free']:.1f}% | {n['collision_free']:.1f}% | {n['subgoal_rate']:.1f} | {fb(b)} -> {fb(n)} |")
N, b, n, fb, fn = tot
print(f"| **offices, {N} plans** | {100*(N-b)/N:.1f}% ({N-b}) | **{100*(N-n)/N:.1f}% ({N-n})** | | {fb} -> {fn} ({100*fb/N:.1f}% -> {100*fn/N:.1f}%) |")
