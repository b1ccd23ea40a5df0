"""``ecahd map``: describe a map and optionally export it as a Nav2 map_server YAML + image, and
draw it as a PNG; or generate a realistic building map.

    ecahd map MAP [--resolution R] [--export YAML] [--png PNG]
    ecahd map generate --kind {warehouse,office,depot} --size W H [--resolution R] [--seed S]
                       --out YAML [--png PNG]

``generate`` is read as the subcommand, not as a map file name (``./generate`` names a file).
"""
from __future__ import annotations

import argparse

GENERATE = "generate"


def add_arguments(p: argparse.ArgumentParser) -> None:
    from ecahd_core.mapgen import MapKind

    p.add_argument("map", help="built-in maze (maze2d-umaze|maze2d-medium|maze2d-large), Nav2 map "
                               f"YAML, or '{GENERATE}' to generate a building map (see --kind)")
    p.add_argument("--resolution", type=float, default=None,
                   help="[m/cell] grid resolution for built-in mazes (default 0.1) and generated "
                        "maps (default 0.05)")
    p.add_argument("--export", default=None, metavar="YAML",
                   help="write the map as Nav2 map_server YAML + PGM beside it")
    p.add_argument("--png", default=None, help="draw the map to this PNG")
    g = p.add_argument_group(f"{GENERATE} (ecahd map {GENERATE} ...)")
    g.add_argument("--kind", default=None, metavar="{" + ",".join(k.value for k in MapKind) + "}",
                   help="kind of building to generate")
    g.add_argument("--size", type=float, nargs=2, default=None, metavar=("W", "H"),
                   help="[m] map width (x) and height (y), each 8..60")
    g.add_argument("--seed", type=int, default=0, help="generator seed (same seed, same map)")
    g.add_argument("--out", default=None, metavar="YAML",
                   help="write the generated map as Nav2 map_server YAML + PGM beside it")


def run(args: argparse.Namespace) -> int:
    from ecahd_core.errors import MapError

    if args.map == GENERATE:
        if args.export:
            raise MapError(f"'ecahd map {GENERATE}' writes the map with --out, not --export")
        return _generate(args)
    for option in ("kind", "size", "out"):
        if getattr(args, option) is not None:
            raise MapError(f"--{option} belongs to 'ecahd map {GENERATE}', not to a map "
                           f"{args.map!r}")
    return _describe(args)


def _describe(args: argparse.Namespace) -> int:
    from ecahd_core.maps import DEFAULT_RESOLUTION, load_map, save_nav2_yaml

    resolution = DEFAULT_RESOLUTION if args.resolution is None else args.resolution
    grid = load_map(args.map, resolution)
    print(_summary(grid))
    if args.export:
        path = save_nav2_yaml(grid, args.export)
        print(f"exported Nav2 map: {path} (+ {path.with_suffix('.pgm').name})")
    if args.png:
        _draw(grid, args.png)
    return 0


def _generate(args: argparse.Namespace) -> int:
    import time
    from pathlib import Path

    from ecahd_core.errors import MapError
    from ecahd_core.maps import save_nav2_yaml
    from ecahd_core.mapgen import MapGenConfig, generate_map

    missing = [f"--{o}" for o in ("kind", "size", "out") if getattr(args, o) is None]
    if missing:
        raise MapError(f"'ecahd map {GENERATE}' needs {', '.join(missing)}")
    config = MapGenConfig(kind=args.kind, width=args.size[0], height=args.size[1],
                          resolution=0.05 if args.resolution is None else args.resolution,
                          seed=args.seed)
    t0 = time.perf_counter()
    grid = generate_map(config)
    elapsed = time.perf_counter() - t0
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    path = save_nav2_yaml(grid, args.out)
    print(f"{_summary(grid)}, generated in {elapsed:.2f} s -> {path} "
          f"(+ {path.with_suffix('.pgm').name})")
    if args.png:
        _draw(grid, args.png)
    return 0


def _summary(grid) -> str:
    import numpy as np

    xmin, ymin, xmax, ymax = grid.bounds
    free = float(np.mean(~grid.occupied))
    unknown = float(np.mean(grid.data < 0))
    return (f"map {grid.name!r}: {grid.width} x {grid.height} cells at {grid.resolution} m/cell, "
            f"x [{xmin:g}, {xmax:g}] m, y [{ymin:g}, {ymax:g}] m, {100 * free:.1f}% free, "
            f"{100 * unknown:.1f}% unknown, fingerprint {grid.fingerprint()}")


def _draw(grid, png: str) -> None:
    from ecahd_core.viz import draw_map, pyplot

    xmin, ymin, xmax, ymax = grid.bounds
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6, 6 * (ymax - ymin) / (xmax - xmin) + 0.5))
    draw_map(ax, grid)
    ax.set_title(grid.name)
    fig.tight_layout()
    fig.savefig(png, dpi=100)
    plt.close(fig)
    print(f"figure: {png}")
