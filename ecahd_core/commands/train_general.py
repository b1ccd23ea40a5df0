"""``ecahd train-general``: the generalist (map-conditioned) SD of issue 40 on many generated
buildings (``ecahd_core.general``).

    ecahd train-general --maps 1000 --minutes 600          # build the data, then train 10 h
    ecahd train-general --resume --minutes 600             # go on from the last checkpoint
    ecahd train-general --data runs/general/data --steps 200 --out /tmp/g.pt
    ecahd train-general --map my.yaml --from general --minutes 3 --out my.pt --ship my_sd.pt
                                                           # fine-tune on one map
    ecahd train-general --map my.yaml --expert mixed.npz --no-mirror --from general ...
                                                           # ... on the robot's own driving
    ecahd train-general-dd --maps 60 --out general_dd.pt     # the segment-frame DD

``--maps N`` builds (or finishes building: resumable) the dataset of N maps in ``--data`` first;
without it ``--data`` must hold a finished dataset. The checkpoint ``--out`` (with training
state) is written every ``--checkpoint-minutes`` and at the end; ``--resume`` continues from it
exactly as the uninterrupted run would (same seed and recipe). ``--ship`` also writes the
inference-only file.
"""
from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

from ecahd_core.errors import DatasetError
from ecahd_core.threads import set_torch_threads

log = logging.getLogger("ecahd.train_general")

DEFAULT_DIR = Path("runs/general")
DEFAULT_STEPS = 60_000  # ~7.5 h at 0.45 s a step on one core; --minutes stops it sooner


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", default=None,
                   help="generalist dataset directory (`general.data`'s shards; default "
                        "runs/general/data)")
    p.add_argument("--maps", type=int, default=None, metavar="N",
                   help="build (or finish building) a dataset of N generated maps in --data "
                        "first (1.4 s a map on one core; resumable)")
    p.add_argument("--data-seed", type=int, default=0,
                   help="the dataset's seed (map seeds 10^6 x seed + j); with --maps")
    p.add_argument("--map", default=None, metavar="YAML",
                   help="fine-tune on this one map (a Nav2 YAML or a built-in maze): its own "
                        "expert data is built in --data (default runs/general/finetune-NAME); "
                        "with --from")
    p.add_argument("--pairs", type=int, default=400,
                   help="with --map: expert paths on the map (two samples each)")
    p.add_argument("--expert", default=None, metavar="NPZ",
                   help="with --map: learn this dataset of the map instead of A* expert "
                        "paths (`ecahd dataset`'s file: demonstrations from the robot's bags, "
                        "--from-bags, or their --mix with the A* expert)")
    p.add_argument("--from", dest="init_from", default=None, metavar="CKPT",
                   help="start from this generalist's weights ('general': the shipped one)")
    p.add_argument("--out", default=str(DEFAULT_DIR / "general.pt"),
                   help="checkpoint with training state (written every --checkpoint-minutes)")
    p.add_argument("--resume", action="store_true", help="continue from --out")
    p.add_argument("--ship", default=None,
                   help="also write the inference-only checkpoint here at the end")
    p.add_argument("--steps", type=int, default=DEFAULT_STEPS, help="total optimiser steps")
    p.add_argument("--minutes", type=float, default=None, metavar="M",
                   help="stop training after M minutes of wall time (with a checkpoint)")
    p.add_argument("--checkpoint-minutes", type=float, default=10.0, metavar="M",
                   help="minutes between checkpoints")
    # None: GeneralTrainConfig's default (one home; torch is not imported to build the parser)
    p.add_argument("--maps-per-batch", type=int, default=None,
                   help="K: maps per batch, their problems share the global CNN's pass "
                        "(default 16)")
    p.add_argument("--problems-per-map", type=int, default=None,
                   help="M: problems per map; batch K x M (default 8)")
    p.add_argument("--lr", type=float, default=None, help="AdamW learning rate (default 1e-4)")
    p.add_argument("--warmup", type=int, default=None,
                   help="LR warm-up steps (default 1000)")
    p.add_argument("--no-augment", action="store_true",
                   help="no rotations and flips of views and waypoints")
    p.add_argument("--no-mirror", action="store_true",
                   help="rotations only, no flips: for demonstrations that keep to one side "
                        "(a mirrored keep-right path keeps left)")
    p.add_argument("--seed", type=int, default=0, help="seed of weights and every draw")
    p.add_argument("--device", default="cpu", help="cpu, cuda, cuda:1, ...")
    p.add_argument("--threads", type=int, default=1,
                   help="torch threads (1 leaves the other cores to the rest of the robot's "
                        "work)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def run(args: argparse.Namespace) -> int:
    from ecahd_core.general.data import GeneralDataConfig, build
    from ecahd_core.general.checkpoint import load_general_checkpoint
    from ecahd_core.general.train import GeneralTrainConfig, GroupedData, train_general

    set_torch_threads(args.threads)
    for name in ("steps", "checkpoint_minutes", "minutes"):
        value = getattr(args, name)
        if value is not None and not value > 0:
            raise DatasetError(f"--{name.replace('_', '-')} must be > 0, got {value}")
    given = {"maps_per_batch": args.maps_per_batch, "problems_per_map": args.problems_per_map,
             "lr": args.lr, "warmup_steps": args.warmup}
    try:
        cfg = GeneralTrainConfig(augment=not args.no_augment, mirror=not args.no_mirror,
                                 seed=args.seed,
                                 **{k: v for k, v in given.items() if v is not None})
    except ValueError as exc:
        raise DatasetError(str(exc)) from exc
    out = Path(args.out)
    if args.resume:  # a missing or broken checkpoint fails before the data is touched
        load_general_checkpoint(out)
    init = None
    if args.init_from is not None:
        from ecahd_core.model_zoo import read_general

        init = read_general("sd", args.init_from)
        if init is None:
            raise DatasetError(f"--from {args.init_from!r} is not a generalist SD checkpoint")
    if args.map is not None and args.maps is not None:
        raise DatasetError("--map (one given map) and --maps (generated maps) exclude each "
                           "other")
    if args.expert is not None and args.map is None:
        raise DatasetError("--expert is a dataset of one map: give the map with --map")
    data_dir = Path(args.data) if args.data else DEFAULT_DIR / "data"
    if args.map is not None:
        from ecahd_core.general.data import build_for_map
        from ecahd_core.maps import load_map

        grid = load_map(args.map)
        expert = None
        if args.expert is not None:
            from ecahd_core.dataset import ExpertDataset

            expert = ExpertDataset.load(args.expert)
        name = grid.name if expert is None else f"{grid.name}-{Path(args.expert).stem}"
        data_dir = Path(args.data) if args.data else DEFAULT_DIR / f"finetune-{name}"
        report = build_for_map(data_dir, grid, pairs=args.pairs, seed=args.data_seed,
                               expert=expert)
        what = "A* expert" if expert is None else repr(args.expert)
        print(f"dataset {data_dir} of map {grid.name!r} from {what}: {report.samples} samples "
              f"in {report.seconds:.0f} s" if report.shards_written else
              f"dataset {data_dir} of map {grid.name!r}: already there", flush=True)
    if args.maps is not None:
        t0 = time.perf_counter()
        report = build(data_dir, GeneralDataConfig(maps=args.maps, seed=args.data_seed),
                       progress=not args.no_progress)
        print(f"dataset {data_dir}: {report.shards_written} shards written, "
              f"{report.shards_skipped} already there, {report.samples} new samples in "
              f"{time.perf_counter() - t0:.0f} s", flush=True)
    if not data_dir.is_dir():
        raise DatasetError(f"dataset directory {str(data_dir)!r} does not exist: build it "
                           f"with --maps N")
    start = ("on from " + str(out) if args.resume
             else f"from {init.source}" if init is not None else "from scratch")
    t0 = time.perf_counter()
    data = GroupedData(data_dir, progress=not args.no_progress)
    if len(list(data_dir.glob("shard-*.npz"))) < data.config.shards:
        raise DatasetError(f"dataset {str(data_dir)!r} is unfinished: "
                           f"{len(list(data_dir.glob('shard-*.npz')))} of "
                           f"{data.config.shards} shards; finish it with --maps "
                           f"{data.config.maps} --data-seed {data.config.seed}")
    print(f"data: {len(data)} samples of {data.maps} maps, {data.distinct_global_views} "
          f"distinct global views, loaded in {time.perf_counter() - t0:.0f} s; training "
          f"{start} up to "
          f"{args.steps} steps x batch {cfg.batch_size}"
          + (f", at most {args.minutes:g} min (until ~"
             f"{time.strftime('%H:%M', time.localtime(time.time() + 60 * args.minutes))})"
             if args.minutes is not None else ""), flush=True)
    result = train_general(data, cfg, out_path=out, steps=args.steps, resume=args.resume,
                           minutes=args.minutes, checkpoint_minutes=args.checkpoint_minutes,
                           device=args.device, progress=not args.no_progress, init_from=init)
    if args.ship:
        result.checkpoint.save(args.ship, include_training_state=False)
        print(f"inference-only model: {args.ship}")
    last = result.loss_history[-1][1] if result.loss_history else float("nan")
    print(f"trained the generalist: step {result.step} (stopped by {result.stopped}), loss "
          f"{last:.4f} -> {result.path}; resume with the same command and --resume")
    return 0


# ------------------------------------------------------------------------- train-general-dd
def add_dd_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--maps", type=int, default=60, metavar="N",
                   help="generated maps whose expert segments it learns (the generalist "
                        "dataset's map schedule; about 2 s a map)")
    p.add_argument("--data-seed", type=int, default=0, help="the maps' seed (as train-general)")
    p.add_argument("--pairs", type=int, default=100, help="expert paths per map")
    p.add_argument("--out", default=str(DEFAULT_DIR / "general_dd.pt"),
                   help="the inference-only checkpoint")
    p.add_argument("--steps", type=int, default=None,
                   help="optimiser steps (default: the per-map DD's recipe)")
    p.add_argument("--minutes", type=float, default=None, metavar="M",
                   help="stop training after M minutes")
    p.add_argument("--seed", type=int, default=0, help="seed of weights and every draw")
    p.add_argument("--threads", type=int, default=1, help="torch threads")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def run_dd(args: argparse.Namespace) -> int:
    from ecahd_core.general.segment_dd import build_segment_data, train_segment_dd
    from ecahd_core.model_zoo import recipe

    set_torch_threads(args.threads)
    for name in ("maps", "pairs", "steps", "minutes"):
        value = getattr(args, name)
        if value is not None and not value > 0:
            raise DatasetError(f"--{name} must be > 0, got {value}")
    data = build_segment_data(args.maps, seed=args.data_seed, pairs_per_map=args.pairs,
                              progress=not args.no_progress)
    print(f"segment data: {len(data.segments)} segments (mirrored) of {data.maps} maps, "
          f"{data.dropped} too short dropped, in {data.seconds:.0f} s", flush=True)
    t0 = time.perf_counter()
    result = train_segment_dd(args.out, data, recipe("dd"), seed=args.seed, steps=args.steps,
                              minutes=args.minutes, progress=not args.no_progress)
    last = result.loss_history[-1][1] if result.loss_history else float("nan")
    print(f"trained the segment-frame DD: {result.checkpoint.step} steps in "
          f"{time.perf_counter() - t0:.0f} s, loss {last:.4f} -> {args.out}")
    return 0
