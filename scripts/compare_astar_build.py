"""Build the A* planners of one map with this checkout's ``ecahd_core/astar.py`` and with another
version of that file, side by side in one process: the build times, and whether the two give
the same clearances, masks, coarse nodes, edges and landmark distances (bit for bit).

    git show f428770:ecahd_core/astar.py > /tmp/astar_old.py
    python scripts/compare_astar_build.py office60.yaml /tmp/astar_old.py [--clearance 0.4]
"""
from __future__ import annotations

import argparse
import importlib.util
import sys
import time

import numpy as np

from ecahd_core import astar
from ecahd_core.maps import load_map


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("map")
    ap.add_argument("other", help="path of the other astar.py")
    ap.add_argument("--clearance", type=float, default=0.4)
    ap.add_argument("--block", type=float, default=astar.COARSE_BLOCK_SIZE, help="[m]")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    spec = importlib.util.spec_from_file_location("astar_other", args.other)
    other = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = other  # its dataclasses look their module up
    spec.loader.exec_module(other)
    grid = load_map(args.map)
    print(f"map {grid.name!r}: {grid.width} x {grid.height} cells at {grid.resolution} m; "
          f"clearance {args.clearance} m, blocks of {args.block} m")
    built = {}
    for name, mod in (("this", astar), ("other", other)):
        fine_s, coarse_s = [], []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            fine = mod.AStarPlanner(grid, args.clearance)
            t1 = time.perf_counter()
            coarse = mod.CoarseAStarPlanner.for_resolution(fine, args.block)
            t2 = time.perf_counter()
            fine_s.append(t1 - t0)
            coarse_s.append(t2 - t1)
        built[name] = (fine, coarse)
        print(f"{name:>6}: AStarPlanner {np.median(fine_s):6.2f} s, CoarseAStarPlanner (with "
              f"{astar.COARSE_LANDMARKS} landmarks) {np.median(coarse_s):6.2f} s "
              f"(medians of {args.repeats})")
    (fa, ca), (fb, cb) = built["this"], built["other"]
    same = (np.array_equal(fa.cell_clearance, fb.cell_clearance)
            and np.array_equal(fa.mask, fb.mask) and np.array_equal(ca.rep_cells, cb.rep_cells)
            and ca._indptr == cb._indptr and ca._dst == cb._dst and ca._cost == cb._cost
            and np.array_equal(ca._landmark_dist, cb._landmark_dist))
    print(f"the same planners bit for bit: {same}")


if __name__ == "__main__":
    main()
