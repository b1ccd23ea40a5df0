import numpy as np, torch
from ecahd_core.collision import check_collision
from ecahd_core.cost import CostConfig, trajectory_cost
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import GridMap
F64=torch.float64
n, res = 300, 0.03
occ = np.zeros((n, n), dtype=bool); occ[150, 150] = True
grid = GridMap(data=np.where(occ, 100, 0).astype(np.int8), resolution=res, name="hand")
c = (150.5)*res
for robot in ("circle","humanoid","quadruped"):
    fp = make_footprint(robot); pts = torch.as_tensor(fp.points, dtype=F64)
    for m in (0.1, 0.5):
        cm = CostConfig(margin=m).make_costmap(grid, dtype=F64)
        vals=[]
        for dy in np.linspace(-0.4, 0.4, 41):
            for x0 in np.linspace(c-1.5, c-1.2, 7):
                leg = np.array([[x0, c+dy], [x0+0.8, c+dy], [x0+1.6, c+dy], [x0+2.4, c+dy]])
                if check_collision(leg, fp, grid).collision_free: continue
                traj = torch.as_tensor(leg[None], dtype=F64)
                vals.append(float(trajectory_cost(traj, traj[:, -1], pts, cm).collision_cost[0]))
        vals=np.array(vals)
        print(robot, m, len(vals), "min %.4f p10 %.4f median %.4f, share < c_th 0.1: %.2f" % (vals.min(), np.percentile(vals,10), np.median(vals), (vals<0.1).mean()))
