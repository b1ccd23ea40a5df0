"""The ``ecahd`` command: one tool, several subcommands.

    ecahd plan      plan one path on a map and draw it
    ecahd map       describe a map, export it as Nav2 YAML + PGM, draw it
    ecahd dataset   generate A* expert data for training
    ecahd bench     benchmarks (cost, ...)

Subcommand modules keep their heavy imports (torch, rclpy) inside ``run``, so building the parser
is fast and ``ecahd bench cost`` never loads rclpy.
"""
from __future__ import annotations

import argparse
import importlib
import logging
import sys

from ecahd_core.errors import EcahdError

# name -> (module, one-line help). Each module defines add_arguments(parser) and run(args).
SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "plan": ("ecahd_core.commands.plan", "plan one path on a map and write a PNG / JSON"),
    "map": ("ecahd_core.commands.map", "describe / export a map (Nav2 YAML + PGM, PNG)"),
    "dataset": ("ecahd_core.commands.dataset", "generate A* expert data (.npz) for training"),
    "bench": ("ecahd_core.commands.bench", "run a benchmark and print ratios against a reference"),
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ecahd", description="ECAHD: collision-aware hierarchical diffusion navigation.")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, (module_name, help_text) in SUBCOMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text,
                           formatter_class=argparse.ArgumentDefaultsHelpFormatter)
        module = importlib.import_module(module_name)
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                        format="[%(levelname)s] %(name)s: %(message)s")
    try:
        return int(args._run(args) or 0)
    except EcahdError as exc:
        print(f"ecahd {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
