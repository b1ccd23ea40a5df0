"""Seconds per optimiser step of each model recipe in float32 and under bfloat16 autocast
(``TrainConfig.precision``), measured in turn in one process so that both share the machine's
moment: the probe ``ecahd train-all`` runs for its ETA (``seconds_per_step``), ``--rounds``
times per precision.

    python scripts/compare_train_precision.py [--map maze2d-large] [--kinds sd dd] [--rounds 3]
"""
from __future__ import annotations

import argparse
import statistics

from ecahd_core.commands.train import seconds_per_step
from ecahd_core.diffusion import native_bf16
from ecahd_core.maps import load_map
from ecahd_core.threads import set_torch_threads, training_threads


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--map", default="maze2d-large", help="sets the horizons' bounds only")
    ap.add_argument("--kinds", nargs="+", default=["sd", "dd"], choices=("sd", "dd", "fd"))
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--threads", type=int, default=None, help="default: every core")
    args = ap.parse_args()
    set_torch_threads(args.threads or training_threads())
    grid = load_map(args.map)
    print(f"native bfloat16 on this CPU: {native_bf16('cpu')}")
    for kind in args.kinds:
        times = {"fp32": [], "bf16": []}
        for _ in range(args.rounds):
            for precision in times:
                times[precision].append(seconds_per_step(kind, grid, precision=precision))
        fp32, bf16 = (statistics.median(times[p]) * 1e3 for p in ("fp32", "bf16"))
        print(f"{kind}: fp32 {fp32:.1f} ms / step, bf16 {bf16:.1f} ms / step "
              f"(bf16 / fp32 = {bf16 / fp32:.2f}; median of {args.rounds} probes each)")


if __name__ == "__main__":
    main()
