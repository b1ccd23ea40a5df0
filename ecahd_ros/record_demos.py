"""``ecahd record-demos``: a scripted operator's driving in simulation, recorded as a rosbag2
MCAP bag that ``ecahd dataset --from-bags`` reads (issue 41, item 3).

    ecahd record-demos --map site.yaml --habit keep-right --hours 2 --out demos_bag/ --seed 0
    ecahd record-demos --map site.yaml --habit zone --zones scenario.yaml --hours 1 --out b/

The operator (``ecahd_core.operator``: the habit, its definition and how it is applied) drives
routes between random start and goal points of the map's free space (each goal the next
route's start, goals at least ``--min-distance`` m from their start), with pure pursuit on the
simulator's unicycle at the local_refiner's limits, in simulated time, until ``--hours`` of
driving are recorded; it stands ``--stop-time`` s at each goal. Recorded at ``--rate`` Hz:

* ``/odom`` nav_msgs/Odometry, header frame ``map``, child ``base_link``, pose and twist;
* ``/tf`` tf2_msgs/TFMessage: ``map -> odom`` (the identity: the simulated odometry does not
  drift) and ``odom -> base_link`` (the pose).

``--zones`` is a scenario YAML with a ``zones:`` list (``ecahd_core.scenario``); the operator
never enters a zone whatever ``--habit`` (``zone`` demands the file). It prints the habit
measures of the operator's planned routes, of its driven paths and of A*'s paths for the same
start/goal pairs; ``--png`` draws the map, the zones and the first routes of both. The bag is
written into a temporary folder beside ``--out`` and renamed when complete.
"""
from __future__ import annotations

import argparse
import logging
import math
import os
import shutil
import time
from pathlib import Path

from ecahd_core.operator import HABITS

log = logging.getLogger("ecahd.record_demos")

DRAWN_ROUTES = 8  # routes drawn by --png


def add_arguments(p: argparse.ArgumentParser) -> None:
    from ecahd_core.operator import DriveConfig

    d = DriveConfig()
    p.add_argument("--map", required=True, help="built-in map name or Nav2 map YAML")
    p.add_argument("--resolution", type=float, default=0.05,
                   help="[m/cell] for a built-in map")
    p.add_argument("--robot", default="circle",
                   help="footprint: circle | quadruped | humanoid | Nav2 polygon string")
    p.add_argument("--habit", choices=HABITS, default="keep-right",
                   help="keep-right: the right half of corridors wider than twice the robot; "
                        "zone: A* round the --zones only")
    p.add_argument("--zones", default=None, metavar="SCENARIO",
                   help="scenario YAML with a 'zones:' list of polygons the operator avoids")
    p.add_argument("--hours", type=float, default=1.0, help="[h] of driving to record")
    p.add_argument("--out", required=True, help="the rosbag2 folder to write (must not exist)")
    p.add_argument("--seed", type=int, default=0, help="seed of the start/goal points")
    p.add_argument("--rate", type=float, default=d.rate, help="[Hz] poses recorded (20-50)")
    p.add_argument("--stop-time", type=float, default=d.stop_time,
                   help="[s] standing still at each goal")
    p.add_argument("--max-v", type=float, default=d.max_v, help="[m/s]")
    p.add_argument("--min-distance", type=float, default=3.0,
                   help="[m] a goal lies at least this far from its start")
    p.add_argument("--png", default=None, help="draw the map, the zones and the first routes")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    import numpy as np
    from tqdm import tqdm

    from ecahd_core.errors import EcahdError, PlanningError
    from ecahd_core.footprint import make_footprint
    from ecahd_core.maps import load_map
    from ecahd_core.operator import (DriveConfig, Operator, OperatorConfig, drive_route,
                                     habit_metrics)
    from ecahd_core.scenario import read_zones

    if not (math.isfinite(args.hours) and args.hours > 0):
        raise EcahdError(f"--hours must be > 0, got {args.hours}")
    if not 1.0 <= args.rate <= 100.0:
        raise EcahdError(f"--rate must be in [1, 100] Hz, got {args.rate}")
    if args.habit == "zone" and not args.zones:
        raise EcahdError("--habit zone needs --zones SCENARIO (a YAML with a 'zones:' list)")
    out = Path(args.out)
    if out.exists():
        raise EcahdError(f"--out {str(out)!r} exists; rosbag2 writes a new folder")
    grid = load_map(args.map, args.resolution)
    grid.require_free_space()
    footprint = make_footprint(args.robot)
    zones = read_zones(args.zones) if args.zones else []
    if args.habit == "zone" and not zones:
        raise EcahdError(f"scenario {args.zones!r} has no zones")
    drive = DriveConfig(rate=args.rate, stop_time=args.stop_time, max_v=args.max_v)
    operator = Operator(grid, footprint, zones,
                        OperatorConfig(keep_right=args.habit == "keep-right"))
    mask = operator.mask
    rng = np.random.default_rng(args.seed)

    t0 = time.perf_counter()
    tmp = out.with_name(out.name + ".partial")
    if tmp.exists():
        shutil.rmtree(tmp)
    writer = _BagWriter(tmp)
    target_ticks = int(round(args.hours * 3600 * drive.rate))
    from ecahd_core.astar import sample_free_point

    start = sample_free_point(rng, mask, grid)
    pose = (*start, float(rng.uniform(-math.pi, math.pi)))
    routes, driven, unreached, tick, tries = [], [], 0, 0, 0
    try:
        with tqdm(total=target_ticks, unit="tick", disable=args.no_progress,
                  desc="recording", mininterval=0.5) as bar:
            writer.write(tick, pose, (0.0, 0.0), drive.rate)
            while tick < target_ticks:
                tries += 1
                if tries > 1000:
                    raise EcahdError(f"no goal at least {args.min_distance:g} m from "
                                     f"{start.round(2).tolist()} that the operator reaches "
                                     f"in 1000 draws (map {grid.name!r})")
                goal = sample_free_point(rng, mask, grid)
                if np.hypot(*(goal - start)) < args.min_distance:
                    continue
                try:  # from the last goal (in the mask), the robot within goal_tolerance of it
                    route = operator.plan(start, goal)
                except PlanningError:
                    continue
                tries = 0
                result = drive_route(route.path, pose, drive)
                for p, tw in zip(result.poses, result.twists):
                    tick += 1
                    writer.write(tick, p, tw, drive.rate)
                bar.update(len(result.poses))
                routes.append(route)
                driven.append(result.poses[:result.moving_ticks + 1, :2])
                unreached += not result.reached
                pose = tuple(float(v) for v in result.poses[-1])
                start = goal
    except BaseException:
        writer.close()
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    writer.close()
    elapsed = time.perf_counter() - t0
    os.replace(tmp, out)

    planned = habit_metrics([r.path for r in routes], grid, footprint, zones)
    drove = habit_metrics(driven, grid, footprint, zones)
    astar = habit_metrics([r.astar for r in routes], grid, footprint, zones)
    print(f"map {grid.name} ({grid.fingerprint()}), robot {footprint.name}, habit {args.habit}"
          + (f", {len(zones)} zone(s)" if zones else ""))
    print(f"recorded {tick / drive.rate / 3600:.2f} h ({tick + 1} poses at {drive.rate:g} Hz) "
          f"of {len(routes)} routes in {elapsed:.1f} s; {unreached} route(s) not reached"
          + (f"; {sum(not r.offset for r in routes)} kept A*'s path (no safe shift)"
             if args.habit == "keep-right" else ""))
    print(f"operator, planned: {planned.summary()}")
    print(f"operator, driven:  {drove.summary()}")
    print(f"A*, same pairs:    {astar.summary()}")
    print(f"wrote {out} ({sum(f.stat().st_size for f in out.iterdir()) / 1e6:.1f} MB)")
    if args.png:
        _figure(grid, zones, routes[:DRAWN_ROUTES], planned, astar, args.habit, Path(args.png))
        print(f"wrote {args.png}")
    return 0


class _BagWriter:
    """/odom and /tf messages into a new MCAP rosbag2 folder (rosbags, the Jazzy types)."""

    def __init__(self, path: Path) -> None:
        import numpy as np
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.typesys import get_typestore

        from ecahd_core.bag_io import TYPESTORE

        self.ts = get_typestore(TYPESTORE)
        self.T = self.ts.types
        self.writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
        self.writer.open()
        self.odom = self.writer.add_connection("/odom", "nav_msgs/msg/Odometry",
                                               typestore=self.ts)
        self.tf = self.writer.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=self.ts)
        T = self.T
        self._zeros = np.zeros(36)
        self._identity = T["geometry_msgs/msg/Transform"](
            translation=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
            rotation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))

    def write(self, tick: int, pose, twist, rate: float) -> None:
        T = self.T
        t_ns = int(round(tick * 1e9 / rate))
        stamp = T["builtin_interfaces/msg/Time"](sec=t_ns // 1_000_000_000,
                                                 nanosec=t_ns % 1_000_000_000)
        x, y, yaw = (float(v) for v in pose)
        v, w = (float(u) for u in twist)
        quat = T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2),
                                                 w=math.cos(yaw / 2))
        vec = T["geometry_msgs/msg/Vector3"]
        odom = T["nav_msgs/msg/Odometry"](
            header=T["std_msgs/msg/Header"](stamp=stamp, frame_id="map"),
            child_frame_id="base_link",
            pose=T["geometry_msgs/msg/PoseWithCovariance"](
                pose=T["geometry_msgs/msg/Pose"](
                    position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0), orientation=quat),
                covariance=self._zeros),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](linear=vec(x=v, y=0.0, z=0.0),
                                                   angular=vec(x=0.0, y=0.0, z=w)),
                covariance=self._zeros))
        stamped = T["geometry_msgs/msg/TransformStamped"]
        tf = T["tf2_msgs/msg/TFMessage"](transforms=[
            stamped(header=T["std_msgs/msg/Header"](stamp=stamp, frame_id="map"),
                    child_frame_id="odom", transform=self._identity),
            stamped(header=T["std_msgs/msg/Header"](stamp=stamp, frame_id="odom"),
                    child_frame_id="base_link",
                    transform=T["geometry_msgs/msg/Transform"](
                        translation=vec(x=x, y=y, z=0.0), rotation=quat))])
        self.writer.write(self.odom, t_ns, self.ts.serialize_cdr(odom, "nav_msgs/msg/Odometry"))
        self.writer.write(self.tf, t_ns, self.ts.serialize_cdr(tf, "tf2_msgs/msg/TFMessage"))

    def close(self) -> None:
        self.writer.close()


def _figure(grid, zones, routes, planned, astar, habit: str, path: Path) -> None:
    """The map, the zones (red, hatched), A*'s paths (grey, dashed) and the operator's (blue,
    an arrow at each goal), written by rename."""
    from ecahd_core.viz import draw_map, pyplot

    from ecahd_ros.dataset_bags import save_figure

    plt = pyplot()
    xmin, ymin, xmax, ymax = grid.bounds
    fig, ax = plt.subplots(figsize=(10, 8.5 * (ymax - ymin) / max(xmax - xmin, 1e-9) + 0.8))
    draw_map(ax, grid)
    for z in zones:
        ax.fill(z.polygon[:, 0], z.polygon[:, 1], facecolor=(0.9, 0.2, 0.2, 0.25),
                edgecolor="tab:red", hatch="//", lw=1.2)
        ax.text(*z.polygon.mean(axis=0), z.name, color="tab:red", fontsize=8, ha="center")
    for r in routes:
        ax.plot(r.astar[:, 0], r.astar[:, 1], "--", color="0.35", lw=1.0)
        ax.plot(r.path[:, 0], r.path[:, 1], color="tab:blue", lw=1.4)
        ax.annotate("", xy=r.path[-1], xytext=r.path[-3],
                    arrowprops=dict(arrowstyle="-|>", color="tab:blue", lw=1.2))
        ax.plot(*r.path[0], "o", color="tab:blue", ms=4)
    ax.plot([], [], "--", color="0.35", label=f"A* ({100 * astar.right_share:.0f}% right, "
                                              f"{astar.zone_entries} in a zone)")
    ax.plot([], [], color="tab:blue", label=f"operator, {habit} "
                                            f"({100 * planned.right_share:.0f}% right, "
                                            f"{planned.zone_entries} in a zone)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.set_title(f"{len(routes)} of the recorded routes; right share: of the corridor length "
                 f"(all routes)", fontsize=9)
    fig.tight_layout()
    save_figure(fig, path)
