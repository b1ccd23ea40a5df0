"""``ecahd bench sampling``: latency of the shipped diffusion models on this machine, next to the
paper's A100 figures (Table I inference times; Table IV per-DD-step breakdown).

Measured (median wall time over ``repeats`` runs, after warm-up):
- ``sd_best_of_10_ms``  SD, one batch of 10 candidates, horizon 10, the shipped step count;
- ``dd_plan_ms``        guided DD for all segments of one plan in one batch (P^g - 1 = 9 rows
                        of P^l = 4 points), guidance at every step;
- ``dd_step_ms``        one guided DD step of that batch, split into denoiser, J forward,
                        gradient of J, and the update (guidance + DDIM + inpainting);
- ``fd_ms`` / ``fd_guided_ms``  FD, one 100-point trajectory, unguided / guided at every step;
- ``sd_replan_ms``      Algorithm 1's first re-plan (horizon 9 from waypoint 1 of an SD plan),
                        SD best-of-10 with the collision-aware selection (``SparseDiffusion``,
                        what the global_planner node runs): {"noise": from noise, "<f>": warm-
                        started from the previous plan's rest running the last f of the DDIM
                        schedule, for each f of ``warm_fractions``}.
"""
from __future__ import annotations

import logging
import statistics
import time
from dataclasses import asdict, dataclass, field, replace

from ecahd_core.bench.timing import interleaved_median_ms, median_ms
from ecahd_core.maps import DEFAULT_MAP

log = logging.getLogger(__name__)

# Paper figures (A100 80GB + 2x Xeon Gold 6338): Table I (seconds per problem) and Table IV.
PAPER = {
    "fd_s": 2.762, "fd_guided_s": 11.881, "sd_s": 1.449, "hd_s": 1.527,
    "dd_step_ms": 3.30, "dd_step_unguided_ms": 1.26, "dd_gradient_share": 0.537,
    "dd_denoiser_ms": 0.38, "dd_cost_forward_ms": 0.94, "dd_gradient_ms": 1.77,
    "dd_update_ms": 0.06,
}


@dataclass(frozen=True, kw_only=True)
class SamplingBenchSettings:
    map: str = DEFAULT_MAP
    robot: str = "circle"
    repeats: int = 20
    threads: int | None = None  # None: torch's default
    guidance_weight: float = 1.0
    seed: int = 0
    warm_fractions: tuple[float, ...] = (0.3, 0.5)  # SD re-plans warm-started (sd_replan_ms)


@dataclass
class SamplingBenchResult:
    sd_best_of_10_ms: float
    dd_plan_ms: float
    dd_step_ms: float
    fd_ms: float
    fd_guided_ms: float
    dd_step_breakdown_ms: dict = field(default_factory=dict)
    sd_replan_ms: dict = field(default_factory=dict)
    bf16_ms: dict = field(default_factory=dict)  # {"sd_best_of_10": ms, "dd_plan": ms}
    context: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return asdict(self)




def run_sampling_benchmark(settings: SamplingBenchSettings, *, models: dict | None = None
                           ) -> SamplingBenchResult:
    """``models``: optional {kind: checkpoint path}; default the shipped models of the map."""
    import torch

    from ecahd_core.cost import CollisionCost, CostConfig, trajectory_cost
    from ecahd_core.diffusion import (DiffusionSampler, SamplerConfig, apply_conditioning,
                                      native_bf16)
    from ecahd_core.footprint import make_footprint
    from ecahd_core.guidance import CostJGuide
    from ecahd_core.maps import load_map
    from ecahd_core.model_zoo import dense_points, load_model, sample_steps
    from ecahd_core.problems import make_problems

    if settings.threads:
        torch.set_num_threads(settings.threads)
    models = models or {}
    grid = load_map(settings.map)
    footprint = make_footprint(settings.robot)
    ckpt = {k: load_model(k, grid, path=models.get(k), footprint=footprint) for k in ("sd", "dd", "fd")}
    samplers = {k: DiffusionSampler.from_checkpoint(c, config=SamplerConfig(
        num_steps=sample_steps(c), guidance_weight=settings.guidance_weight))
        for k, c in ckpt.items()}
    cost_config = CostConfig()
    costmap = cost_config.make_costmap(grid)
    problem = make_problems(grid, 1, seed=settings.seed)[0]
    start = torch.tensor(problem.start, dtype=torch.float32)
    goal = torch.tensor(problem.goal, dtype=torch.float32)
    gen = torch.Generator().manual_seed(settings.seed)
    reps = settings.repeats

    # SD best-of-10: one batch of 10 candidates, the Transformer in float32 and in bfloat16
    # (SamplerConfig.precision), timed in turn
    bf16 = {k: DiffusionSampler.from_checkpoint(ckpt[k], config=replace(
        samplers[k].config, precision="bf16")) for k in ("sd", "dd")}

    def sd(sampler=samplers["sd"]):
        return sampler.sample(batch=10, horizon=10, conditions={0: start, -1: goal},
                              generator=gen)
    sd_pair = interleaved_median_ms({"fp32": sd, "bf16": lambda: sd(bf16["sd"])}, reps,
                                    warmup=2)
    sd_ms = sd_pair["fp32"]

    # Algorithm 1's first re-plan with the planner's selection: from noise vs warm-started
    from ecahd_core.planning.sparse import SparseConfig, SparseDiffusion

    cost = CollisionCost(costmap=costmap, footprint_points=torch.as_tensor(
        footprint.points, dtype=torch.float32), config=cost_config)
    planners = {"noise": SparseDiffusion(ckpt["sd"], SparseConfig(selection="collision_aware"),
                                         cost=cost)}
    for f in settings.warm_fractions:
        planners[f"{f:g}"] = SparseDiffusion(ckpt["sd"], SparseConfig(
            selection="collision_aware", warm_fraction=f), cost=cost)
    previous = planners["noise"].plan(problem.start, problem.goal, generator=gen).waypoints
    here = previous[1]
    replan_ms = {name: median_ms(lambda sdp=sdp: sdp.replan(here, problem.goal, previous,
                                                             horizon=len(previous) - 1,
                                                             generator=gen), reps, warmup=2)
                 for name, sdp in planners.items()}

    # DD for all 9 segments of one plan: local start t^g[p], local goal t^g[p+1]
    from ecahd_core.dataset import resample_by_arclength
    wp = torch.tensor(resample_by_arclength(problem.astar_path, 10), dtype=torch.float32)
    seg_start, seg_goal = wp[:-1], wp[1:]  # (9, 2)
    n_seg, P_l = len(seg_start), dense_points(ckpt["dd"])  # P^l the DD learnt
    guide = CostJGuide(costmap, footprint.points, seg_goal, cost_config)

    def dd(sampler=samplers["dd"]):
        return sampler.sample(batch=n_seg, horizon=P_l, conditions={0: seg_start, -1: seg_goal},
                              generator=gen, guide=guide)
    dd_pair = interleaved_median_ms({"fp32": dd, "bf16": lambda: dd(bf16["dd"])}, reps,
                                    warmup=2)
    dd_ms = dd_pair["fp32"]
    bf16_ms = {"sd_best_of_10": sd_pair["bf16"], "dd_plan": dd_pair["bf16"]}

    # One guided DD step, timed stage by stage (Table IV)
    dd_s = samplers["dd"]
    model, sched, norm = dd_s.model, dd_s.scheduler, dd_s.normalizer
    timesteps = sched.set_timesteps(dd_s.config.num_steps)
    t = int(timesteps[len(timesteps) // 2])
    cond = {0: norm.normalize(seg_start), -1: norm.normalize(seg_goal)}
    z = apply_conditioning(torch.randn(n_seg, P_l, 2, generator=gen), cond)
    t_batch = torch.full((n_seg,), t, dtype=torch.long)
    fp = torch.as_tensor(footprint.points, dtype=torch.float32)
    stage = {"denoiser": [], "cost_forward": [], "gradient": [], "update": []}
    for i in range(reps + 2):
        with torch.no_grad():
            t0 = time.perf_counter()
            eps = model(z, t_batch)
            t1 = time.perf_counter()
        with torch.enable_grad():
            x = norm.unnormalize(z).detach().requires_grad_(True)
            terms = trajectory_cost(x, seg_goal, fp, costmap, **cost_config.cost_kwargs())
            total = (terms.dist_cost + terms.collision_cost).sum()
            t2 = time.perf_counter()
            (grad,) = torch.autograd.grad(total, x)
            t3 = time.perf_counter()
        with torch.no_grad():
            eps_hat = eps + settings.guidance_weight * norm.grad_to_normalized(grad)
            out = sched.step(eps_hat, t, z, eta=0.0)
            _ = apply_conditioning(out.prev_sample, cond)
            t4 = time.perf_counter()
        if i >= 2:
            for k, (a, b) in zip(stage, ((t0, t1), (t1, t2), (t2, t3), (t3, t4))):
                stage[k].append((b - a) * 1e3)
    breakdown = {k: statistics.median(v) for k, v in stage.items()}
    step_ms = sum(breakdown.values())

    # FD: one 100-point trajectory, unguided and guided over the whole sequence
    H = max(ckpt["fd"].horizons)

    def fd():
        return samplers["fd"].sample(batch=1, horizon=H, conditions={0: start, -1: goal},
                                     generator=gen)
    fd_guide = CostJGuide(costmap, footprint.points, goal[None], cost_config)

    def fd_guided():
        return samplers["fd"].sample(batch=1, horizon=H, conditions={0: start, -1: goal},
                                     generator=gen, guide=fd_guide)
    fd_ms = median_ms(fd, max(3, reps // 2), warmup=2)
    fdg_ms = median_ms(fd_guided, max(3, reps // 2), warmup=2)

    context = {"map": grid.name, "robot": footprint.name, "R": int(len(footprint.points)),
               "n_interp": cost_config.n_interp, "threads": torch.get_num_threads(),
               "torch": torch.__version__, "repeats": reps,
               "sample_steps": {k: sample_steps(c) for k, c in ckpt.items()},
               "guidance_weight": settings.guidance_weight, "native_bf16": native_bf16("cpu"),
               "paper": PAPER}
    return SamplingBenchResult(sd_best_of_10_ms=sd_ms, dd_plan_ms=dd_ms, dd_step_ms=step_ms,
                               fd_ms=fd_ms, fd_guided_ms=fdg_ms, dd_step_breakdown_ms=breakdown,
                               sd_replan_ms=replan_ms, bf16_ms=bf16_ms, context=context)


def format_table(r: SamplingBenchResult) -> str:
    c, p = r.context, PAPER
    lines = [
        f"diffusion sampling on {c['map']} ({c['robot']}, |R|={c['R']}, N_interp={c['n_interp']}), "
        f"{c['threads']} torch thread(s), torch {c['torch']}, DDIM steps {c['sample_steps']}, "
        f"median of {c['repeats']}",
        f"{'what':44s} {'here [ms]':>10s} {'paper A100':>12s} {'paper/here':>11s}",
    ]

    def row(name, ms, paper_ms):
        ratio = f"{paper_ms / ms:10.1f}x" if paper_ms else ""
        paper = f"{paper_ms:10.2f}ms" if paper_ms else ""
        lines.append(f"{name:44s} {ms:10.2f} {paper:>12s} {ratio:>11s}")

    row("SD best-of-10 (one batch, horizon 10)", r.sd_best_of_10_ms, p["sd_s"] * 1e3)
    for name, ms in r.sd_replan_ms.items():
        row(f"SD re-plan, h 9, {'from noise' if name == 'noise' else 'warm ' + name}", ms, None)
    row("guided DD, all 9 segments of a plan", r.dd_plan_ms, None)
    for key, name, fp32 in (("sd_best_of_10", "SD best-of-10", r.sd_best_of_10_ms),
                            ("dd_plan", "guided DD, 9 segments", r.dd_plan_ms)):
        if key in r.bf16_ms:
            ms = r.bf16_ms[key]
            row(f"{name}, bf16 ({fp32 / ms:.2f}x as fast)", ms, None)
    row("FD 100 points, unguided", r.fd_ms, p["fd_s"] * 1e3)
    row("FD 100 points, guided", r.fd_guided_ms, p["fd_guided_s"] * 1e3)
    row("one guided DD step (9 segments)", r.dd_step_ms, p["dd_step_ms"])
    b = r.dd_step_breakdown_ms
    for k, pk in (("denoiser", "dd_denoiser_ms"), ("cost_forward", "dd_cost_forward_ms"),
                  ("gradient", "dd_gradient_ms"), ("update", "dd_update_ms")):
        row(f"  {k}", b[k], p[pk])
    share = b["gradient"] / max(r.dd_step_ms, 1e-12)
    lines.append(f"gradient share of a guided DD step: {100 * share:.1f}% "
                 f"(paper {100 * p['dd_gradient_share']:.1f}%)")
    lines.append("paper SD / FD figures are per planning problem on an A100 (Table I); ours are "
                 "the sampling calls alone on this CPU")
    lines.append("SD re-plan: Algorithm 1's re-plan from waypoint 1 (horizon 9) with the "
                 "collision-aware selection; warm f: started from the previous plan's rest, the "
                 "last f of the DDIM schedule")
    if r.bf16_ms:
        kind = "native" if c.get("native_bf16") else "emulated: no AVX512-BF16/AMX"
        lines.append(f"bf16: SamplerConfig.precision, the Transformers' encoder layers in "
                     f"bfloat16 ({kind})")
    return "\n".join(lines)
