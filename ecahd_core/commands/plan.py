"""``ecahd plan``: plan one path on a map, check it with the exact collision checker, and write
a figure (path, footprint sweep, collisions in red) and a JSON record.

Methods:
- ``ecahd``  Algorithm 1: SD best-of-N global plan, straight local plans checked by J, guided
             Dense Diffusion where J's collision cost exceeds c_th (= ``hd --guidance``);
- ``hd``     the same hierarchy, DD unguided unless ``--guidance``;
- ``sd``     Sparse Diffusion alone: N candidates in one batch, the best by the paper's rule,
             followed by straight lines between its waypoints (``--guidance``: SD guided by J);
- ``fd``     Diffuser-style full-sequence diffusion, 100 points (``--guidance``: guided by J);
- ``astar``  A* with footprint clearance (the expert and classical reference).

The safety net (``--safety-net``, default on; ``ecahd_core.safety``) judges the plan by the exact
checker and repairs it when it collides: fresh DD samples for the colliding local segments
(ECAHD / HD), then A* for the offending stretches only, drawn in orange. A plan it cannot make
collision-free is written for diagnosis, labelled unsafe, and the command exits 2.
"""
from __future__ import annotations

import argparse
import logging
import time
from dataclasses import dataclass, field

from ecahd_core.bench.output import write_json
from ecahd_core.commands import add_map_arguments
from ecahd_core.errors import EcahdError
from ecahd_core.threads import (add_precision_argument, add_threads_argument,
                                resolve_precision, set_torch_threads)
from ecahd_core.viz import PlanFigure

log = logging.getLogger("ecahd.plan")

METHODS = ("ecahd", "hd", "sd", "fd", "astar")
DEFAULT_START = (1.5, 1.5)
DEFAULT_GOAL = (10.5, 7.5)
SWEEP_SPACING = 0.25  # [m] between footprint outlines drawn along the path


def add_replan_argument(p: argparse.ArgumentParser, default: str = "every_waypoint",
                        warm_fraction: float = -1.0) -> None:
    """``--replan``, ``--warm-fraction`` and ``--replan-spacing``: HD / ECAHD's SD policy
    (HierarchicalPlanner's ``replan`` and ``replan_spacing``, SparseConfig's ``warm_fraction``),
    one definition for ``ecahd plan`` and ``ecahd bench planning``."""
    from ecahd_core.planning.horizon import REPLAN_POLICIES

    p.add_argument("--replan", default=default, choices=REPLAN_POLICIES,
                   help="HD: SD best-of-N at every waypoint (Algorithm 1) or once")
    p.add_argument("--warm-fraction", type=float, default=warm_fraction, metavar="F",
                   help="HD every_waypoint: warm-start each re-plan from the previous plan, "
                        "running the last F (0..1) of the DDIM schedule, a re-plan whose first "
                        "leg crosses a wall drawn again from noise (0: from noise, Algorithm 1 "
                        "as written; -1: by the map, 0.3 on building maps, else 0)")
    p.add_argument("--replan-spacing", type=float, default=None, metavar="M",
                   help="[m] HD every_waypoint: each SD re-plan keeps at least ceil(D / M) + 1 "
                        "waypoints (at most P^g) for the straight distance D left to the goal, "
                        "instead of Algorithm 1's P^g - p (ours; 0: off; default: by the map and "
                        "model, on maps over 50 000 cells the SD model's expert waypoint "
                        "spacing, at least 3 m; off on smaller ones)")


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_map_arguments(p)
    p.add_argument("--robot", default="circle",
                   help="footprint: circle | quadruped | humanoid | Nav2 polygon '[[x, y], ...]'")
    p.add_argument("--padding", type=float, default=0.0,
                   help="[m] extra clearance around the footprint for A* (and the safety "
                        "net's A* fallback)")
    p.add_argument("--start", nargs=2, type=float, default=DEFAULT_START, metavar=("X", "Y"),
                   help="start position [m] in the map frame")
    p.add_argument("--goal", nargs=2, type=float, default=DEFAULT_GOAL, metavar=("X", "Y"),
                   help="goal position [m] in the map frame")
    p.add_argument("--method", choices=METHODS, default="ecahd", help="planner")
    p.add_argument("--guidance", action=argparse.BooleanOptionalAction, default=None,
                   help="guide the diffusion by the cost J (default: on for ecahd, off otherwise)")
    p.add_argument("--waypoints", type=int, default=10,
                   help="number of sparse waypoints reported (P^g)")
    p.add_argument("--max-spacing", type=float, default=None, metavar="M",
                   help="[m] SD/ECAHD: waypoint spacing by distance, legs longer than this "
                        "re-sampled by SD between their ends (big maps; default: off)")
    p.add_argument("--place-reach", type=float, default=None, metavar="R",
                   help="[m] SD/ECAHD: SD's waypoints in a wall move into free space within R "
                        "and legs crossing a wall get a placed midpoint (ours; 0: off; "
                        "default: on at 1 m for maps over 50 000 cells, off on smaller ones)")
    add_threads_argument(p)
    add_precision_argument(p, "auto", "the SD Transformer's inference precision (auto: bf16 "
                                      "where the CPU has native bfloat16, as global_planner's "
                                      "inference_precision)")
    p.add_argument("--candidates", type=int, default=10,
                   help="diffusion candidates sampled in one batch (best of N)")
    p.add_argument("--selection", default="collision_aware",
                   choices=("shortest_reaching", "collision_aware"),
                   help="best-of-N rule: the paper's Sec. III-A rule or J-aware (default)")
    p.add_argument("--polish-steps", type=int, default=None,
                   help="ECAHD/HD: J-descent steps on local plans still above c_th (ours, "
                        "beyond the paper; 0: the paper's Algorithm 1; default DenseConfig's)")
    p.add_argument("--no-keep-better", action="store_true",
                   help="ECAHD/HD: accept DD's plan even when J finds the straight one cheaper "
                        "(the paper's rule)")
    p.add_argument("--no-exact-rule", action="store_true",
                   help="ECAHD/HD: keep a refined local plan the exact checker finds colliding "
                        "even where the straight or unpolished one is free (ours: put that "
                        "back)")
    p.add_argument("--no-shortcut", action="store_true",
                   help="ECAHD/HD: keep the joined local plans as they are (ours: a plan the "
                        "exact checker finds free is pulled taut by straight segments whose J "
                        "cost is <= c_th and that the exact checker finds free)")
    add_replan_argument(p)
    p.add_argument("--safety-net", action=argparse.BooleanOptionalAction, default=True,
                   help="ours, beyond the paper: judge the plan by the exact checker; when it "
                        "collides, sample the colliding DD segments again, then draw the whole "
                        "plan again (twice at most), then splice in A* for the offending "
                        "stretches; exit 2 when no safe plan exists")
    p.add_argument("--seed", type=int, default=0, help="sampling seed")
    p.add_argument("--sd-model", default=None, help="SD checkpoint (default: the shipped one)")
    p.add_argument("--dd-model", default=None, help="DD checkpoint (default: the shipped one)")
    p.add_argument("--fd-model", default=None, help="FD checkpoint (default: the shipped one)")
    p.add_argument("--png", default="runs/plan.png", help="figure to write")
    p.add_argument("--json", default=None, help="plan record to write (JSON)")


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from ecahd_core.astar import clearance_for_footprint, path_length, planner_for
    from ecahd_core.collision import check_collision
    from ecahd_core.dataset import resample_by_arclength
    from ecahd_core.footprint import make_footprint
    from ecahd_core.maps import load_map
    from ecahd_core.viz import save_figures

    set_torch_threads(args.threads)  # 1 by default: a busy CPU is not oversubscribed
    grid = load_map(args.map, args.resolution)
    grid.require_free_space()
    footprint = make_footprint(args.robot)
    start = grid.validate_point(args.start, "start")
    goal = grid.validate_point(args.goal, "goal")

    candidates, dd_calls, dd_poses, segments, hd, astar = [], 0, None, None, None, None
    counts = {"waypoints_placed": 0, "exact_rule_segments": 0}
    if args.method == "astar":
        t0 = time.perf_counter()
        planner = planner_for(grid, clearance_for_footprint(footprint, padding=args.padding))
        t1 = time.perf_counter()
        path = planner.plan(start, goal)
        t2 = time.perf_counter()
        waypoints = resample_by_arclength(path, args.waypoints)
        timings = {"inflate": (t1 - t0) * 1e3, "search": (t2 - t1) * 1e3,
                   "total": (t2 - t0) * 1e3}
        astar = planner  # the net's fallback plans with the same clearance: reuse it
    else:
        path, waypoints, candidates, timings, dd_calls, dd_poses, segments, hd, counts = \
            _plan_diffusion(args, grid, footprint, start, goal)
    safe = None
    if args.safety_net:
        import torch

        from ecahd_core.safety import SafetyNet, SafetyNetConfig

        net = SafetyNet(grid, footprint, SafetyNetConfig(padding=args.padding), planner=hd,
                        astar=astar)
        safe = net.apply(path, segments=segments,
                         generator=torch.Generator().manual_seed(args.seed + 1))
        timings["safety_net"] = safe.time_ms
        timings["total_with_net"] = timings["total"] + safe.time_ms
        if safe.rule != "none":
            candidates = [path] + list(candidates)  # the diffusion plan, drawn in grey
            path = safe.path
    report = check_collision(path, footprint, grid)
    length = path_length(path)
    success = bool(np.min(np.linalg.norm(path - goal, axis=1)) <= 1.0)

    poses = report.dense_poses
    step = max(1, int(round(SWEEP_SPACING / max(float(np.median(
        np.linalg.norm(np.diff(poses[:, :2], axis=0), axis=1))) if len(poses) > 1 else 1.0, 1e-9))))
    rule = safe.rule if safe is not None else "off"
    net_text = "" if safe is None else (
        f"\nsafety net: {rule}" + (f" ({len(safe.stretches)} A* stretch(es) in orange)"
                                   if safe.stretches else "")
        + (": UNSAFE, no safe plan, do not follow" if not safe.safe else ""))
    title = (f"{args.method}{' + guidance' if _guided(args) and args.method != 'ecahd' else ''} "
             f"on {grid.name}, robot {footprint.name}: length {length:.2f} m, "
             f"{'collision-free' if report.collision_free else 'COLLIDES'}, "
             f"{timings['total']:.1f} ms{net_text}")
    figure = NetFigure(grid=grid, footprint=footprint, title=title, start=start, goal=goal,
                        trajectory=path, waypoints=waypoints,
                        sweep_poses=poses[::step] if dd_poses is None else dd_poses,
                        colliding_poses=poses[report.colliding][::step], extra_paths=candidates,
                        fallback_paths=safe.stretch_paths() if safe is not None else [])
    png = save_figures([figure], args.png)
    print(title.replace("\n", ", "))
    print(f"figure: {png}")
    if args.json:
        record = {
            "map": grid.name, "robot": footprint.name, "method": args.method,
            "start": start.tolist(), "goal": goal.tolist(),
            "waypoints": waypoints.tolist(), "trajectory": path.tolist(),
            "length_m": length, "success": success,
            "collision_free": bool(report.collision_free),
            "penetration_fraction": float(report.penetration_fraction),
            "timings_ms": timings, "dd_calls": dd_calls, **counts,
            "replan": args.replan if args.method in ("ecahd", "hd") else None,
            "warm_fraction": args.warm_fraction if args.method in ("ecahd", "hd") else None,
            "replan_spacing": hd.replan_spacing if hd is not None else None,
            "precision": (resolve_precision(args.precision)
                          if args.method in ("ecahd", "hd", "sd") else None),
            "safety_net": bool(args.safety_net), "rule": rule,
            "collision_free_before_net": (bool(report.collision_free) if safe is None
                                          else not safe.collided_before),
            "fallback_stretches": [] if safe is None else [list(s) for s in safe.stretches],
            "retried_segments": 0 if safe is None else safe.retried_segments,
            "resampled_plans": 0 if safe is None else safe.resampled,
            "unsafe_reason": None if safe is None or safe.safe else safe.reason,
        }
        write_json(args.json, record, indent=1)
        print(f"record: {args.json}")
    if safe is not None and not safe.safe:
        raise EcahdError(f"no safe plan: {safe.reason} (the plan written above is unsafe)")
    return 0


@dataclass
class NetFigure(PlanFigure):
    """PlanFigure plus the safety net's A* stretches, drawn in orange."""

    fallback_paths: list = field(default_factory=list)  # each (K, 2) [m]

    def draw(self, ax) -> None:
        super().draw(ax)
        for i, p in enumerate(self.fallback_paths):
            ax.plot(p[:, 0], p[:, 1], color="tab:orange", lw=2.4,
                    label="A* fallback (safety net)" if i == 0 else None)
        if self.fallback_paths and self.legend:
            ax.legend(loc="best", fontsize=7, framealpha=0.8)


def _guided(args) -> bool:
    return args.method == "ecahd" if args.guidance is None else bool(args.guidance)


def _plan_diffusion(args, grid, footprint, start, goal):
    """SD / FD / HD / ECAHD -> (path, waypoints, candidates, timings, dd_calls, dd_poses,
    local segments (HD / ECAHD, else None), the HierarchicalPlanner (else None), counts for the
    JSON: SD waypoints the placer moved or added, local segments the exact rule put back)."""
    import numpy as np
    import torch

    from ecahd_core.collision import densify
    from ecahd_core.cost import CollisionCost
    from ecahd_core.model_zoo import load_model
    from ecahd_core.planning.full import FullDiffusion
    from ecahd_core.planning.dense import DenseConfig
    from ecahd_core.planning.hierarchical import HierarchicalPlanner
    from ecahd_core.planning.sparse import SparseConfig, SparseDiffusion

    polish = {} if args.polish_steps is None else {"polish_steps": args.polish_steps}
    polish["keep_better"] = not args.no_keep_better
    guided = _guided(args)
    cost = CollisionCost.build(grid, footprint)

    def gen():
        return torch.Generator().manual_seed(args.seed)

    if args.method == "fd":
        fd = FullDiffusion(load_model("fd", grid, path=args.fd_model, footprint=footprint),
                           guidance=guided, cost=cost)
        fd.plan(start, goal, generator=gen())  # warm-up
        t0 = time.perf_counter()
        path = fd.plan(start, goal, generator=gen())
        ms = (time.perf_counter() - t0) * 1e3
        return (path, path[:: max(1, len(path) // 10)], [], {"fd": ms, "total": ms}, 0, None,
                None, None, {"waypoints_placed": 0, "exact_rule_segments": 0})
    sd = SparseDiffusion.for_map(grid, footprint, SparseConfig(
        num_candidates=args.candidates, horizon=args.waypoints, selection=args.selection,
        max_spacing=args.max_spacing, guidance=(args.method == "sd" and guided),
        warm_fraction=args.warm_fraction, precision=args.precision),
        cost=cost, place_reach=args.place_reach, model=args.sd_model)
    if args.method == "sd":
        sd.plan(start, goal, generator=gen())  # warm-up
        plan = sd.plan(start, goal, generator=gen())
        others = [c for i, c in enumerate(plan.candidates) if i != plan.best]
        return (plan.waypoints, plan.waypoints, others, {"sd": plan.time_ms, "total": plan.time_ms},
                0, None, None, None,
                {"waypoints_placed": plan.placed, "exact_rule_segments": 0})
    hd = HierarchicalPlanner.for_map(grid, footprint, sd,
                                     dense=DenseConfig(guidance=guided, **polish),
                                     replan=args.replan, replan_spacing=args.replan_spacing,
                                     exact=not args.no_exact_rule,
                                     shortcut=not args.no_shortcut, model=args.dd_model)
    hd.plan(start, goal, generator=gen())  # warm-up
    plan = hd.plan(start, goal, generator=gen())
    # footprint outlines where DD fired; along the whole path where the shortcut rule pulled
    # it taut (DD's local plans are then no longer all on it)
    refined = [seg for seg, used in zip(plan.segments, plan.dd_segments) if used]
    dd_poses = (None if plan.shortcut else
                np.concatenate([densify(seg, step=0.15) for seg in refined]) if refined
                else np.zeros((0, 3)))
    return (plan.trajectory, plan.global_plans[0], [], dict(plan.timings_ms), plan.dd_calls,
            dd_poses, plan.segments, hd, {"waypoints_placed": plan.placed,
                                          "exact_rule_segments": int(sum(plan.exact_kept)),
                                          "first_leg_changed": plan.first_leg_changed,
                                          "backtracked": plan.backtracked,
                                          "subgoals": plan.subgoals,
                                          "settled": plan.settled,
                                          "shortcut": plan.shortcut})
