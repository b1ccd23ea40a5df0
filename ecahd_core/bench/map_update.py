"""``ecahd bench map-update``: what global_planner does when a changed map arrives (a SLAM
update, an edited map), timed against what it did for the first map, in the same run.

For each problem (a seeded start / goal pair joined on the map), a 2 x 2 m block (``--box``) is
added across the A* route halfway along it, so the update closes the way the first plan took
(problems whose goal the block cuts off are drawn again). Per problem:

- ``first``: the node's work on the first map (the reference): the SD checkpoint read, J's cost
  map built, SD made on the map (the generalist's views' summed-area table), its warm-up plan,
  ``OnlinePlanner.set_map`` (placers, the subgoal rule's graph) and the first plan.
- ``update``: the same on the updated map, then the goal planned again from the start: the time
  from the map's arrival to the new plan. A per-map model keeps the site's model
  (``model_zoo.learnt_map``: the block is a wall SD never learnt, detoured when SD crosses it);
  the generalist sees the block in its views.
- ``round``: the new plan's straight legs, swept with the footprint (exact checker), keep clear
  of the block.

Run it: ``ecahd bench map-update --map MAP [--sd-model general|FILE]`` (1 torch thread, as the
node). Nothing else of ours should run beside it (say so when it does).
"""
from __future__ import annotations

import argparse
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from ecahd_core.errors import EcahdError, PlanningError


@dataclass(frozen=True, kw_only=True)
class MapUpdateBenchSettings:
    """Attributes:
        map: a built-in maze, a Nav2 YAML, or ``KIND:WxH:RES:SEED`` (a generated building).
        sd_model: SD's checkpoint (None: the map's own; "general": the generalist; a file).
        robot: footprint preset or Nav2 polygon.
        problems: start / goal pairs.
        box: [m] side of the block added on each route.
        seed: seed of the pairs and the sampling.
    """

    map: str = "maze2d-large"
    sd_model: str | None = None
    robot: str = "circle"
    problems: int = 5
    box: float = 2.0
    seed: int = 0


@dataclass
class MapUpdateRecord:
    start: list
    goal: list
    first_ms: float
    update_ms: float
    build_ms: float  # of update_ms: model read, J, SD, warm-up, set_map
    plan_ms: float  # of update_ms: the new plan
    method: str  # the new plan's stage ("sd" or "fallback_astar")
    round: bool  # its legs keep clear of the block
    changed_share: float


@dataclass
class MapUpdateBenchResult:
    settings: MapUpdateBenchSettings
    map: str
    records: list = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"settings": asdict(self.settings), "map": self.map,
                "records": [asdict(r) for r in self.records]}


def _with_block(grid, centre, side: float):
    from ecahd_core.maps import GridMap

    data = grid.data.copy()
    r0, c0 = grid.world_to_cell(np.asarray(centre) - 0.5 * side)
    r1, c1 = grid.world_to_cell(np.asarray(centre) + 0.5 * side)
    data[max(min(r0, r1), 0):max(r0, r1) + 1, max(min(c0, c1), 0):max(c0, c1) + 1] = 100
    return GridMap(data, grid.resolution, grid.origin, name=grid.name, frame_id=grid.frame_id)


def run_map_update_benchmark(settings: MapUpdateBenchSettings, *, progress: bool = True
                             ) -> MapUpdateBenchResult:
    import torch
    from tqdm import tqdm

    from ecahd_core.astar import clearance_for_footprint, planner_for
    from ecahd_core.bench.replan import load_bench_map
    from ecahd_core.collision import check_collision
    from ecahd_core.cost import CollisionCost, CostConfig
    from ecahd_core.dataset import points_at_arclength, cumulative_arclength
    from ecahd_core.footprint import make_footprint
    from ecahd_core.maps import GridMap
    from ecahd_core.model_zoo import learnt_map, load_sd, read_general
    from ecahd_core.planning.online import GlobalRunnerConfig, OnlinePlanner, OnlinePlannerConfig
    from ecahd_core.planning.sparse import SparseConfig, SparseDiffusion
    from ecahd_core.problems import make_problems

    grid = load_bench_map(settings.map)
    fp = make_footprint(settings.robot)
    general = settings.sd_model is not None and \
        read_general("sd", settings.sd_model) is not None
    astar = planner_for(grid, clearance_for_footprint(fp))
    result = MapUpdateBenchResult(settings=settings, map=grid.name)
    rng = np.random.default_rng(settings.seed)

    def node_map(new, site):
        """global_planner._on_map's work on ``new`` -> (OnlinePlanner, ms)."""
        t0 = time.perf_counter()
        learnt, _ = (new, 0.0) if general else learnt_map(site, new)
        ckpt = load_sd(learnt, path=settings.sd_model, footprint=fp)
        sd = SparseDiffusion(ckpt, SparseConfig(), grid=new,
                             cost=CollisionCost.build(new, fp, CostConfig.for_map(new)))
        x0, y0, x1, y1 = new.bounds
        sd.warm_up((0.5 * (x0 + x1), 0.5 * (y0 + y1)))
        planning = OnlinePlanner(OnlinePlannerConfig(), GlobalRunnerConfig(), fp,
                                 clock=lambda: 0.0,
                                 generator=torch.Generator().manual_seed(settings.seed))
        planning.set_map(new, sd=sd, learnt=learnt)
        return planning, (time.perf_counter() - t0) * 1e3

    candidates = make_problems(grid, 20 * settings.problems + 20, seed=settings.seed)
    bar = tqdm(total=settings.problems, desc="map update", disable=not progress)
    for prob in candidates:
        if len(result.records) == settings.problems:
            break
        try:
            route = astar.plan(prob.start, prob.goal)
        except PlanningError:
            continue
        s = cumulative_arclength(route)
        centre = points_at_arclength(route, np.array([0.5 * s[-1]]))[0]
        far = min(np.linalg.norm(centre - prob.start), np.linalg.norm(centre - prob.goal))
        if far < settings.box + fp.circumscribed_radius:
            continue
        updated = _with_block(grid, centre, settings.box)
        try:  # the goal must stay reachable round the block
            planner_for(updated, clearance_for_footprint(fp)).plan(prob.start, prob.goal)
        except PlanningError:
            continue
        planning, first_build = node_map(grid, None)
        planning.set_goal(prob.goal)
        t0 = time.perf_counter()
        planning.step(prob.start)
        first = first_build + (time.perf_counter() - t0) * 1e3
        planning, build = node_map(updated, grid)
        planning.set_goal(prob.goal)
        t0 = time.perf_counter()
        outcome = planning.step(prob.start)
        plan_ms = (time.perf_counter() - t0) * 1e3
        only = GridMap(np.where(updated.occupied & ~grid.occupied, 100, 0).astype(np.int8),
                       grid.resolution, grid.origin, name="block")
        clear = check_collision(outcome.waypoints, fp, only).collision_free
        result.records.append(MapUpdateRecord(
            start=list(map(float, prob.start)), goal=list(map(float, prob.goal)),
            first_ms=first, update_ms=build + plan_ms, build_ms=build, plan_ms=plan_ms,
            method=outcome.method, round=bool(clear),
            changed_share=grid.changed_share(updated)))
        bar.update(1)
    bar.close()
    if not result.records:
        raise EcahdError(f"no problem on {grid.name!r} whose route a {settings.box:g} m block "
                         f"can close with the goal still reachable")
    del rng
    return result


def format_table(result: MapUpdateBenchResult) -> str:
    s, recs = result.settings, result.records
    first = np.array([r.first_ms for r in recs])
    update = np.array([r.update_ms for r in recs])
    lines = [f"Map update on {result.map} ({s.sd_model or 'its own SD model'}, {s.robot}, "
             f"{len(recs)} problems, a {s.box:g} m block on each route, seed {s.seed})", "",
             "| step | median ms | max ms | ratio to first map |", "|---|---|---|---|",
             f"| first map: build + plan (reference) | {np.median(first):.0f} | "
             f"{first.max():.0f} | 1.00 |",
             f"| update: build + plan | {np.median(update):.0f} | {update.max():.0f} | "
             f"{np.median(update / first):.2f} |",
             f"| of which the new plan | {np.median([r.plan_ms for r in recs]):.0f} | "
             f"{max(r.plan_ms for r in recs):.0f} | |", "",
             f"planned round the block: {sum(r.round for r in recs)}/{len(recs)}; by SD "
             f"{sum(r.method == 'sd' for r in recs)}, by the A* detour "
             f"{sum(r.method == 'fallback_astar' for r in recs)}"]
    return "\n".join(lines)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    d = MapUpdateBenchSettings()
    parser.add_argument("--map", default=d.map,
                        help="built-in maze, Nav2 YAML, or KIND:WxH:RES:SEED for a generated "
                             "building")
    parser.add_argument("--sd-model", default=d.sd_model, metavar="CKPT",
                        help="SD's checkpoint: 'general', a file, or the map's own (default)")
    parser.add_argument("--robot", default=d.robot)
    parser.add_argument("--problems", type=int, default=d.problems)
    parser.add_argument("--box", type=float, default=d.box, help="[m] side of the block")
    parser.add_argument("--seed", type=int, default=d.seed)
    parser.add_argument("--json", metavar="FILE", help="also write the result as JSON to FILE")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    if args.problems < 1 or not args.box > 0:
        raise EcahdError(f"--problems must be >= 1 and --box > 0, got {args.problems}, "
                         f"{args.box}")
    result = run_map_update_benchmark(MapUpdateBenchSettings(
        map=args.map, sd_model=args.sd_model, robot=args.robot, problems=args.problems,
        box=args.box, seed=args.seed), progress=not args.no_progress)
    print(format_table(result))
    if args.json:
        from ecahd_core.bench.output import write_json

        write_json(args.json, result.to_dict())
    return 0
