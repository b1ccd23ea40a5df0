"""The ``ecahd`` command: one tool, several subcommands.

    ecahd plan      plan one path on a map and draw it
    ecahd map       describe a map, export it as Nav2 YAML + PGM, draw it
    ecahd dataset   generate A* expert data for training (--from-bags: the robot's own driving)
    ecahd record-demos   a scripted operator's driving with a habit, recorded as a bag
    ecahd train     train one diffusion model;  ecahd train-all: a map's dataset and all models
    ecahd train-general   the generalist SD that reads the map, on many generated buildings
    ecahd train-general-dd   the generalist DD, in each segment's own frame
    ecahd bench     benchmarks (cost, sampling, sd-quality, planning; navigation: Table III in
                    closed loop, the one that needs rclpy)
    ecahd demo      the closed loop in simulation, recorded and scored;  ecahd eval-bag: score a bag

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
    "dataset": ("ecahd_ros.dataset_bags",
                "generate A* expert data (.npz) for training, or demonstrations from bags"),
    "train": ("ecahd_core.commands.train", "train one diffusion model (sd, dd, fd) on a dataset"),
    "train-all": ("ecahd_core.commands.train:all",
                  "dataset + all models of a map, seeded (reproduces the shipped models)"),
    "train-general": ("ecahd_core.commands.train_general",
                      "the generalist map-conditioned SD on many generated buildings "
                      "(resumable)"),
    "train-general-dd": ("ecahd_core.commands.train_general:dd",
                         "the generalist DD (in each segment's frame) on generated buildings"),
    "lanes": ("ecahd_core.commands.lanes",
              "learn where the robot drives, by direction, from its demonstrations (a lane "
              "field that plans are moved onto)"),
    "record-demos": ("ecahd_ros.record_demos",
                     "a scripted operator with a habit (keep right, no-go zones) driven in "
                     "simulation, recorded as a bag for dataset --from-bags"),
    "demo": ("ecahd_ros.demo",
             "run the ROS 2 graph through seeded goals, record a bag and score it (Table III)"),
    "eval-bag": ("ecahd_ros.eval_bag",
                 "Table III metrics of a recorded closed-loop bag (JSON, markdown, PNG)"),
    "config": ("ecahd_ros.config_doc", "print / write the parameters of every node as ROS YAML"),
    # the core's benchmarks (ecahd_core.commands.bench) plus the closed-loop one
    "bench": ("ecahd_ros.bench_navigation:bench",
              "run a benchmark and print ratios against a reference"),
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ecahd", description="ECAHD: collision-aware hierarchical diffusion navigation.")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, (module_name, help_text) in SUBCOMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text,
                           formatter_class=argparse.ArgumentDefaultsHelpFormatter)
        module_name, _, variant = module_name.partition(":")
        module = importlib.import_module(module_name)
        suffix = f"_{variant}" if variant else ""
        getattr(module, f"add{suffix}_arguments")(p)
        p.set_defaults(_run=getattr(module, f"run{suffix}"))
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
