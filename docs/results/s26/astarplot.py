import sys, pickle, numpy as np
import matplotlib; matplotlib.use("Agg"); import matplotlib.pyplot as plt
from ecahd_core.maps import load_map
from ecahd_core.footprint import make_footprint
from ecahd_core.astar import astar_path, clearance_for_footprint
mp, pkl, robot, k, z = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4]), float(sys.argv[5])
grid = load_map(mp); fp = make_footprint(robot)
v = pickle.load(open(pkl, 'rb'))[k]; plan = v['plan']; traj = plan.trajectory
occ = (grid.data >= 65) | (grid.data < 0)
ap = astar_path(grid, v['start'], v['goal'], clearance_for_footprint(fp))
fig, ax = plt.subplots(figsize=(9, 9))
ex = [grid.origin[0], grid.origin[0] + occ.shape[1] * grid.resolution, grid.origin[1], grid.origin[1] + occ.shape[0] * grid.resolution]
ax.imshow(occ, origin='lower', extent=ex, cmap='Greys', interpolation='nearest')
ax.plot(ap[:, 0], ap[:, 1], 'g-', lw=2, label='A*')
ax.plot(traj[:, 0], traj[:, 1], 'b-', lw=1, label='ECAHD')
n = len(plan.global_plans)
for q in range(n - 6, n):
    g = plan.global_plans[q]; ax.plot(g[:, 0], g[:, 1], 'o--', ms=3, lw=0.7, color=plt.cm.autumn((q - n + 6) / 6))
ax.plot(*v['goal'], 'r*', ms=14); ax.legend()
c = np.asarray([float(a) for a in sys.argv[6].split(",")]) if len(sys.argv) > 6 else np.asarray(v["goal"]); ax.set_xlim(c[0] - z, c[0] + z); ax.set_ylim(c[1] - z, c[1] + z)
fig.savefig(f"astar_{pkl[:-4]}_{k}.png", dpi=70)
