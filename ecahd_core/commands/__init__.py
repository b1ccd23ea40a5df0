"""Command-line subcommands of the ``ecahd`` tool that need no ROS.

Each module defines ``add_arguments(parser)`` and ``run(args) -> int``; the dispatcher in
``ecahd_ros.cli`` imports a module only when its subcommand is used.
"""
