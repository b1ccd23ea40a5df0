"""Where does ECAHD alone collide on a map? A diagnostic for issue 10 (not a benchmark).

For seeded problems (``ecahd_core.problems.make_problems``), ECAHD plans with ``replan once``
(SD best of 10, then the local stage on every segment) and every segment between two SD
waypoints is judged by the exact checker: is a waypoint itself in a wall, does the straight
segment collide, does the local stage's plan (DD + polishing) still collide; by segment length.

    ECAHD_MODELS=DIR python scripts/diagnose_segments.py MAP.yaml [--problems 16] [--seed 7]
        [--max-spacing M] [--place REACH [--leg-rounds N]] [--candidates N]
        [--selection RULE] [--no-exact-rule] [--png FILE]
"""
from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from ecahd_core.collision import DEFAULT_TOLERANCE, check_collision, exact_check_for, pose_depths
from ecahd_core.cost import CollisionCost, CostConfig
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import load_map
from ecahd_core.model_zoo import load_model
from ecahd_core.placement import WaypointPlacer
from ecahd_core.planner import (SELECTION_RULES, DenseConfig, HierarchicalPlanner, SparseConfig,
                                SparseDiffusion)
from ecahd_core.problems import make_problems

BINS = ((0, 1), (1, 2), (2, 3), (3, 5), (5, 1000))  # [m] segment lengths


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("map", help="built-in map or Nav2 YAML (models via $ECAHD_MODELS)")
    ap.add_argument("--problems", type=int, default=16)
    ap.add_argument("--seed", type=int, default=7, help="seed of the problems")
    ap.add_argument("--robot", default="circle")
    ap.add_argument("--max-spacing", type=float, default=None, help="SparseConfig.max_spacing")
    ap.add_argument("--candidates", type=int, default=10, help="SD's best of N")
    ap.add_argument("--selection", choices=SELECTION_RULES, default="collision_aware",
                    help="SD's best-of-N rule (the commands' default; shortest_reaching: the "
                         "paper's)")
    ap.add_argument("--place", type=float, default=None, metavar="REACH",
                    help="SD's waypoints in a wall moved into free space within REACH m "
                         "(placement.WaypointPlacer, the SparseDiffusion's placer)")
    ap.add_argument("--leg-rounds", type=int, default=3,
                    help="with --place: rounds of leg repair (WaypointPlacer.repair; 0: off)")
    ap.add_argument("--sd-repair", type=int, default=0, metavar="H",
                    help="a segment still colliding after the local stage gets an SD plan of H "
                         "waypoints between its ends (best of N, placed), whose legs get the "
                         "local stage; twice at most (0: off)")
    ap.add_argument("--exact-rule", action=argparse.BooleanOptionalAction, default=True,
                    help="HierarchicalPlanner's exact rule (the commands' default)")
    ap.add_argument("--png", help="draw up to 8 segments still colliding after the local stage")
    args = ap.parse_args()
    torch.set_num_threads(1)
    grid, fp = load_map(args.map), make_footprint(args.robot)
    cost = CollisionCost.build(grid, fp, CostConfig.for_map(grid)).as_tuple()
    sd = SparseDiffusion(load_model("sd", grid, footprint=fp),
                         SparseConfig(num_candidates=args.candidates, selection=args.selection,
                                      max_spacing=args.max_spacing), cost=cost,
                         placer=None if args.place is None else WaypointPlacer(
                             grid, fp, reach=args.place, leg_rounds=args.leg_rounds))
    hd = HierarchicalPlanner(sd, load_model("dd", grid, footprint=fp), costmap=cost[0],
                             footprint_points=cost[1], cost_config=cost[2], dense=DenseConfig(),
                             replan="once",
                             exact_check=exact_check_for(grid, fp) if args.exact_rule else None)
    gen = torch.Generator().manual_seed(0)
    rows = []  # (length [m], an end in a wall, straight free, local plan free)
    bad_ends = []  # (a, b) [m] of every segment still colliding after the local stage
    free_plans = repaired_plans = 0
    stats = {"tried": 0, "fixed": 0}
    shown = []  # (problem, segment, SD waypoints, trajectory, segment) still colliding
    for n, prob in enumerate(make_problems(grid, args.problems, seed=args.seed)):
        t0 = time.perf_counter()
        plan = hd.plan(prob.start, prob.goal, generator=gen)
        ms = (time.perf_counter() - t0) * 1e3
        wp = np.asarray(plan.global_plans[0])  # (P^g, 2) [m]
        in_wall = pose_depths(np.c_[wp, np.zeros(len(wp))], fp, grid) > DEFAULT_TOLERANCE
        for k, seg in enumerate(plan.segments):
            rows.append((float(np.linalg.norm(wp[k + 1] - wp[k])), in_wall[k] or in_wall[k + 1],
                         check_collision(wp[k:k + 2], fp, grid).collision_free,
                         check_collision(seg, fp, grid).collision_free))
            if not rows[-1][3]:
                bad_ends.append((wp[k], wp[k + 1]))
            if not rows[-1][3] and len(shown) < 8:
                shown.append((n, k, wp, plan.trajectory, seg))
        free = check_collision(plan.trajectory, fp, grid).collision_free
        if not free and args.sd_repair:
            repaired = all(sd_repair(sd, hd, grid, fp, seg, args.sd_repair, gen, stats)
                           for seg in plan.segments)
            repaired_plans += repaired
        free_plans += free
        print(f"SD path {np.linalg.norm(np.diff(wp, axis=0), axis=1).sum():6.1f} m, "
              f"{int(in_wall.sum())} of {len(wp)} waypoints in a wall, plan "
              f"{'free' if free else 'colliding'}, {ms:.0f} ms")
    if args.sd_repair:
        print(f"SD repair (H={args.sd_repair}): {repaired_plans} more plans collision-free; "
              f"segments tried {stats['tried']}, cleared {stats['fixed']}")
    r = np.array(rows, dtype=float)
    print(f"\n{free_plans} of {args.problems} plans collision-free; {len(r)} segments, mean "
          f"length {r[:, 0].mean():.2f} m; a waypoint in a wall: {100 * r[:, 1].mean():.1f}%; "
          f"straight colliding {100 * (1 - r[:, 2].mean()):.1f}%, after the local stage "
          f"{100 * (1 - r[:, 3].mean()):.1f}%")
    print("| segment length [m] | segments | a waypoint in a wall | straight colliding | "
          "after DD + polishing colliding |\n|---|---:|---:|---:|---:|")
    for lo, hi in BINS:
        m = (r[:, 0] >= lo) & (r[:, 0] < hi)
        if m.any():
            print(f"| {lo}-{hi if hi < 1000 else ''} | {int(m.sum())} | {100 * r[m, 1].mean():.0f}% "
                  f"| {100 * (1 - r[m, 2].mean()):.0f}% | {100 * (1 - r[m, 3].mean()):.0f}% |")
    ok = r[:, 1] == 0
    print(f"after the local stage, colliding among segments with both ends free: "
          f"{100 * (1 - r[ok, 3].mean()):.1f}%")
    worse = int(((r[:, 2] == 1) & (r[:, 3] == 0)).sum())
    print(f"segments whose straight leg was free but the local stage's plan collides: {worse}")
    # what a local stage could clear at all: the footprint's A* way between the two ends
    from ecahd_core.astar import clearance_for_footprint, planner_for
    from ecahd_core.errors import PlanningError

    astar = planner_for(grid, clearance_for_footprint(fp))
    kinds = {"near (A* <= 1.3 x straight)": 0, "detour (A* > 1.3 x)": 0, "no A* way": 0}
    for a, b in bad_ends:
        try:
            ratio = float(np.linalg.norm(np.diff(astar.plan(a, b), axis=0), axis=1).sum()
                          / max(np.linalg.norm(b - a), 1e-6))
        except PlanningError:
            kinds["no A* way"] += 1
            continue
        kinds["near (A* <= 1.3 x straight)" if ratio <= 1.3 else "detour (A* > 1.3 x)"] += 1
    print(f"segments still colliding ({len(bad_ends)}), by the footprint's A* way between "
          "their ends: " + ", ".join(f"{k}: {v}" for k, v in kinds.items()))
    if args.png:
        draw(grid, fp, shown, args.png)


def sd_repair(sd, hd, grid, fp, seg, horizon: int, gen, stats, depth: int = 2) -> bool:
    """``seg`` (P^l, 2) [m] if free, else SD between its ends and the local stage on its legs,
    recursively: whether the result is collision-free."""
    if check_collision(seg, fp, grid).collision_free:
        return True
    if depth == 0:
        return False
    stats["tried"] += 1
    a, b = np.asarray(seg[0], dtype=np.float64), np.asarray(seg[-1], dtype=np.float64)
    wp = sd.plan(a, b, horizon=horizon, generator=gen).waypoints
    w = torch.as_tensor(wp, dtype=torch.float32)
    stages = hd.local_stages(w[:-1], w[1:], end_fixed=torch.ones(len(w) - 1, dtype=torch.bool),
                             joined=True, generator=gen)
    ok = all(sd_repair(sd, hd, grid, fp, s.numpy(), horizon, gen, stats, depth - 1)
             for s in stages.plans)
    stats["fixed"] += ok
    return ok


def draw(grid, fp, shown, png: str) -> None:
    """Up to 8 panels, 6 x 6 m round each colliding segment: the map, SD's waypoints (blue),
    the plan (orange), the segment (red), the footprint at its two waypoints (green)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not shown:
        print("no colliding segment to draw")
        return
    x0, y0, x1, y1 = grid.bounds
    cols = min(4, len(shown))
    rows = (len(shown) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 3.4 * rows), squeeze=False)
    for ax in axes.flat[len(shown):]:
        ax.axis("off")
    for ax, (n, k, wp, traj, seg) in zip(axes.flat, shown):
        ax.imshow(grid.occupied, origin="lower", extent=(x0, x1, y0, y1), cmap="gray_r",
                  interpolation="nearest")
        ax.plot(traj[:, 0], traj[:, 1], "-", color="tab:orange", lw=1)
        ax.plot(wp[:, 0], wp[:, 1], "o-", color="tab:blue", ms=3, lw=0.7)
        ax.plot(seg[:, 0], seg[:, 1], "-", color="red", lw=1.6)
        for p in wp[k:k + 2]:
            ax.add_patch(plt.Circle(p, fp.circumscribed_radius, fill=False, color="tab:green"))
        c = 0.5 * (wp[k] + wp[k + 1])
        ax.set_xlim(c[0] - 3, c[0] + 3)
        ax.set_ylim(c[1] - 3, c[1] + 3)
        ax.set_title(f"problem {n}, segment {k} ({np.linalg.norm(wp[k + 1] - wp[k]):.1f} m)",
                     fontsize=8)
        ax.tick_params(labelsize=6)
    fig.suptitle("still colliding after DD + polishing: SD's waypoints (blue), the plan "
                 "(orange), the segment (red)", fontsize=9)
    fig.tight_layout()
    fig.savefig(png, dpi=90)
    plt.close(fig)
    print(f"wrote {png}")


if __name__ == "__main__":
    main()
