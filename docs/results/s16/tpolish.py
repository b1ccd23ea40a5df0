import numpy as np, torch
from ecahd_core.collision import check_collision
from ecahd_core.cost import CostConfig
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import GridMap
from ecahd_core.polish import polish_paths as polish, PolishConfig
F32=torch.float32
n, res = 300, 0.03
occ = np.zeros((n, n), dtype=bool); occ[150, 150] = True
grid = GridMap(data=np.where(occ, 100, 0).astype(np.int8), resolution=res, name="hand")
c = (150.5)*res
for robot in ("circle","humanoid","quadruped"):
    fp = make_footprint(robot); pts = torch.as_tensor(fp.points, dtype=F32)
    for m in (0.1, 0.3, 0.5):
        cc = CostConfig(margin=m); cm = cc.make_costmap(grid, dtype=F32)
        legs=[]
        for dy in np.linspace(-0.4, 0.4, 41):
            for x0 in np.linspace(c-1.5, c-1.2, 4):
                leg = np.array([[x0, c+dy], [x0+0.8, c+dy], [x0+1.6, c+dy], [x0+2.4, c+dy]])
                if not check_collision(leg, fp, grid).collision_free: legs.append(leg)
        legs=np.array(legs)
        fixed=np.array([True,False,False,True])
        out,_ = polish(torch.as_tensor(legs,dtype=F32), fixed, cm, pts, cc, PolishConfig(steps=30))
        freed = np.mean([check_collision(p.numpy().astype(float), fp, grid).collision_free for p in out])
        print(robot, m, len(legs), "freed by polishing %.2f" % freed)
