"""Benchmark of the cost J (Algorithm 2 lines 11-25): forward + backward of the batched torch
version next to the same computation as the literal Python loops, in one run.

The default problem is one dense-diffusion guidance step of the paper (Sec. IV-A): B = 10 local
trajectories of P^l = 4 points on maze2d-large, the circle footprint (|R| = 34 sample points at
the default spacing) and N_interp = 8 DDA points per segment, float32 on the CPU.

torch is imported inside the functions, so ``ecahd --help`` does not load it.
"""
from __future__ import annotations

import logging
import os
import platform
from dataclasses import asdict, dataclass

from ecahd_core.maps import DEFAULT_MAP
from ecahd_core.bench.timing import median_ms
from ecahd_core.errors import EcahdError

log = logging.getLogger(__name__)


@dataclass(frozen=True, kw_only=True)
class CostBenchSettings:
    """What the cost benchmark measures (one place defines each default).

    Attributes:
        batch: B, trajectories per call of J.
        horizon: P^l, points per trajectory.
        n_interp: N_interp, DDA points per segment.
        footprint: footprint preset or Nav2 polygon string (see ecahd_core.footprint).
        map_name: built-in map.
        mode: cost mode ("surface" is the paper's method).
        repeats: timed calls of the batched J (median reported).
        loop_repeats: timed calls of the loop reference; 0 skips it.
        warmup: untimed calls of the batched J first.
        threads: torch intra-op threads during the run; None keeps torch's setting. Tensors
            this small gain nothing from more threads, so 1 is the default.
        seed: seed of the random trajectories.
    """

    batch: int = 10
    horizon: int = 4
    n_interp: int = 8
    footprint: str = "circle"
    map_name: str = DEFAULT_MAP
    mode: str = "surface"
    repeats: int = 200
    loop_repeats: int = 3
    warmup: int = 20
    threads: int | None = 1
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("batch", "horizon", "n_interp", "repeats"):
            if getattr(self, name) < 1:
                raise EcahdError(f"bench cost: {name} must be >= 1, got {getattr(self, name)}")
        for name in ("loop_repeats", "warmup"):
            if getattr(self, name) < 0:
                raise EcahdError(f"bench cost: {name} must be >= 0, got {getattr(self, name)}")
        if self.threads is not None and self.threads < 1:
            raise EcahdError(f"bench cost: threads must be >= 1, got {self.threads}")


@dataclass(frozen=True)
class CostBenchResult:
    """Median wall-clock times [ms] of one forward + backward pass of J, and the context."""

    batched_ms: float
    loop_ms: float | None  # None when the loop reference was skipped
    speedup: float | None  # loop_ms / batched_ms
    max_abs_diff: float | None  # largest |J_batched - J_loops| over the batch (agreement check)
    B: int
    P: int
    R: int
    n_interp: int
    samples: int  # map lookups per call: B ((P-1) N + 1) R
    mode: str
    map: str
    footprint: str
    dtype: str
    device: str
    threads: int
    repeats: int
    loop_repeats: int
    torch: str
    python: str
    cpu_count: int | None

    def to_dict(self) -> dict:
        return asdict(self)


def make_problem(settings: CostBenchSettings):
    """Deterministic inputs of J: (traj (B, P, 2) requiring grad, goal (B, 2), footprint (R, 2),
    cost map), float32 on the CPU. Each trajectory starts at a random free cell centre and runs
    about 1 m in a random direction with 5 cm jitter, so many of them brush a wall."""
    import numpy as np
    import torch

    from ecahd_core.costmap import CostMap
    from ecahd_core.footprint import make_footprint
    from ecahd_core.maps import builtin_map

    grid = builtin_map(settings.map_name)
    costmap = CostMap.from_grid(grid)
    footprint = torch.as_tensor(make_footprint(settings.footprint).points, dtype=torch.float32)
    rng = np.random.default_rng(settings.seed)
    free = grid.free_cell_centres()
    start = free[rng.integers(len(free), size=settings.batch)]  # (B, 2)
    angle = rng.uniform(-np.pi, np.pi, size=settings.batch)
    direction = np.stack([np.cos(angle), np.sin(angle)], axis=1)  # (B, 2)
    frac = np.linspace(0.0, 1.0, settings.horizon)  # (P,)
    traj = start[:, None] + frac[None, :, None] * direction[:, None]  # (B, P, 2)
    traj = traj + rng.normal(scale=0.05, size=traj.shape)
    traj_t = torch.tensor(traj, dtype=torch.float32, requires_grad=True)
    goal = torch.tensor(traj[:, -1], dtype=torch.float32)
    return traj_t, goal, footprint, costmap




def run_cost_benchmark(settings: CostBenchSettings = CostBenchSettings()) -> CostBenchResult:
    """Time forward + backward of J, batched and as literal loops, on the same inputs."""
    import torch

    from ecahd_core.cost import trajectory_cost, trajectory_cost_loops

    previous_threads = torch.get_num_threads()
    if settings.threads is not None:
        torch.set_num_threads(settings.threads)
    try:
        traj, goal, footprint, costmap = make_problem(settings)
        kwargs = dict(mode=settings.mode, n_interp=settings.n_interp)

        def batched():
            terms = trajectory_cost(traj, goal, footprint, costmap, **kwargs)
            return torch.autograd.grad(terms.total.sum(), traj)[0]

        def loops():
            terms = trajectory_cost_loops(traj, goal, footprint, costmap, **kwargs)
            return torch.autograd.grad(terms.total.sum(), traj)[0]

        batched_ms = median_ms(batched, settings.repeats, settings.warmup)
        loop_ms = speedup = max_abs_diff = None
        if settings.loop_repeats:
            log.info("timing the loop reference (%d run(s), a few seconds each)",
                     settings.loop_repeats)
            loop_ms = median_ms(loops, settings.loop_repeats)
            speedup = loop_ms / batched_ms
            with torch.no_grad():
                a = trajectory_cost(traj, goal, footprint, costmap, **kwargs).total
                b = trajectory_cost_loops(traj, goal, footprint, costmap, **kwargs).total
            max_abs_diff = float((a - b).abs().max())
        threads = torch.get_num_threads()
    finally:
        torch.set_num_threads(previous_threads)
    B, P, _ = traj.shape
    R = footprint.shape[0] if settings.mode == "surface" else 1
    M = P if settings.mode == "point" else (P - 1) * settings.n_interp + 1
    return CostBenchResult(
        batched_ms=batched_ms, loop_ms=loop_ms, speedup=speedup, max_abs_diff=max_abs_diff,
        B=B, P=P, R=R, n_interp=settings.n_interp, samples=B * M * R, mode=settings.mode,
        map=settings.map_name, footprint=settings.footprint,
        dtype=str(traj.dtype).removeprefix("torch."),
        device=str(traj.device), threads=threads, repeats=settings.repeats,
        loop_repeats=settings.loop_repeats, torch=torch.__version__,
        python=platform.python_version(), cpu_count=os.cpu_count())


def format_table(result: CostBenchResult) -> str:
    """A small human-readable table of a result."""
    r = result
    lines = [
        f"cost J forward+backward, mode {r.mode}: B={r.B} x P={r.P} x R={r.R}"
        f" x N_interp={r.n_interp} ({r.samples} map lookups) on {r.map}, {r.dtype} {r.device}, {r.threads} thread(s),"
        f" torch {r.torch}",
        f"{'variant':<10}{'median [ms]':>14}{'runs':>8}",
        f"{'batched':<10}{r.batched_ms:>14.3f}{r.repeats:>8d}",
    ]
    if r.loop_ms is None:
        lines.append(f"{'loops':<10}{'skipped':>14}{0:>8d}")
    else:
        lines.append(f"{'loops':<10}{r.loop_ms:>14.1f}{r.loop_repeats:>8d}")
        lines.append(f"speedup (loops / batched): {r.speedup:.0f}x;"
                     f" max |J_batched - J_loops| = {r.max_abs_diff:.2e}")
    return "\n".join(lines)
