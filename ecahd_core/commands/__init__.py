"""Command-line subcommands of the ``ecahd`` tool that need no ROS.

Each module defines ``add_arguments(parser)`` and ``run(args) -> int``; the dispatcher in
``ecahd_ros.cli`` imports a module only when its subcommand is used.
"""

from ecahd_core.maps import DEFAULT_MAP


def add_map_arguments(p) -> None:
    """``--map`` and ``--resolution``, the same for every command that loads a map."""
    p.add_argument("--map", default=DEFAULT_MAP,
                   help="built-in maze (maze2d-umaze|maze2d-medium|maze2d-large) or Nav2 map YAML")
    p.add_argument("--resolution", type=float, default=0.1,
                   help="[m/cell] grid resolution for built-in mazes")
