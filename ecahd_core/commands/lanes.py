"""``ecahd lanes``: learn where the robot drives, by direction, from its demonstrations
(issue 41; ``ecahd_core.lanes``).

    ecahd dataset --from-bags BAG... --map office.yaml --out demos.npz
    ecahd lanes --data demos.npz --out office_lanes.npz --png office_lanes.png

The lane field is fitted in well under a second; ``ecahd plan --lanes`` and ``ecahd bench
habits --lanes`` move plans onto it.
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


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from ecahd_core.dataset import ExpertDataset
    from ecahd_core.lanes import LaneConfig, LaneField, demonstration_paths, plot_lanes

    config = LaneConfig(cell=args.cell, bins=args.bins, sigma=args.sigma)
    dataset = ExpertDataset.load(args.data)
    paths = demonstration_paths(dataset)
    grid = dataset.grid()
    t0 = time.perf_counter()
    field = LaneField.fit(paths, grid, config, source=Path(args.data).name)
    out = field.save(args.out)
    print(f"lanes of map {grid.name!r}: {field.paths} demonstrations, {field.length:.0f} m, "
          f"{field.density.shape[0]} headings x {field.density.shape[1]} x "
          f"{field.density.shape[2]} cells of {config.cell:g} m, fitted in "
          f"{time.perf_counter() - t0:.2f} s -> {out}")
    if args.png:
        print(f"figure: {plot_lanes(field, grid, args.png)}")
    return 0
