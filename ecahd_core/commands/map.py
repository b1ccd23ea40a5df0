"""``ecahd map``: describe a map and optionally export it as a Nav2 map_server YAML + image, and
draw it as a PNG."""
from __future__ import annotations

import argparse


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("map", help="built-in maze (maze2d-umaze|maze2d-medium|maze2d-large) or Nav2 map YAML")
    p.add_argument("--resolution", type=float, default=0.1,
                   help="[m/cell] grid resolution for built-in mazes")
    p.add_argument("--export", default=None, metavar="YAML",
                   help="write the map as Nav2 map_server YAML + PGM beside it")
    p.add_argument("--png", default=None, help="draw the map to this PNG")


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from ecahd_core.maps import load_map, save_nav2_yaml

    grid = load_map(args.map, args.resolution)
    xmin, ymin, xmax, ymax = grid.bounds
    free = float(np.mean(~grid.occupied))
    print(f"map {grid.name!r}: {grid.width} x {grid.height} cells at {grid.resolution} m/cell, "
          f"x [{xmin:g}, {xmax:g}] m, y [{ymin:g}, {ymax:g}] m, {100 * free:.1f}% free, "
          f"fingerprint {grid.fingerprint()}")
    if args.export:
        path = save_nav2_yaml(grid, args.export)
        print(f"exported Nav2 map: {path} (+ {path.with_suffix('.pgm').name})")
    if args.png:
        from ecahd_core.viz import pyplot, draw_map

        plt = pyplot()
        fig, ax = plt.subplots(figsize=(6, 6 * (ymax - ymin) / (xmax - xmin) + 0.5))
        draw_map(ax, grid)
        ax.set_title(grid.name)
        fig.tight_layout()
        fig.savefig(args.png, dpi=100)
        plt.close(fig)
        print(f"figure: {args.png}")
    return 0
