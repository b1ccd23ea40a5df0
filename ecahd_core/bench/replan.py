"""``ecahd bench replan``: what global_planner does round one plan on a big map once the scans
have found obstacles that are not on it, each step next to the way it was done before, timed
in the same run on the same problems:

- ``fused cost``: J's cost map with the remembered obstacles (``ObstacleMemory.fused_cost``:
  the static cost map with the obstacles added tile by tile). Reference: a whole cost map built
  from the fused grid (``CollisionCost.build``). Also reported: the largest difference between
  the two in free space (0 expected; inside a wall that a mark touches the depth part of the
  cost may be lower, see ``costmap.add_obstacles``).
- ``crosses``: whether a plan's legs meet a remembered obstacle (``ObstacleMemory.crosses``:
  the exact checker on the marks with their distance transform). Reference: the exact checker
  on the marks without it. The verdicts must agree.
- ``judge``: local_refiner's exact check of a local plan on the static map fused with a scan
  window (``sensing.fuse_grid``, which derives the fused grid's distance bound from the static
  map's, so the checker passes poses far from every wall and mark), for the 6 m of the route
  round the first box, fusion included. Reference: the same check on the fused grid without
  the bound (every pose tested cell by cell, as before). The verdicts must agree.
- ``detour``: the A* detour round what is known (``navigation.detour``: coarse A* on a big map,
  no landmarks, no box search when the box holds most of the map). Reference: the same with the
  exact A* (``coarse=False``). Also reported: the detour's length against the exact one's.

Problems: seeded start / goal pairs with the footprint's clearance, at least ``min_distance``
apart and joined on the static map; ``obstacles`` boxes (``box`` m a side) are remembered on
the static map's A* route between them (at evenly spread fractions of its length), as if the
scans had seen them there. Torch and the timings run in this process; nothing else of ours
should run beside it (say so when it does). Run it: ``ecahd bench replan [--map M]``.
"""
from __future__ import annotations

import argparse
import math
from dataclasses import asdict, dataclass, field

import numpy as np

from ecahd_core.errors import EcahdError, PlanningError

DEFAULT_MAP = "office:60x60:0.03:11"  # the generated office of the building figures


@dataclass(frozen=True, kw_only=True)
class ReplanBenchSettings:
    """What ``ecahd bench replan`` measures.

    Attributes:
        map: a built-in maze, a Nav2 YAML, or ``KIND:WxH:RES:SEED`` for a generated building
            (``ecahd map generate``).
        robot: footprint preset or Nav2 polygon string.
        problems: start / goal pairs.
        min_distance: [m] least straight distance between a pair's start and goal.
        obstacles: boxes remembered on each pair's route.
        box: [m] side of each box.
        repeats: timed calls of each new step per problem (the median is reported); the
            references run once.
        seed: seed of the pairs.
    """

    map: str = DEFAULT_MAP
    robot: str = "circle"
    problems: int = 5
    min_distance: float = 20.0
    obstacles: int = 2
    box: float = 0.6
    repeats: int = 3
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("problems", "repeats"):
            if getattr(self, name) < 1:
                raise EcahdError(f"bench replan: {name} must be >= 1, got {getattr(self, name)}")
        if self.obstacles < 0:
            raise EcahdError(f"bench replan: obstacles must be >= 0, got {self.obstacles}")
        if not (math.isfinite(self.box) and self.box > 0):
            raise EcahdError(f"bench replan: box must be a finite side > 0 m, got {self.box}")
        if not (math.isfinite(self.min_distance) and self.min_distance >= 0):
            raise EcahdError(f"bench replan: min_distance must be >= 0 m, "
                             f"got {self.min_distance}")


@dataclass
class ProblemRecord:
    """One problem: its ends, and per step the new and the reference time [ms]."""

    start: list[float]
    goal: list[float]
    route_m: float
    remembered_cells: int
    cost_ms: float
    cost_ref_ms: float
    cost_max_diff: float
    crosses: bool
    crosses_ms: float
    crosses_ref_ms: float
    crosses_agree: bool
    judge_ms: float
    judge_ref_ms: float
    judge_agree: bool
    detour_ms: float | None  # None: no detour exists (both agree, else detour_agree False)
    detour_ref_ms: float | None
    detour_m: float | None
    detour_ref_m: float | None
    detour_agree: bool


@dataclass
class ReplanBenchResult:
    settings: ReplanBenchSettings
    map_name: str
    map_cells: tuple[int, int]
    resolution: float
    machine: dict
    records: list[ProblemRecord] = field(default_factory=list)

    def to_dict(self) -> dict:
        return asdict(self)

    def median(self, name: str) -> float | None:
        values = [getattr(r, name) for r in self.records if getattr(r, name) is not None]
        return float(np.median(values)) if values else None

    def ratio(self, new: str, ref: str) -> float | None:
        """Median over the problems of reference / new."""
        pairs = [(getattr(r, ref), getattr(r, new)) for r in self.records
                 if getattr(r, new) is not None and getattr(r, ref) is not None]
        return float(np.median([a / b for a, b in pairs])) if pairs else None


def load_bench_map(spec: str):
    """A GridMap from a map spec, or a generated building from ``KIND:WxH:RES:SEED``."""
    from ecahd_core.maps import load_map

    parts = spec.split(":")
    if len(parts) == 4 and "x" in parts[1]:
        from ecahd_core.mapgen import MapGenConfig, generate_map

        try:
            w, h = (float(v) for v in parts[1].split("x"))
            config = MapGenConfig(kind=parts[0], width=w, height=h, resolution=float(parts[2]),
                                  seed=int(parts[3]))
        except ValueError as exc:
            raise EcahdError(f"bench map {spec!r}: expected KIND:WxH:RES:SEED ({exc})") from None
        return generate_map(config)
    return load_map(spec)


def _remember_boxes(memory, grid, centres: np.ndarray, side: float, now: float) -> None:
    """Mark square boxes of ``side`` m round ``centres`` (K, 2) [m] in ``memory`` at ``now``."""
    from ecahd_core.maps import GridMap

    data = np.full(grid.data.shape, -1, dtype=np.int8)  # not seen
    half = 0.5 * side
    for cx, cy in centres:
        r0, c0 = grid.world_to_cell(np.array([cx - half, cy - half]))
        r1, c1 = grid.world_to_cell(np.array([cx + half, cy + half]))
        data[max(r0, 0):max(r1 + 1, 0), max(c0, 0):max(c1 + 1, 0)] = 100
    memory.update(GridMap(data, grid.resolution, grid.origin, name="boxes"), now)


def _median_ms(fn, repeats: int) -> tuple[float, object]:
    """(``bench.timing.median_ms`` of ``repeats`` calls, the last call's result)."""
    from ecahd_core.bench.timing import median_ms

    out = []
    return median_ms(lambda: out.append(fn()), repeats), out[-1]


def _timed_detour(grid, footprint, start, goal, coarse: bool, repeats: int):
    """(median ms, path or None when there is no way)."""
    from ecahd_core.planning.detour import detour

    def run():
        try:
            return detour(grid, footprint, start, goal, coarse=coarse)
        except PlanningError:
            return None
    return _median_ms(run, repeats)


def run_replan_benchmark(settings: ReplanBenchSettings = ReplanBenchSettings(), *,
                         progress: bool = True) -> ReplanBenchResult:
    """Measure every step on ``settings.problems`` seeded problems (see the module docstring)."""
    import torch
    from tqdm import tqdm

    from ecahd_core.astar import (clearance_for_footprint, path_length, planner_for,
                                  sample_free_points)
    from ecahd_core.bench.timing import machine_info
    from ecahd_core.collision import check_collision
    from ecahd_core.controller import resample
    from ecahd_core.cost import CollisionCost
    from ecahd_core.footprint import make_footprint
    from ecahd_core.maps import GridMap
    from ecahd_core.sensing import ObstacleMemory, fuse_grid

    s = settings
    grid = load_bench_map(s.map)
    footprint = make_footprint(s.robot)
    static = CollisionCost.build(grid, footprint)
    astar = planner_for(grid, clearance_for_footprint(footprint))
    grid.free_distance  # noqa: B018  once per map, as the nodes' static map has it
    rng = np.random.default_rng(s.seed)
    result = ReplanBenchResult(settings=s, map_name=grid.name, map_cells=grid.data.shape,
                               resolution=grid.resolution, machine=machine_info())
    bar = tqdm(total=s.problems, desc="bench replan", unit="problem", disable=not progress)
    tries = 0
    while len(result.records) < s.problems:
        tries += 1
        if tries > 200 * s.problems:
            raise EcahdError(f"bench replan: found only {len(result.records)} of {s.problems} "
                             f"pairs at least {s.min_distance:g} m apart and joined on "
                             f"{grid.name!r}")
        start, goal = sample_free_points(rng, astar.mask, grid, 2)
        if np.linalg.norm(goal - start) < s.min_distance:
            continue
        try:
            route = astar.plan(start, goal)
        except PlanningError:
            continue
        now = 100.0
        memory = ObstacleMemory(grid)
        dense = resample(route, grid.resolution)  # (N, 2) the route a cell apart
        if s.obstacles:
            at = np.linspace(0, len(dense) - 1, s.obstacles + 2)[1:-1].round().astype(int)
            _remember_boxes(memory, grid, dense[at], s.box, now)
        fused = memory.fused(now)
        mask = memory.mask(now)
        # fused cost: new (cache emptied each call) against a whole new cost map
        def new_cost():
            memory._cost_cache = None
            return memory.fused_cost(now, static)
        cost_ms, cost = _median_ms(new_cost, s.repeats)
        cost_ref_ms, ref = _median_ms(lambda: CollisionCost.build(fused, footprint), 1)
        free = torch.as_tensor(~fused.occupied)
        diff = float((cost.costmap.grid - ref.costmap.grid).abs()[free].max())
        # crossing check on the route's legs
        crosses_ms, crosses = _median_ms(lambda: memory.crosses(route, footprint, now),
                                         s.repeats)
        only = GridMap(np.where(mask, 100, 0).astype(np.int8), grid.resolution, grid.origin)
        crosses_ref_ms, report = _median_ms(lambda: check_collision(route, footprint, only), 1)
        crosses_ref = not report.collision_free
        # local_refiner: fuse a 6 m window round the first box, judge 6 m of the route there
        if s.obstacles:
            k = int(round((len(dense) - 1) / (s.obstacles + 1)))
            segment = dense[max(k - int(3 / grid.resolution), 0):
                            k + int(3 / grid.resolution) + 1]
            r0, c0 = (int(v) - 100 for v in grid.world_to_cell(dense[k]))
            window = mask[max(r0, 0):r0 + 200, max(c0, 0):c0 + 200]
            w_origin = tuple(np.asarray(grid.origin) + grid.resolution
                             * np.array([max(c0, 0), max(r0, 0)]))

            def judge(bound: bool):
                g = fuse_grid(grid, window, w_origin)
                if not bound:
                    g.__dict__.pop("free_distance", None)
                return check_collision(segment, footprint, g).collision_free
            judge_ms, verdict = _median_ms(lambda: judge(True), s.repeats)
            judge_ref_ms, verdict_ref = _median_ms(lambda: judge(False), 1)
        else:
            judge_ms = judge_ref_ms = 0.0
            verdict = verdict_ref = True
        # detour round the remembered boxes
        detour_ms, path = _timed_detour(fused, footprint, start, goal, True, s.repeats)
        detour_ref_ms, path_ref = _timed_detour(fused, footprint, start, goal, False, 1)
        result.records.append(ProblemRecord(
            start=start.tolist(), goal=goal.tolist(), route_m=path_length(route),
            remembered_cells=int(mask.sum()), cost_ms=cost_ms, cost_ref_ms=cost_ref_ms,
            cost_max_diff=diff, crosses=bool(crosses), crosses_ms=crosses_ms,
            crosses_ref_ms=crosses_ref_ms, crosses_agree=bool(crosses) == crosses_ref,
            judge_ms=judge_ms, judge_ref_ms=judge_ref_ms, judge_agree=verdict == verdict_ref,
            detour_ms=detour_ms if path is not None else None,
            detour_ref_ms=detour_ref_ms if path_ref is not None else None,
            detour_m=path_length(path) if path is not None else None,
            detour_ref_m=path_length(path_ref) if path_ref is not None else None,
            detour_agree=(path is None) == (path_ref is None)))
        bar.update(1)
    bar.close()
    return result


def format_table(result: ReplanBenchResult) -> str:
    """The per-problem table and the medians, human-readable."""
    s, r = result.settings, result
    m = r.machine
    lines = [
        f"global_planner's work round a plan with remembered obstacles: map {r.map_name!r} "
        f"({r.map_cells[1]} x {r.map_cells[0]} cells at {r.resolution} m), {s.robot}, "
        f"{s.problems} problems (seed {s.seed}, >= {s.min_distance:g} m apart), "
        f"{s.obstacles} box(es) of {s.box:g} m on each route; {m['cpu']}, "
        f"{m['logical_cpus']} CPUs, {m['torch_threads']} torch thread(s)",
        f"{'#':>2}{'route m':>9}{'cost ms':>9}{'(ref)':>8}{'crosses':>9}{'ms':>7}{'(ref)':>8}"
        f"{'judge ms':>10}{'(ref)':>8}{'detour ms':>11}{'(ref)':>9}{'len / ref':>11}",
    ]
    for i, p in enumerate(r.records):
        if p.detour_m is not None and p.detour_ref_m is not None:
            length = f"{p.detour_m / p.detour_ref_m:.3f}"
        else:
            length = "no way" if p.detour_agree else "DISAGREE"
        det = "-" if p.detour_ms is None else f"{p.detour_ms:.0f}"
        det_ref = "-" if p.detour_ref_ms is None else f"{p.detour_ref_ms:.0f}"
        verdict = ("yes" if p.crosses else "no") + ("" if p.crosses_agree else "!")
        judge = f"{p.judge_ms:.1f}" + ("" if p.judge_agree else "!")
        lines.append(f"{i:>2}{p.route_m:>9.1f}{p.cost_ms:>9.1f}{p.cost_ref_ms:>8.0f}"
                     f"{verdict:>9}{p.crosses_ms:>7.1f}{p.crosses_ref_ms:>8.0f}{judge:>10}"
                     f"{p.judge_ref_ms:>8.0f}{det:>11}{det_ref:>9}{length:>11}")

    def summary(label, new, ref):
        a, b, q = r.median(new), r.median(ref), r.ratio(new, ref)
        if a is None or b is None:
            return f"{label:<14} -"
        return f"{label:<14} {a:8.1f} ms   reference {b:8.1f} ms   reference / new {q:6.1f}x"
    lines += ["medians:", summary("fused cost", "cost_ms", "cost_ref_ms"),
              summary("crosses", "crosses_ms", "crosses_ref_ms"),
              summary("judge", "judge_ms", "judge_ref_ms"),
              summary("detour", "detour_ms", "detour_ref_ms")]
    diff = max(p.cost_max_diff for p in r.records)
    agree = all(p.crosses_agree and p.judge_agree and p.detour_agree for p in r.records)
    lengths = [p.detour_m / p.detour_ref_m for p in r.records
               if p.detour_m is not None and p.detour_ref_m is not None]
    lines.append(f"largest cost difference in free space {diff:.2e}; verdicts agree: {agree}; "
                 f"detour length / exact A*'s: "
                 + (f"mean {np.mean(lengths):.3f}, worst {max(lengths):.3f}" if lengths else "-"))
    lines.append("references: a whole cost map from the fused grid; the exact checker without "
                 "a distance transform (crosses, judge); the detour by exact A*")
    return "\n".join(lines)


# ------------------------------------------------------------------- ``ecahd bench replan``
def add_arguments(parser: argparse.ArgumentParser) -> None:
    d = ReplanBenchSettings()
    parser.add_argument("--map", default=d.map,
                        help="built-in maze, Nav2 YAML, or KIND:WxH:RES:SEED for a generated "
                             "building")
    parser.add_argument("--robot", default=d.robot,
                        help="footprint: circle, quadruped, humanoid or a Nav2 polygon string")
    parser.add_argument("--problems", type=int, default=d.problems)
    parser.add_argument("--min-distance", type=float, default=d.min_distance, metavar="M",
                        help="[m] least distance between start and goal")
    parser.add_argument("--obstacles", type=int, default=d.obstacles,
                        help="boxes remembered on each route")
    parser.add_argument("--box", type=float, default=d.box, help="[m] side of each box")
    parser.add_argument("--repeats", type=int, default=d.repeats,
                        help="timed calls of each new step per problem (median)")
    parser.add_argument("--seed", type=int, default=d.seed)
    parser.add_argument("--json", metavar="FILE", help="also write the result as JSON to FILE")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    settings = ReplanBenchSettings(map=args.map, robot=args.robot, problems=args.problems,
                                   min_distance=args.min_distance, obstacles=args.obstacles,
                                   box=args.box, repeats=args.repeats, seed=args.seed)
    result = run_replan_benchmark(settings, progress=not args.no_progress)
    print(format_table(result))
    if args.json:
        from ecahd_core.bench.output import write_json

        write_json(args.json, result.to_dict())
    return 0
