import sys, numpy as np
sys.argv = sys.argv
exec(open('/tmp/s27/one.py').read().split("to_go = GoalField")[0])
from ecahd_core.collision import check_collision
for j, seg in enumerate(r.segments):
    if not check_collision(seg, fp, grid).collision_free:
        w = r.global_plans[j]
        print("it", j, "first_leg", repr(r.first_leg[j]), "leg_wall", round(float(hd.sparse.placer.leg_walls(w[:2])[0]), 3), "len", round(float(np.linalg.norm(w[1]-w[0])), 2), "dd", r.dd_segments[j], "polished", r.polished[j], "exact_kept", r.exact_kept[j])
