"""``ecahd train {sd,dd,fd}`` and ``ecahd train-all``: train the diffusion models of a map.

    ecahd train sd --data data/large.npz --out runs/train/sd.pt
    ecahd train-all --map my_map.yaml --out-dir my_models   # dataset + SD + DD, seeded
    ecahd train-all --map maze2d-large --kinds sd dd fd --precision fp32   # the shipped models

Defaults come from ``ecahd_core.model_zoo.RECIPES``; ``--device cuda`` trains on a GPU, and the
same command under ``torchrun --nproc_per_node N`` trains with DistributedDataParallel.
``--threads N`` sets torch's CPU threads on purpose (``ecahd_core.threads``; default: every core
this process may use).
"""
from __future__ import annotations

import argparse
import logging
import math
import time
from pathlib import Path

from ecahd_core.maps import DEFAULT_MAP
from ecahd_core.errors import EcahdError
from ecahd_core.threads import (add_precision_argument, add_threads_argument, resolve_precision,
                                set_torch_threads, training_threads)

log = logging.getLogger("ecahd.train")


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seed", type=int, default=0, help="seed of weights and every random draw")
    p.add_argument("--device", default="cpu", help="cpu, cuda, cuda:1, ...")
    p.add_argument("--steps-scale", type=float, default=1.0,
                   help="multiply every recipe's step count (and warm-up) by this")
    add_threads_argument(p, default=None)
    add_precision_argument(p, "auto", "bf16: forward pass under bfloat16 autocast (float32 "
                                      "weights); auto: bf16 where the device computes it "
                                      "natively (AVX512-BF16 / AMX CPUs, recent GPUs), fp32 "
                                      "elsewhere")
    p.add_argument("--fourier-period", type=float, default=None, metavar="M",
                   help="[m] the finest period of SD's Fourier features on a building's map "
                        "(maps over 50 000 cells; default 0.5: 7 bands on a 60 m office); 0: "
                        "none, the paper's linear embedding of the waypoints (maze2d-large "
                        "never gets them)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def _recipe(kind: str, fourier_period: float | None):
    """``kind``'s ModelRecipe, with ``--fourier-period`` (None: the recipe's; 0: none) where
    the recipe has Fourier features."""
    from dataclasses import replace

    from ecahd_core.model_zoo import recipe

    r = recipe(kind)
    if fourier_period is None or r.fourier_period is None:
        return r
    if not (math.isfinite(fourier_period) and fourier_period >= 0):
        raise EcahdError(f"--fourier-period must be a finite number >= 0 m (0: none), "
                         f"got {fourier_period}")
    return replace(r, fourier_period=fourier_period or None)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("kind", choices=("sd", "dd", "fd"), help="which model")
    p.add_argument("--data", required=True, help="expert dataset (.npz from `ecahd dataset`)")
    p.add_argument("--out", required=True, help="checkpoint to write (with training state)")
    p.add_argument("--steps", type=int, default=None, help="optimiser steps (default: recipe)")
    p.add_argument("--batch-size", type=int, default=None, help="batch (default: recipe)")
    p.add_argument("--warmup", type=int, default=None, help="LR warm-up steps (default: recipe)")
    p.add_argument("--resume", default=None, help="continue from this checkpoint")
    p.add_argument("--ship", default=None,
                   help="also write an inference-only copy here (what the package ships)")
    _add_common(p)


def add_all_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--map", default=DEFAULT_MAP, help="built-in maze or Nav2 map YAML")
    p.add_argument("--robot", default="circle",
                   help="footprint whose clearance the expert A* paths keep")
    p.add_argument("--pairs", type=int, default=5000, help="expert start/goal pairs")
    p.add_argument("--waypoints", choices=("auto", "arclength", "corners"), default="auto",
                   help="rule of SD's sparse waypoints in the expert data (see `ecahd dataset "
                        "--help`; auto: corners when the expert's median waypoint spacing "
                        "exceeds 1.5 m)")
    p.add_argument("--kinds", nargs="+", default=["sd", "dd"], choices=("sd", "dd", "fd"),
                   help="models to train: ECAHD needs SD and DD; add fd for the Full "
                        "Diffusion baseline of the benchmarks (about 8-10 more minutes)")
    p.add_argument("--work-dir", default="runs/train",
                   help="dataset and full checkpoints (resumable) go here")
    p.add_argument("--out-dir", default=None,
                   help="inference-only models go here (default: the package's models folder; "
                        "another folder is found through $ECAHD_MODELS)")
    p.add_argument("--minutes", type=float, default=None, metavar="M",
                   help="a time budget: once the dataset is made, each model trains until its "
                        "share of the time left is spent (shares by step times measured at the "
                        "start), so that train-all ends about M minutes after the start: more "
                        "steps on a fast machine, fewer on a slow or busy one (replaces "
                        "--steps-scale; the warm-up is the recipes' scaled by the expected "
                        "steps). Default: the recipes' steps")
    _add_common(p)


def train_one(kind: str, dataset, *, out: Path, seed: int, device: str, steps: int | None = None,
              batch_size: int | None = None, warmup: int | None = None,
              steps_scale: float = 1.0, resume: str | None = None, ship: Path | None = None,
              progress: bool = True, precision: str = "fp32",
              time_limit_s: float | None = None, fourier_period: float | None = None):
    """Train one model kind on an ExpertDataset; returns the TrainResult. With
    ``time_limit_s`` [s] training stops then, or at ``STEP_CAP`` x the scaled steps (the warm-up
    stays the scaled run's). ``fourier_period``: [m] as ``--fourier-period`` (None: the
    recipe's)."""
    from ecahd_core.diffusion import Normalizer, TrainConfig, train
    from ecahd_core.model_zoo import model_meta, training_arrays

    r = _recipe(kind, fourier_period)
    arrays = training_arrays(kind, dataset)
    steps = steps or max(1, int(round(r.steps * steps_scale)))
    warmup = warmup if warmup is not None else int(round(r.warmup_steps * min(1.0, steps_scale)))
    if time_limit_s is not None:
        steps = int(steps * STEP_CAP)
    config = r.denoiser_config(max(arrays), dataset.grid())
    tc = TrainConfig(steps=steps, batch_size=batch_size or r.batch_for(max(arrays)),
                     warmup_steps=warmup,
                     lr=r.lr, ema_decay=r.ema_decay, seed=seed, device=device,
                     log_every=max(1, min(100, steps // 20)), precision=precision,
                     time_limit_s=time_limit_s)
    normalizer = Normalizer.from_bounds(*dataset.grid().bounds)
    n = sum(len(a) for a in arrays.values())
    log.info("training %s: %d trajectories, horizons %s, %d steps x batch %d on %s (%s)",
             kind, n, sorted(arrays), tc.steps, tc.batch_size, device, precision)
    result = train(config, arrays, normalizer, tc, kind=kind, out_path=out,
                   meta=model_meta(kind, dataset), resume_from=resume, progress=progress)
    if ship is not None and result.checkpoint is not None:
        result.checkpoint.save(ship, include_training_state=False)
        log.info("inference-only model: %s (%.1f MB)", ship, ship.stat().st_size / 1e6)
    return result


# the horizons each kind learns with the dataset's defaults (ecahd_core.dataset): SD 2..P^g,
# DD P^l points, FD the whole 100-point sequence; only their lengths matter to a step's cost
# (a DD of more points, `ecahd dataset --dense-points N`, trains with a batch of as many
# tokens: ModelRecipe.batch_for)
ESTIMATE_HORIZONS = {"sd": tuple(range(2, 11)), "dd": (4,), "fd": (100,)}


def seconds_per_step(kind: str, grid, *, device: str = "cpu", probe: int = 8,
                     precision: str = "fp32", fourier_period: float | None = None) -> float:
    """[s] one optimiser step of ``kind``'s recipe on this machine, measured on synthetic
    trajectories of the learnt horizons (a step's cost does not depend on the values): short
    runs of :func:`~ecahd_core.diffusion.train` (a warm-up, then 1 and 1 + ``probe`` steps; the
    difference divides out the set-up)."""
    import tempfile

    import numpy as np

    from ecahd_core.diffusion import Normalizer, TrainConfig, train

    r = _recipe(kind, fourier_period)
    lo, hi = grid.bounds[:2], grid.bounds[2:]
    rng = np.random.default_rng(0)
    arrays = {h: rng.uniform(lo, hi, size=(r.batch_size, h, 2)).astype(np.float32)
              for h in ESTIMATE_HORIZONS[kind]}
    config = r.denoiser_config(max(arrays), grid)
    normalizer = Normalizer.from_bounds(*grid.bounds)
    times = []
    quiet = logging.getLogger("ecahd_core.diffusion.training")
    level = quiet.level
    quiet.setLevel(logging.WARNING)  # the probes' own log lines are noise
    with tempfile.TemporaryDirectory() as tmp:
        for steps in (1, 1, 1 + probe):
            tc = TrainConfig(steps=steps, batch_size=r.batch_size, warmup_steps=0, lr=r.lr,
                             ema_decay=r.ema_decay, seed=0, device=device, log_every=10 ** 9,
                             precision=precision)
            t0 = time.perf_counter()
            train(config, arrays, normalizer, tc, kind=kind, out_path=Path(tmp) / "probe.pt",
                  progress=False)
            times.append(time.perf_counter() - t0)
    quiet.setLevel(level)
    return max(0.0, (times[2] - times[1]) / probe)


def _set_threads(n: int | None) -> None:
    """``--threads``: n torch threads (None: every core, :func:`training_threads`)."""
    set_torch_threads(training_threads() if n is None else n)


def run(args: argparse.Namespace) -> int:
    from ecahd_core.dataset import ExpertDataset

    _recipe("sd", args.fourier_period)  # a bad --fourier-period fails before any work
    _set_threads(args.threads)
    precision = resolve_precision(args.precision, args.device)
    dataset = ExpertDataset.load(args.data)
    t0 = time.perf_counter()
    result = train_one(args.kind, dataset, out=Path(args.out), seed=args.seed, device=args.device,
                       steps=args.steps, batch_size=args.batch_size, warmup=args.warmup,
                       steps_scale=args.steps_scale, resume=args.resume,
                       ship=Path(args.ship) if args.ship else None,
                       progress=not args.no_progress, precision=precision,
                       fourier_period=args.fourier_period)
    last = result.loss_history[-1][1] if result.loss_history else float("nan")
    print(f"trained {args.kind}: {result.step} steps in {time.perf_counter() - t0:.0f} s, "
          f"final loss {last:.4f} -> {result.path}")
    return 0


# share of a --minutes budget left after the dataset that training fills: each model trains
# until its share of it is spent (TrainConfig.time_limit_s), whatever the machine's load; the
# rest covers each model's set-up and checkpoints
BUDGET_FILL = 0.96
# with a time limit, the most steps a model may take, x the steps its measured step time
# predicts for its share: the 3 s step-time probe read 1.6x slow once with other work beside
# it (docs/RESULTS.md); the time limit, not this cap, is meant to stop training
STEP_CAP = 3.0


def budget_scale(seconds_left: float, recipe_seconds: dict) -> float:
    """The one factor on every recipe's step count that fills ``seconds_left`` [s] of training
    (``BUDGET_FILL`` of it), given each kind's estimated time at its recipe's steps [s]."""
    total = sum(recipe_seconds.values())
    if seconds_left <= 0 or total <= 0:
        raise EcahdError(f"the time budget is spent before training starts "
                         f"({seconds_left / 60:.1f} min left after the dataset): give "
                         f"--minutes more room, or fewer --pairs")
    return BUDGET_FILL * seconds_left / total


def _duration(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 90 else f"{seconds / 60:.0f} min"


def _clock(seconds_from_now: float) -> str:
    """The local wall-clock time ``seconds_from_now`` s from now, HH:MM."""
    return time.strftime("%H:%M", time.localtime(time.time() + seconds_from_now))


def run_all(args: argparse.Namespace) -> int:
    from ecahd_core.dataset import generate_dataset, waypoint_rule
    from ecahd_core.maps import load_map
    from ecahd_core.model_zoo import MODELS_DIR, MODELS_ENV, recipe, shipped_path

    _recipe("sd", args.fourier_period)  # a bad --fourier-period fails before any work
    _set_threads(args.threads)
    precision = resolve_precision(args.precision, args.device)
    work = Path(args.work_dir)
    work.mkdir(parents=True, exist_ok=True)
    grid = load_map(args.map)
    out_dir = Path(args.out_dir) if args.out_dir else MODELS_DIR
    t_start = time.perf_counter()
    if args.minutes is not None and not (args.minutes > 0 and args.steps_scale == 1.0):
        raise EcahdError(f"--minutes must be > 0 and replaces --steps-scale, got --minutes "
                         f"{args.minutes} with --steps-scale {args.steps_scale}")
    # an ETA from the start: each model's step time measured now, the dataset has its own bar
    per_step = {k: seconds_per_step(k, grid, device=args.device, precision=precision,
                                    fourier_period=args.fourier_period)
                for k in args.kinds}

    def sized(scale: float) -> tuple[dict, dict]:
        """Each kind's steps at ``scale`` x its recipe's, and their estimated time [s]."""
        steps = {k: max(1, int(round(recipe(k).steps * scale))) for k in args.kinds}
        return steps, {k: steps[k] * per_step[k] for k in args.kinds}

    scale = args.steps_scale
    steps, estimate = sized(scale)
    train_s = sum(estimate.values())
    plan = (f"training until ~{_clock(args.minutes * 60)} ({args.minutes:g} min from now), its "
            f"steps set once the dataset is made" if args.minutes is not None else
            ", ".join(f"{k.upper()} {steps[k]} steps ~{_duration(estimate[k])}"
                      for k in args.kinds) + f": training ~{_duration(train_s)} after the dataset")
    print(f"train-all on {grid.name}: {args.pairs} expert pairs (progress bar below), then "
          f"{plan} (step times measured in {time.perf_counter() - t_start:.0f} s; {precision})",
          flush=True)
    data_path = work / f"{grid.name}_{args.robot}_{args.pairs}_s{args.seed}.npz"
    dataset = generate_dataset(grid, pairs=args.pairs, seed=args.seed, footprint_spec=args.robot,
                               waypoints=args.waypoints,
                               progress=not args.no_progress)
    dataset.save(data_path)
    times = {"dataset": time.perf_counter() - t_start}
    if args.minutes is not None:
        scale = budget_scale(args.minutes * 60 - times["dataset"], sized(1.0)[1])
        steps, estimate = sized(scale)
        train_s = sum(estimate.values())
        if scale < 0.5:
            log.warning("the %g min budget leaves the models %.0f%% of their recipes' steps: "
                        "expect worse plans", args.minutes, 100 * scale)
    print(f"dataset: {dataset.num_pairs} pairs, {waypoint_rule(dataset)} waypoints -> "
          f"{data_path} ({times['dataset']:.0f} s); "
          + (f"{args.minutes:g} min budget: recipes' steps x {scale:.3g} ("
             + ", ".join(f"{k.upper()} {steps[k]}" for k in args.kinds)
             + " by the step times; each model stops when its share of the time is spent); "
             if args.minutes is not None else "")
          + f"ETA {_clock(train_s)} (~{_duration(train_s)} of training)", flush=True)
    deadline = (t_start + times["dataset"] + BUDGET_FILL * (args.minutes * 60 - times["dataset"])
                if args.minutes is not None else None)
    todo = list(args.kinds)
    for kind in args.kinds:
        t0 = time.perf_counter()
        limit = None
        if deadline is not None:  # this model's share of the time left
            limit = max(1.0, (deadline - t0) * estimate[kind] / sum(estimate[k] for k in todo))
        ship = out_dir / shipped_path(grid.name, kind).name
        result = train_one(kind, dataset, out=work / f"{grid.name}_{kind}.pt", seed=args.seed,
                           device=args.device, steps_scale=scale, ship=ship,
                           precision=precision, time_limit_s=limit,
                           progress=not args.no_progress, fourier_period=args.fourier_period)
        times[kind] = time.perf_counter() - t0
        last = result.loss_history[-1][1] if result.loss_history else float("nan")
        todo.remove(kind)
        left = (max(0.0, deadline - time.perf_counter()) if limit is not None
                else sum(estimate[k] for k in todo)) if todo else 0.0
        print(f"{kind}: {result.step} steps"
              + (f" (estimated {steps[kind]}, {result.step / steps[kind]:.2f}x)"
                 if limit is not None else "")
              + f", final loss {last:.4f}, {times[kind]:.0f} s "
              f"({'time limit' if limit is not None else 'estimated'} "
              f"{limit if limit is not None else estimate[kind]:.0f} s) -> {ship}"
              + (f"; ETA {_clock(left)}" if left else ""), flush=True)
    total = time.perf_counter() - t_start
    print("wall time: " + ", ".join(f"{k} {v:.0f} s" for k, v in times.items())
          + f"; total {total / 60:.1f} min")
    if out_dir.resolve() != MODELS_DIR.resolve():
        print(f"to use them: export {MODELS_ENV}={out_dir.resolve()}  (or --models on demo)")
    return 0
