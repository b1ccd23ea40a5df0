import sys, pickle, numpy as np
import matplotlib; matplotlib.use("Agg"); import matplotlib.pyplot as plt
from ecahd_core.maps import load_map
from ecahd_core.footprint import make_footprint
from ecahd_core.collision import segment_collisions
mp, pkl, robot = sys.argv[1], sys.argv[2], sys.argv[3]
grid = load_map(mp); fp = make_footprint(robot)
d = pickle.load(open(pkl, 'rb'))
occ = (grid.data >= 65) | (grid.data < 0)
for k, v in d.items():
    plan = v['plan']; traj = plan.trajectory
    col = segment_collisions(traj, fp, grid); idx = np.nonzero(col)[0]
    fig, axes = plt.subplots(1, 2, figsize=(14, 7))
    for ax, zoom in zip(axes, [None, 4.0]):
        ex = [grid.origin[0], grid.origin[0] + occ.shape[1] * grid.resolution, grid.origin[1], grid.origin[1] + occ.shape[0] * grid.resolution]
        ax.imshow(occ, origin='lower', extent=ex, cmap='Greys', interpolation='nearest')
        ax.plot(traj[:, 0], traj[:, 1], 'b-', lw=1)
        for i in idx: ax.plot(traj[i:i+2, 0], traj[i:i+2, 1], 'r-', lw=3)
        n = len(plan.global_plans)
        for q, g in enumerate(plan.global_plans):
            ax.plot(g[0, 0], g[0, 1], 'o', ms=3, color=plt.cm.viridis(q / n))
        last = plan.global_plans[-1]
        # the forced plan: first iteration whose first_leg is '' after the others, show whole plans of the last 3 SD iterations
        for q in range(max(0, n - 12), n):
            g = plan.global_plans[q]
            ax.plot(g[:, 0], g[:, 1], '--', lw=0.7, color=plt.cm.autumn((q - n + 12) / 12))
        ax.plot(*v['start'], 'g^', ms=10); ax.plot(*v['goal'], 'r*', ms=14)
        if zoom:
            c = traj[idx[-1]]; ax.set_xlim(c[0] - zoom, c[0] + zoom); ax.set_ylim(c[1] - zoom, c[1] + zoom)
    axes[0].set_title(f"problem {k}: {len(plan.global_plans)} iterations, first_leg tail {plan.first_leg[-8:]}")
    fig.tight_layout(); fig.savefig(f"{pkl[:-4]}_{k}.png", dpi=70); plt.close(fig)
    print(k, 'segs', idx, 'at', traj[idx[-1]], 'goal', v['goal'], 'n iter', len(plan.global_plans))
