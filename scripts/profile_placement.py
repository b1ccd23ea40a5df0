"""Where global_planner's time goes on one SD plan of a big map: SD best-of-N, waypoint
placement and leg repair (``ecahd_core.placement``), timed per plan on seeded problems, one
torch thread, as the node runs them (placement reach by the map, the goal's own reach 0.2 m).

    ECAHD_MODELS=DIR python scripts/profile_placement.py office60.yaml [--problems 12]
        [--robot circle] [--seed 5]
"""
from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from ecahd_core.astar import clearance_for_footprint, planner_for, sample_free_points
from ecahd_core.cost import CollisionCost
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import load_map
from ecahd_core.model_zoo import load_model
from ecahd_core.navigation import SNAP_DISTANCE
from ecahd_core.placement import WaypointPlacer, auto_reach
from ecahd_core.planner import SparseConfig, SparseDiffusion


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("map")
    ap.add_argument("--problems", type=int, default=12)
    ap.add_argument("--robot", default="circle")
    ap.add_argument("--seed", type=int, default=5)
    args = ap.parse_args()
    torch.set_num_threads(1)
    grid, fp = load_map(args.map), make_footprint(args.robot)
    sd = SparseDiffusion(load_model("sd", grid, footprint=fp, horizon=10), SparseConfig(),
                         cost=CollisionCost.build(grid, fp).as_tuple())
    astar = planner_for(grid, clearance_for_footprint(fp))
    placer = WaypointPlacer(grid, fp, reach=auto_reach(grid))
    grid.free_distance  # noqa: B018  built once per map, as in the node
    rng, gen = np.random.default_rng(args.seed), torch.Generator().manual_seed(0)
    times = {"sd": [], "place": [], "repair": []}
    print(f"{'distance m':>10} {'SD ms':>7} {'place ms':>9} {'moved':>6} {'repair ms':>10} "
          f"{'added':>6}")
    for _ in range(args.problems):
        s, t = sample_free_points(rng, astar.mask, grid, 2)
        t0 = time.perf_counter()
        wp = sd.plan(s, t, horizon=10, generator=gen).waypoints.copy()
        t1 = time.perf_counter()
        wp[0], wp[-1] = s, t
        xy, moved = placer.place(wp, last_reach=SNAP_DISTANCE)
        t2 = time.perf_counter()
        xy, added = placer.repair(xy)
        t3 = time.perf_counter()
        for k, dt in zip(times, (t1 - t0, t2 - t1, t3 - t2)):
            times[k].append(1e3 * dt)
        print(f"{np.linalg.norm(t - s):>10.1f} {1e3 * (t1 - t0):>7.1f} {1e3 * (t2 - t1):>9.1f} "
              f"{moved:>6} {1e3 * (t3 - t2):>10.1f} {added:>6}")
    print("medians [ms]: " + ", ".join(f"{k} {np.median(v):.1f} (max {max(v):.1f})"
                                       for k, v in times.items()))


if __name__ == "__main__":
    main()
