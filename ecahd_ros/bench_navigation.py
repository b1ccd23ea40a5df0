"""``ecahd bench navigation``: the paper's Table III in closed loop, ECAHD and its baselines
driven through the same seeded goals by the same ROS 2 graph.

Every variant is one ``ecahd demo`` run (:func:`ecahd_ros.demo.run_demo`: sim_bridge,
global_planner, local_refiner each in its own process at real time, bag_recorder in the
benchmark process, on a fresh ROS domain), the
same map, robot, seed (hence goals and start) and controller; only the nodes' parameters
differ (:data:`VARIANTS`):

    ECAHD w/ DD           global_planner method sd, local_refiner dd_enabled true (the paper's)
    ECAHD w/o DD          sd, dd_enabled false, exact_check false: the straight local plans
                          are followed, whatever they hit (the paper's ablation)
    A* + controller       astar (one whole A* path per goal), dd_enabled false
    FD, no local planner  fd (one 100-point Full Diffusion path per goal), dd_enabled false,
                          exact_check false

Each bag is scored by ``ecahd eval-bag`` (``ecahd_core.evaluation``): episode reward, first
reach, collision rate (% of sim steps in contact; and the exact swept-footprint checker's share
of driven poses in a wall), inference time per episode (planning records only), reached
episodes, the control callback's p50 / p99 wall time and the goal -> first plan latency. The
table puts the paper's Table III columns beside ours; the markdown states the control period,
the velocity limits and the machine.

``--results FILE`` puts the markdown and the command line into FILE between the lines
``<!-- bench-navigation:begin -->`` and ``<!-- bench-navigation:end -->`` (replacing what was
there), or appends them as a new section when FILE has no such block.

This module also assembles ``ecahd bench``: the core's benchmarks
(``ecahd_core.commands.bench.BENCHMARKS``, no rclpy) plus ``navigation``, which needs rclpy and
so lives here; rclpy is imported only when the navigation benchmark runs.
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import shlex
import time
from dataclasses import dataclass, field
from pathlib import Path

from ecahd_core.maps import DEFAULT_MAP
from ecahd_core.bench.output import write_json

log = logging.getLogger("ecahd.bench.navigation")

BEGIN = "<!-- bench-navigation:begin -->"
END = "<!-- bench-navigation:end -->"
SECTION = "## Closed-loop navigation (Table III)"
HELP = "Table III in closed loop: ECAHD w/ and w/o DD, A* and FD baselines on the same goals"


@dataclass(frozen=True)
class Variant:
    """One column of the table: the parameters its global_planner and local_refiner get."""

    key: str  # the name --variants takes
    label: str
    planner_params: dict
    refiner_params: dict


VARIANTS: tuple[Variant, ...] = (
    Variant("ecahd", "ECAHD w/ DD", {"method": "sd"}, {"dd_enabled": True}),
    Variant("ecahd-no-dd", "ECAHD w/o DD", {"method": "sd"},
            {"dd_enabled": False, "exact_check": False}),
    Variant("astar", "A* + controller", {"method": "astar"}, {"dd_enabled": False}),
    Variant("fd", "FD, no local planner", {"method": "fd"},
            {"dd_enabled": False, "exact_check": False}),
    # obstacles that are not on the map (issue 11)
    Variant("ecahd-blind", "ECAHD without sensing", {"method": "sd"}, {"use_scan": False}),
    Variant("monitor-only", "ECAHD, collision monitor alone", {"method": "sd"},
            {"scan_in_plans": False}),
)
VARIANT_KEYS = tuple(v.key for v in VARIANTS)
TABLE_III_VARIANTS = ("ecahd", "ecahd-no-dd", "astar", "fd")  # the default without obstacles
OBSTACLE_VARIANTS = ("ecahd", "ecahd-blind", "astar", "monitor-only")  # the default with


@dataclass(frozen=True, kw_only=True)
class NavigationBenchSettings:
    """Settings shared by every variant (defaults: ``ecahd demo``'s)."""

    episodes: int = 3
    seed: int = 0
    robot: str = "circle"
    map: str = DEFAULT_MAP
    variants: tuple[str, ...] = TABLE_III_VARIANTS
    realtime_factor: float = 1.0
    max_steps: int = 800
    hold_steps: int = 10  # an episode ends once the goal is held this long (800: D4RL's length)
    domain_id: int | None = None  # the first variant's; the others count up. None: from the pid
    obstacles: int = 0  # static boxes per episode (not on the map)
    moving: int = 0  # moving cylinders per episode
    first_episode: int = 0  # the seeded episode to start at (ecahd demo's first_episode)
    # (node, parameter, value) set on every variant's node on top of its own (--set)
    overrides: tuple[tuple[str, str, object], ...] = ()


@dataclass
class VariantResult:
    """One variant's run: its means and episodes (eval-bag's dicts), latencies and wall times."""

    key: str
    label: str
    summary: dict  # ecahd_core.evaluation.Summary.to_dict()
    episodes: list  # [EpisodeMetrics.to_dict()]
    goal_to_plan_ms: list  # per episode, None when no plan came
    wall_s: float  # [s] the whole run: start-up, episodes, scoring
    episodes_wall_s: float  # [s] the episode loop
    sim_s: float  # [s of sim time] the episode loop
    out: str  # the run's folder (bag, metrics.json, metrics.md, trajectories.png)

    @property
    def exact_penetration(self) -> float | None:
        """Mean share [%] of driven poses the exact checker finds in a wall."""
        values = [e["penetration_fraction"] for e in self.episodes
                  if e.get("penetration_fraction") is not None]
        return 100.0 * sum(values) / len(values) if values else None


@dataclass
class NavigationBenchResult:
    settings: NavigationBenchSettings
    variants: list  # [VariantResult]
    context: dict = field(default_factory=dict)  # limits, machine

    def to_dict(self) -> dict:
        from dataclasses import asdict

        from ecahd_core.evaluation import PAPER_TABLE_III

        return {"settings": asdict(self.settings), "context": self.context,
                "variants": [{**asdict(v), "exact_penetration_pct": v.exact_penetration}
                             for v in self.variants],
                "paper_table_iii": {k: vars(v) for k, v in PAPER_TABLE_III.items()}}


# ----------------------------------------------------------------------------------- running
OVERRIDABLE = ("global_planner", "local_refiner")  # nodes whose parameters --set may change


def parse_override(text: str) -> tuple[str, str, object]:
    """``NODE.PARAM=VALUE`` (``--set``) -> (node, parameter, value). VALUE is read as JSON
    (``true``, ``3``, ``0.5``, ``"x"``) and taken as a string when it is not JSON; the node must
    be one of OVERRIDABLE and declare the parameter. EcahdError names what is wrong."""
    from ecahd_core.errors import EcahdError

    key, sep, raw = text.partition("=")
    node, dot, name = key.strip().partition(".")
    if not sep or not dot or not name:
        raise EcahdError(f"--set {text!r}: expected NODE.PARAM=VALUE, e.g. "
                         "local_refiner.max_v=0.3")
    if node not in OVERRIDABLE:
        raise EcahdError(f"--set {text!r}: node {node!r} is not one of {list(OVERRIDABLE)}")
    module = {"global_planner": "ecahd_ros.global_planner",
              "local_refiner": "ecahd_ros.local_refiner"}[node]
    import importlib

    specs = {spec.name: spec for spec in importlib.import_module(module).PARAMETERS}
    if name not in specs:
        raise EcahdError(f"--set {text!r}: {node} has no parameter {name!r}")
    try:
        value = json.loads(raw)
    except json.JSONDecodeError:
        value = raw
    if isinstance(specs[name].default, float) and isinstance(value, int) \
            and not isinstance(value, bool):
        value = float(value)  # a double parameter given as "1"
    return node, name, value


def control_context() -> dict:
    """The controller and simulator limits every variant runs with (the nodes' defaults)."""
    from ecahd_ros.local_refiner import PARAMETERS as REFINER
    from ecahd_ros.sim_bridge_params import PARAMETERS as SIM

    refiner = {s.name: s.default for s in REFINER}
    sim = {s.name: s.default for s in SIM}
    return {"control_rate_hz": refiner["control_rate"],
            "control_period_s": 1.0 / refiner["control_rate"],
            "max_v": refiner["max_v"], "max_w": refiner["max_w"],
            "max_accel": refiner["max_accel"], "sim_rate_hz": sim["rate_hz"],
            "sim_max_v": sim["max_v"], "sim_max_w": sim["max_w"],
            "control_timeout_s": sim["control_timeout"]}


def _control_clock(settings: NavigationBenchSettings) -> str:
    """What local_refiner's control timer ran on (``ecahd_ros.demo.control_clock`` unless
    overridden)."""
    from ecahd_ros.demo import control_clock

    clock = _overrides(settings, "local_refiner").get(
        "control_clock", control_clock(settings.realtime_factor))
    return "the steady wall clock" if clock == "steady" else "sim time"


def _overrides(settings: NavigationBenchSettings, node: str) -> dict:
    return {name: value for n, name, value in settings.overrides if n == node}


def run_navigation_benchmark(settings: NavigationBenchSettings, out: Path, *,
                             progress: bool = True) -> NavigationBenchResult:
    """Run every selected variant (one ``ecahd demo`` each, into ``out/<key>``)."""
    from tqdm import tqdm

    from ecahd_core.bench.timing import machine_info
    from ecahd_ros.demo import DemoConfig, run_demo

    chosen = [v for v in VARIANTS if v.key in settings.variants]
    base = settings.domain_id if settings.domain_id is not None else 1 + os.getpid() % 90
    results = []
    bar = tqdm(chosen, desc="bench navigation", unit="variant", disable=not progress)
    for i, variant in enumerate(bar):
        bar.set_postfix_str(variant.label)
        planner_params = {**variant.planner_params, **_overrides(settings, "global_planner")}
        refiner_params = {**variant.refiner_params, **_overrides(settings, "local_refiner")}
        log.info("variant %d/%d: %s (planner %s, refiner %s), domain %d", i + 1, len(chosen),
                 variant.label, planner_params, refiner_params, base + i)
        config = DemoConfig(out=out / variant.key, episodes=settings.episodes,
                            robot=settings.robot, map=settings.map, seed=settings.seed,
                            realtime_factor=settings.realtime_factor,
                            max_steps=settings.max_steps, hold_steps=settings.hold_steps,
                            domain_id=base + i, obstacles=settings.obstacles,
                            moving=settings.moving, first_episode=settings.first_episode,
                            planner_params=planner_params, refiner_params=refiner_params)
        t0 = time.monotonic()
        demo = run_demo(config)
        wall = time.monotonic() - t0
        ev = demo.evaluation
        results.append(VariantResult(
            key=variant.key, label=variant.label, summary=ev.summary.to_dict(),
            episodes=[m.to_dict() for m in ev.metrics],
            goal_to_plan_ms=list(demo.goal_to_plan_ms), wall_s=wall,
            episodes_wall_s=demo.wall_s, sim_s=demo.sim_s, out=str(config.out)))
        s = ev.summary
        log.info("%s: %.1f s wall (episodes %.1f s); reward %.1f, reached %d/%d, collision "
                 "%.3f%%, inference %.3f s/episode", variant.label, wall, demo.wall_s,
                 s.episode_reward, round(s.reached * s.episodes), s.episodes, s.collision_rate,
                 s.inference_time_s)
    context = {**control_context(), "machine": machine_info(),
               "realtime_factor": settings.realtime_factor, "max_steps": settings.max_steps}
    return NavigationBenchResult(settings=settings, variants=results, context=context)


# ---------------------------------------------------------------------------------- tables
def _fmt(value, digits: int) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def _pair(a, b, digits: int) -> str:
    return "-" if a is None and b is None else f"{_fmt(a, digits)} / {_fmt(b, digits)}"


def _latency(values: list) -> tuple[float | None, float | None]:
    """(p50, max) [ms] of the goal -> plan latencies that were measured."""
    import numpy as np

    ms = [v for v in values if v is not None]
    return (float(np.percentile(ms, 50)), float(max(ms))) if ms else (None, None)


def format_table(result: NavigationBenchResult) -> str:
    """Rows = metrics; columns = our variants, then the paper's Table III."""
    from ecahd_core.evaluation import PAPER_TABLE_III

    ours, paper = result.variants, list(PAPER_TABLE_III.items())
    head = ["Metric"] + [f"**{v.label}**" for v in ours] + [f"{k} (paper)" for k, _ in paper]
    rows = []

    def row(name: str, cells: list[str], paper_cells: list[str] | None = None) -> None:
        rows.append([name] + cells + (paper_cells or ["-"] * len(paper)))

    row("Episode Reward ↑", [_fmt(v.summary["episode_reward"], 3) for v in ours],
        [f"{r.episode_reward:.3f}" for _, r in paper])
    row("First Reach [steps] ↓", [_fmt(v.summary["first_reach"], 3) for v in ours],
        [f"{r.first_reach:.3f}" for _, r in paper])
    row("Collision Rate [% of sim steps in contact] ↓",
        [_fmt(v.summary["collision_rate"], 4) for v in ours],
        [f"{r.collision_rate:.4f}" for _, r in paper])
    row("Collision, exact checker [% of driven poses in a wall]",
        [_fmt(v.exact_penetration, 3) for v in ours])
    row("Collision-free episodes, exact checker [%]",
        [_fmt(None if v.summary["path_collision_free"] is None
              else 100 * v.summary["path_collision_free"], 0) for v in ours])
    row("Inference Time [s / episode] ↓", [_fmt(v.summary["inference_time_s"], 3) for v in ours],
        [f"{r.inference_time_s:.3f}" for _, r in paper])
    row("Reached episodes", [f"{round(v.summary['reached'] * v.summary['episodes'])} / "
                             f"{v.summary['episodes']}" for v in ours])
    row("Control callback p50 / p99 [ms]",
        [_pair(v.summary.get("control_ms_p50"), v.summary.get("control_ms_p99"), 2)
         for v in ours])
    row("Goal -> first plan p50 / max [ms]",
        [_pair(*_latency(v.goal_to_plan_ms), 1) for v in ours])
    # obstacles off the map, the collision monitor, replanning, cmd_vel timing (issues 9, 11);
    # .get: results saved before these keys existed show "-"
    row("Episodes with a static / moving obstacle contact",
        [_pair(v.summary.get("static_contact_episodes"),
               v.summary.get("moving_contact_episodes"), 0)
         + ("" if v.summary.get("static_contact_episodes") is None
            else f" of {v.summary['episodes']}") for v in ours])
    row("Collision monitor stops / slowdowns / yields [control ticks / episode]",
        [_pair(v.summary.get("monitor_stops"), v.summary.get("monitor_slowdowns"), 1)
         + (" / -" if v.summary.get("monitor_yields") is None
            else f" / {v.summary['monitor_yields']:.1f}") for v in ours])
    row("Global plans (first + replans) / A* fallbacks [per episode]",
        [_pair(v.summary.get("global_plans"), v.summary.get("fallbacks"), 1) for v in ours])
    row("Time to goal [s of sim time, reaching episodes]",
        [_fmt(v.summary.get("time_to_goal_s"), 1) for v in ours])
    row("cmd_vel interval p99 / jitter p99 [ms, wall clock]",
        [_pair(v.summary.get("cmd_interval_ms_p99"), v.summary.get("cmd_jitter_ms_p99"), 1)
         for v in ours])
    row("Wall time: run / episodes [s]", [f"{v.wall_s:.1f} / {v.episodes_wall_s:.1f}"
                                          for v in ours])
    lines = ["| " + " | ".join(head) + " |",
             "|---|" + "---:|" * (len(head) - 1)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def format_markdown(result: NavigationBenchResult) -> str:
    """The table with the settings, limits and machine it was measured with."""
    s, c = result.settings, result.context
    m = c.get("machine", {})
    return (
        f"Closed loop on {s.map}, robot {s.robot}, {s.episodes} seeded "
        f"episode{'s' if s.episodes != 1 else ''} (seed {s.seed}"
        f"{f', from episode {s.first_episode}' if s.first_episode else ''}), the same goals "
        f"for every variant"
        + "".join(f"; {node}.{name} = {value!r} on every variant"
                  for node, name, value in s.overrides)
        + f"; sim_bridge at {c['sim_rate_hz']:g} "
        f"steps per sim second, realtime factor {s.realtime_factor:g}; local_refiner control "
        f"every {c['control_period_s']:g} s ({c['control_rate_hz']:g} Hz) of "
        f"{_control_clock(s)}, "
        f"|v| <= {c['max_v']:g} m/s, |w| <= {c['max_w']:g} rad/s, |dv/dt| <= "
        f"{c['max_accel']:g} m/s²; sim_bridge stops the robot {c['control_timeout_s']:g} s "
        f"after the last cmd_vel. An episode ends once the goal is held for "
        f"{s.hold_steps} control steps or after {s.max_steps} steps (the paper "
        f"counts reward over all 800; --hold-steps 800 does too). Inference time: "
        f"the planning records (SD / FD / A*, J checks, DD), not the control ticks. Machine: "
        f"{m.get('cpu', '?')}, {m.get('logical_cpus', '?')} logical CPUs, torch "
        f"{m.get('torch', '?')} with {m.get('torch_threads', '?')} thread(s) per process, "
        f"Python {m.get('python', '?')}.\n\n" + format_table(result))


def command_line(settings: NavigationBenchSettings) -> str:
    """The ``ecahd bench navigation`` command that reproduces ``settings``."""
    d = NavigationBenchSettings()
    argv = ["ecahd", "bench", "navigation", "--episodes", str(settings.episodes), "--seed",
            str(settings.seed), "--robot", settings.robot, "--map", settings.map]
    if settings.obstacles:
        argv += ["--obstacles", str(settings.obstacles)]
    if settings.moving:
        argv += ["--moving", str(settings.moving)]
    if settings.first_episode:
        argv += ["--first-episode", str(settings.first_episode)]
    default = OBSTACLE_VARIANTS if settings.obstacles or settings.moving else d.variants
    if tuple(settings.variants) != tuple(default):
        argv += ["--variants", *settings.variants]
    if settings.realtime_factor != d.realtime_factor:
        argv += ["--realtime-factor", f"{settings.realtime_factor:g}"]
    if settings.max_steps != d.max_steps:
        argv += ["--max-steps", str(settings.max_steps)]
    if settings.hold_steps != d.hold_steps:
        argv += ["--hold-steps", str(settings.hold_steps)]
    for node, name, value in settings.overrides:
        text = value if isinstance(value, str) else json.dumps(value)
        argv += ["--set", f"{node}.{name}={text}"]
    return shlex.join(argv)


def results_block(result: NavigationBenchResult) -> str:
    """What ``--results`` puts between the markers: the command, then the markdown."""
    return (f"`{command_line(result.settings)}` ({time.strftime('%Y-%m-%d')}):\n\n"
            + format_markdown(result))


def replace_block(text: str, block: str) -> str:
    """``text`` with the lines between BEGIN and END replaced by ``block``; without both
    markers (in that order), ``text`` with a new SECTION holding them appended."""
    lines = text.splitlines(keepends=True)
    stripped = [line.strip() for line in lines]
    body = block if block.endswith("\n") else block + "\n"
    if BEGIN in stripped and END in stripped[stripped.index(BEGIN):]:
        i = stripped.index(BEGIN)
        j = i + stripped[i:].index(END)
        return "".join(lines[:i + 1]) + body + "".join(lines[j:])
    sep = "" if not text or text.endswith("\n\n") else ("\n" if text.endswith("\n") else "\n\n")
    return f"{text}{sep}{SECTION}\n\n{BEGIN}\n{body}{END}\n"


def write_results(path, block: str) -> None:
    from ecahd_core.errors import EcahdError

    path = Path(path)
    try:
        text = path.read_text() if path.exists() else ""
        path.write_text(replace_block(text, block))
    except OSError as exc:
        raise EcahdError(f"cannot update {str(path)!r}: {exc}") from exc


# ------------------------------------------------------------------------------ interface
def add_arguments(p: argparse.ArgumentParser) -> None:
    d = NavigationBenchSettings()
    p.add_argument("--episodes", type=int, default=d.episodes, help="seeded goals per variant")
    p.add_argument("--seed", type=int, default=d.seed, help="seed of the goals and samplers")
    p.add_argument("--robot", default=d.robot,
                   help="footprint: circle | quadruped | humanoid | Nav2 polygon '[[x, y], ...]'")
    p.add_argument("--map", default=d.map,
                   help="built-in maze or Nav2 map YAML; its models: shipped, or found "
                        "through $ECAHD_MODELS (ecahd train-all --out-dir)")
    p.add_argument("--variants", nargs="+", choices=VARIANT_KEYS, default=None,
                   help="which columns to run (ecahd: w/ DD, ecahd-no-dd: w/o DD, astar: A* + "
                        "controller, fd: FD without a local planner; ecahd-blind: without "
                        "sensing, monitor-only: scans reach only the collision monitor); "
                        f"default {list(TABLE_III_VARIANTS)}, with obstacles "
                        f"{list(OBSTACLE_VARIANTS)}")
    p.add_argument("--realtime-factor", type=float, default=d.realtime_factor,
                   help="sim seconds per wall second")
    p.add_argument("--max-steps", type=int, default=d.max_steps, help="control steps per episode")
    p.add_argument("--hold-steps", type=int, default=d.hold_steps,
                   help="control steps the reached goal is held before the next episode "
                        "(>= max-steps: every episode runs its full length, as D4RL counts)")
    p.add_argument("--domain-id", type=int, default=None,
                   help="ROS_DOMAIN_ID of the first variant, the others count up (None: "
                        "from the process id)")
    p.add_argument("--out", default=None,
                   help="folder of the runs (None: runs/bench-navigation-<timestamp>)")
    p.add_argument("--json", metavar="FILE", help="write every variant's results here")
    p.add_argument("--md", metavar="FILE", help="write the markdown table here")
    p.add_argument("--results", metavar="FILE",
                   help=f"put the table and command into FILE between {BEGIN} and {END}")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--set", dest="overrides", action="append", default=[],
                   metavar="NODE.PARAM=VALUE",
                   help="a global_planner or local_refiner parameter for every variant, on top "
                        "of the variant's own (repeatable; VALUE as JSON, e.g. "
                        "local_refiner.monitor_shuttles=true)")
    from ecahd_ros.demo import add_obstacle_arguments

    add_obstacle_arguments(p)


def run(args: argparse.Namespace) -> int:
    from ecahd_core.errors import EcahdError

    if args.episodes < 1 or args.max_steps < 1 or args.hold_steps < 0:
        raise EcahdError("bench navigation needs --episodes >= 1, --max-steps >= 1 and "
                         "--hold-steps >= 0")
    chosen = args.variants or (OBSTACLE_VARIANTS if args.obstacles or args.moving
                               else TABLE_III_VARIANTS)
    settings = NavigationBenchSettings(
        episodes=args.episodes, seed=args.seed, robot=args.robot, map=args.map,
        variants=tuple(k for k in VARIANT_KEYS if k in chosen),
        realtime_factor=args.realtime_factor, max_steps=args.max_steps,
        hold_steps=args.hold_steps, domain_id=args.domain_id, obstacles=args.obstacles,
        moving=args.moving, first_episode=args.first_episode,
        overrides=tuple(parse_override(text) for text in args.overrides))
    out = (Path(args.out) if args.out
           else Path("runs") / time.strftime("bench-navigation-%Y%m%d-%H%M%S"))
    result = run_navigation_benchmark(settings, out, progress=not args.no_progress)
    md = format_markdown(result)
    print(md)
    print(f"runs: {out}")
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "navigation.json", result.to_dict())
    (out / "navigation.md").write_text(md)
    if args.json:
        write_json(args.json, result.to_dict())
    if args.md:
        Path(args.md).parent.mkdir(parents=True, exist_ok=True)
        Path(args.md).write_text(md)
    if args.results:
        write_results(args.results, results_block(result))
        print(f"updated {args.results}")
    return 0


# ------------------------------------------------------------------- `ecahd bench` as a whole
def benchmarks() -> dict:
    """Every ``ecahd bench`` benchmark: the core's, then navigation."""
    from ecahd_core.commands.bench import BENCHMARKS, Benchmark

    from ecahd_ros import bench_control

    return {**BENCHMARKS,
            "navigation": Benchmark(help=HELP, add_arguments=add_arguments, run=run),
            "control": Benchmark(help=bench_control.HELP,
                                 add_arguments=bench_control.add_arguments,
                                 run=bench_control.run)}


def add_bench_arguments(parser: argparse.ArgumentParser) -> None:
    """``ecahd bench`` takes the benchmark name, then that benchmark's options."""
    from ecahd_core.commands.bench import add_arguments as add_core_bench_arguments

    add_core_bench_arguments(parser, benchmarks())


def run_bench(args: argparse.Namespace) -> int:
    """Run ``args.benchmark`` after its ``--threads`` is applied (``ecahd_core.commands.bench``)."""
    from ecahd_core.commands.bench import run as run_core_bench

    return run_core_bench(args, benchmarks())
