"""The intervals between local_refiner's control ticks in a recorded run, from the wall-clock
stamps of its "control" timing records (what ``ecahd bench navigation`` pools into "cmd_vel
interval / jitter"): percentiles and a histogram, to see what the jitter is made of.

    python scripts/cmd_intervals.py runs/bench-navigation-.../ecahd/bag [--period 0.05]
"""
from __future__ import annotations

import argparse
import json

import numpy as np

from ecahd_core.bag_io import read_bag
from ecahd_core.evaluation import CONTROL_STAGE

GAP = 0.2  # [s] longer intervals are pauses between episodes, not ticks


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bag", help="the run's bag directory")
    ap.add_argument("--period", type=float, default=0.05, help="[s] nominal control period")
    args = ap.parse_args()
    walls = []
    for _, msg in read_bag(args.bag, ["/ecahd/timing"]).get("/ecahd/timing", []):
        record = json.loads(msg.data)
        if record.get("stage") == CONTROL_STAGE and "wall" in record:
            walls.append(float(record["wall"]))
    d = np.diff(np.asarray(walls))
    d = d[d < GAP] * 1e3  # [ms]
    if not len(d):
        raise SystemExit(f"no control ticks with wall stamps in {args.bag}")
    nominal = args.period * 1e3
    q = (1, 10, 25, 50, 75, 90, 99)
    print(f"{len(d)} intervals [ms]: " + ", ".join(
        f"p{p} {v:.1f}" for p, v in zip(q, np.percentile(d, q))))
    print(f"|interval - {nominal:g}| p99: {np.percentile(np.abs(d - nominal), 99):.1f} ms")
    edges = [0, 0.6, 0.7, 0.9, 1.1, 1.3, 1.4, 2.0, GAP * 1e3 / nominal]
    counts, _ = np.histogram(d / nominal, bins=edges)
    for lo, hi, n in zip(edges[:-1], edges[1:], counts):
        print(f"  {lo * nominal:5.0f}-{hi * nominal:4.0f} ms: {n:6d} ({100 * n / len(d):.1f}%)")


if __name__ == "__main__":
    main()
