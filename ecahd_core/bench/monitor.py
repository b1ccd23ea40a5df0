"""Benchmark of the obstacle path of issue 11: per-call wall time (p50 / p99) of
:meth:`CollisionMonitor.filter` and of :meth:`LocalCostmap.update` + :meth:`fused_costmap`,
each next to its budget and to a plain reference measured in the same run:

- ``filter``: 360 scan points (a ring 0.9 m around the robot, all within reach), a 10-step
  horizon; budget 2 ms (a 50 Hz command stream). Reference: the same clearance test written as a
  loop over the steps calling :func:`ecahd_core.footprint.point_in_polygon` (inside test only).
- ``static``: the filter with the optional static-map check of the command over 0.5 s
  (``static_horizon``, off by default; ``StaticClearance`` depths); budget 2 ms.
- ``yield``: the filter when a moving obstacle (a cylinder's 20 returns, coming at the robot
  at 0.4 m/s, among the 360) makes it look for an escape: 14 commands over the 3 s yield
  horizon, each pose checked on the static map (``StaticClearance``: the distance transform in
  the open, the exact checker near walls); budget 2 ms.
- ``track``: :meth:`MotionTracker.update` on 360 returns in 6 moving clusters (the worst case:
  every return unmapped); budget 10 ms, a tenth of a 10 Hz scan period (it runs on the scan
  worker, not in the control tick).
- ``update``: 360 beams on a 200 x 200 window (6 m at 0.03 m); budget 5 ms.
- ``fused``: the fused cost map over a 2000 x 2000 static map (60 m at 0.03 m, a few walls);
  budget 100 ms (10 Hz scans). Reference: rebuilding the whole cost map with the marks drawn in
  (``CostConfig.make_costmap``), what fusing without a window would cost.

``ecahd bench monitor`` runs it; torch is imported inside the functions, so ``ecahd --help``
does not load it.
"""
from __future__ import annotations

import argparse
import math
import platform
import time
from dataclasses import asdict, dataclass

from ecahd_core.errors import EcahdError

FILTER_BUDGET_MS = 2.0  # [ms] one CollisionMonitor.filter call
UPDATE_BUDGET_MS = 5.0  # [ms] one LocalCostmap.update (360 beams, 200 x 200 window)
TRACK_BUDGET_MS = 10.0  # [ms] one MotionTracker.update: 10% of a 10 Hz scan period (scan worker)
FUSED_BUDGET_MS = 100.0  # [ms] update + fused_costmap at 10 Hz scans


@dataclass(frozen=True, kw_only=True)
class MonitorBenchSettings:
    """What the monitor benchmark measures (one place defines each default).

    Attributes:
        points: scan points per filter call (and beams per scan).
        map_cells: side of the square static map [cells].
        resolution: [m/cell] of the static map and the window.
        window: [m] side of the local window.
        footprint: footprint preset or Nav2 polygon string.
        repeats: timed calls per measurement (p50 / p99 reported).
        reference_repeats: timed calls of the references (the full-map rebuild takes ~0.5 s).
        warmup: untimed calls first.
        threads: torch intra-op threads during the run; None keeps torch's setting.
        seed: seed of the simulated ranges.
    """

    points: int = 360
    map_cells: int = 2000
    resolution: float = 0.03
    window: float = 6.0
    footprint: str = "quadruped"
    repeats: int = 100
    reference_repeats: int = 3
    warmup: int = 5
    threads: int | None = 1
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("points", "map_cells", "repeats", "reference_repeats"):
            if getattr(self, name) < 1:
                raise EcahdError(f"bench monitor: {name} must be >= 1, got {getattr(self, name)}")
        if self.warmup < 0:
            raise EcahdError(f"bench monitor: warmup must be >= 0, got {self.warmup}")
        if not (self.resolution > 0 and self.window > 0):
            raise EcahdError("bench monitor: resolution and window must be > 0 m")
        if self.threads is not None and self.threads < 1:
            raise EcahdError(f"bench monitor: threads must be >= 1, got {self.threads}")


@dataclass(frozen=True)
class Timing:
    """Per-call wall time [ms] of one measured function, and how it compares."""

    p50_ms: float
    p99_ms: float
    calls: int
    budget_ms: float
    reference_ms: float | None  # median of the reference, None if none

    @property
    def budget_ratio(self) -> float:
        """p99 / budget: below 1 fits."""
        return self.p99_ms / self.budget_ms

    @property
    def speedup(self) -> float | None:
        """reference / p50."""
        return None if self.reference_ms is None else self.reference_ms / self.p50_ms


@dataclass(frozen=True)
class MonitorBenchResult:
    filter: Timing
    static: Timing
    yield_: Timing
    track: Timing
    update: Timing
    fused: Timing
    settings: MonitorBenchSettings
    steps: int
    window_cells: int
    map_cells: int
    footprint_vertices: int
    torch: str
    python: str
    threads: int

    def to_dict(self) -> dict:
        out = asdict(self)
        for name in ("filter", "static", "yield_", "track", "update", "fused"):
            t = getattr(self, name)
            out[name].update(budget_ratio=t.budget_ratio, speedup=t.speedup)
        return out


def rng_points(seed: int, n: int):
    """(n, 2) [m] cluster centres 1-3 m from the origin, seeded."""
    import numpy as np

    rng = np.random.default_rng(seed)
    a, r = rng.uniform(0, 2 * math.pi, n), rng.uniform(1.0, 3.0, n)
    return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)


def _percentiles_ms(fn, repeats: int, warmup: int) -> tuple[float, float]:
    """(p50, p99) wall time [ms] of ``repeats`` calls of ``fn`` after ``warmup`` calls."""
    import numpy as np

    for _ in range(warmup):
        fn()
    times = np.empty(repeats)
    for i in range(repeats):
        t0 = time.perf_counter()
        fn()
        times[i] = time.perf_counter() - t0
    return 1e3 * float(np.percentile(times, 50)), 1e3 * float(np.percentile(times, 99))


def run_monitor_benchmark(settings: MonitorBenchSettings = MonitorBenchSettings()
                          ) -> MonitorBenchResult:
    """Time the filter, the window update and the fused cost map (see the module docstring)."""
    import numpy as np
    import torch

    from ecahd_core.collision_monitor import CollisionMonitor
    from ecahd_core.cost import CostConfig
    from ecahd_core.footprint import make_footprint, point_in_polygon
    from ecahd_core.local_costmap import LocalCostmap, LocalCostmapConfig
    from ecahd_core.maps import OCCUPIED, GridMap

    s = settings
    previous_threads = torch.get_num_threads()
    if s.threads is not None:
        torch.set_num_threads(s.threads)
    try:
        # ------------------------------------------------------------------- the filter
        footprint = make_footprint(s.footprint)
        monitor = CollisionMonitor(footprint)
        angle = np.linspace(-math.pi, math.pi, s.points, endpoint=False)
        ring = 0.9 * np.stack([np.cos(angle), np.sin(angle)], axis=1)  # (M, 2) [m]
        pose = (0.0, 0.0, 0.0)
        p50, p99 = _percentiles_ms(lambda: monitor.filter(pose, 0.5, 0.3, ring, 0.0, 0.0),
                                   s.repeats, s.warmup)
        poses = monitor.simulate(pose, 0.5, 0.3)  # (K+1, 3)

        def filter_reference():
            for x, y, yaw in poses:  # one step at a time, points into the robot frame
                c, sn = math.cos(yaw), math.sin(yaw)
                d = ring - (x, y)
                local = np.stack([c * d[:, 0] + sn * d[:, 1], -sn * d[:, 0] + c * d[:, 1]], 1)
                point_in_polygon(local, footprint.polygon)

        ref, _ = _percentiles_ms(filter_reference, s.repeats, s.warmup)
        filter_t = Timing(p50, p99, s.repeats, FILTER_BUDGET_MS, ref)

        n = s.map_cells
        data = np.zeros((n, n), dtype=np.int8)
        for k in range(1, 8):  # a few walls across the map
            data[k * n // 8, : n // 2] = OCCUPIED  # rows in the left half
            data[n // 2:, k * n // 8] = OCCUPIED  # columns in the upper half
        grid = GridMap(data=data, resolution=s.resolution, name=f"bench {n}x{n}")
        centre = 0.5 * n * s.resolution + 0.3 * s.resolution  # [m] off the walls

        # ------------------------------------------------------------ yield and tracker
        from ecahd_core.collision_monitor import CollisionMonitorConfig
        from ecahd_core.sensing import StaticClearance
        from ecahd_core.tracking import MotionTracker

        yielding = CollisionMonitor(footprint, CollisionMonitorConfig(escape_limits=(0.5, 1.5)))
        here = (centre + 1.0, centre - 1.0, 0.0)  # clear of the walls (rows left, columns up)
        arc = math.pi + np.linspace(-1.2, 1.2, 20)  # the near side of a 0.2 m cylinder
        cyl = np.stack([here[0] + 1.3 + 0.2 * np.cos(arc), here[1] + 0.2 * np.sin(arc)], 1)
        ring_here = ring[20:] + here[:2]  # (M - 20, 2) static returns
        pts = np.concatenate([cyl, ring_here])  # (M, 2)
        vel = np.zeros_like(pts)
        vel[:len(cyl)] = (-0.4, 0.0)  # coming at the robot
        clear = StaticClearance(grid)  # what local_refiner's LocalWorld.free uses
        depths = lambda q: clear.depths(q, footprint)  # noqa: E731
        probe = yielding.filter(here, 0.5, 0.0, pts, 0.0, 0.0, velocities=vel, depths=depths)
        if probe.action != "yield":
            raise EcahdError(f"bench monitor: the yield case did not yield ({probe.reason})")
        checking = CollisionMonitor(footprint, CollisionMonitorConfig(static_horizon=0.5))
        s50, s99 = _percentiles_ms(
            lambda: checking.filter(here, 0.5, 0.3, ring_here, 0.0, 0.0, depths=depths),
            s.repeats, s.warmup)
        static_t = Timing(s50, s99, s.repeats, FILTER_BUDGET_MS, None)
        y50, y99 = _percentiles_ms(
            lambda: yielding.filter(here, 0.5, 0.0, pts, 0.0, 0.0, velocities=vel, depths=depths),
            max(1, s.repeats // 5), 1)
        yield_t = Timing(y50, y99, max(1, s.repeats // 5), FILTER_BUDGET_MS, None)
        tracker = MotionTracker()
        blobs = np.concatenate([c + 0.15 * np.stack([np.cos(a), np.sin(a)], 1) for c, a in zip(
            rng_points(s.seed, 6), np.array_split(np.linspace(0, 2 * math.pi, s.points), 6))])
        tick = iter(range(10 ** 9))

        def track():  # the clusters move +x at 0.4 m/s, scans 0.1 s apart
            k = next(tick)
            tracker.update(blobs + (0.04 * (k % 25), 0.0), 0.1 * k)

        t50, t99 = _percentiles_ms(track, s.repeats, s.warmup)
        track_t = Timing(t50, t99, s.repeats, TRACK_BUDGET_MS, None)

        # ---------------------------------------------------------- update + fused map
        lc = LocalCostmap.for_map(grid, LocalCostmapConfig(size=s.window))
        cfg = CostConfig()
        rng = np.random.default_rng(s.seed)
        ranges = rng.uniform(0.5, 0.45 * s.window, s.points)  # (N,) [m] returns in the window
        ranges[::9] = math.inf
        scan = dict(angle_min=-math.pi, angle_increment=2 * math.pi / s.points, range_min=0.1,
                    range_max=10.0)
        clock = iter(range(10 ** 9))

        def update():
            k = next(clock)
            lc.update((centre + 0.01 * (k % 7), centre, 0.01 * k), ranges, stamp=0.1 * k,
                      **scan)

        u50, u99 = _percentiles_ms(update, s.repeats, s.warmup)
        update_t = Timing(u50, u99, s.repeats, UPDATE_BUDGET_MS, None)
        lc.fused_costmap(grid, cfg)  # builds and remembers the static cost map
        f50, f99 = _percentiles_ms(lambda: (update(), lc.fused_costmap(grid, cfg)),
                                   max(1, s.repeats // 5), 1)

        def fused_reference():
            rows, cols = np.nonzero(lc.obstacle_mask())
            r0, c0 = grid.world_to_cell(np.asarray(lc.origin) + 0.5 * s.resolution)
            drawn = data.copy()
            drawn[rows + r0, cols + c0] = OCCUPIED
            cfg.make_costmap(GridMap(data=drawn, resolution=s.resolution))

        ref, _ = _percentiles_ms(fused_reference, s.reference_repeats, 0)
        fused_t = Timing(f50, f99, max(1, s.repeats // 5), FUSED_BUDGET_MS, ref)
        threads = torch.get_num_threads()
    finally:
        torch.set_num_threads(previous_threads)
    return MonitorBenchResult(filter=filter_t, static=static_t, yield_=yield_t, track=track_t,
                              update=update_t, fused=fused_t, settings=s,
                              steps=monitor.config.steps, window_cells=lc.cells, map_cells=n,
                              footprint_vertices=len(footprint.polygon),
                              torch=torch.__version__, python=platform.python_version(),
                              threads=threads)


def format_table(result: MonitorBenchResult) -> str:
    """A small human-readable table of a result."""
    r, s = result, result.settings
    lines = [
        f"obstacle path: filter {s.points} points x {r.steps} steps ({s.footprint}, "
        f"{r.footprint_vertices} vertices); window {r.window_cells}x{r.window_cells} cells, "
        f"{s.points} beams; static map {r.map_cells}x{r.map_cells} at {s.resolution} m; "
        f"{r.threads} torch thread(s), torch {r.torch}",
        f"{'measured':<22}{'p50 [ms]':>10}{'p99 [ms]':>10}{'budget':>9}{'p99/budget':>12}"
        f"{'reference [ms]':>16}{'ref/p50':>9}",
    ]
    rows = (("CollisionMonitor.filter", r.filter), ("filter + static check", r.static),
            ("filter, yielding", r.yield_),
            ("MotionTracker.update", r.track), ("LocalCostmap.update", r.update),
            ("update + fused_costmap", r.fused))
    for name, t in rows:
        ref = "-" if t.reference_ms is None else f"{t.reference_ms:.2f}"
        speed = "-" if t.speedup is None else f"{t.speedup:.1f}x"
        lines.append(f"{name:<22}{t.p50_ms:>10.3f}{t.p99_ms:>10.3f}{t.budget_ms:>9.0f}"
                     f"{t.budget_ratio:>12.2f}{ref:>16}{speed:>9}")
    lines.append("references: filter = per-step loop of footprint.point_in_polygon; fused = "
                 "rebuilding the whole cost map with the marks drawn in")
    return "\n".join(lines)


# ------------------------------------------------------------------ ``ecahd bench monitor``
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``ecahd bench monitor``."""
    d = MonitorBenchSettings()
    parser.add_argument("--points", type=int, default=d.points,
                        help="scan points per filter call and beams per scan")
    parser.add_argument("--map-cells", type=int, default=d.map_cells,
                        help="side of the square static map [cells]")
    parser.add_argument("--resolution", type=float, default=d.resolution, help="[m/cell]")
    parser.add_argument("--window", type=float, default=d.window, help="[m] local window side")
    parser.add_argument("--robot", default=d.footprint,
                        help="footprint: circle, quadruped, humanoid or a Nav2 polygon string")
    parser.add_argument("--repeats", type=int, default=d.repeats, metavar="N",
                        help="timed calls per measurement (p50 / p99 reported)")
    parser.add_argument("--reference-repeats", type=int, default=d.reference_repeats,
                        metavar="N", help="timed calls of the references")
    parser.add_argument("--threads", type=int, default=1, metavar="T",
                        help="torch intra-op threads; 0 keeps torch's default")
    parser.add_argument("--json", metavar="FILE", help="also write the result as JSON to FILE")


def run(args: argparse.Namespace) -> int:
    """Run ``ecahd bench monitor`` with parsed arguments; prints the table."""
    settings = MonitorBenchSettings(points=args.points, map_cells=args.map_cells,
                                    resolution=args.resolution, window=args.window,
                                    footprint=args.robot, repeats=args.repeats,
                                    reference_repeats=args.reference_repeats,
                                    threads=args.threads or None)
    result = run_monitor_benchmark(settings)
    print(format_table(result))
    if args.json:
        from ecahd_core.bench.output import write_json

        write_json(args.json, result.to_dict())
    return 0
