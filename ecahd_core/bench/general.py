"""``ecahd bench general``: ECAHD with one model on maps it never saw (issue 40's targets).

On each map (default: three generated buildings of every family, with map seeds the
generalist's data never used, and the D4RL maze2d-large, whose kind it never saw), ``ecahd bench
planning``'s ECAHD cell (HD with J's guidance, the exact rule and our rules, then the safety net)
runs for every robot on held-out problems, with the SD and DD models given (default: the
shipped generalists, zero-shot). Rows are per family and robot, over all its maps' problems:

- ECAHD alone: collision-free by the exact checker before the net;
- with the net: collision-free after it; A* fallback: plans where the net spliced in A*;
- the time of a plan with the net (median, p95) [ms];
- the plans' length over A*'s (median, p99; ECAHD alone);
- the least room beside the footprint along each plan (ECAHD alone; median, 5th percentile)
  [cm]: the margin the robot has for tracking error (``planning.least_room``).

A* (with the footprint's clearance) is the reference of every length, computed in the same run
on the same problems. Run it: ``ecahd bench general [--maps SPEC ...] [--sd-model CKPT]``.
"""
from __future__ import annotations

import argparse
import logging
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from ecahd_core.errors import EcahdError

log = logging.getLogger(__name__)

# 3 generated buildings per family: sizes of the generalist's data, map seeds it never used
# (its data: 10^6 x data seed + j, j < maps; these are 7001..7003)
HELD_OUT_MAPS = tuple(f"{kind}:{size}:0.05:{7000 + i}"
                      for kind in ("warehouse", "office", "depot")
                      for i, size in enumerate(("24x24", "36x24", "48x36"), start=1)) \
    + ("maze2d-large",)


# our rules that can be switched off, as ``ecahd bench planning``'s settings (docs/rules.md)
RULES_OFF = {"placement": {"place_reach": 0.0}, "leg-batches": {"leg_batches": -1},
             "backtracks": {"backtracks": 0}, "subgoals": {"subgoals": False},
             "settle": {"settle": False}, "exact-rule": {"exact_rule": False},
             "polish": {"polish_steps": 0}, "keep-better": {"keep_better": False},
             "shortcut": {"shortcut": False}}


@dataclass(frozen=True, kw_only=True)
class GeneralBenchSettings:
    maps: tuple[str, ...] = HELD_OUT_MAPS
    problems: int = 16  # per map and robot
    seed: int = 31  # problems (not the planning benchmark's 2026)
    sample_seed: int = 0
    robots: tuple[str, ...] = ("circle", "quadruped", "humanoid")
    sd_model: str | None = "general"
    dd_model: str | None = "general"
    off: tuple[str, ...] = ()  # rules switched off (RULES_OFF)
    sd_steps: int | None = None  # SD's DDIM steps (None: the model's; the generalist's: 10)
    # re-plans warm-started from the plan before (SparseConfig's; -1: by the map)
    warm_fraction: float = -1.0
    # [m] the re-plans' spacing (None: by the map and the model; 0: off, Algorithm 1's P^g - p)
    replan_spacing: float | None = None
    # the SD Transformer's inference precision: "auto" (bf16 where the CPU computes it
    # natively), as global_planner's inference_precision and ``ecahd plan``; "fp32", "bf16"
    precision: str = "auto"


@dataclass
class GeneralBenchResult:
    settings: GeneralBenchSettings
    cells: list = field(default_factory=list)  # (map, family, CellResult dict)
    seconds: float = 0.0
    precision: str = ""  # what settings.precision resolved to on this machine

    def to_dict(self) -> dict:
        return {"settings": asdict(self.settings), "precision": self.precision,
                "seconds": self.seconds, "cells": self.cells}


def family_of(spec: str) -> str:
    """A map spec's family: the generated kind, else the map's name (a YAML file's stem)."""
    from pathlib import Path

    head = spec.split(":")[0]
    if head in ("warehouse", "office", "depot"):
        return head
    return Path(spec).stem if spec.endswith((".yaml", ".yml")) else spec


def run_general_benchmark(settings: GeneralBenchSettings, *, progress: bool = True
                          ) -> GeneralBenchResult:
    from ecahd_core.bench.planning import PlanningBenchSettings, run_planning_benchmark

    if settings.problems < 1 or not settings.maps:
        raise EcahdError("need at least one map and one problem")
    unknown = sorted(set(settings.off) - set(RULES_OFF))
    if unknown:
        raise EcahdError(f"unknown rule(s) {unknown}; known: {sorted(RULES_OFF)}")
    overrides = {k: v for rule in settings.off for k, v in RULES_OFF[rule].items()}
    from ecahd_core.threads import resolve_precision

    precision = resolve_precision(settings.precision)
    result = GeneralBenchResult(settings=settings, precision=precision)
    t0 = time.perf_counter()
    for spec in settings.maps:
        r = run_planning_benchmark(PlanningBenchSettings(
            map=spec, problems=settings.problems, seed=settings.seed,
            sample_seed=settings.sample_seed, per_problem_seeds=True,
            robots=tuple(settings.robots), methods=("hd",), guidance="on", ablation=False,
            sd_model=settings.sd_model, dd_model=settings.dd_model,
            sd_steps=settings.sd_steps, warm_fraction=settings.warm_fraction,
            replan_spacing=settings.replan_spacing, precision=precision, **overrides),
            progress=progress)
        for cell in r.cells:
            result.cells.append({"map": spec, "family": family_of(spec), **cell.to_dict()})
            log.info("%s %s: alone %.1f%%, net %.1f%%, fallback %.1f%%, %.0f ms median", spec,
                     cell.robot, cell.collision_free, cell.net_collision_free,
                     cell.net_fallback_rate, cell.net_time_ms_median)
    result.seconds = time.perf_counter() - t0
    return result


def rows(result: GeneralBenchResult) -> list[dict]:
    """One row per (family, robot) over its maps' problems."""
    out = []
    families = list(dict.fromkeys(c["family"] for c in result.cells))
    for family in families:
        for robot in result.settings.robots:
            cells = [c for c in result.cells if c["family"] == family and c["robot"] == robot]
            if not cells:
                continue
            free = np.concatenate([c["free_by_problem"] for c in cells])
            net = np.concatenate([c["net_free_by_problem"] for c in cells])
            rules = sum((c["net_rule_by_problem"] for c in cells), [])
            times = np.concatenate([c["net_time_ms_by_problem"] for c in cells])
            ratio = np.concatenate([c["length_ratio_by_problem"] for c in cells])
            room = np.concatenate([c.get("room_by_problem") or [np.nan] * c["problems"]
                                   for c in cells])
            out.append({"family": family, "robot": robot, "maps": len(cells),
                        "problems": len(free), "alone": 100 * free.mean(),
                        "net": 100 * net.mean(),
                        "fallback": 100 * np.mean([r == "fallback" for r in rules]),
                        "unsafe": 100 * np.mean([r == "unsafe" for r in rules]),
                        "time_median": float(np.median(times)),
                        "time_p95": float(np.percentile(times, 95)),
                        "length_median": float(np.median(ratio)),
                        "length_p99": float(np.percentile(ratio, 99)),
                        "room_median": float(np.median(room)),
                        "room_p5": float(np.percentile(room, 5))})
    return out


def format_table(result: GeneralBenchResult) -> str:
    s = result.settings
    lines = [f"ECAHD with SD {s.sd_model or 'per map'} and DD {s.dd_model or 'per map'} on "
             f"{len(s.maps)} maps, {s.problems} problems each (seed {s.seed}, sampling seed "
             f"{s.sample_seed} per problem), rules off: {', '.join(s.off) or 'none'}, "
             + (f"SD {s.sd_steps} DDIM steps, " if s.sd_steps else "")
             + (f"replan spacing {s.replan_spacing:g} m, " if s.replan_spacing is not None
                else "")
             + f"SD in {result.precision or s.precision}, {result.seconds / 60:.1f} min", "",
             "| family | robot | maps | problems | ECAHD alone % | with the net % | A* fallback "
             "% | unsafe % | median ms | p95 ms | length / A* median | p99 | least room cm "
             "median | p5 |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows(result):
        lines.append(f"| {r['family']} | {r['robot']} | {r['maps']} | {r['problems']} | "
                     f"{r['alone']:.1f} | {r['net']:.1f} | {r['fallback']:.1f} | "
                     f"{r['unsafe']:.1f} | {r['time_median']:.0f} | {r['time_p95']:.0f} | "
                     f"{r['length_median']:.2f} | {r['length_p99']:.2f} | "
                     f"{100 * r['room_median']:.1f} | {100 * r['room_p5']:.1f} |")
    return "\n".join(lines)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    d = GeneralBenchSettings()
    parser.add_argument("--maps", nargs="+", default=list(d.maps), metavar="SPEC",
                        help="maps: built-in mazes, Nav2 YAMLs, or KIND:WxH:RES:SEED "
                             "(default: 3 held-out buildings per family and maze2d-large)")
    parser.add_argument("--problems", type=int, default=d.problems,
                        help="problems per map and robot")
    parser.add_argument("--seed", type=int, default=d.seed, help="seed of the problems")
    parser.add_argument("--sample-seed", type=int, default=d.sample_seed)
    parser.add_argument("--robots", nargs="+", default=list(d.robots),
                        choices=("circle", "quadruped", "humanoid"))
    parser.add_argument("--sd-model", default=d.sd_model, metavar="CKPT",
                        help="SD: 'general', a file, or 'map' (each map's own)")
    parser.add_argument("--dd-model", default=d.dd_model, metavar="CKPT",
                        help="DD: 'general', a file, or 'map' (each map's own)")
    parser.add_argument("--off", nargs="+", default=[], choices=sorted(RULES_OFF),
                        metavar="RULE", help=f"switch rules off: {', '.join(sorted(RULES_OFF))}")
    parser.add_argument("--sd-steps", type=int, default=None, metavar="N",
                        help="SD's DDIM steps (default: the model's; the generalist's 10)")
    parser.add_argument("--warm-fraction", type=float, default=d.warm_fraction, metavar="F",
                        help="SD's re-plans start from the rest of the plan before, noised to "
                             "the last F (0..1) of the DDIM schedule; 0: from noise (the "
                             "paper); -1: by the map (0.3 on buildings)")
    parser.add_argument("--replan-spacing", type=float, default=None, metavar="M",
                        help="re-plans keep a waypoint per M metres left to the goal (default: "
                             "by the map and the model, 3 m for the generalist; 0: off, "
                             "Algorithm 1's P^g - p)")
    from ecahd_core.threads import add_precision_argument

    add_precision_argument(parser, d.precision, "the SD Transformer's inference precision "
                           "(auto: bf16 where the CPU computes it natively, as global_planner's "
                           "inference_precision)")
    parser.add_argument("--json", metavar="FILE", help="also write every cell as JSON")
    parser.add_argument("--md", metavar="FILE", help="also write the table as markdown")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")


def run(args: argparse.Namespace) -> int:
    def model(value):
        return None if value == "map" else value

    result = run_general_benchmark(GeneralBenchSettings(
        maps=tuple(args.maps), problems=args.problems, seed=args.seed,
        sample_seed=args.sample_seed, robots=tuple(args.robots),
        sd_model=model(args.sd_model), dd_model=model(args.dd_model), off=tuple(args.off),
        sd_steps=args.sd_steps, warm_fraction=args.warm_fraction,
        replan_spacing=args.replan_spacing, precision=args.precision),
        progress=not args.no_progress)
    table = format_table(result)
    print(table)
    if args.md:
        from pathlib import Path

        Path(args.md).write_text(table + "\n")
    if args.json:
        from ecahd_core.bench.output import write_json

        write_json(args.json, result.to_dict())
    return 0
