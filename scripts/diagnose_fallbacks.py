"""Which plans does ECAHD leave to the safety net, and where do they collide? A diagnostic for
issue 10 (not a benchmark).

ECAHD plans each seeded problem as ``ecahd bench planning`` does (Algorithm 1 with SD at every
waypoint, placement, the exact rule; the same generators), the safety net judges it, and every
plan still colliding is printed with the Algorithm 1 iterations whose local segment collides:
the horizon of that iteration's SD plan, the segment's length and the straight distance left to
the goal. ``--png`` draws the plans the net left to A* (or every colliding plan with ``--all``).

    ECAHD_MODELS=DIR python scripts/diagnose_fallbacks.py MAP.yaml [--robot circle]
        [--seed 2026] [--problems 32] [--replan-spacing M] [--all] [--png FILE]
"""
from __future__ import annotations

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from ecahd_core.astar import clearance_for_footprint, planner_for  # noqa: E402
from ecahd_core.collision import exact_check_for, segment_collisions  # noqa: E402
from ecahd_core.cost import CollisionCost, CostConfig  # noqa: E402
from ecahd_core.footprint import make_footprint  # noqa: E402
from ecahd_core.maps import load_map  # noqa: E402
from ecahd_core.model_zoo import load_model  # noqa: E402
from ecahd_core.navigation import replan_spacing_for  # noqa: E402
from ecahd_core.placement import placer_for  # noqa: E402
from ecahd_core.planner import (DenseConfig, HierarchicalPlanner, SparseConfig,  # noqa: E402
                                SparseDiffusion)
from ecahd_core.problems import make_problems  # noqa: E402
from ecahd_core.safety import SafetyNet  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("map", help="built-in map or Nav2 YAML (models via $ECAHD_MODELS)")
    ap.add_argument("--robot", default="circle")
    ap.add_argument("--seed", type=int, default=2026, help="seed of the problems")
    ap.add_argument("--problems", type=int, default=32)
    ap.add_argument("--replan-spacing", type=float, default=None, metavar="M",
                    help="[m] as on `ecahd bench planning` (default: by the map; 0: off)")
    ap.add_argument("--all", action="store_true", help="draw every colliding plan")
    ap.add_argument("--png", help="draw the plans (at most 4)")
    args = ap.parse_args()
    torch.set_num_threads(1)
    grid, fp = load_map(args.map), make_footprint(args.robot)
    cost = CollisionCost.build(grid, fp, CostConfig.for_map(grid)).as_tuple()
    sd = SparseDiffusion(load_model("sd", grid, footprint=fp),
                         SparseConfig(selection="collision_aware", precision="auto"), cost=cost,
                         placer=placer_for(grid, fp, None))
    hd = HierarchicalPlanner(sd, load_model("dd", grid, footprint=fp), costmap=cost[0],
                             footprint_points=cost[1], cost_config=cost[2], dense=DenseConfig(),
                             exact_check=exact_check_for(grid, fp),
                             replan_spacing=replan_spacing_for(grid, args.replan_spacing,
                                                               sd.expert_spacing))
    net = SafetyNet(grid, fp, planner=hd, astar=planner_for(grid, clearance_for_footprint(fp)))
    gen, net_gen = torch.Generator().manual_seed(0), torch.Generator().manual_seed(1)
    drawn, colliding = [], 0
    for k, prob in enumerate(make_problems(grid, args.problems, seed=args.seed)):
        plan = hd.plan(prob.start, prob.goal, generator=gen)
        safe = net.apply(plan.trajectory, segments=plan.segments, generator=net_gen)
        if safe.rule == "none":
            continue
        colliding += 1
        parts = []
        for i, seg in enumerate(plan.segments):
            seg = np.asarray(seg, dtype=np.float64)
            if segment_collisions(seg, fp, grid).any():
                wp = plan.global_plans[i]
                parts.append(f"iteration {i + 1}/{len(plan.segments)}: horizon {len(wp)}, "
                             f"segment {np.linalg.norm(seg[-1] - seg[0]):.1f} m, "
                             f"{np.linalg.norm(wp[-1] - wp[0]):.1f} m left to the goal")
        print(f"problem {k}: net rule {safe.rule}; " + "; ".join(parts))
        if args.all or safe.rule in ("fallback", "unsafe"):
            drawn.append((k, safe.rule, plan))
    print(f"{colliding} of {args.problems} plans collide before the net")
    if args.png and drawn:
        _draw(grid, fp, drawn[:4], args.png)
        print(f"figure: {args.png}")


def _draw(grid, fp, drawn, path) -> None:
    fig, axes = plt.subplots(1, len(drawn), figsize=(4.5 * len(drawn), 6.5), squeeze=False)
    x0, y0, x1, y1 = grid.bounds
    for ax, (k, rule, plan) in zip(axes[0], drawn):
        ax.imshow(np.where(grid.occupied, 0.0, 1.0), origin="lower", extent=(x0, x1, y0, y1),
                  cmap="gray", vmin=0, vmax=1)
        traj = np.asarray(plan.trajectory, dtype=np.float64)
        reached = np.array([g[0] for g in plan.global_plans] + [plan.global_plans[-1][-1]])
        ax.plot(traj[:, 0], traj[:, 1], "-", color="orange", lw=1, label="plan")
        ax.plot(reached[:, 0], reached[:, 1], "o", color="tab:blue", ms=3,
                label="reached waypoints")
        for i in np.flatnonzero(segment_collisions(traj, fp, grid)):
            ax.plot(traj[i:i + 2, 0], traj[i:i + 2, 1], "r-", lw=3)
        ax.plot(*traj[0], "g^", ms=9)
        ax.plot(*traj[-1], "r*", ms=12)
        ax.set_title(f"problem {k} (net: {rule})\nred: colliding", fontsize=9)
    axes[0][0].legend(loc="lower left", fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=70)


if __name__ == "__main__":
    main()
