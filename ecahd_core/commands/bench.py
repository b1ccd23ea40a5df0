"""``ecahd bench``: benchmarks, one sub-subcommand each.

    ecahd bench cost [--json FILE] [--repeats N] [--threads T]   the cost J, batched vs loops

``BENCHMARKS`` maps each name to its argument builder and runner; a new benchmark (sampling,
planning, ...) is one more entry. torch is only imported when a benchmark runs, so
``ecahd --help`` stays fast.
"""
from __future__ import annotations

import argparse
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from ecahd_core.bench.cost import CostBenchSettings
from ecahd_core.errors import EcahdError


@dataclass(frozen=True)
class Benchmark:
    """One ``ecahd bench NAME`` sub-subcommand."""

    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]


def _int_at_least(minimum: int):
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from exc
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be >= {minimum}, got {value}")
        return value
    return parse


def _write_json(path: str, payload: dict) -> None:
    try:
        Path(path).write_text(json.dumps(payload, indent=2) + "\n")
    except OSError as exc:
        raise EcahdError(f"cannot write the JSON result to {path!r}: {exc}") from exc


# ------------------------------------------------------------------------------------ cost
def _add_cost_arguments(parser: argparse.ArgumentParser) -> None:
    d = CostBenchSettings()
    parser.add_argument("--json", metavar="FILE", help="also write the result as JSON to FILE")
    parser.add_argument("--repeats", type=_int_at_least(1), default=d.repeats, metavar="N",
                        help="timed runs of the batched J (the median is reported)")
    parser.add_argument("--loop-repeats", type=_int_at_least(0), default=d.loop_repeats,
                        metavar="N", help="timed runs of the literal loop reference "
                                          "(seconds each); 0 skips it")
    parser.add_argument("--threads", type=_int_at_least(0), default=d.threads, metavar="T",
                        help="torch intra-op threads during the benchmark; 0 keeps torch's "
                             "default")
    parser.add_argument("--batch", type=_int_at_least(1), default=d.batch, metavar="B",
                        help="trajectories per call of J")
    parser.add_argument("--horizon", type=_int_at_least(1), default=d.horizon, metavar="P",
                        help="points per trajectory (P^l)")
    parser.add_argument("--n-interp", type=_int_at_least(1), default=d.n_interp, metavar="N",
                        help="DDA points per segment (N_interp)")
    parser.add_argument("--robot", default=d.footprint,
                        help="footprint: circle, quadruped, humanoid or a Nav2 polygon string")
    parser.add_argument("--mode", default=d.mode,
                        help="how the cost map is read: a cost mode of Table II")


def _run_cost(args: argparse.Namespace) -> int:
    from ecahd_core.bench.cost import format_table, run_cost_benchmark

    settings = CostBenchSettings(repeats=args.repeats, loop_repeats=args.loop_repeats,
                                 threads=args.threads or None, batch=args.batch,
                                 horizon=args.horizon, n_interp=args.n_interp,
                                 footprint=args.robot, mode=args.mode)
    result = run_cost_benchmark(settings)
    print(format_table(result))
    if args.json:
        _write_json(args.json, result.to_dict())
    return 0


BENCHMARKS: dict[str, Benchmark] = {
    "cost": Benchmark(help="forward+backward time of the cost J: batched torch vs literal loops",
                      add_arguments=_add_cost_arguments, run=_run_cost),
}


# ----------------------------------------------------------------------------- interface
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``ecahd bench`` takes the benchmark name, then that benchmark's options."""
    sub = parser.add_subparsers(dest="benchmark", metavar="BENCHMARK", required=True)
    for name, bench in BENCHMARKS.items():
        p = sub.add_parser(name, help=bench.help, description=bench.help,
                           formatter_class=argparse.ArgumentDefaultsHelpFormatter)
        bench.add_arguments(p)


def run(args: argparse.Namespace) -> int:
    return BENCHMARKS[args.benchmark].run(args)
