"""``ecahd bench habits``: do plans show the habit the demonstrations carry? (issue 41, item 4)

    ecahd bench habits --map office.yaml --models astar=a.pt demos=d.pt mix=m.pt \
        [--habit keep-right|zone] [--zones scenario.yaml] [--problems 40] [--png F] [--json F]

On held-out start/goal pairs of one map (``ecahd_core.problems.make_problems`` with the
benchmarks' seed, 2026, not the seeds of the expert data; pairs the operator cannot plan, or with
an end in a zone, are skipped, so every row has the same pairs), each of up to three per-map SD
checkpoints (``NAME=CKPT``; "general" is the shipped generalist) plans every pair three ways:

- **SD** alone: best of ``candidates`` unguided samples, the waypoints joined by straight legs
  (what ECAHD's sparse stage starts from);
- **ECAHD**: ``HierarchicalPlanner`` with J's guidance and our rules, as ``ecahd bench planning``
  builds its ECAHD cell (the same defaults, :class:`~ecahd_core.bench.planning.
  PlanningBenchSettings`), with the map's DD (``--dd-model``);
- **ECAHD + net**: that same plan through the safety net (``ecahd_core.safety``);
- **ECAHD + net + lanes** (``--lanes FIELD``, ``ecahd lanes``): ECAHD as the nodes run it with
  the ``lanes`` parameter: SD's waypoints moved onto the lane field learnt from the
  demonstrations in every iteration (``ecahd_core.lanes.WaypointLanes``, as global_planner),
  the net, then the plan moved sideways onto the lanes (``lanes.shape_path``, as local_refiner
  does to each local plan; never into collision: a shaped plan the exact checker rejects is
  kept as it came). With ``--lanes`` A*'s paths are shaped too (row "A* + lanes"). A lane
  field with keep-out places (``ecahd lanes``: where the expert's routes go and the robot
  never did) has the "+ lanes" rows plan on the map with those places as walls
  (``LaneField.with_keep_out``, as global_planner does); every row is judged on the map.

Beside them, on the same pairs: **A*** with the footprint's clearance (the expert; about 50% on
the right half) and the **operator** of ``ecahd record-demos`` (``ecahd_core.operator``: its
routes are the target). Each row:

- ``right``: share of the corridor length on the right half of the corridor, relative to the
  direction of travel (``operator.habit_metrics``: corridors wider than twice the robot and at
  most 4 m); ``zone``: share of plans entering a zone (``--zones`` only);
- ``collision_free``: share of plans the exact checker (the footprint along the path) finds free;
- ``success``: a point of the plan within 1 m of the goal (the paper's rule); ``success_free``:
  both;
- ``length_ratio``: mean plan length over the A* length of ``make_problems`` (clearance 0.4 m);
- time per plan [ms], median and p95 (ECAHD + net: planning + the net).

The habit measures are over all plans of a row, reaching the goal or not. Run with 1 torch
thread (``--threads``, default 1); every problem samples from its own seed (sample seed, problem
index), so two models are compared on the same draws.
"""
from __future__ import annotations

import argparse
import logging
import math
import os
import re
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ecahd_core.errors import EcahdError, PlanningError
from ecahd_core.operator import HABITS

log = logging.getLogger(__name__)

MAX_MODELS = 3
MODEL_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_.-]{0,31}$")
PLANNERS = ("SD", "ECAHD", "ECAHD + net")  # each model's rows, in order
LANES = "ECAHD + net + lanes"  # with --lanes: each model's fourth row
ASTAR, OPERATOR = "A*", "operator"  # the reference rows' names
ASTAR_LANES = "A* + lanes"  # with --lanes: A*'s paths moved onto the lanes


@dataclass(frozen=True, kw_only=True)
class HabitsBenchSettings:
    """What ``ecahd bench habits`` runs.

    Attributes:
        map: a built-in map, a Nav2 YAML or KIND:WxH:RES:SEED (``replan.load_bench_map``); the
            checkpoints must have been trained on it.
        models: ((name, checkpoint), ...), 1 to :data:`MAX_MODELS`; checkpoint: a per-map SD
            file or "general".
        problems: held-out start/goal pairs.
        seed: seed of the pairs; sample_seed: of the samples (per problem: (seed, index)).
        robot: footprint name (circle, quadruped, humanoid).
        habit: the operator's habit (:data:`HABITS`); "zone" needs ``zones``.
        zones: scenario YAML with a ``zones:`` list, or None.
        dd_model: DD's checkpoint (None: the map's own, else the shipped generalist).
        figure_problems: pairs drawn by ``--png``.
        lanes: a lane field (``ecahd lanes``) of the map, or None: adds the "+ lanes" rows.
    """

    map: str
    models: tuple[tuple[str, str], ...]
    problems: int = 40
    seed: int = 2026
    sample_seed: int = 0
    robot: str = "circle"
    habit: str = "keep-right"
    zones: str | None = None
    dd_model: str | None = None
    figure_problems: int = 3
    lanes: str | None = None


@dataclass
class HabitRow:
    """One row of the table: one planner of one model (or a reference) over every pair.

    ``right`` / ``zone`` / rates in %, ``None`` where undefined (no corridor length on the
    paths; no zones given). Per-problem lists are in the order of
    :attr:`HabitsBenchResult.pairs`."""

    model: str  # the model's name, or A* / operator
    planner: str  # one of PLANNERS, or A* / operator
    checkpoint: str | None
    problems: int
    right: float | None
    corridor_m: float  # [m] corridor length the share is of
    zone: float | None
    collision_free: float
    success: float
    success_free: float
    length_ratio: float
    time_ms_median: float
    time_ms_p95: float
    fallback: float | None = None  # ECAHD + net: % of plans with A* stretches spliced in
    shaped: float | None = None  # + lanes: % of plans moved onto the lanes
    shape_dropped: float | None = None  # + lanes: % whose shaped plan collided (kept as came)
    free_by_problem: list = field(default_factory=list)
    time_ms_by_problem: list = field(default_factory=list)

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class HabitsBenchResult:
    settings: HabitsBenchSettings
    map_name: str
    rows: list[HabitRow]
    pairs: list  # [[sx, sy], [gx, gy]] per problem [m]
    paths: dict  # (model, planner) -> [(N, 2) array per problem]
    grid: object = None  # the GridMap (not in the JSON)
    seconds: float = 0.0

    def row(self, model: str, planner: str) -> HabitRow:
        for r in self.rows:
            if (r.model, r.planner) == (model, planner):
                return r
        raise KeyError((model, planner))

    def to_dict(self) -> dict:
        return {"settings": asdict(self.settings), "map": self.map_name,
                "seconds": round(self.seconds, 1), "pairs": self.pairs,
                "rows": [r.to_dict() for r in self.rows]}


def parse_models(texts) -> tuple[tuple[str, str], ...]:
    """``NAME=CKPT`` strings -> ((name, ckpt), ...); EcahdError (one line) for a malformed
    entry, a repeated name, none or more than :data:`MAX_MODELS`."""
    out = []
    for text in texts:
        name, sep, ckpt = str(text).partition("=")
        if not sep or not MODEL_NAME.match(name) or not ckpt:
            raise EcahdError(f"--models: expected NAME=CKPT (a name of letters, digits, '_.-' "
                             f"starting with a letter, then a checkpoint; e.g. astar=a.pt), "
                             f"got {text!r}")
        if name in (n for n, _ in out):
            raise EcahdError(f"--models: the name {name!r} is given twice")
        out.append((name, ckpt))
    if not 1 <= len(out) <= MAX_MODELS:
        raise EcahdError(f"--models: give 1 to {MAX_MODELS} NAME=CKPT, got {len(out)}")
    return tuple(out)


def _percent(x: float) -> float | None:
    return None if math.isnan(x) else 100.0 * x


def _pairs(grid, operator, zones, settings: HabitsBenchSettings) -> list:
    """The first ``settings.problems`` problems of ``make_problems`` (seeded; a longer list
    extends a shorter one) whose ends lie outside every zone and which the operator plans:
    [(Problem, the operator's Route, its planning time [ms])]. EcahdError when the map has too
    few."""
    from ecahd_core.problems import make_problems

    n = settings.problems
    try:
        drawn = make_problems(grid, 2 * n + 4, seed=settings.seed)
    except PlanningError as exc:
        raise EcahdError(f"map {grid.name!r}: too few start/goal pairs ({exc})") from None
    kept = []
    for prob in drawn:
        ends = np.stack([prob.start, prob.goal])
        if any(z.contains(ends).any() for z in zones):
            continue
        t0 = time.perf_counter()
        try:
            route = operator.plan(prob.start, prob.goal)
        except PlanningError:
            continue
        kept.append((prob, route, (time.perf_counter() - t0) * 1e3))
        if len(kept) == n:
            return kept
    raise EcahdError(f"map {grid.name!r}: only {len(kept)} of {n} start/goal pairs (of "
                     f"{len(drawn)} drawn) lie outside the zones and can be planned by the "
                     f"operator")


def run_habits_benchmark(settings: HabitsBenchSettings, *, progress: bool = True
                         ) -> HabitsBenchResult:
    """Every model's SD / ECAHD / ECAHD + net rows, A*'s and the operator's, on the same
    pairs (module docstring). Every checkpoint is loaded, and checked against the map, before
    anything is planned."""
    import torch
    from tqdm import tqdm

    from ecahd_core.astar import clearance_for_footprint, planner_for
    from ecahd_core.bench.planning import PlanningBenchSettings, judge_paths, problem_seed
    from ecahd_core.bench.replan import load_bench_map
    from ecahd_core.cost import CollisionCost, CostConfig
    from ecahd_core.footprint import make_footprint
    from ecahd_core.lanes import LaneField, WaypointLanes, shape_path
    from ecahd_core.operator import Operator, OperatorConfig, habit_metrics
    from ecahd_core.planning.dense import DenseConfig
    from ecahd_core.planning.hierarchical import HierarchicalPlanner
    from ecahd_core.planning.sparse import SparseConfig, SparseDiffusion
    from ecahd_core.safety import SafetyNet, SafetyNetConfig
    from ecahd_core.scenario import read_zones

    if settings.habit not in HABITS:
        raise EcahdError(f"habit must be one of {list(HABITS)}, got {settings.habit!r}")
    if settings.problems < 1:
        raise EcahdError(f"need at least one problem, got {settings.problems}")
    models = parse_models(f"{n}={c}" for n, c in settings.models)
    zones = read_zones(settings.zones) if settings.zones else []
    if settings.habit == "zone" and not zones:
        raise EcahdError("habit 'zone' needs --zones SCENARIO with a 'zones:' list")
    t_start = time.perf_counter()
    grid = load_bench_map(settings.map)
    fp = make_footprint(settings.robot)
    field = None
    if settings.lanes:
        field = LaneField.load(settings.lanes)
        field.check_map(grid)
    d = PlanningBenchSettings()  # ECAHD exactly as `ecahd bench planning` runs its ECAHD cell
    cost = CollisionCost.build(grid, fp, CostConfig(margin=CostConfig.for_map(grid).margin))
    sparse = SparseConfig(num_candidates=d.candidates, selection=d.selection, guidance=False,
                          guidance_weight=d.guidance_weight, guidance_space=d.guidance_space,
                          warm_fraction=d.warm_fraction, max_spacing=d.max_spacing,
                          precision=d.precision, leg_batches=d.leg_batches)
    dense = DenseConfig(c_th=d.c_th, guidance=True, guidance_weight=d.guidance_weight,
                        guidance_space=d.guidance_space, retries=d.dd_retries,
                        polish_steps=d.polish_steps, keep_better=d.keep_better)
    astar = planner_for(grid, clearance_for_footprint(fp))
    planners = {}
    # + lanes plans on the map with the learnt keep-out places as walls (as global_planner)
    plan_grid = field.with_keep_out(grid) if field is not None else grid
    if plan_grid is not grid:
        plan_cost = CollisionCost.build(plan_grid, fp,
                                        CostConfig(margin=CostConfig.for_map(grid).margin))
        plan_astar = planner_for(plan_grid, clearance_for_footprint(fp))

    def ecahd(sd, lanes=None, on=None):  # Algorithm 1 with our rules and its safety net
        on = grid if on is None else on
        # the shortcut rule off: it pulls a whole plan taut, which the nodes, following it
        # iteration by iteration, never do (and it would cut the habit's lanes)
        hd = HierarchicalPlanner.for_map(
            on, fp, sd, dense=dense, replan=d.replan, replan_spacing=d.replan_spacing,
            backtracks=d.backtracks, subgoals=d.subgoals, settle=d.settle, shortcut=False,
            exact=d.exact_rule, model=settings.dd_model, learnt=grid)
        hd.stage.lanes = lanes
        net = SafetyNet(on, fp, SafetyNetConfig(retries=d.net_retries,
                                                resamples=d.net_resamples),
                        planner=hd, astar=astar if on is grid else plan_astar)
        return hd, net

    def sd_on_plan_grid(sd, ckpt):  # SD planning on the map with the keep-out places
        from ecahd_core.placement import placer_for

        if plan_grid is grid:
            return sd
        if sd.general:  # the generalist sees the map: it is given the keep-out places
            return SparseDiffusion.for_map(plan_grid, fp, sparse, cost=plan_cost,
                                           place_reach=d.place_reach, model=ckpt)
        return sd.on(cost=plan_cost, placer=placer_for(plan_grid, fp, d.place_reach))

    for name, ckpt in models:  # every checkpoint checked before any planning
        try:
            sd = SparseDiffusion.for_map(grid, fp, sparse, cost=cost, place_reach=d.place_reach,
                                         model=ckpt)
            hd, net = ecahd(sd)
            # + lanes: as the nodes run it, SD's waypoints moved onto the lanes in every
            # iteration (global_planner), the refined plan moved onto them (local_refiner)
            laned = (ecahd(sd_on_plan_grid(sd, ckpt), WaypointLanes(field, plan_grid, fp),
                           on=plan_grid) if field is not None else None)
        except EcahdError as exc:
            raise EcahdError(f"--models {name}={ckpt}: {exc}") from None
        planners[name] = (sd, hd, net, laned)
    operator = Operator(grid, fp, zones, OperatorConfig(keep_right=settings.habit == "keep-right"))
    chosen = _pairs(grid, operator, zones, settings)
    problems = [p for p, _, _ in chosen]

    paths, times, fallbacks, shaping = {}, {}, {}, {}

    def shaped(key, path, ms):  # path moved onto the lanes, recorded under key
        t0 = time.perf_counter()
        res = shape_path(path, field, plan_grid, fp)
        record(key, res.path, ms + (time.perf_counter() - t0) * 1e3)
        shaping.setdefault(key, []).append((res.shaped, res.kept_original))

    def record(key, path, ms):
        paths.setdefault(key, []).append(np.asarray(path, dtype=np.float64).reshape(-1, 2))
        times.setdefault(key, []).append(ms)

    for prob, route, route_ms in chosen:  # the references: the operator's route, A* timed here
        record((OPERATOR, OPERATOR), route.path, route_ms)
        t0 = time.perf_counter()
        path = astar.plan(prob.start, prob.goal)
        ms = (time.perf_counter() - t0) * 1e3
        record((ASTAR, ASTAR), path, ms)
        if field is not None:  # A* round the keep-out places (where it can), then shaped
            if plan_grid is not grid:
                t0 = time.perf_counter()
                try:
                    path = plan_astar.plan(prob.start, prob.goal)
                except PlanningError:  # an end in a keep-out place: A*'s own path
                    pass
                ms = (time.perf_counter() - t0) * 1e3
            shaped((ASTAR_LANES, ASTAR_LANES), path, ms)
    for name, (sd, hd, net, laned) in planners.items():
        gen, net_gen = torch.Generator(), torch.Generator()
        rules, laned_rules = [], []
        for k, prob in enumerate(tqdm(problems, desc=f"{name}: SD, ECAHD, net",
                                      disable=not progress, leave=False)):
            gen.manual_seed(problem_seed(settings.sample_seed, k))
            t0 = time.perf_counter()
            waypoints = sd.plan(prob.start, prob.goal, generator=gen).waypoints
            record((name, "SD"), waypoints, (time.perf_counter() - t0) * 1e3)
            gen.manual_seed(problem_seed(settings.sample_seed, k))
            net_gen.manual_seed(problem_seed(settings.sample_seed + 1, k))
            t0 = time.perf_counter()
            plan = hd.plan(prob.start, prob.goal, generator=gen)
            ms = (time.perf_counter() - t0) * 1e3
            record((name, "ECAHD"), plan.trajectory, ms)
            safe = net.apply(np.asarray(plan.trajectory, dtype=np.float64),
                             segments=plan.segments, generator=net_gen)
            record((name, "ECAHD + net"), safe.path, ms + safe.time_ms)
            rules.append(safe.rule)
            if laned is not None:
                gen.manual_seed(problem_seed(settings.sample_seed, k))
                net_gen.manual_seed(problem_seed(settings.sample_seed + 1, k))
                t0 = time.perf_counter()
                plan = laned[0].plan(prob.start, prob.goal, generator=gen)
                ms = (time.perf_counter() - t0) * 1e3
                safe = laned[1].apply(np.asarray(plan.trajectory, dtype=np.float64),
                                      segments=plan.segments, generator=net_gen)
                shaped((name, LANES), safe.path, ms + safe.time_ms)
                laned_rules.append(safe.rule)
        fallbacks[name] = 100.0 * float(np.mean([r == "fallback" for r in rules]))
        if laned_rules:
            fallbacks[(name, LANES)] = 100.0 * float(np.mean([r == "fallback"
                                                               for r in laned_rules]))
        log.info("%s: %d pairs planned in %.0f s", name, len(problems),
                 sum(times[(name, "SD")] + times[(name, "ECAHD + net")]) / 1e3)

    rows = []
    checkpoints = dict(models)
    planners_rows = PLANNERS + ((LANES,) if field is not None else ())
    keys = ([(OPERATOR, OPERATOR), (ASTAR, ASTAR)]
            + ([(ASTAR_LANES, ASTAR_LANES)] if field is not None else [])
            + [(n, p) for n in planners for p in planners_rows])
    for key in keys:
        model, planner = key
        judged = judge_paths(paths[key], problems, fp, grid)
        free, success, ratio = judged.free, judged.success, judged.ratio
        habit = habit_metrics(paths[key], grid, fp, zones)
        ms = np.asarray(times[key])
        rows.append(HabitRow(
            model=model, planner=planner, checkpoint=checkpoints.get(model),
            problems=len(problems), right=_percent(habit.right_share),
            corridor_m=round(habit.corridor_length, 2),
            zone=_percent(habit.zone_share) if zones else None,
            collision_free=100 * float(free.mean()), success=100 * float(success.mean()),
            success_free=100 * float((free & success).mean()), length_ratio=float(ratio.mean()),
            time_ms_median=float(np.median(ms)), time_ms_p95=float(np.percentile(ms, 95)),
            fallback=(fallbacks[model] if planner == "ECAHD + net"
                      else fallbacks[key] if planner == LANES else None),
            shaped=(100 * float(np.mean([a for a, _ in shaping[key]]))
                    if key in shaping else None),
            shape_dropped=(100 * float(np.mean([b for _, b in shaping[key]]))
                           if key in shaping else None),
            free_by_problem=[bool(f) for f in free],
            time_ms_by_problem=[round(float(t), 2) for t in ms]))
    pairs = [[[round(float(v), 4) for v in p.start], [round(float(v), 4) for v in p.goal]]
             for p in problems]
    return HabitsBenchResult(settings=settings, map_name=grid.name, rows=rows, pairs=pairs,
                             paths=paths, grid=grid, seconds=time.perf_counter() - t_start)


def _cell(v, nd=1) -> str:
    return "–" if v is None else f"{v:.{nd}f}"


def format_table(result: HabitsBenchResult) -> str:
    """The markdown table: the operator (the target), A*, then each model's three rows."""
    s = result.settings
    zones, lanes = s.zones is not None, s.lanes is not None
    lines = [f"Habits on {result.map_name}: {len(result.pairs)} held-out start/goal pairs (seed "
             f"{s.seed}), robot {s.robot}, operator habit {s.habit}"
             + (f", zones of {s.zones}" if zones else "")
             + (f", lanes of {Path(s.lanes).name}" if lanes else "")
             + f", sampling seed {s.sample_seed} per problem, DD {s.dd_model or 'the map’s'}, "
             f"{result.seconds / 60:.1f} min. Right half: share of the corridor length on the "
             f"right half (corridors wider than twice the robot, at most 4 m)"
             + ("; in a zone: share of plans entering a zone" if zones else "") + ".", "",
             "| model | planner | right half % | corridor m |"
             + (" in a zone % |" if zones else "")
             + " collision-free % | success % | success & free % | length / A* "
             "| time median ms | time p95 ms | A* fallback % |"
             + (" shaped % | shaped, collided % |" if lanes else ""),
             "|---|---|---|---|" + ("---|" if zones else "") + "---|---|---|---|---|---|---|"
             + ("---|---|" if lanes else "")]
    for r in result.rows:
        name = {OPERATOR: "operator (target)", ASTAR: "A* (expert)",
                ASTAR_LANES: "A* + lanes"}.get(r.model, r.model)
        planner = "–" if r.model in (OPERATOR, ASTAR, ASTAR_LANES) else r.planner
        lines.append(f"| {name} | {planner} | {_cell(r.right)} | {r.corridor_m:.0f} |"
                     + (f" {_cell(r.zone)} |" if zones else "")
                     + f" {r.collision_free:.1f} | {r.success:.1f} | {r.success_free:.1f} | "
                     f"{r.length_ratio:.3f} | {r.time_ms_median:.0f} | {r.time_ms_p95:.0f} | "
                     f"{_cell(r.fallback)} |"
                     + (f" {_cell(r.shaped)} | {_cell(r.shape_dropped)} |" if lanes else ""))
    return "\n".join(lines)


def plot_habits(result: HabitsBenchResult, path) -> Path:
    """The first ``figure_problems`` pairs on the map: one panel with A* (dashed) and the
    operator (solid), then one per model with ECAHD + net (solid) and SD's waypoints (dotted);
    one colour per pair, two panels a row. Written by rename (no half-written file)."""
    from ecahd_core.scenario import read_zones
    from ecahd_core.viz import draw_map, pyplot

    s, grid = result.settings, result.grid
    k = min(s.figure_problems, len(result.pairs))
    zones = read_zones(s.zones) if s.zones else []
    names = [n for n, _ in s.models]
    plt = pyplot()
    xmin, ymin, xmax, ymax = grid.bounds
    aspect = (ymax - ymin) / max(xmax - xmin, 1e-9)
    panels = 1 + len(names)
    cols = 2 if panels > 2 else panels  # two panels a row: a building map stays readable
    rows = -(-panels // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(7.0 * cols, (7.0 * aspect + 0.5) * rows + 0.4),
                             squeeze=False)
    axes = axes.ravel()
    for ax in axes[panels:]:
        ax.axis("off")
    colours = plt.get_cmap("tab10").colors

    def panel(ax, title, solid, dotted=None, dashed=None):
        draw_map(ax, grid)
        for z in zones:
            ax.fill(z.polygon[:, 0], z.polygon[:, 1], facecolor=(0.9, 0.2, 0.2, 0.25),
                    edgecolor="tab:red", hatch="//", lw=1.0)
        for i in range(k):
            c = colours[i % len(colours)]
            if dashed is not None:
                ax.plot(dashed[i][:, 0], dashed[i][:, 1], "--", color=c, lw=1.0, alpha=0.8)
            if dotted is not None:
                ax.plot(dotted[i][:, 0], dotted[i][:, 1], ":o", color=c, lw=0.9, ms=2.5,
                        alpha=0.8)
            ax.plot(solid[i][:, 0], solid[i][:, 1], color=c, lw=1.5)
            (sx, sy), (gx, gy) = result.pairs[i]
            ax.plot(sx, sy, "s", color=c, mec="k", ms=6)
            ax.plot(gx, gy, "*", color=c, mec="k", ms=11)
        ax.set_title(title, fontsize=9)

    op, a = result.row(OPERATOR, OPERATOR), result.row(ASTAR, ASTAR)
    panel(axes[0], f"operator, solid ({_cell(op.right, 0)}% right); A*, dashed "
                      f"({_cell(a.right, 0)}% right)",
          result.paths[(OPERATOR, OPERATOR)], dashed=result.paths[(ASTAR, ASTAR)])
    for ax, name in zip(axes[1:], names):
        net, sd = result.row(name, "ECAHD + net"), result.row(name, "SD")
        if s.lanes:  # solid: with the lanes; dashed: ECAHD + net without them
            ln = result.row(name, LANES)
            panel(ax, f"{name}: ECAHD + net + lanes, solid ({_cell(ln.right, 0)}% right, "
                      f"{ln.collision_free:.0f}% free); without lanes, dashed "
                      f"({_cell(net.right, 0)}% right)",
                  result.paths[(name, LANES)], dashed=result.paths[(name, "ECAHD + net")])
            continue
        panel(ax, f"{name}: ECAHD + net, solid ({_cell(net.right, 0)}% right, "
                  f"{net.collision_free:.0f}% free); SD, dotted ({_cell(sd.right, 0)}% right)",
              result.paths[(name, "ECAHD + net")], dotted=result.paths[(name, "SD")])
    fig.suptitle(f"{k} of the {len(result.pairs)} pairs (square: start, star: goal); right: "
                 f"over all pairs", fontsize=9)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    os.replace(tmp, path)
    return path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ecahd_core.maps import DEFAULT_MAP

    d = HabitsBenchSettings(map=DEFAULT_MAP, models=())
    parser.add_argument("--map", required=True,
                        help="the map the models were trained on: a built-in map, a Nav2 YAML "
                             "or KIND:WxH:RES:SEED")
    parser.add_argument("--models", nargs="+", required=True, metavar="NAME=CKPT",
                        help=f"1 to {MAX_MODELS} SD checkpoints of the map, each named "
                             "(e.g. astar=a.pt demos=d.pt mix=m.pt; 'general': the generalist)")
    parser.add_argument("--dd-model", default=None, metavar="CKPT",
                        help="DD's checkpoint for every model's ECAHD (default: the map's own, "
                             "else the shipped generalist)")
    parser.add_argument("--habit", choices=HABITS, default=d.habit,
                        help="the operator's habit, the target row (as ecahd record-demos)")
    parser.add_argument("--zones", default=None, metavar="SCENARIO",
                        help="scenario YAML with a 'zones:' list: the share of plans entering "
                             "one is measured, and the operator avoids them")
    parser.add_argument("--robot", default=d.robot, choices=("circle", "quadruped", "humanoid"))
    parser.add_argument("--problems", type=int, default=d.problems, metavar="N",
                        help="held-out start/goal pairs")
    parser.add_argument("--seed", type=int, default=d.seed, help="seed of the pairs")
    parser.add_argument("--sample-seed", type=int, default=d.sample_seed,
                        help="seed of the samples (each problem its own: (seed, index))")
    parser.add_argument("--png", metavar="FILE",
                        help="the first pairs planned by A*, the operator and each model")
    parser.add_argument("--figure-problems", type=int, default=d.figure_problems, metavar="K",
                        help="pairs drawn by --png")
    parser.add_argument("--lanes", metavar="FIELD", default=None,
                        help="a lane field of the map (`ecahd lanes`): adds the rows with "
                             "plans moved onto it (ECAHD + net + lanes, A* + lanes)")
    parser.add_argument("--json", metavar="FILE", help="also write every row as JSON")
    parser.add_argument("--md", metavar="FILE", help="also write the table as markdown")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")


def run(args: argparse.Namespace) -> int:
    from ecahd_core.bench.output import write_json

    settings = HabitsBenchSettings(
        map=args.map, models=parse_models(args.models), problems=args.problems, seed=args.seed,
        sample_seed=args.sample_seed, robot=args.robot, habit=args.habit, zones=args.zones,
        dd_model=args.dd_model, figure_problems=args.figure_problems, lanes=args.lanes)
    result = run_habits_benchmark(settings, progress=not args.no_progress)
    table = format_table(result)
    print(table)
    if args.md:
        Path(args.md).write_text(table + "\n")
    if args.json:
        write_json(args.json, result.to_dict())
    if args.png:
        print(f"figure: {plot_habits(result, args.png)}")
    return 0
