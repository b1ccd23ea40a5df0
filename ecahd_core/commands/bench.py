"""``ecahd bench``: benchmarks, one sub-subcommand each.

    ecahd bench cost [--json FILE] [--repeats N] [--threads T]   the cost J, batched vs loops
    ecahd bench sampling [--json FILE]        SD / DD / FD latency next to the paper's figures
    ecahd bench sd-quality [--problems 128]   SD alone: goal reach, collision-free (point robot)
    ecahd bench contention [--quick]          plan latency quiet vs beside a CPU hog
    ecahd bench replan [--map M]              global_planner's work round a plan with
                                              remembered obstacles on a big map

``BENCHMARKS`` maps each name to its argument builder and runner; a new benchmark (sampling,
planning, ...) is one more entry. Every benchmark takes ``--threads T`` (one definition,
``ecahd_core.threads``; default 1, 0: torch's default), applied before it runs. torch is only
imported when a benchmark runs, so ``ecahd --help`` stays fast.
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from ecahd_core.maps import DEFAULT_MAP
from ecahd_core.bench import contention as bench_contention
from ecahd_core.bench import monitor as bench_monitor
from ecahd_core.bench import replan as bench_replan
from ecahd_core.bench import general as bench_general
from ecahd_core.bench import habits as bench_habits
from ecahd_core.bench import map_update as bench_map_update
from ecahd_core.bench.cost import CostBenchSettings
from ecahd_core.bench.output import write_json
from ecahd_core.commands.plan import add_replan_argument
from ecahd_core.threads import add_precision_argument, add_threads_argument, set_torch_threads


@dataclass(frozen=True)
class Benchmark:
    """One ``ecahd bench NAME`` sub-subcommand."""

    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]


def _int_at_least(minimum: int):
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from exc
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be >= {minimum}, got {value}")
        return value
    return parse


# ------------------------------------------------------------------------------------ cost
def _add_cost_arguments(parser: argparse.ArgumentParser) -> None:
    d = CostBenchSettings()
    parser.add_argument("--json", metavar="FILE", help="also write the result as JSON to FILE")
    parser.add_argument("--repeats", type=_int_at_least(1), default=d.repeats, metavar="N",
                        help="timed runs of the batched J (the median is reported)")
    parser.add_argument("--loop-repeats", type=_int_at_least(0), default=d.loop_repeats,
                        metavar="N", help="timed runs of the literal loop reference "
                                          "(seconds each); 0 skips it")
    parser.add_argument("--batch", type=_int_at_least(1), default=d.batch, metavar="B",
                        help="trajectories per call of J")
    parser.add_argument("--horizon", type=_int_at_least(1), default=d.horizon, metavar="P",
                        help="points per trajectory (P^l)")
    parser.add_argument("--n-interp", type=_int_at_least(1), default=d.n_interp, metavar="N",
                        help="DDA points per segment (N_interp)")
    parser.add_argument("--robot", default=d.footprint,
                        help="footprint: circle, quadruped, humanoid or a Nav2 polygon string")
    parser.add_argument("--mode", default=d.mode,
                        help="how the cost map is read: a cost mode of Table II")


def _run_cost(args: argparse.Namespace) -> int:
    from ecahd_core.bench.cost import format_table, run_cost_benchmark

    settings = CostBenchSettings(repeats=args.repeats, loop_repeats=args.loop_repeats,
                                 threads=args.threads or None, batch=args.batch,
                                 horizon=args.horizon, n_interp=args.n_interp,
                                 footprint=args.robot, mode=args.mode)
    result = run_cost_benchmark(settings)
    print(format_table(result))
    if args.json:
        write_json(args.json, result.to_dict())
    return 0


# -------------------------------------------------------------------------------- sampling
def _add_model_arguments(parser: argparse.ArgumentParser, kinds: tuple[str, ...]) -> None:
    parser.add_argument("--map", default=DEFAULT_MAP, help="built-in maze or Nav2 map YAML")
    for kind in kinds:
        parser.add_argument(f"--{kind}", metavar="CKPT", default=None,
                            help=f"{kind.upper()} checkpoint (default: the shipped model)")


def _add_sampling_arguments(parser: argparse.ArgumentParser) -> None:
    _add_model_arguments(parser, ("sd", "dd", "fd"))
    parser.add_argument("--robot", default="circle", help="footprint for the guided runs")
    parser.add_argument("--repeats", type=_int_at_least(1), default=20, metavar="N",
                        help="timed runs per measurement (the median is reported)")
    parser.add_argument("--json", metavar="FILE", help="also write the result as JSON to FILE")


def _run_sampling(args: argparse.Namespace) -> int:
    from ecahd_core.bench.sampling import (SamplingBenchSettings, format_table,
                                           run_sampling_benchmark)

    settings = SamplingBenchSettings(map=args.map, robot=args.robot, repeats=args.repeats,
                                     threads=args.threads or None)
    models = {k: getattr(args, k) for k in ("sd", "dd", "fd") if getattr(args, k)}
    result = run_sampling_benchmark(settings, models=models)
    print(format_table(result))
    if args.json:
        write_json(args.json, result.to_dict())
    return 0


# ------------------------------------------------------------------------------ sd-quality
def _add_sd_quality_arguments(parser: argparse.ArgumentParser) -> None:
    _add_model_arguments(parser, ("sd",))
    parser.add_argument("--problems", type=_int_at_least(1), default=128, metavar="N",
                        help="held-out start/goal pairs (>= 3 m apart along the A* path)")
    parser.add_argument("--seed", type=int, default=2026, help="seed of the problems")
    parser.add_argument("--sample-seed", type=int, default=0, help="seed of the samples")
    parser.add_argument("--steps", type=_int_at_least(1), default=None,
                        help="DDIM steps (default: the checkpoint's)")
    parser.add_argument("--eta", type=float, default=None,
                        help="DDIM eta (default: the SD planner's, SparseConfig.eta)")
    add_precision_argument(parser, "fp32", "the SD Transformer's inference precision")
    parser.add_argument("--png", metavar="FILE", help="draw the first 8 plans")
    parser.add_argument("--json", metavar="FILE", help="also write the result as JSON to FILE")


def _run_sd_quality(args: argparse.Namespace) -> int:
    from ecahd_core.bench.sd_quality import evaluate_sd, plot_plans
    from ecahd_core.maps import load_map
    from ecahd_core.model_zoo import load_model, sample_steps
    from ecahd_core.problems import make_problems

    grid = load_map(args.map)
    ckpt = load_model("sd", grid, path=args.sd, horizon=10)
    problems = make_problems(grid, args.problems, seed=args.seed)
    from ecahd_core.planning.sparse import SparseConfig

    steps = args.steps or sample_steps(ckpt)
    eta = SparseConfig().eta if args.eta is None else args.eta
    metrics, plans = evaluate_sd(ckpt, grid, problems, num_steps=steps, eta=eta,
                                 seed=args.sample_seed, precision=args.precision)
    print(f"SD alone (unguided, 1 sample) on {grid.name}: {metrics.problems} problems "
          f"(seed {args.seed}), {steps} DDIM steps, eta {eta}, {metrics.precision}")
    print(f"  a waypoint within 1.0 m of the goal: {100 * metrics.goal_reached:.1f}%  (target >= 85%)")
    print(f"  collision-free for a point robot:    {100 * metrics.collision_free_point:.1f}%  "
          f"(target >= 80%)")
    print(f"  the A* expert resampled to the same waypoints: "
          f"{100 * metrics.expert_collision_free_point:.1f}% collision-free")
    print(f"  mean length / A* length:             {metrics.mean_length_ratio:.3f}")
    print(f"  sampling all {metrics.problems} in one batch: {metrics.sample_ms:.0f} ms")
    if args.png:
        plot_plans(grid, problems[:8], plans[:8], args.png)
        print(f"figure: {args.png}")
    if args.json:
        write_json(args.json, metrics.to_dict())
    return 0


# -------------------------------------------------------------------------------- planning
def _add_planning_arguments(parser: argparse.ArgumentParser) -> None:
    from ecahd_core.bench.planning import GUIDANCE_RUNS, METHODS, ROBOTS, PlanningBenchSettings
    from ecahd_core.planning.sparse import SELECTION_RULES

    d = PlanningBenchSettings()
    parser.add_argument("--map", default=d.map, help="built-in maze or Nav2 map YAML")
    parser.add_argument("--problems", type=_int_at_least(1), default=d.problems, metavar="N",
                        help="held-out start/goal pairs (>= 3 m apart along the A* path)")
    parser.add_argument("--seed", type=int, default=d.seed, help="seed of the problems")
    parser.add_argument("--sample-seed", type=int, default=d.sample_seed, help="sampling seed")
    parser.add_argument("--per-problem-seeds", action="store_true",
                        help="seed each problem's sampling by (sample seed, problem index), so a "
                             "rule that changes how much one problem samples leaves the other "
                             "problems' draws alone (paired comparisons of two settings)")
    parser.add_argument("--robots", nargs="+", default=list(d.robots), choices=ROBOTS)
    parser.add_argument("--methods", nargs="+", default=list(d.methods), choices=METHODS)
    parser.add_argument("--candidates", type=_int_at_least(1), default=d.candidates,
                        help="SD candidates per plan (best of N)")
    parser.add_argument("--selection", default=d.selection, choices=SELECTION_RULES,
                        help="SD best-of-N rule: the paper's, or ours weighing J")
    parser.add_argument("--omega", type=float, default=d.guidance_weight, help="guidance weight")
    parser.add_argument("--guidance-space", default=d.guidance_space, choices=("eps", "x0"),
                        help="where J is evaluated and how omega is scaled (diffusion.sampler)")
    parser.add_argument("--margin", type=float, default=d.margin,
                        help="[m] cost-map margin: J is 0 farther than this from obstacles "
                             "(default: by the map, 0.5 m on maps over 50 000 cells, else "
                             "0.1 m)")
    parser.add_argument("--c-th", type=float, default=d.c_th, help="DD trigger threshold")
    parser.add_argument("--dd-retries", type=_int_at_least(0), default=d.dd_retries,
                        help="our safety rule: resample DD while still colliding (0: paper)")
    parser.add_argument("--polish-steps", type=_int_at_least(0), default=d.polish_steps,
                        help="our safety rule: descend J on local plans still above c_th "
                             "(0: paper)")
    parser.add_argument("--polish-along", action="store_true",
                        help="polishing moves points along the path too (the earlier rule; "
                             "ours moves them only across it: local plans never double back)")
    parser.add_argument("--no-keep-better", action="store_true",
                        help="accept DD's plan even when J says the straight one was cheaper "
                             "(the paper's rule; ours keeps the cheaper)")
    parser.add_argument("--no-exact-rule", action="store_true",
                        help="HD: keep a refined local plan the exact checker finds colliding "
                             "even where the straight or unpolished one is free (ours: put "
                             "that back)")
    parser.add_argument("--net-resamples", type=int, default=d.net_resamples, metavar="N",
                        help="the safety net's whole plans drawn again before its A* fallback "
                             "(0: skip that rule)")
    add_replan_argument(parser, d.replan, d.warm_fraction)
    add_precision_argument(parser, d.precision, "the SD Transformer's inference precision "
                                                "(auto: bf16 where the CPU has native bfloat16)")
    parser.add_argument("--max-spacing", type=float, default=d.max_spacing, metavar="M",
                        help="[m] waypoint spacing by distance: SD re-samples legs longer than "
                             "this between their ends (big maps; default: off, the paper's "
                             "fixed P^g)")
    parser.add_argument("--place-reach", type=float, default=d.place_reach, metavar="R",
                        help="[m] SD's waypoints in a wall move into free space within R, legs "
                             "crossing a wall get a placed midpoint (ours; 0: off; default: "
                             "on at 1 m for maps over 50 000 cells, off on smaller ones)")
    parser.add_argument("--leg-batches", type=int, default=d.leg_batches, metavar="K",
                        help="HD, every_waypoint, with placement on: a re-plan whose first leg "
                             "still crosses a wall after leg repair takes another SD candidate "
                             "whose first leg does not, else one of up to K more batches (one "
                             "waypoint more each; ours; 0: the other candidates only; -1: off)")
    parser.add_argument("--backtracks", type=int, default=d.backtracks, metavar="K",
                        help="HD, every_waypoint, with placement and the exact rule on: up to K "
                             "rounds in which a re-plan whose local plan the exact checker "
                             "still finds in collision (or the re-plan before it) takes another "
                             "SD candidate whose local plan is free, and the rest is planned "
                             "again (ours; 0: off)")
    parser.add_argument("--no-subgoals", action="store_true",
                        help="HD, every_waypoint, on building maps: turn off the subgoal rule "
                             "(a re-plan loop past P^g - 1 iterations whose plan makes no "
                             "progress by the goal's cost-to-go plans toward a point along the "
                             "shortest route; ours)")
    parser.add_argument("--no-settle", action="store_true",
                        help="HD, every_waypoint, on building maps: turn off the settle rule "
                             "(an SD plan whose every straight leg is free by the leg test is "
                             "followed whole instead of re-planned at each waypoint; ours)")
    parser.add_argument("--no-shortcut", action="store_true",
                        help="HD with the exact rule: turn off the shortcut rule (a plan the "
                             "exact checker finds free is pulled taut by straight segments "
                             "whose J cost is <= c_th and that the exact checker finds free; "
                             "ours)")
    parser.add_argument("--guidance", choices=tuple(GUIDANCE_RUNS), default=d.guidance,
                        help="run the diffusion methods with and without J's guidance, or only "
                             "one of the two (on: ECAHD's own setting)")
    parser.add_argument("--no-ablation", action="store_true", help="skip Table II")
    parser.add_argument("--sd-model", metavar="CKPT", default=None,
                        help="SD's checkpoint: a file (per-map or generalist) or 'general' (the "
                             "shipped generalist, zero-shot on any map); default: the map's own")
    parser.add_argument("--dd-model", metavar="CKPT", default=None,
                        help="DD's checkpoint: a file (per-map or segment-frame) or 'general' "
                             "(the shipped segment-frame DD, any map); default: the map's own")
    parser.add_argument("--json", metavar="FILE", help="one record per cell")
    parser.add_argument("--md", metavar="FILE", help="Table I / Table II as markdown")
    parser.add_argument("--png", metavar="FILE", help="one problem planned by every method")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")


def _run_planning(args: argparse.Namespace) -> int:
    from ecahd_core.bench.planning import (PlanningBenchSettings, format_markdown, plot_examples,
                                           run_planning_benchmark)

    settings = PlanningBenchSettings(
        map=args.map, problems=args.problems, seed=args.seed, sample_seed=args.sample_seed,
        per_problem_seeds=args.per_problem_seeds,
        robots=tuple(args.robots), methods=tuple(args.methods), candidates=args.candidates,
        selection=args.selection,
        guidance_weight=args.omega, guidance_space=args.guidance_space, margin=args.margin,
        c_th=args.c_th, dd_retries=args.dd_retries, polish_steps=args.polish_steps,
        polish_across=not args.polish_along, keep_better=not args.no_keep_better, exact_rule=not args.no_exact_rule,
        replan=args.replan, warm_fraction=args.warm_fraction, max_spacing=args.max_spacing,
        place_reach=args.place_reach, ablation=not args.no_ablation, precision=args.precision,
        net_resamples=args.net_resamples, replan_spacing=args.replan_spacing,
        guidance=args.guidance, leg_batches=args.leg_batches, backtracks=args.backtracks,
        subgoals=not args.no_subgoals, settle=not args.no_settle,
        shortcut=not args.no_shortcut, sd_model=args.sd_model, dd_model=args.dd_model)
    result = run_planning_benchmark(settings, progress=not args.no_progress)
    md = format_markdown(result)
    print(md)
    if args.md:
        Path(args.md).write_text(md)
    if args.json:
        write_json(args.json, {"context": result.context,
                                "cells": [c.to_dict() for c in result.cells],
                                "ablation": [c.to_dict() for c in result.ablation]})
    if args.png:
        plot_examples(result, args.png, robot=result.cells[0].robot)
        print(f"figure: {args.png}")
    return 0


# ------------------------------------------------------------------------------ contention
def _run_contention(args: argparse.Namespace) -> int:
    result = bench_contention.run_contention_benchmark(bench_contention.settings_from_args(args))
    print(bench_contention.format_table(result))
    if args.json:
        write_json(args.json, result.to_dict())
    return 0


BENCHMARKS: dict[str, Benchmark] = {
    "cost": Benchmark(help="forward+backward time of the cost J: batched torch vs literal loops",
                      add_arguments=_add_cost_arguments, run=_run_cost),
    "sampling": Benchmark(help="latency of SD / DD / FD sampling next to the paper's A100 figures",
                          add_arguments=_add_sampling_arguments, run=_run_sampling),
    "planning": Benchmark(help="Table I / II: every method x guidance x robot on held-out problems",
                          add_arguments=_add_planning_arguments, run=_run_planning),
    "sd-quality": Benchmark(help="SD alone: goal reach and point-robot collision-free rate",
                            add_arguments=_add_sd_quality_arguments, run=_run_sd_quality),
    "monitor": Benchmark(help="collision monitor filter and local costmap update + fusion: "
                              "p50/p99 per call against their budgets",
                         add_arguments=bench_monitor.add_arguments, run=bench_monitor.run),
    "contention": Benchmark(help="plan latency (SD best-of-10, Alg. 1 replan once) quiet and "
                                 "beside a CPU hog, with 1 torch thread and with every core",
                            add_arguments=bench_contention.add_arguments, run=_run_contention),
    "replan": Benchmark(help="global_planner's work round a plan on a big map with remembered "
                             "obstacles (fused cost, crossing check, detour) against the "
                             "previous way, in one run",
                        add_arguments=bench_replan.add_arguments, run=bench_replan.run),
    "map-update": Benchmark(help="global_planner's work when a changed map arrives (a block on "
                                 "the route) against the first map's, in one run",
                            add_arguments=bench_map_update.add_arguments,
                            run=bench_map_update.run),
    "general": Benchmark(help="ECAHD with one model (the generalists by default) on held-out "
                              "maps of every family: alone, with the net, A* fallback, time, "
                              "length over A*'s",
                         add_arguments=bench_general.add_arguments, run=bench_general.run),
    "habits": Benchmark(help="plans of SD models trained on A*, demonstrations or both: share "
                             "on the right half of corridors, in zones, collision-free, "
                             "success, time, beside A* and the operator",
                        add_arguments=bench_habits.add_arguments, run=bench_habits.run),
}


# ----------------------------------------------------------------------------- interface
def add_arguments(parser: argparse.ArgumentParser,
                  benchmarks: dict[str, Benchmark] | None = None) -> None:
    """``ecahd bench`` takes the benchmark name, then that benchmark's options (``benchmarks``:
    the table to offer, default :data:`BENCHMARKS`)."""
    sub = parser.add_subparsers(dest="benchmark", metavar="BENCHMARK", required=True)
    for name, bench in (benchmarks or BENCHMARKS).items():
        p = sub.add_parser(name, help=bench.help, description=bench.help,
                           formatter_class=argparse.ArgumentDefaultsHelpFormatter)
        bench.add_arguments(p)
        try:
            add_threads_argument(p)
            p.set_defaults(threads_set_by_benchmark=False)
        except argparse.ArgumentError:  # the benchmark has its own --threads and applies it
            p.set_defaults(threads_set_by_benchmark=True)


def run(args: argparse.Namespace, benchmarks: dict[str, Benchmark] | None = None) -> int:
    """Run ``args.benchmark`` of ``benchmarks`` (default :data:`BENCHMARKS`) with torch's
    threads set from ``--threads`` (0: torch's default), restored afterwards."""
    bench = (benchmarks or BENCHMARKS)[args.benchmark]
    if not args.threads or args.threads_set_by_benchmark:
        return bench.run(args)
    import torch

    previous = torch.get_num_threads()
    set_torch_threads(args.threads)
    try:
        return bench.run(args)
    finally:
        torch.set_num_threads(previous)
