"""``ecahd bench contention``: plan latency on a quiet CPU and beside a CPU hog, in one run.

Why (issue 9): ``ecahd plan`` took 0.41 s on a quiet 2-core machine and 35 s while a training
run used the CPU, because two torch thread pools oversubscribed two cores. Inference therefore
runs with :data:`ecahd_core.threads.INFERENCE_THREADS` (1) torch thread; this benchmark shows
what that buys.

Workloads (the shipped models of the map, the core's default planner settings, as
``ecahd plan`` builds them):
- ``sd``  Sparse Diffusion best-of-N alone (``SparseDiffusion.plan``, N = 10), one problem;
- ``hd``  Algorithm 1 with ``replan="once"`` (``HierarchicalPlanner``: one SD best-of-N, then
          guided DD where J exceeds c_th, polishing, the exact rule) on a few held-out problems
          (``ecahd_core.problems``, seed 2026);
- ``alg1`` Algorithm 1 as the nodes run it: an SD re-plan at every waypoint with the map's
          rules (``SparseStage``: the same code as global_planner's) and the local stages, on
          the same problems: what ``ecahd plan`` runs.

Each workload is timed with torch threads = ``threads`` (ours, default 1) and, as the cautionary
reference, = every core, under three conditions:
- ``none``   no hog (on a shared machine "quiet" means: no hog of ours; the 1-minute load
             average before each cell is recorded);
- ``torch``  one child process training a small MLP with torch's default threads (every core),
             as a naive training run would;
- ``spin``   one busy pure-Python process per core.

Hogs are separate processes (``multiprocessing``, spawn) started before a cell and terminated
(then killed, then reaped) after it; each also exits by itself when its parent is gone. A cell
stops timing a workload after ``budget_s`` seconds (at least one call is timed), so the slow
reference cells cannot stretch the run. Reported per cell: p50 / p99 [ms] and the ratios
hogged / quiet of the same workload and thread count; the issue's target is hogged p50 <= 3x
quiet with our default.
"""
from __future__ import annotations

import logging
import math
import multiprocessing
import os
import time
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from ecahd_core.maps import DEFAULT_MAP
from ecahd_core.errors import EcahdError
from ecahd_core.problems import DEFAULT_SEED
from ecahd_core.threads import INFERENCE_THREADS, set_torch_threads, training_threads

log = logging.getLogger(__name__)

HOGS = ("torch", "spin")
WORKLOADS = ("sd", "hd", "alg1")
WORKLOAD_LABELS = {"sd": "SD best-of-N", "hd": "Alg. 1, replan once",
                   "alg1": "Alg. 1, every waypoint"}
TARGET_RATIO = 3.0  # issue 9: hogged <= 3x quiet with our default threads


@dataclass(frozen=True, kw_only=True)
class ContentionBenchSettings:
    """Attributes:
        map, robot: the shipped models' map and the footprint J is computed for.
        threads: our torch threads (the default of nodes and ``ecahd plan``).
        reference_threads: the cautionary reference (None: every core).
        candidates: SD's N (best of N).
        sd_repeats: timed SD calls per cell.
        problems: held-out problems for Algorithm 1; ``hd_rounds`` passes over them per cell.
        seed, sample_seed: seeds of the problems and of the samples.
        hogs: which hogs to run (``torch``, ``spin``).
        spinners: processes of the ``spin`` hog (None: one per core).
        hog_width: the torch hog's MLP width and batch.
        budget_s: [s] a cell stops timing a workload after this (at least one call).
        settle_s: [s] between a hog's start and the first timed call.
        warmup: untimed calls of each workload per thread count, before its quiet cell.
    """

    map: str = DEFAULT_MAP
    robot: str = "circle"
    threads: int = INFERENCE_THREADS
    reference_threads: int | None = None
    candidates: int = 10
    sd_repeats: int = 20
    problems: int = 4
    hd_rounds: int = 2
    seed: int = DEFAULT_SEED
    sample_seed: int = 0
    hogs: tuple[str, ...] = HOGS
    spinners: int | None = None
    hog_width: int = 512
    budget_s: float = 10.0
    settle_s: float = 1.0
    warmup: int = 2

    def __post_init__(self) -> None:
        for name in ("threads", "candidates", "sd_repeats", "problems", "hd_rounds",
                     "hog_width"):
            if getattr(self, name) < 1:
                raise EcahdError(f"bench contention: {name} must be >= 1, got "
                                 f"{getattr(self, name)}")
        for name in ("reference_threads", "spinners"):
            value = getattr(self, name)
            if value is not None and value < 1:
                raise EcahdError(f"bench contention: {name} must be >= 1 or None, got {value}")
        bad = [h for h in self.hogs if h not in HOGS]
        if bad or not self.hogs:
            raise EcahdError(f"bench contention: hogs must be some of {HOGS}, got {self.hogs}")
        if self.budget_s <= 0 or self.settle_s < 0 or self.warmup < 0:
            raise EcahdError("bench contention: budget_s must be > 0, settle_s and warmup >= 0")

    def quick(self) -> "ContentionBenchSettings":
        """The same benchmark at a smoke-test size (seconds, not minutes)."""
        return replace(self, candidates=2, sd_repeats=2, problems=1, hd_rounds=1,
                       hog_width=32, budget_s=1.0, settle_s=0.1, warmup=1,
                       spinners=min(self.spinners or 2, 2))

    def thread_counts(self) -> tuple[int, ...]:
        """Ours first, then the reference (once, when they are the same)."""
        ref = self.reference_threads or training_threads()
        return (self.threads,) if ref == self.threads else (self.threads, ref)


@dataclass
class Cell:
    """One workload x torch threads x hog: latencies [ms] of its timed calls."""

    workload: str  # one of WORKLOADS
    threads: int
    hog: str  # "none" | "torch" | "spin"
    p50_ms: float
    p99_ms: float
    mean_ms: float
    calls: int
    budget_hit: bool  # stopped by budget_s before every planned call ran
    load_before: float  # 1-minute load average when the cell started
    times_ms: list[float] = field(default_factory=list)


@dataclass
class ContentionBenchResult:
    cells: list[Cell]
    ratios: list[dict]  # workload, threads, hog, p50_ratio, p99_ratio, within_target
    context: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"cells": [asdict(c) for c in self.cells], "ratios": self.ratios,
                "context": self.context}


# ------------------------------------------------------------------------------------- hogs
def _parent_gone(parent: int) -> bool:
    return os.getppid() != parent


def _spin_hog(parent: int, ready) -> None:
    """A busy pure-Python loop (one core), until terminated or its parent is gone."""
    ready.set()
    n = 0
    while True:
        n += 1
        if n % 2_000_000 == 0 and _parent_gone(parent):
            return


def _torch_hog(parent: int, ready, width: int, threads: int) -> None:
    """A naive training run: MLP steps with ``threads`` torch threads (every core)."""
    import torch

    torch.set_num_threads(threads)
    gen = torch.Generator().manual_seed(0)
    model = torch.nn.Sequential(torch.nn.Linear(width, width), torch.nn.ReLU(),
                                torch.nn.Linear(width, width), torch.nn.ReLU(),
                                torch.nn.Linear(width, 1))
    opt = torch.optim.Adam(model.parameters(), lr=1e-4)
    x = torch.randn(width, width, generator=gen)  # (batch, width)
    y = torch.randn(width, 1, generator=gen)
    ready.set()
    step = 0
    while True:
        loss = ((model(x) - y) ** 2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        step += 1
        if step % 10 == 0 and _parent_gone(parent):
            return


def stop_processes(procs, timeout_s: float = 5.0) -> None:
    """Terminate, then kill, then reap every process of ``procs`` (no orphans, no zombies)."""
    for p in procs:
        if p.is_alive():
            p.terminate()
    deadline = time.monotonic() + timeout_s
    for p in procs:
        p.join(max(0.0, deadline - time.monotonic()))
        if p.is_alive():
            p.kill()
            p.join()


@contextmanager
def cpu_hog(kind: str, *, spinners: int, width: int, threads: int, settle_s: float,
            start_timeout_s: float = 120.0):
    """Run hog ``kind`` ("none", "torch" or "spin") for the body; yields the hog's pids."""
    if kind == "none":
        yield []
        return
    ctx = multiprocessing.get_context("spawn")
    parent = os.getpid()
    if kind == "torch":
        plan = [(_torch_hog, (width, threads))]
    elif kind == "spin":
        plan = [(_spin_hog, ())] * spinners
    else:
        raise EcahdError(f"unknown hog {kind!r}; allowed: none, {', '.join(HOGS)}")
    procs, events = [], []
    try:
        for i, (target, extra) in enumerate(plan):
            ready = ctx.Event()
            p = ctx.Process(target=target, args=(parent, ready, *extra), daemon=True,
                            name=f"ecahd-hog-{kind}-{i}")
            p.start()
            procs.append(p)
            events.append(ready)
        deadline = time.monotonic() + start_timeout_s
        for p, ready in zip(procs, events):
            if not ready.wait(max(0.0, deadline - time.monotonic())):
                raise EcahdError(f"the {kind} hog (pid {p.pid}) did not start within "
                                 f"{start_timeout_s:.0f} s (exit code {p.exitcode})")
        time.sleep(settle_s)
        yield [p.pid for p in procs]
    finally:
        stop_processes(procs)


# ------------------------------------------------------------------------------- measuring
def _time_calls(fn, calls: int, budget_s: float) -> tuple[list[float], bool]:
    """Wall times [ms] of up to ``calls`` calls of ``fn(i)``, stopping after ``budget_s``."""
    times = []
    t_start = time.perf_counter()
    for i in range(calls):
        if times and time.perf_counter() - t_start > budget_s:
            return times, True
        t0 = time.perf_counter()
        fn(i)
        times.append(1e3 * (time.perf_counter() - t0))
    return times, False


def _cell(workload, threads, hog, times, budget_hit, load) -> Cell:
    t = np.asarray(times, dtype=np.float64)
    return Cell(workload=workload, threads=threads, hog=hog,
                p50_ms=float(np.percentile(t, 50)), p99_ms=float(np.percentile(t, 99)),
                mean_ms=float(t.mean()), calls=len(times), budget_hit=budget_hit,
                load_before=load, times_ms=[float(x) for x in t])


def _ratios(cells: list[Cell], ours: int) -> list[dict]:
    quiet = {(c.workload, c.threads): c for c in cells if c.hog == "none"}
    out = []
    for c in cells:
        if c.hog == "none":
            continue
        q = quiet[(c.workload, c.threads)]
        p50, p99 = c.p50_ms / q.p50_ms, c.p99_ms / q.p99_ms
        out.append({"workload": c.workload, "threads": c.threads, "hog": c.hog,
                    "p50_ratio": p50, "p99_ratio": p99,
                    "within_target": bool(p50 <= TARGET_RATIO) if c.threads == ours else None})
    return out


def _planners(settings: ContentionBenchSettings):
    """SparseDiffusion and the two HierarchicalPlanners (replan once; every waypoint with the
    map's rules, as the nodes re-plan) with the core's defaults, as ``ecahd plan`` and
    ``ecahd bench planning`` build them from the shipped models."""
    from ecahd_core.footprint import make_footprint
    from ecahd_core.maps import load_map
    from ecahd_core.planning.hierarchical import HierarchicalPlanner
    from ecahd_core.planning.sparse import SparseConfig, SparseDiffusion

    grid = load_map(settings.map)
    fp = make_footprint(settings.robot)
    sd = SparseDiffusion.for_map(grid, fp, SparseConfig(num_candidates=settings.candidates,
                                                        selection="collision_aware"))
    once = HierarchicalPlanner.for_map(grid, fp, sd, replan="once")
    every = HierarchicalPlanner.for_map(grid, fp, sd)
    return grid, sd, once, every


def run_contention_benchmark(settings: ContentionBenchSettings) -> ContentionBenchResult:
    """Every workload x thread count x hog, in one process; torch's threads are restored."""
    import torch

    from ecahd_core.bench.timing import machine_info
    from ecahd_core.problems import make_problems

    previous_threads = torch.get_num_threads()
    grid, sd, once, every = _planners(settings)
    problems = make_problems(grid, settings.problems, seed=settings.seed)
    gen = torch.Generator()
    p0 = problems[0]
    workloads = {
        "sd": (lambda i: sd.plan(p0.start, p0.goal, generator=gen), settings.sd_repeats),
        "hd": (lambda i: once.plan(problems[i % len(problems)].start,
                                   problems[i % len(problems)].goal, generator=gen),
               settings.problems * settings.hd_rounds),
        "alg1": (lambda i: every.plan(problems[i % len(problems)].start,
                                      problems[i % len(problems)].goal, generator=gen),
                 settings.problems * settings.hd_rounds),
    }
    spinners = settings.spinners or training_threads()
    cells, hog_pids = [], []
    t_run = time.perf_counter()
    try:
        for threads in settings.thread_counts():
            set_torch_threads(threads)
            gen.manual_seed(settings.sample_seed)
            for fn, calls in workloads.values():
                for i in range(settings.warmup):
                    fn(i)
            for hog in ("none", *settings.hogs):
                load = os.getloadavg()[0]
                with cpu_hog(hog, spinners=spinners, width=settings.hog_width,
                             threads=training_threads(), settle_s=settings.settle_s) as pids:
                    hog_pids.extend(pids)
                    for workload, (fn, calls) in workloads.items():
                        gen.manual_seed(settings.sample_seed)
                        times, hit = _time_calls(fn, calls, settings.budget_s)
                        cells.append(_cell(workload, threads, hog, times, hit, load))
                        log.info("%s, %d thread(s), hog %s: p50 %.0f ms, p99 %.0f ms (%d calls)",
                                 workload, threads, hog, cells[-1].p50_ms, cells[-1].p99_ms,
                                 len(times))
    finally:
        torch.set_num_threads(previous_threads)
    context = {"map": grid.name, "robot": settings.robot, "candidates": settings.candidates,
               "problems": len(problems), "seed": settings.seed,
               "sample_seed": settings.sample_seed, "threads": settings.threads,
               "thread_counts": list(settings.thread_counts()), "hogs": list(settings.hogs),
               "spinners": spinners, "hog_width": settings.hog_width,
               "hog_torch_threads": training_threads(), "budget_s": settings.budget_s,
               "settle_s": settings.settle_s, "target_ratio": TARGET_RATIO,
               "hog_pids": hog_pids, "wall_s": time.perf_counter() - t_run,
               "machine": machine_info()}
    return ContentionBenchResult(cells=cells, ratios=_ratios(cells, settings.threads),
                                 context=context)


# ---------------------------------------------------------------------------------- table
def format_table(r: ContentionBenchResult) -> str:
    c = r.context
    m = c["machine"]
    ratio = {(x["workload"], x["threads"], x["hog"]): x for x in r.ratios}
    lines = [
        f"Plan latency beside a CPU hog: {c['map']}, {c['robot']}, SD best of "
        f"{c['candidates']}, Alg. 1 (replan once; every waypoint, as the nodes) on "
        f"{c['problems']} held-out problems; "
        f"{m['cpu']}, {m['logical_cpus']} logical CPUs, torch {m['torch']}",
        f"hogs: torch = one MLP training process (width {c['hog_width']}, "
        f"{c['hog_torch_threads']} threads), spin = {c['spinners']} busy Python processes; "
        f"'none' = no hog of ours (load average before each cell in the last column)",
        "",
        f"{'workload':<20} {'threads':>7} {'hog':>5} {'calls':>5} {'p50 ms':>8} {'p99 ms':>8} "
        f"{'p50 x':>6} {'p99 x':>6} {'load':>5}",
    ]
    for cell in r.cells:
        x = ratio.get((cell.workload, cell.threads, cell.hog))
        p50x = f"{x['p50_ratio']:.1f}" if x else "-"
        p99x = f"{x['p99_ratio']:.1f}" if x else "-"
        calls = f"{cell.calls}{'*' if cell.budget_hit else ''}"
        lines.append(f"{WORKLOAD_LABELS[cell.workload]:<20} {cell.threads:>7} {cell.hog:>5} "
                     f"{calls:>5} {cell.p50_ms:>8.0f} {cell.p99_ms:>8.0f} {p50x:>6} {p99x:>6} "
                     f"{cell.load_before:>5.1f}")
    ours = [x for x in r.ratios if x["within_target"] is not None]
    met = all(x["within_target"] for x in ours)
    worst = max((x["p50_ratio"] for x in ours), default=math.nan)
    lines += ["", f"target (issue 9): hogged p50 <= {c['target_ratio']:.0f}x quiet with "
                  f"{c['threads']} thread(s): {'met' if met else 'NOT met'} (worst "
                  f"{worst:.1f}x); * = stopped by the {c['budget_s']:.0f} s budget; "
                  f"{c['wall_s']:.0f} s in all"]
    return "\n".join(lines)


# ------------------------------------------------------------------------------ interface
def add_arguments(parser) -> None:
    d = ContentionBenchSettings()
    parser.add_argument("--map", default=d.map, help="built-in maze with shipped models")
    parser.add_argument("--robot", default=d.robot, help="footprint J is computed for")
    parser.add_argument("--reference-threads", type=int, default=None, metavar="T",
                        help="the cautionary reference's torch threads (default: every core)")
    parser.add_argument("--sd-repeats", type=int, default=d.sd_repeats, metavar="N",
                        help="timed SD best-of-N calls per cell")
    parser.add_argument("--problems", type=int, default=d.problems, metavar="N",
                        help="held-out problems for Algorithm 1 (both policies)")
    parser.add_argument("--hd-rounds", type=int, default=d.hd_rounds, metavar="N",
                        help="passes over the problems per cell")
    parser.add_argument("--hogs", nargs="+", choices=HOGS, default=list(d.hogs),
                        help="torch: one training process on every core; spin: one busy "
                             "Python process per core")
    parser.add_argument("--spinners", type=int, default=None, metavar="N",
                        help="processes of the spin hog (default: one per core)")
    parser.add_argument("--budget", type=float, default=d.budget_s, metavar="S",
                        help="[s] a cell stops timing a workload after this")
    parser.add_argument("--quick", action="store_true",
                        help="smoke-test size (SD best of 2, 2 calls, 1 problem, tiny hog)")
    parser.add_argument("--json", metavar="FILE", help="also write the result as JSON to FILE")


def settings_from_args(args) -> ContentionBenchSettings:
    settings = ContentionBenchSettings(
        map=args.map, robot=args.robot, threads=args.threads,
        reference_threads=args.reference_threads, sd_repeats=args.sd_repeats,
        problems=args.problems, hd_rounds=args.hd_rounds, hogs=tuple(args.hogs),
        spinners=args.spinners, budget_s=args.budget)
    return settings.quick() if args.quick else settings
