"""``ecahd dataset``: generate A* expert data (.npz) for training the SD / DD / FD models
(paper Sec. IV-A; the file format is described in ``ecahd_core.dataset``).

    ecahd dataset --map maze2d-large --pairs 1000 --seed 0 --out data/maze2d-large.npz
"""
from __future__ import annotations

import argparse
import time

from ecahd_core.commands import add_map_arguments


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_map_arguments(p)
    p.add_argument("--robot", default="circle",
                   help="footprint: circle | quadruped | humanoid | Nav2 polygon '[[x, y], ...]'; "
                        "the A* clearance is its circumscribed radius plus --padding")
    p.add_argument("--padding", type=float, default=0.0, help="[m] extra clearance for A*")
    p.add_argument("--pairs", type=int, default=1000,
                   help="number of expert paths to keep (rejected pairs are redrawn)")
    p.add_argument("--seed", type=int, default=0, help="random seed for the start/goal pairs")
    p.add_argument("--min-distance", type=float, default=3.0,
                   help="[m] shortest A* path length kept")
    p.add_argument("--sparse-horizon", type=int, default=10, help="sparse waypoints P^g (SD)")
    p.add_argument("--dense-points", type=int, default=4,
                   help="points P^l per local segment between sparse waypoints (DD)")
    p.add_argument("--full-points", type=int, default=100, help="points per full path (FD)")
    p.add_argument("--expert", choices=("auto", "exact", "coarse"), default="auto",
                   help="exact: A* on the map's cells; coarse: A* on 0.3 m blocks made exact on "
                        "the cells, for large maps; auto: exact up to 50 000 cells")
    p.add_argument("--workers", type=int, default=None,
                   help="processes for the coarse expert (default: one per CPU; the data do "
                        "not depend on it)")
    p.add_argument("--max-spacing", type=float, default=None,
                   help="[m] cut longer paths into pieces so that the sparse waypoints lie at "
                        "most this far apart (maze2d-large's data: 0.4-1.9 m); default: off")
    p.add_argument("--waypoints", choices=("auto", "arclength", "corners"), default="auto",
                   help="rule of SD's sparse waypoints: arclength (the paper's, evenly spaced), "
                        "corners (the path's corners kept, the rest evenly on its legs), auto "
                        "(corners when the expert's median waypoint spacing exceeds 1.5 m)")
    p.add_argument("--out", default=None,
                   help="dataset file to write (.npz); required for the A* expert data")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from ecahd_core.dataset import generate_dataset, median_spacing, waypoint_rule
    from ecahd_core.errors import DatasetError
    from ecahd_core.maps import load_map

    if args.out is None:
        raise DatasetError("--out FILE is required (the .npz to write)")
    grid = load_map(args.map, args.resolution)
    grid.require_free_space()
    t0 = time.perf_counter()
    dataset = generate_dataset(
        grid, pairs=args.pairs, seed=args.seed, footprint_spec=args.robot, padding=args.padding,
        min_distance=args.min_distance, sparse_horizon=args.sparse_horizon,
        dense_points=args.dense_points, full_points=args.full_points,
        progress=not args.no_progress, expert=args.expert, workers=args.workers,
        max_spacing=args.max_spacing, waypoints=args.waypoints)
    elapsed = time.perf_counter() - t0
    out = dataset.save(args.out)

    p = dataset.params
    rejected = p["rejected_short"] + p["rejected_unreachable"]
    size_mb = Path(out).stat().st_size / 1e6
    print(f"map {grid.name} ({grid.fingerprint()}), robot {p['footprint']} "
          f"(clearance {p['clearance']:.3f} m), seed {p['seed']}, expert {p['expert']}")
    print(f"kept {dataset.num_pairs} pairs of {p['attempts']} drawn; rejected {rejected} "
          f"({100.0 * rejected / p['attempts']:.1f} %: {p['rejected_short']} shorter than "
          f"{p['min_distance']} m, {p['rejected_unreachable']} unreachable)")
    print(f"sparse waypoints: {waypoint_rule(dataset)} rule, {dataset.sparse_horizon} per path, "
          f"median spacing {median_spacing(dataset.lengths, dataset.sparse_horizon):.2f} m")
    if "max_spacing" in p:
        print(f"{p['split_paths']} paths longer than {p['sparse_horizon'] - 1} x "
              f"{p['max_spacing']} m were cut into pieces, one pair each")
    print(f"time {elapsed:.2f} s ({1e3 * elapsed / dataset.num_pairs:.2f} ms per kept pair)")
    print(f"wrote {out} ({size_mb:.2f} MB, sha256 {dataset.sha256[:16]})")
    return 0
