"""``ecahd bench planning``: the paper's Table I (and Table II's ablation) on our models.

Every method x {without, with guidance} x robot on the same held-out problems
(``ecahd_core.problems``). Per problem the *executed* path is judged: FD's 100 points, SD's
waypoints joined by straight lines, HD/ECAHD's local plans joined end to end, A*'s path.

Metrics per cell:
- ``success``: some point of the path within 1.0 m of the goal (the paper's rule);
- ``success_final``: the final point within 0.5 m of the goal;
- ``success_free``: ``success`` and collision-free (what a robot following the path gets);
- ``collision_free``: fraction of paths the exact checker finds collision-free;
- ``collision_rate``: mean penetration fraction (share of densely interpolated poses whose
  footprint overlaps an obstacle), in %;
- ``length_ratio``: mean path length / A* path length (same clearance-respecting A*);
- ``time_ms_mean`` / ``time_ms_median`` / ``time_ms_p95``: planning wall time per problem;
- ``dd_ratio``: share of local segments where DD fired (HD methods).

``warm_fraction`` (``--warm-fraction``, ours): HD's every-waypoint re-plans start from the rest
of the previous plan and run only that share of the DDIM schedule (``SparseConfig.warm_fraction``;
0 samples every re-plan from noise, Algorithm 1 as written). SD alone plans once per problem,
so it is unaffected.

The safety net (ours, ``ecahd_core.safety``; ``safety_net``, default on) is judged beside the HD
cells, not instead of them: every HD / ECAHD path above is also handed to the net (its DD retries
draw from their own generator, so the rows without the net keep their numbers) and the ``net_*``
fields give the same problems with the net: collision-free and success & free after it, the share
of plans where retries / the A* fallback acted or no safe plan existed, and the time per plan with
the net (planning + net).
"""
from __future__ import annotations

import logging
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from ecahd_core.maps import DEFAULT_MAP
from ecahd_core.errors import EcahdError
from ecahd_core.placement import BACKTRACKS, LEG_BATCHES

log = logging.getLogger(__name__)

METHODS = ("fd", "sd", "hd", "astar")
ROBOTS = ("circle", "quadruped", "humanoid")
METHOD_LABELS = {"fd": "FD", "sd": "SD", "hd": "HD", "astar": "A*"}

# Paper Table I (maze2d-large, 128 problems, A100): success %, collision rate %, time s
PAPER_TABLE_I = {
    ("fd", False): {"success": {"circle": 91.41, "quadruped": 85.94, "humanoid": 81.25},
                    "collision_rate": {"circle": 0.06165, "quadruped": 0.07513, "humanoid": 0.08923},
                    "time_s": 2.762},
    ("fd", True): {"success": {"circle": 64.84, "quadruped": 69.53, "humanoid": 67.97},
                   "collision_rate": {"circle": 0.05004, "quadruped": 0.04689, "humanoid": 0.04370},
                   "time_s": 11.881},
    ("sd", False): {"success": {"circle": 90.63, "quadruped": 89.84, "humanoid": 85.94},
                    "collision_rate": {"circle": 0.08646, "quadruped": 0.11323, "humanoid": 0.11358},
                    "time_s": 1.449},
    ("sd", True): {"success": {"circle": 83.59, "quadruped": 80.47, "humanoid": 84.38},
                   "collision_rate": {"circle": 0.03983, "quadruped": 0.04197, "humanoid": 0.04112},
                   "time_s": 2.443},
    ("hd", False): {"success": {"circle": 86.72, "quadruped": 87.50, "humanoid": 92.97},
                    "collision_rate": {"circle": 0.04452, "quadruped": 0.05840, "humanoid": 0.05401},
                    "time_s": 1.484},
    ("hd", True): {"success": {"circle": 89.06, "quadruped": 89.06, "humanoid": 84.43},
                   "collision_rate": {"circle": 0.03365, "quadruped": 0.03516, "humanoid": 0.03534},
                   "time_s": 1.527},
}
# Paper Table II (circle robot): success %, collision rate %
PAPER_TABLE_II = {("line", False): (89.06, 0.4675), ("line", True): (87.50, 0.4372),
                  ("surface", False): (94.53, 0.0363), ("surface", True): (98.44, 0.1320)}


@dataclass(frozen=True, kw_only=True)
class PlanningBenchSettings:
    map: str = DEFAULT_MAP
    problems: int = 128
    seed: int = 2026
    sample_seed: int = 0
    # each problem's sampling from its own seed (sample_seed, problem index): a rule that changes
    # how many samples one problem draws leaves the others' draws alone (paired comparisons)
    per_problem_seeds: bool = False
    robots: tuple[str, ...] = ROBOTS
    methods: tuple[str, ...] = METHODS
    candidates: int = 10
    selection: str = "collision_aware"  # ours; "shortest_reaching" is Sec. III-A's rule
    guidance_weight: float = 0.03  # DenseConfig's default
    guidance_space: str = "x0"  # DenseConfig's default
    margin: float | None = None  # [m] the cost map's (None: by the map, costmap.auto_margin)
    c_th: float = 0.1
    dd_retries: int = 0
    polish_steps: int = 30  # DenseConfig's default; 0 = the paper's Algorithm 1
    polish_across: bool = True  # DenseConfig's default; False: points move along paths too
    keep_better: bool = True  # DenseConfig's default; False = the paper's Algorithm 1
    exact_rule: bool = True  # ours: HierarchicalPlanner.exact_check (not on Table II's variants)
    replan: str = "every_waypoint"
    max_spacing: float | None = None  # [m] SparseConfig.max_spacing (None: off)
    place_reach: float | None = None  # [m] placement.placer_for (0: off; None: by map size)
    # SparseConfig.warm_fraction: HD's warm-started re-plans (0: off; -1: by the map, building
    # maps 0.3)
    warm_fraction: float = -1.0
    replan_spacing: float | None = None  # [m] HierarchicalPlanner's (None: by the map; 0: off)
    precision: str = "fp32"  # the SD Transformer's inference precision (SparseConfig.precision)
    sd_steps: int | None = None  # SD's DDIM steps (SparseConfig.num_steps; None: the model's)
    leg_batches: int = LEG_BATCHES  # SparseConfig.leg_batches: a free first leg (-1: off)
    backtracks: int = BACKTRACKS  # HierarchicalPlanner's backtracking rounds (0: off)
    subgoals: bool = True  # HierarchicalPlanner's subgoal rule
    settle: bool = True  # HierarchicalPlanner's settle rule
    shortcut: bool = True  # HierarchicalPlanner's shortcut rule
    ablation: bool = True
    guidance: str = "both"  # diffusion methods with and without guidance, or "on" / "off" only
    safety_net: bool = True  # ours: judge HD / ECAHD with and without the net (ecahd_core.safety)
    net_retries: int = 2  # SafetyNetConfig's default
    net_resamples: int = 2  # SafetyNetConfig's default (0: the net skips its resample rule)
    sd_model: str | None = None  # SD's checkpoint (None: the map's; "general": the generalist)
    dd_model: str | None = None  # DD's checkpoint (None: the map's; "general": segment-frame)


GUIDANCE_RUNS = {"both": (False, True), "on": (True,), "off": (False,)}


@dataclass
class CellResult:
    method: str
    guidance: bool
    robot: str
    success: float
    success_final: float
    success_free: float
    collision_free: float
    collision_rate: float
    length_ratio: float
    time_ms_mean: float
    time_ms_median: float
    time_ms_p95: float
    dd_ratio: float
    problems: int
    variant: str = ""  # Table II: cost mode (+ dilation)
    exact_rule_rate: float | None = None  # HD: % of plans where the exact rule acted
    first_leg_rate: float | None = None  # HD: % of plans where SD's free-first-leg rule acted
    backtrack_rate: float | None = None  # HD: % of plans where backtracking took a candidate
    subgoal_rate: float | None = None  # HD: % of plans where the subgoal rule drew a re-plan
    settle_rate: float | None = None  # HD: % of plans where the settle rule followed an SD plan
    # the same paths through the safety net (HD cells when settings.safety_net; None otherwise)
    net_collision_free: float | None = None  # % after the net
    net_success_free: float | None = None
    net_retry_rate: float | None = None  # % of plans where DD retries made the plan free
    net_resample_rate: float | None = None  # % of plans drawn again, then free
    net_fallback_rate: float | None = None  # % of plans with A* stretches spliced in
    net_unsafe_rate: float | None = None  # % of plans with no safe plan
    net_time_ms_mean: float | None = None  # planning + net
    net_time_ms_p95: float | None = None
    net_time_ms_median: float | None = None
    # per problem, in order: collision-free by the exact checker (before the net), and the
    # plan's time [ms], for paired comparisons of two runs on the same problems
    free_by_problem: list = field(default_factory=list)
    time_ms_by_problem: list = field(default_factory=list)
    length_ratio_by_problem: list = field(default_factory=list)  # path length / A*'s
    room_by_problem: list = field(default_factory=list)  # [m] least room (least_room)
    # with the net: collision-free and the rule that acted last, per problem (None: no net)
    net_free_by_problem: list | None = None
    net_rule_by_problem: list | None = None
    net_time_ms_by_problem: list | None = None

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class PlanningBenchResult:
    cells: list[CellResult]
    ablation: list[CellResult]
    examples: dict = field(default_factory=dict)  # (method, guidance, robot) -> first 4 paths
    problems: list = field(default_factory=list)  # the first 4 problems (for the figures)
    context: dict = field(default_factory=dict)


SUCCESS_RADIUS = 1.0  # [m] a plan succeeds with a point this close to the goal (the paper's)
FINAL_RADIUS = 0.5  # [m] ... and ends this close to it (success_final)


@dataclass(frozen=True)
class PathJudgement:
    """How plans did on their problems, each (n,): ``success`` (a point within SUCCESS_RADIUS
    of the goal), ``final`` (the last point within FINAL_RADIUS), ``free`` (collision-free by
    the exact checker), ``penetration`` (its share of poses in contact), ``ratio`` (length
    over the problem's A* length), ``room`` [m] (the least room beside the footprint along the
    path, :func:`least_room`)."""

    success: np.ndarray
    final: np.ndarray
    free: np.ndarray
    penetration: np.ndarray
    ratio: np.ndarray
    room: np.ndarray


ROOM_STEP = 0.01  # [m] least_room samples a path this finely


def least_room(path, footprint, grid) -> float:
    """The least room [m] beside ``footprint`` along ``path`` (N, 2) [m]: over points every
    ROOM_STEP along its legs, the exact distance to the nearest occupied cell's square (off the
    map counts as occupied) less the footprint's inscribed radius: the room a robot has beside
    it in any heading, its margin for tracking error (<= 0 where the inscribed circle touches a
    wall, which for a non-round footprint need not be a collision)."""
    from ecahd_core.collision import wall_distance

    path = np.asarray(path, dtype=np.float64).reshape(-1, 2)
    legs = np.diff(path, axis=0)
    n = np.maximum(1, np.ceil(np.linalg.norm(legs, axis=1) / ROOM_STEP).astype(int))
    pts = np.concatenate([path[:1]] + [path[i] + legs[i] * (np.arange(1, k + 1) / k)[:, None]
                                       for i, k in enumerate(n)])
    res, h = grid.resolution, 0.5 * grid.resolution
    # the distance field (cell centre to cell centre) is within a cell of the exact distance:
    # only points within two cells of its least value can hold the least exact distance
    approx = wall_distance(grid, pts)
    near = approx <= approx.min() + 2 * res
    pts, approx = pts[near], approx[near]
    occ = np.pad(grid.occupied, 1, constant_values=True)  # (H + 2, W + 2): the edge is a wall
    # [cells] round each point: the nearest square's centre lies within the distance field's
    # value + a cell + two half cell diagonals of the point's cell centre
    reach = int(np.ceil(approx.max() / res)) + 3
    rows, cols = grid.world_to_cell(pts)
    dr, dc = np.meshgrid(np.arange(-reach, reach + 1), np.arange(-reach, reach + 1),
                         indexing="ij")
    best = np.inf
    for chunk in range(0, len(pts), 256):
        r = np.clip(rows[chunk:chunk + 256, None] + dr.ravel() + 1, 0, occ.shape[0] - 1)
        c = np.clip(cols[chunk:chunk + 256, None] + dc.ravel() + 1, 0, occ.shape[1] - 1)
        centre = grid.cell_to_world(r - 1, c - 1)  # (K, M, 2) the cells' centres
        gap = np.maximum(np.abs(pts[chunk:chunk + 256, None] - centre) - h, 0.0)
        d = np.where(occ[r, c], np.hypot(gap[..., 0], gap[..., 1]), np.inf)
        best = min(best, float(d.min()))
    return best - footprint.inscribed_radius


def judge_paths(paths, problems, footprint, grid) -> PathJudgement:
    """Judge plans [(N_i, 2) [m]] on their problems (each with ``goal`` (2,) and
    ``astar_length`` [m]) for ``footprint`` on ``grid``, as every planning benchmark does."""
    from ecahd_core.collision import check_collision

    succ, fin, free, pen, ratio, room = [], [], [], [], [], []
    for path, prob in zip(paths, problems):
        path = np.asarray(path, dtype=np.float64).reshape(-1, 2)
        d = np.linalg.norm(path - prob.goal, axis=1)
        rep = check_collision(path, footprint, grid)
        succ.append(bool(d.min() <= SUCCESS_RADIUS))
        fin.append(bool(d[-1] <= FINAL_RADIUS))
        free.append(rep.collision_free)
        pen.append(rep.penetration_fraction)
        ratio.append(float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
                     / max(prob.astar_length, 1e-9))
        room.append(least_room(path, footprint, grid))
    return PathJudgement(success=np.array(succ, dtype=bool), final=np.array(fin, dtype=bool),
                         free=np.array(free, dtype=bool), penetration=np.array(pen),
                         ratio=np.array(ratio), room=np.array(room))


def _judge(paths, times, dd, problems, footprint, grid, *, method, guidance, robot, variant=""):
    j = judge_paths(paths, problems, footprint, grid)
    succ, fin, free, pen, ratio, ok_free = (j.success, j.final, j.free, j.penetration, j.ratio,
                                            j.success & j.free)
    return CellResult(method=method, guidance=guidance, robot=robot, variant=variant,
                      success=100 * float(np.mean(succ)), success_final=100 * float(np.mean(fin)),
                      success_free=100 * float(np.mean(ok_free)),
                      collision_free=100 * float(np.mean(free)),
                      collision_rate=100 * float(np.mean(pen)),
                      length_ratio=float(np.mean(ratio)),
                      time_ms_mean=float(np.mean(times)), time_ms_median=float(np.median(times)),
                      time_ms_p95=float(np.percentile(times, 95)),
                      dd_ratio=float(np.mean(dd)) if dd else 0.0, problems=len(problems),
                      free_by_problem=[bool(f) for f in free],
                      time_ms_by_problem=[round(float(t), 2) for t in times],
                      length_ratio_by_problem=[round(float(r), 4) for r in ratio],
                      room_by_problem=[round(float(r), 4) for r in j.room])


def problem_seed(seed: int, index: int) -> int:
    """The sampling seed of problem ``index`` under ``per_problem_seeds`` (one 63-bit number per
    (seed, index) pair)."""
    return (int(seed) * 1_000_003 + int(index)) % (2 ** 63)


def run_planning_benchmark(settings: PlanningBenchSettings, *, progress: bool = True
                           ) -> PlanningBenchResult:
    import torch
    from tqdm import tqdm

    if settings.guidance not in GUIDANCE_RUNS:
        raise EcahdError(f"guidance must be one of {list(GUIDANCE_RUNS)}, got "
                         f"{settings.guidance!r}")

    from ecahd_core.astar import clearance_for_footprint, planner_for
    from ecahd_core.cost import CollisionCost, CostConfig
    from ecahd_core.footprint import make_footprint
    from ecahd_core.bench.replan import load_bench_map
    from ecahd_core.model_zoo import load_model
    from ecahd_core.placement import auto_reach
    from ecahd_core.planning.full import FullDiffusion
    from ecahd_core.planning.dense import DenseConfig, guidance_weight_for
    from ecahd_core.planning.hierarchical import HierarchicalPlanner
    from ecahd_core.planning.sparse import SparseConfig, SparseDiffusion
    from ecahd_core.problems import make_problems
    from ecahd_core.safety import SafetyNet, SafetyNetConfig

    grid = load_bench_map(settings.map)
    from ecahd_core.model_zoo import is_general

    place_reach = (auto_reach(grid, general=is_general("sd", settings.sd_model, grid.name))
                   if settings.place_reach is None else settings.place_reach)  # what "auto" chose
    margin = CostConfig.for_map(grid, margin=settings.margin).margin
    spacings = {}  # robot -> the re-plan spacing its ECAHD cells used [m] (None: off)
    problems = make_problems(grid, settings.problems, seed=settings.seed)
    cells, ablation, examples = [], [], {}
    astars = {}  # robot -> AStarPlanner: one clearance mask per map and robot, reused

    def astar_for(robot, fp):
        if robot not in astars:
            astars[robot] = planner_for(grid, clearance_for_footprint(fp))
        return astars[robot]

    def run_cell(method, guidance, robot, cost_config=None, variant=""):
        fp = make_footprint(robot)
        cost = CollisionCost.build(grid, fp, cost_config or CostConfig(margin=margin))
        gen = torch.Generator().manual_seed(settings.sample_seed)
        net = None
        if method == "astar":
            astar = astar_for(robot, fp)
            plan_fn = lambda s, g: (astar.plan(s, g), None)  # noqa: E731
        elif method == "fd":
            fd = FullDiffusion(load_model("fd", grid, footprint=fp), guidance=guidance, cost=cost,
                               guidance_weight=settings.guidance_weight,
                               guidance_space=settings.guidance_space)
            plan_fn = lambda s, g: (fd.plan(s, g, generator=gen), None)  # noqa: E731
        else:
            sd = SparseDiffusion.for_map(grid, fp, SparseConfig(
                num_candidates=settings.candidates, selection=settings.selection,
                guidance=(method == "sd" and guidance),
                guidance_weight=settings.guidance_weight,
                guidance_space=settings.guidance_space,
                warm_fraction=settings.warm_fraction, max_spacing=settings.max_spacing,
                precision=settings.precision, leg_batches=settings.leg_batches,
                num_steps=settings.sd_steps),
                cost=cost, place_reach=settings.place_reach, model=settings.sd_model)
            if method == "sd":
                plan_fn = lambda s, g: (sd.plan(s, g, generator=gen).waypoints, None)  # noqa: E731
            else:
                hd = HierarchicalPlanner.for_map(
                    grid, fp, sd, dense=DenseConfig(
                        c_th=settings.c_th, guidance=guidance,
                        guidance_weight=settings.guidance_weight,
                        guidance_space=settings.guidance_space, retries=settings.dd_retries,
                        polish_steps=settings.polish_steps,
                        polish_across=settings.polish_across, keep_better=settings.keep_better),
                    replan=settings.replan, replan_spacing=settings.replan_spacing,
                    backtracks=settings.backtracks, subgoals=settings.subgoals,
                    settle=settings.settle, shortcut=settings.shortcut,
                    exact=settings.exact_rule and not variant,
                    model=settings.dd_model)
                spacings[robot] = hd.replan_spacing

                last = []  # the last HierarchicalPlan, for the net's retries

                def plan_fn(s, g):
                    r = hd.plan(s, g, generator=gen)
                    last[:] = [r]
                    return r.trajectory, r.dd_segments

                if settings.safety_net and not variant:
                    net = SafetyNet(grid, fp, SafetyNetConfig(
                        retries=settings.net_retries, resamples=settings.net_resamples),
                                    planner=hd, astar=astar_for(robot, fp))
                    net_gen = torch.Generator().manual_seed(settings.sample_seed + 1)
        paths, times, dd, kept, switched, backtracked, subgoaled, settled = ([] for _ in range(8))
        net_paths, net_times, net_rules = [], [], []
        label = f"{METHOD_LABELS[method]}{' guided' if guidance else ''} {robot} {variant}".strip()
        for k, prob in enumerate(tqdm(problems, desc=label, disable=not progress, leave=False)):
            if settings.per_problem_seeds:
                gen.manual_seed(problem_seed(settings.sample_seed, k))
                if net is not None:
                    net_gen.manual_seed(problem_seed(settings.sample_seed + 1, k))
            t0 = time.perf_counter()
            path, dd_segs = plan_fn(prob.start, prob.goal)
            times.append((time.perf_counter() - t0) * 1e3)
            paths.append(np.asarray(path, dtype=np.float64))
            if dd_segs is not None:
                dd.extend(dd_segs)
                kept.append(any(last[0].exact_kept))
                switched.append(last[0].first_leg_changed)
                backtracked.append(last[0].backtracked > 0)
                subgoaled.append(last[0].subgoals > 0)
                settled.append(last[0].settled is not None)
            if net is not None:  # the same path through the net, timed on its own
                safe = net.apply(paths[-1], segments=last[0].segments, generator=net_gen)
                net_paths.append(safe.path)
                net_times.append(times[-1] + safe.time_ms)
                net_rules.append(safe.rule)
        cell = _judge(paths, times, dd, problems, fp, grid, method=method, guidance=guidance,
                      robot=robot, variant=variant)
        if kept:
            cell.exact_rule_rate = 100 * float(np.mean(kept))
            cell.first_leg_rate = 100 * float(np.mean(switched))
            cell.backtrack_rate = 100 * float(np.mean(backtracked))
            cell.subgoal_rate = 100 * float(np.mean(subgoaled))
            cell.settle_rate = 100 * float(np.mean(settled))
        if net is not None:
            after = _judge(net_paths, net_times, dd, problems, fp, grid, method=method,
                           guidance=guidance, robot=robot)
            rate = lambda rule: 100 * float(np.mean([r == rule for r in net_rules]))  # noqa: E731
            cell.net_collision_free, cell.net_success_free = after.collision_free, after.success_free
            cell.net_retry_rate, cell.net_fallback_rate = rate("retry"), rate("fallback")
            cell.net_resample_rate = rate("resample")
            cell.net_unsafe_rate = rate("unsafe")
            cell.net_time_ms_mean, cell.net_time_ms_p95 = after.time_ms_mean, after.time_ms_p95
            cell.net_time_ms_median = after.time_ms_median
            cell.net_free_by_problem, cell.net_rule_by_problem = after.free_by_problem, net_rules
            cell.net_time_ms_by_problem = after.time_ms_by_problem
            log.info("%s with the safety net: collision-free %.1f%%, retry %.1f%%, resample "
                     "%.1f%%, fallback %.1f%%, unsafe %.1f%%, %.0f ms", label,
                     cell.net_collision_free, cell.net_retry_rate, cell.net_resample_rate,
                     cell.net_fallback_rate, cell.net_unsafe_rate, cell.net_time_ms_mean)
        return cell, paths

    for robot in settings.robots:
        for method in settings.methods:
            for guidance in ((False,) if method == "astar" else GUIDANCE_RUNS[settings.guidance]):
                cell, paths = run_cell(method, guidance, robot)
                cells.append(cell)
                examples[(method, guidance, robot)] = paths[:4]
    if settings.ablation and "hd" in settings.methods:
        from ecahd_core.footprint import make_footprint as _mf

        radius = _mf("circle").circumscribed_radius
        for mode in ("point", "line", "surface"):
            for dilation in (0.0, radius):
                cc = CostConfig(mode=mode, dilation=dilation, margin=margin)
                variant = f"{mode}{' + dilation' if dilation else ''}"
                cell, _ = run_cell("hd", True, "circle", cost_config=cc, variant=variant)
                ablation.append(cell)
    context = {"map": grid.name, "map_source": settings.map, "problems": len(problems),
               "seed": settings.seed,
               "sample_seed": settings.sample_seed, "candidates": settings.candidates,
               "per_problem_seeds": settings.per_problem_seeds,
               "selection": settings.selection,
               "guidance_weight": settings.guidance_weight, "c_th": settings.c_th,
               "dd_guidance_weight": guidance_weight_for(settings.guidance_weight, margin),
               "guidance_space": settings.guidance_space, "margin": margin,
               "dd_retries": settings.dd_retries, "polish_steps": settings.polish_steps,
               "polish_across": settings.polish_across,
               "keep_better": settings.keep_better, "exact_rule": settings.exact_rule,
               "leg_batches": settings.leg_batches, "backtracks": settings.backtracks,
               "subgoals": settings.subgoals,
               "settle": settings.settle, "shortcut": settings.shortcut,
               "replan": settings.replan, "warm_fraction": settings.warm_fraction,
               # one number when every robot's model asked for the same, else per robot
               "replan_spacing": (next(iter(spacings.values()))
                                  if len(set(spacings.values())) == 1 else spacings or None),
               "max_spacing": settings.max_spacing, "place_reach": place_reach,
               "safety_net": settings.safety_net, "net_retries": settings.net_retries,
               "net_resamples": settings.net_resamples,
               "sd_model": settings.sd_model or "the map's",
               "dd_model": settings.dd_model or "the map's",
               "torch": torch.__version__,
               "threads": torch.get_num_threads()}
    return PlanningBenchResult(cells=cells, ablation=ablation, examples=examples,
                               problems=problems[:4], context=context)


def _fmt(v, nd=1):
    return "–" if v is None else f"{v:.{nd}f}"


def _spacing_text(spacing) -> str:
    """The context's replan_spacing, one number or {robot: number or None}, as text."""
    if isinstance(spacing, dict):
        return "robot (" + ", ".join(f"{robot} {'off' if v is None else f'{v:g} m'}"
                                     for robot, v in spacing.items()) + ")"
    return f"{spacing:g} m"


def format_markdown(r: PlanningBenchResult) -> str:
    """Table I layout (ours beside the paper's), the full per-cell table, and Table II."""
    from ecahd_core.planning.sparse import AUTO_WARM_FRACTION

    c = r.context
    # the free-first-leg rule (and backtracking with it) acts with placement, every_waypoint
    leg_rule = bool(c.get("place_reach") and c.get("leg_batches", -1) >= 0
                    and c["replan"] == "every_waypoint")
    cell = {(x.method, x.guidance, x.robot): x for x in r.cells}
    robots = [rb for rb in ROBOTS if any(k[2] == rb for k in cell)]
    cols = [(m, g) for m in ("fd", "sd", "hd") for g in (False, True) if (m, g, robots[0]) in cell]
    head = " | ".join(f"{METHOD_LABELS[m]} {'✓' if g else '×'}" + (" (ECAHD)" if (m, g) == ("hd", True) else "")
                      for m, g in cols)
    lines = [f"Planning on {c['map']}: {c['problems']} held-out problems (seed {c['seed']}), "
             f"sampling seed {c['sample_seed']}"
             + (" (each problem its own: (seed, index))" if c.get("per_problem_seeds") else "")
             + f", best of {c['candidates']} SD candidates "
             f"({c.get('selection', 'shortest_reaching')}), "
             f"omega {c['guidance_weight']} ({c['guidance_space']} space"
             + (f"; DD's x 0.1 m / margin = {c['dd_guidance_weight']:g}"
                if c.get("dd_guidance_weight", c["guidance_weight"]) != c["guidance_weight"]
                else "") + f"), c_th {c['c_th']}, "
             f"cost-map margin {c['margin']} m, DD retries {c['dd_retries']}, "
             f"polishing steps {c.get('polish_steps', 0)}"
             + (" (across the path)" if c.get("polish_across") else
                " (along the path too)" if c.get("polish_steps") else "") + ", "
             f"keep the straight plan when DD is worse: {c.get('keep_better', False)}, "
             f"exact rule: {c.get('exact_rule', False)}, "
             f"SD replanning {c['replan']}"
             + ((" warm-started by the map (building maps at "
                 f"{AUTO_WARM_FRACTION:g} of the schedule)" if c["warm_fraction"] == -1 else
                 f" warm-started at {c['warm_fraction']:g} of the schedule")
                if c.get("warm_fraction") and c["replan"] == "every_waypoint" else "")
             + (f", re-plans keep a waypoint per {_spacing_text(c['replan_spacing'])} left to "
                "the goal" if c.get("replan_spacing") and c["replan"] == "every_waypoint" else "")
             + (f", waypoints at most {c['max_spacing']:g} m apart (SD re-samples longer legs)"
                if c.get("max_spacing") else "")
             + (f", SD's waypoints in walls placed in free space within {c['place_reach']:g} m "
                "and legs crossing walls repaired" if c.get("place_reach") else "")
             + (f", a re-plan whose first leg still crosses a wall takes another candidate "
                f"(up to {c['leg_batches']} more batches)" if leg_rule else "")
             + (f", a re-plan whose local plan still collides takes another candidate (up to "
                f"{c['backtracks']} rounds)"
                if leg_rule and c.get("backtracks") and c.get("exact_rule") else "")
             + (", a re-plan loop past P^g - 1 iterations that makes no progress by the goal's "
                "cost-to-go plans toward a point along the shortest route"
                if leg_rule and c.get("subgoals") and c.get("replan_spacing")
                and c["replan"] == "every_waypoint" else "")
             + (", an SD plan whose every leg is free by the leg test is followed whole"
                if leg_rule and c.get("settle", False) and c.get("replan_spacing")
                and c["replan"] == "every_waypoint" else "")
             + ", "
             f"torch {c['torch']} with {c['threads']} thread(s). Each cell: ours / paper"
             + ("." if c["map"] == DEFAULT_MAP else
                " (the paper's figures are for maze2d-large, shown for scale only)."), "",
             f"| metric | robot | {head} |", "|---|---|" + "---|" * len(cols)]

    def row(metric, key, nd, paper_key):
        for rb in robots:
            vals = []
            for m, g in cols:
                ours = getattr(cell[(m, g, rb)], key)
                paper = PAPER_TABLE_I.get((m, g), {}).get(paper_key, {})
                paper = paper.get(rb) if isinstance(paper, dict) else None
                vals.append(f"{_fmt(ours, nd)} / {_fmt(paper, nd)}")
            lines.append(f"| {metric} | {rb} | " + " | ".join(vals) + " |")

    row("Success (%) ↑", "success", 1, "success")
    row("Collision rate (%) ↓", "collision_rate", 4, "collision_rate")
    times = []
    for m, g in cols:
        ours = np.mean([cell[(m, g, rb)].time_ms_mean for rb in robots]) / 1e3
        times.append(f"{ours:.3f} / {PAPER_TABLE_I[(m, g)]['time_s']:.3f}")
    lines.append("| Inference time (s) ↓ | mean | " + " | ".join(times) + " |")
    lines += ["", "All cells (A* is the classical reference; `success_free` = reaches the goal "
              "and is collision-free):", "",
              "| method | guidance | robot | success % | final ≤0.5 m % | success & free % | "
              "collision-free % | collision rate % | length / A* | time mean ms | time median ms | "
              "time p95 ms | DD ratio |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for x in r.cells:
        lines.append(f"| {METHOD_LABELS[x.method]} | {'✓' if x.guidance else '×'} | {x.robot} | "
                     f"{x.success:.1f} | {x.success_final:.1f} | {x.success_free:.1f} | "
                     f"{x.collision_free:.1f} | {x.collision_rate:.4f} | {x.length_ratio:.3f} | "
                     f"{x.time_ms_mean:.1f} | {x.time_ms_median:.1f} | {x.time_ms_p95:.1f} | "
                     f"{x.dd_ratio:.3f} |")
    netted = [x for x in r.cells if x.net_collision_free is not None]
    if netted:
        lines += ["", f"The safety net (ours, beyond the paper; DD retries "
                  f"{c.get('net_retries', '–')}, whole plans drawn again "
                  f"{c.get('net_resamples', 0)}, then A* for the offending stretches): the same "
                  "paths without / with the net. Retry, resample, fallback and unsafe: share of "
                  "plans where "
                  "that rule acted last. Exact rule: share of plans where the planner itself put "
                  "back a straight or unpolished local plan the exact checker finds free "
                  "(HierarchicalPlanner's exact_check; counted in ECAHD alone). First leg: share "
                  "of plans where a re-plan took another SD candidate, or one of a further "
                  "batch, because the selected one's first leg crossed a wall "
                  "(SparseConfig.leg_batches; counted in ECAHD alone). Backtrack: share of plans "
                  "where a re-plan whose local plan still collided took another SD candidate "
                  "(HierarchicalPlanner's backtracks; counted in ECAHD alone). Subgoal: share of "
                  "plans where a re-plan loop past P^g - 1 iterations drew SD toward a point "
                  "along the shortest route because its plan's first leg made no progress by the "
                  "goal's cost-to-go (HierarchicalPlanner's subgoals; SD draws the waypoints; "
                  "counted in ECAHD alone). Settle: share of plans where an SD plan whose every "
                  "leg was free by the leg test was followed whole instead of drawn again at "
                  "each waypoint (HierarchicalPlanner's settle; counted in ECAHD alone).", "",
                  "| method | guidance | robot | collision-free % | success & free % | exact rule % "
                  "| first leg % | backtrack % | subgoal % | settle % | retry % | resample % | "
                  "fallback % | unsafe % | time mean ms | time median ms | time p95 ms |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for x in netted:
            lines.append(
                f"| {METHOD_LABELS[x.method]}{' (ECAHD)' if x.guidance else ''} | "
                f"{'✓' if x.guidance else '×'} | {x.robot} | "
                f"{x.collision_free:.1f} → {x.net_collision_free:.1f} | "
                f"{x.success_free:.1f} → {x.net_success_free:.1f} | "
                f"{'–' if x.exact_rule_rate is None else f'{x.exact_rule_rate:.1f}'} | "
                f"{'–' if x.first_leg_rate is None else f'{x.first_leg_rate:.1f}'} | "
                f"{'–' if x.backtrack_rate is None else f'{x.backtrack_rate:.1f}'} | "
                f"{'–' if x.subgoal_rate is None else f'{x.subgoal_rate:.1f}'} | "
                f"{'–' if x.settle_rate is None else f'{x.settle_rate:.1f}'} | "
                f"{x.net_retry_rate:.1f} | "
                f"{'–' if x.net_resample_rate is None else f'{x.net_resample_rate:.1f}'} | "
                f"{x.net_fallback_rate:.1f} | {x.net_unsafe_rate:.1f} | "
                f"{x.time_ms_mean:.1f} → {x.net_time_ms_mean:.1f} | "
                f"{x.time_ms_median:.1f} → {x.net_time_ms_median:.1f} | "
                f"{x.time_ms_p95:.1f} → {x.net_time_ms_p95:.1f} |")
    if r.ablation:
        lines += ["", "Table II ablation (ECAHD, circle robot): how J reads the cost map. "
                  "Ours / paper.", "",
                  "| variant | success % | success & free % | collision-free % | collision rate % | DD ratio |",
                  "|---|---|---|---|---|---|"]
        for x in r.ablation:
            mode, dil = x.variant.split(" + ")[0], "dilation" in x.variant
            ps, pc = PAPER_TABLE_II.get((mode, dil), (None, None))
            lines.append(f"| {x.variant} | {x.success:.1f} / {_fmt(ps, 2)} | {x.success_free:.1f} | "
                         f"{x.collision_free:.1f} | {x.collision_rate:.4f} / {_fmt(pc, 4)} | "
                         f"{x.dd_ratio:.3f} |")
    return "\n".join(lines) + "\n"


def plot_examples(r: PlanningBenchResult, path, *, robot: str = "circle", problem: int = 0) -> None:
    """One problem, every method (Fig. 3 style): path in purple, collisions in red."""
    from ecahd_core.collision import check_collision
    from ecahd_core.footprint import make_footprint
    from ecahd_core.maps import load_map
    from ecahd_core.viz import PlanFigure, save_figures

    grid = load_map(r.context.get("map_source", r.context["map"]))  # a YAML's path, not its name
    fp = make_footprint(robot)
    prob = r.problems[problem]
    figures = []
    for (method, guidance, rb), paths in r.examples.items():
        if rb != robot:
            continue
        p = paths[problem]
        rep = check_collision(p, fp, grid)
        step = max(1, len(rep.dense_poses) // 40)
        figures.append(PlanFigure(
            grid=grid, footprint=fp, start=prob.start, goal=prob.goal, trajectory=p,
            sweep_poses=rep.dense_poses[::step], colliding_poses=rep.dense_poses[rep.colliding][::4],
            title=f"{METHOD_LABELS[method]}{' + guidance' if guidance else ''}: "
                  f"{'collision-free' if rep.collision_free else 'collides'}"))
    save_figures(figures, path, cols=4, panel_size=4.0)
