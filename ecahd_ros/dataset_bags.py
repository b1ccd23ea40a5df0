"""``ecahd dataset``: the A* expert data (``ecahd_core.commands.dataset``), or with
``--from-bags`` demonstrations from the robot's own recorded driving.

    ecahd dataset --from-bags run1/ run2/ --map site.yaml [--out demos.npz] [--png coverage.png]
    ecahd dataset --mix demos.npz expert.npz --share 0.5 --out mixed.npz

Each bag's robot pose comes as ``ecahd eval-bag`` reads it (``ecahd_ros.eval_bag``: the
namespace auto-detected or ``--namespace``; ``odom`` in ``map``, or in another frame placed
in ``map`` by the recorded ``/tf``; without odometry ``--base-frame`` in ``map`` from ``/tf``
+ ``/tf_static``); the bag needs no ``map`` topic, ``--map`` is the map. The bag is read
streaming (``ecahd_core.bag_io.scan_bag``: one pose record kept per message), so a damaged
MCAP bag gives what can be read, with a count of what was skipped. The pose stream is cut
into demonstrations by ``ecahd_core.demonstrations`` (the rules, and every threshold, are
in its docstring) and written as an expert dataset in the A* expert's format, so ``ecahd
train sd|dd --data demos.npz`` trains on it. Prints how many demonstrations were kept, every
cut and drop by reason, and the coverage of the map; ``--png`` draws the map, the covered
cells, the kept paths and the dropped pieces.

Bad input is one line and exit code 2 (``ecahd_ros.cli``): no pose topic, poses in a frame
the recorded tf does not place in map, a map the poses put the robot in walls of for most of
the run, a bag nothing can be read from. Nothing is written before everything is computed;
the dataset and the figure are written by rename.
"""
from __future__ import annotations

import argparse
import logging
import os
import time
from pathlib import Path

log = logging.getLogger("ecahd.dataset")

POSE_TOPICS = ("/odom", "/tf", "/tf_static")  # what a bag's robot pose is read from
DROP_COLORS = {"collision": "tab:red", "too_short": "0.55", "looping": "tab:orange"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    from ecahd_core.commands.dataset import add_arguments as add_expert_arguments
    from ecahd_core.demonstrations import DemoConfig

    from ecahd_ros.eval_bag import BASE_FRAME

    add_expert_arguments(p)
    g = p.add_argument_group(
        "demonstrations (--from-bags; --pairs, --seed, --expert and --workers do not apply, "
        "--min-distance is the shortest demonstration kept)")
    g.add_argument("--mix", nargs=2, default=None, metavar=("DEMOS", "EXPERT"),
                   help="mix a demonstrations dataset and an A* expert dataset of one map so "
                        "that --share of the pairs are demonstrations (--out, --seed)")
    g.add_argument("--share", type=float, default=0.5,
                   help="with --mix: the demonstrations' share of the pairs")
    g.add_argument("--from-bags", nargs="+", default=None, metavar="BAG",
                   help="rosbag2 folders (MCAP or SQLite3) of the robot driving on --map")
    g.add_argument("--png", default=None, help="write the coverage figure here")
    g.add_argument("--namespace", default=None, metavar="NS",
                   help="the robot's topic namespace (default: auto, as eval-bag)")
    g.add_argument("--base-frame", default=BASE_FRAME,
                   help="the robot's frame whose pose in map tf gives when a bag has no odom")
    d = DemoConfig()
    g.add_argument("--stop-time", type=float, default=d.stop_time,
                   help="[s] still (within --stop-radius) longer than this: a stop, cut there")
    g.add_argument("--stop-radius", type=float, default=d.stop_radius, help="[m]")
    g.add_argument("--max-gap", type=float, default=d.max_gap,
                   help="[s] a longer time without a pose cuts")
    g.add_argument("--max-speed", type=float, default=d.max_speed,
                   help="[m/s] a pose jump farther than this allows (+ 0.25 m) is a teleport")
    g.add_argument("--loop-length", type=float, default=d.loop_length,
                   help="[m] a demonstration loops when it comes back within the robot's "
                        "radius of where it was after more driving than this")


def run(args: argparse.Namespace) -> int:
    if args.mix:
        return run_mix(args)
    if not args.from_bags:
        from ecahd_core.commands.dataset import run as run_expert

        return run_expert(args)
    return run_from_bags(args)


def run_mix(args: argparse.Namespace) -> int:
    """``--mix DEMOS EXPERT --share S --out F``: ``dataset.mix_datasets``."""
    from ecahd_core.dataset import ExpertDataset, mix_datasets
    from ecahd_core.errors import DatasetError

    if not args.out:
        raise DatasetError("--mix needs --out FILE")
    demos, expert = (ExpertDataset.load(p) for p in args.mix)
    mixed = mix_datasets(demos, expert, args.share, seed=args.seed)
    mixed.save(args.out)
    m = mixed.params["mixed"]
    print(f"{args.out}: {m['demonstrations']} demonstrations of {demos.num_pairs} + "
          f"{m['expert']} expert paths of {expert.num_pairs} on {mixed.map_name!r} "
          f"(share {args.share:g})")
    return 0


# ------------------------------------------------------------------------------ one bag
def read_pose_stream(bag, *, namespace: str | None = None, base_frame: str | None = None):
    """A bag's robot poses in map -> (PoseStream (stamp [s], x, y, yaw), where they came from
    (e.g. "/odom", "tf (base_link in map)"), BagScan). Raises BagError (one line) when the bag
    cannot be read, has no pose topic, or its poses cannot be placed in map."""
    from ecahd_core.bag_io import scan_bag
    from ecahd_core.demonstrations import PoseStream
    from ecahd_core.errors import BagError

    from ecahd_ros.eval_bag import (BASE_FRAME, GLOBAL_FRAME, odometry_record, resolve_topics,
                                    robot_poses)

    base_frame = base_frame or BASE_FRAME
    odom: dict = {}  # topic -> [(record, frame)]: one small tuple per message
    tf: dict = {}  # topic -> [(t_ns, TFMessage)]

    def handle(topic: str, t_ns: int, msg) -> None:
        if topic.endswith("/odom"):
            odom.setdefault(topic, []).append(odometry_record(t_ns, msg))
        else:
            tf.setdefault(topic, []).append((t_ns, msg))

    scan = scan_bag(bag, lambda topic: topic.endswith(POSE_TOPICS), handle)
    counts = {topic: len(v) for topic, v in {**odom, **tf}.items()}
    if not counts:
        raise BagError(f"bag {str(bag)!r} has no pose topic (no message on /odom, /tf or "
                       f"/tf_static{', ' + scan.describe() if scan.damaged else ''})")
    ns, topics = resolve_topics(counts, namespace, bag, require_map=False)
    data = {name: tf[topic] for name, topic in topics.items() if topic in tf}
    records = odom.get(topics["/odom"], [])
    poses, poses_from = robot_poses([r for r, _ in records], [f for _, f in records], data,
                                    topics, bag, base_frame)
    stamps = [p[1] for p in poses]
    t_index = 1 if len(set(stamps)) > 1 else 0  # unstamped poses: their receive times
    stream = PoseStream.from_records([(p[t_index], p[2], p[3], p[4]) for p in poses],
                                     source=str(bag))
    where = (topics["/odom"] if poses_from == "odom" else
             f"tf ({base_frame} in {GLOBAL_FRAME})")
    return stream, where, scan


# ---------------------------------------------------------------------------------- run
def run_from_bags(args: argparse.Namespace) -> int:
    from ecahd_core.demonstrations import (CutResult, DemoConfig, check_map_matches, coverage,
                                           cut_demonstrations, demonstrations_dataset)
    from ecahd_core.errors import EcahdError
    from ecahd_core.footprint import make_footprint
    from ecahd_core.maps import load_map

    grid = load_map(args.map, args.resolution)
    grid.require_free_space()
    footprint = make_footprint(args.robot)
    config = DemoConfig(min_distance=args.min_distance, stop_time=args.stop_time,
                        stop_radius=args.stop_radius, max_gap=args.max_gap,
                        max_speed=args.max_speed, loop_length=args.loop_length)
    out = Path(args.out or f"{grid.name}_demonstrations.npz")
    for bag in args.from_bags:
        if not Path(bag).is_dir():
            raise EcahdError(f"bag {bag!r} is not a folder (give the rosbag2 directory)")
    t0 = time.perf_counter()
    result, lines, damaged = CutResult(), [], {}
    for bag in args.from_bags:
        stream, where, scan = read_pose_stream(bag, namespace=args.namespace,
                                               base_frame=args.base_frame)
        share = check_map_matches(stream, grid, footprint, config)
        part = cut_demonstrations(stream, grid, footprint, config)
        result.extend(part)
        lines.append(f"bag {bag}: {len(stream)} poses from {where}, "
                     f"{stream.duration / 60:.1f} min, {100 * share:.1f}% in walls, "
                     f"{len(part.kept)} demonstrations")
        if scan.damaged:
            lines.append(f"  damaged: {scan.describe()}")
            damaged[str(bag)] = {"read": scan.read, "skipped_messages": scan.skipped_messages,
                                 "skipped_chunks": scan.skipped_chunks,
                                 "skipped_bytes": scan.skipped_bytes}
    dataset = demonstrations_dataset(
        result, grid, footprint_spec=args.robot, padding=args.padding, config=config,
        sparse_horizon=args.sparse_horizon, dense_points=args.dense_points,
        full_points=args.full_points, max_spacing=args.max_spacing, waypoints=args.waypoints,
        sources=[str(b) for b in args.from_bags],
        extra={"damaged_bags": damaged} if damaged else None)
    share, covered = coverage(grid, [p.xy for p in result.kept], config.coverage_radius)
    figure = _coverage_figure(grid, result, covered, share) if args.png else None
    elapsed = time.perf_counter() - t0
    # everything computed: now write, each file by rename
    dataset.save(out)
    if figure is not None:
        save_figure(figure, Path(args.png))
    print(f"map {grid.name} ({grid.fingerprint()}), robot {footprint.name}")
    for line in lines:
        print(line)
    print(result.summary())
    print(f"coverage: {100 * share:.1f}% of the map's free cells within "
          f"{config.coverage_radius:g} m of a kept path")
    print(f"{dataset.num_pairs} training pairs, time {elapsed:.2f} s")
    print(f"wrote {out} ({out.stat().st_size / 1e6:.2f} MB, sha256 {dataset.sha256[:16]})")
    if args.png:
        print(f"wrote {args.png}")
    return 0


def _coverage_figure(grid, result, covered, share: float):
    """The map, the covered free cells (light green), the kept paths (blue) and the dropped
    pieces (by reason), as a matplotlib figure."""
    import numpy as np

    from ecahd_core.viz import draw_map, pyplot

    plt = pyplot()
    xmin, ymin, xmax, ymax = grid.bounds
    fig, ax = plt.subplots(figsize=(9.5, 8 * (ymax - ymin) / max(xmax - xmin, 1e-9) + 0.8))
    draw_map(ax, grid)
    rgba = np.zeros(covered.shape + (4,))
    rgba[covered] = (0.2, 0.75, 0.3, 0.25)
    ax.imshow(rgba, origin="lower", extent=(xmin, xmax, ymin, ymax), interpolation="nearest")
    for piece in result.dropped:
        ax.plot(piece.xy[:, 0], piece.xy[:, 1], color=DROP_COLORS[piece.reason], lw=1.4,
                alpha=0.9)
    for piece in result.kept:
        ax.plot(piece.xy[:, 0], piece.xy[:, 1], color="tab:blue", lw=1.0, alpha=0.8)
        ax.plot(*piece.xy[0], "o", color="tab:blue", ms=3)
        ax.plot(*piece.xy[-1], "s", color="navy", ms=3)
    ax.fill([], [], color=(0.2, 0.75, 0.3, 0.25), label=f"within 1 m of a kept path "
                                                      f"({100 * share:.1f}% of free)")
    ax.plot([], [], color="tab:blue", label=f"kept ({len(result.kept)}; o start, s goal)")
    for reason, color in DROP_COLORS.items():
        ax.plot([], [], color=color, label=f"dropped: {reason.replace('_', ' ')} "
                                           f"({result.counts[reason]})")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7, framealpha=0.8)
    c = result.counts
    ax.set_title(f"{len(result.kept)} demonstrations; cut at {c['stop']} stops, "
                 f"{c['turn_in_place']} turns in place, {c['teleport']} teleports, "
                 f"{c['pose_gap']} pose gaps", fontsize=9)
    fig.tight_layout()
    return fig


def save_figure(fig, path: Path) -> None:
    """Write a PNG by rename (no half-written file under ``path``)."""
    from ecahd_core.viz import pyplot

    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    fig.savefig(tmp, dpi=110, format="png", bbox_inches="tight")
    pyplot().close(fig)
    os.replace(tmp, path)
