"""``ecahd lanes``: learn where the robot drives, by direction, from its demonstrations
(issue 41; ``ecahd_core.lanes``).

    ecahd dataset --from-bags BAG... --map office.yaml --out demos.npz
    ecahd lanes --data demos.npz --out office_lanes.npz --png office_lanes.png

The lane field is fitted in well under a second (the keep-out places: A* for every
demonstrated trip, about a second more); the nodes' ``lanes`` parameter, ``ecahd demo
--lanes`` and ``ecahd bench habits --lanes`` move plans onto it.
"""
from __future__ import annotations

import argparse
import time


def add_arguments(p: argparse.ArgumentParser) -> None:
    from ecahd_core.lanes import LaneConfig

    d = LaneConfig()
    p.add_argument("--data", required=True, metavar="NPZ",
                   help="demonstrations (`ecahd dataset --from-bags`) or a mix (`--mix`: its "
                        "demonstrations only); the map is the dataset's")
    p.add_argument("--out", required=True, metavar="NPZ", help="the lane field to write")
    p.add_argument("--png", metavar="FILE", help="also draw the lanes per direction")
    p.add_argument("--cell", type=float, default=d.cell, help="[m] the field's cell")
    p.add_argument("--bins", type=int, default=d.bins, help="heading bins over the circle")
    p.add_argument("--sigma", type=float, default=d.sigma,
                   help="[m] Gaussian blur of the demonstrated driving")
    p.add_argument("--no-keep-out", action="store_true",
                   help="do not learn keep-out places (where the A* expert's routes for the "
                        "same trips go but the robot never did)")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from ecahd_core.dataset import ExpertDataset
    from ecahd_core.footprint import make_footprint
    from ecahd_core.lanes import (LaneConfig, LaneField, demonstration_paths,
                                  demonstration_trips, expert_routes, plot_lanes)

    config = LaneConfig(cell=args.cell, bins=args.bins, sigma=args.sigma)
    dataset = ExpertDataset.load(args.data)
    paths = demonstration_paths(dataset)
    grid = dataset.grid()
    footprint = make_footprint(dataset.params.get("footprint_spec", "circle"))
    t0 = time.perf_counter()
    expert = None if args.no_keep_out else expert_routes(grid, footprint,
                                                         *demonstration_trips(dataset))
    field = LaneField.fit(paths, grid, config, source=Path(args.data).name, expert=expert,
                          footprint=footprint)
    out = field.save(args.out)
    keep = ("" if field.keep_out is None else
            f"; keep-out: {field.keep_out.sum() * config.cell ** 2:.1f} m^2 the expert's "
            f"routes for {len(expert)} of the trips cross and the robot never drove")
    print(f"lanes of map {grid.name!r}: {field.paths} demonstrations, {field.length:.0f} m, "
          f"{field.density.shape[0]} headings x {field.density.shape[1]} x "
          f"{field.density.shape[2]} cells of {config.cell:g} m{keep}, fitted in "
          f"{time.perf_counter() - t0:.2f} s -> {out}")
    if args.png:
        print(f"figure: {plot_lanes(field, grid, args.png)}")
    return 0
