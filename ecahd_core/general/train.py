"""Training of the generalist (map-conditioned) SD (issue 40) on a ``general.data`` dataset.

The recipe is the per-map SD's (``ecahd_core.diffusion.training``, paper Sec. III-B) with views:
eps-prediction (DDPM) on waypoints in view coordinates u in [-1, 1]^2, the start and goal
(waypoints 0 and h - 1) overwritten with their clean values in x_t and left out of the loss
(``apply_conditioning``, as the sampler inpaints them), AdamW with a linear warm-up, gradient
clipping, an EMA of the weights for sampling, and one horizon h per batch drawn in proportion to
the samples of each horizon (the dataset stores the whole problems, P^g = 10, and one shorter
horizon 3..9 per expert path).

Batches of K maps x M problems (``maps_per_batch`` x ``problems_per_map``, 16 x 8 by default):
with the default "map" view extent the problems of one map share its global view, so the
global CNN runs once per distinct global view (``ViewTensors.global_index``), not once per
problem. The loader keeps each distinct global view once (:class:`GroupedData`), which also
keeps 1000 maps' data in about 2 GB of memory instead of 5 (the local views, kept per sample,
are most of it).

Measured (this 2-core machine, 1 thread, float32, the default model of 1.46 M parameters,
forward + backward + AdamW at batch 128, P = 10; ``python -m ecahd_core.general.train``):
1.44-1.53 s a step with a global view per problem, 0.40-0.45 s with 16 maps x 8 problems.

Augmentation: each distinct global view gets one of the 8 symmetries of the square (rotations
by 90 degrees and flips), applied to it, to the local views and to the waypoints of the problems
that use it (:func:`symmetric_views`, :func:`symmetric_points`). Views and frames are symmetric
about u = 0 (pixel centres at -1 + (k + 1/2) 2 / S), so the transformed sample is exactly the
sample of the transformed map; the robot's footprint is a circle, so the expert's clearance is
kept.

Randomness: every step draws from a generator seeded with (seed, step) (``step_seed``), so a
run resumed from a checkpoint continues exactly as the uninterrupted run; torch's global RNG
state (dropout) is stored in the checkpoint too.

Checkpoints (:mod:`ecahd_core.general.checkpoint`) every ``checkpoint_minutes`` of wall time
and at the end, written atomically.
"""
from __future__ import annotations

import copy
import json
import logging
import os
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn

from ecahd_core.diffusion.conditioning import START_GOAL, apply_conditioning, condition_mask
from ecahd_core.diffusion.scheduler import NoiseSchedule, ScheduleConfig
from ecahd_core.diffusion.training import cpu_state, ema_update, step_seed
from ecahd_core.errors import CheckpointError, DatasetError
from ecahd_core.general.checkpoint import GeneralCheckpoint, load_general_checkpoint
from ecahd_core.general.data import GeneralDataConfig, dequantise, iter_shards
from ecahd_core.general.model import (GeneralDenoiserConfig, MapConditionedDenoiser,
                                      ViewTensors)

log = logging.getLogger(__name__)

SYMMETRIES = 8  # the dihedral group of the square: code bit 0 flip x, bit 1 flip y, bit 2 swap
# its rotations (an even number of the three reflections): left stays left, so a side habit of
# demonstrations (keep to the right) survives the augmentation; the other four mirror it
ROTATIONS = (0, 3, 5, 6)
_STREAM_BATCH = 0  # step_seed stream of the batch's draws
_STREAM_GLOBAL = 1  # step_seed stream that seeds torch's global RNG at a fresh start


@dataclass(frozen=True, kw_only=True)
class GeneralTrainConfig:
    """The generalist's training recipe (a resumed run must use the same one).

    Attributes:
        maps_per_batch: K, maps per batch.
        problems_per_map: M, problems drawn from each (with replacement); batch K x M.
        lr, betas, weight_decay: AdamW (the paper's lr).
        warmup_steps: linear learning-rate warm-up.
        ema_decay: EMA of the sampling weights; min(ema_decay, (1 + n) / (10 + n)) after n
            updates, as the per-map recipe.
        grad_clip_norm: global gradient-norm clip, or None.
        augment: the 8 symmetries of the square (module docstring).
        mirror: with ``augment``, the mirror images too; False: the 4 rotations only
            (:data:`ROTATIONS`), for data whose paths keep to one side (demonstrations of a
            keep-right habit: a mirrored sample teaches keep-left).
        seed: seed of the initial weights and of every draw.
        log_every: steps between logged (and recorded) mean losses.
        schedule: the forward process.
    """

    maps_per_batch: int = 16
    problems_per_map: int = 8
    lr: float = 1e-4
    betas: tuple[float, float] = (0.9, 0.999)
    weight_decay: float = 1e-2
    warmup_steps: int = 1000
    ema_decay: float = 0.999
    grad_clip_norm: float | None = 1.0
    augment: bool = True
    mirror: bool = True
    seed: int = 0
    log_every: int = 100
    schedule: ScheduleConfig = field(default_factory=ScheduleConfig)

    def __post_init__(self) -> None:
        for name, least in (("maps_per_batch", 1), ("problems_per_map", 1), ("log_every", 1),
                            ("warmup_steps", 0), ("seed", 0)):
            value = getattr(self, name)
            if isinstance(value, bool) or int(value) != value or value < least:
                raise ValueError(f"GeneralTrainConfig.{name} must be an integer >= {least}, "
                                 f"got {value!r}")
            object.__setattr__(self, name, int(value))
        if not self.lr > 0:
            raise ValueError(f"GeneralTrainConfig.lr must be positive, got {self.lr}")
        if not 0.0 <= self.ema_decay < 1.0:
            raise ValueError(f"GeneralTrainConfig.ema_decay must be in [0, 1), "
                             f"got {self.ema_decay}")
        object.__setattr__(self, "betas", tuple(float(b) for b in self.betas))
        if isinstance(self.schedule, dict):
            object.__setattr__(self, "schedule", ScheduleConfig.from_dict(self.schedule))

    @property
    def batch_size(self) -> int:
        return self.maps_per_batch * self.problems_per_map

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["betas"] = list(self.betas)
        d["schedule"] = self.schedule.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "GeneralTrainConfig":
        return cls(**d)


# ------------------------------------------------------------------------------- symmetries
def symmetric_views(images: Tensor, code: int) -> Tensor:
    """One of the 8 symmetries of the square on views.

    Args:
        images: (..., S, S) views, row = y, column = x (``views.py``'s layout).
        code: 0..7; bit 2 swaps x and y (transpose), then bit 0 negates x (flips the columns),
            bit 1 negates y (flips the rows). 0 is the identity.
    Returns:
        the transformed images, (..., S, S).
    """
    _check_code(code)
    if code & 4:
        images = images.transpose(-1, -2)
    if code & 1:
        images = images.flip(-1)
    if code & 2:
        images = images.flip(-2)
    return images


def symmetric_points(uv: Tensor, code: int) -> Tensor:
    """The same symmetry as :func:`symmetric_views` on (..., 2) points (x, y) in view
    coordinates."""
    _check_code(code)
    if code & 4:
        uv = uv.flip(-1)
    if code & 1:
        uv = uv * uv.new_tensor([-1.0, 1.0])
    if code & 2:
        uv = uv * uv.new_tensor([1.0, -1.0])
    return uv


def _check_code(code: int) -> None:
    if not 0 <= code < SYMMETRIES:
        raise ValueError(f"symmetry code must be in 0..{SYMMETRIES - 1}, got {code}")


# -------------------------------------------------------------------------------- the data
@dataclass(frozen=True)
class Batch:
    """One training batch (K maps x M problems, one horizon).

    Attributes:
        x0: (B, h, 2) expert waypoints in view coordinates.
        views: the model's views; U distinct global views, ``global_index`` (B,).
        horizon: h.
    """

    x0: Tensor
    views: ViewTensors
    horizon: int


class GroupedData:
    """A generalist dataset held for training: each distinct global view once.

    Arrays (N samples, U distinct global views):
        global_view (U, C, S, S) uint8, global_half (U,) [m]; view_row (N,) sample -> row;
        local_views (N, 2, C, S_l, S_l) uint8; waypoints (N, P^g, 2) float32 (NaN beyond the
        horizon); horizon (N,); map_index (N,).
    """

    def __init__(self, directory: str | os.PathLike, *, progress: bool = False) -> None:
        directory = Path(directory)
        globals_, halves, rows, parts, maps = [], [], [], [], 0
        config = None
        n_rows = 0
        shards = iter_shards(directory)
        if progress:
            from tqdm import tqdm
            shards = tqdm(shards, unit="shard", desc="load generalist data", mininterval=5)
        for shard in shards:
            a, config = shard.arrays, shard.config
            g, half = a["global_view"], a["half_side"]
            N = len(g)
            maps += len(shard.maps)
            if not N:
                continue
            # a global view is its pixels and its scale: dedupe on both (exact)
            key = np.concatenate([g.reshape(N, -1),
                                  np.ascontiguousarray(half, dtype=np.float64)
                                  .view(np.uint8).reshape(N, 8)], axis=1)
            key = np.ascontiguousarray(key).view(np.dtype((np.void, key.shape[1]))).ravel()
            _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
            globals_.append(g[first])
            halves.append(half[first])
            rows.append(n_rows + inverse.reshape(-1))
            n_rows += len(first)
            parts.append({k: a[k] for k in ("local_views", "waypoints", "horizon",
                                            "map_index")})
        if not parts:
            raise DatasetError(f"{str(directory)!r} holds no samples")
        self.directory = directory
        self.config: GeneralDataConfig = config
        self.maps = maps
        self.global_view = np.concatenate(globals_)
        self.global_half = np.concatenate(halves).astype(np.float32)
        self.view_row = np.concatenate(rows).astype(np.int64)
        self.local_views = np.concatenate([p["local_views"] for p in parts])
        self.waypoints = np.concatenate([p["waypoints"] for p in parts])
        self.horizon = np.concatenate([p["horizon"] for p in parts]).astype(np.int64)
        self.map_index = np.concatenate([p["map_index"] for p in parts]).astype(np.int64)
        # per horizon: the samples sorted by map, each map's first position and count
        self.horizons = tuple(int(h) for h in np.unique(self.horizon))
        self._by_h: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        for h in self.horizons:
            idx = np.flatnonzero(self.horizon == h)
            idx = idx[np.argsort(self.map_index[idx], kind="stable")]
            _, starts, counts = np.unique(self.map_index[idx], return_index=True,
                                          return_counts=True)
            self._by_h[h] = (idx, starts, counts)
        self.horizon_weights = torch.tensor([len(self._by_h[h][0]) for h in self.horizons],
                                            dtype=torch.float64)

    def __len__(self) -> int:
        return int(self.horizon.shape[0])

    @property
    def distinct_global_views(self) -> int:
        return int(self.global_view.shape[0])

    def identity(self) -> dict[str, Any]:
        """What a checkpoint records of the data (and a resumed run compares)."""
        return {"directory": str(self.directory), "config": json.loads(self.config.to_json()),
                "samples": len(self), "maps": self.maps,
                "global_views": self.distinct_global_views}

    def draw(self, generator: torch.Generator, cfg: GeneralTrainConfig,
             horizons: tuple[int, ...] | None = None) -> Batch:
        """A batch of ``cfg.maps_per_batch`` maps x ``cfg.problems_per_map`` problems of one
        horizon (drawn in proportion to its samples among ``horizons``, default all), with
        the augmentation, from ``generator`` (CPU)."""
        horizons = horizons or self.horizons
        weights = self.horizon_weights[[self.horizons.index(h) for h in horizons]]
        h = horizons[int(torch.multinomial(weights, 1, generator=generator))]
        idx, starts, counts = self._by_h[h]
        K, M = cfg.maps_per_batch, cfg.problems_per_map
        n_maps = len(starts)
        if n_maps >= K:  # K distinct maps
            maps = torch.randperm(n_maps, generator=generator)[:K].numpy()
        else:
            maps = torch.randint(n_maps, (K,), generator=generator).numpy()
        u = torch.rand(K, M, generator=generator, dtype=torch.float64).numpy()
        offset = np.minimum((u * counts[maps, None]).astype(np.int64), counts[maps, None] - 1)
        sample = idx[(starts[maps, None] + offset).reshape(-1)]  # (B,), map-major
        rows, inverse = np.unique(self.view_row[sample], return_inverse=True)
        x0 = torch.from_numpy(self.waypoints[sample, :h].astype(np.float32))  # (B, h, 2)
        global_view = torch.from_numpy(dequantise(self.global_view[rows]))  # (U, C, S, S)
        local_views = torch.from_numpy(dequantise(self.local_views[sample]))  # (B, 2, C, Sl, Sl)
        index = torch.from_numpy(inverse.reshape(-1).astype(np.int64))  # (B,)
        if cfg.augment:
            codes = torch.randint(SYMMETRIES, (len(rows),), generator=generator)  # (U,)
            if not cfg.mirror:  # the draw stays the same; each code maps to a rotation
                codes = torch.tensor(ROTATIONS)[codes % len(ROTATIONS)]
            per_sample = codes[index]  # (B,)
            for code in codes.unique().tolist():
                if code == 0:
                    continue
                g_sel, s_sel = codes == code, per_sample == code
                global_view[g_sel] = symmetric_views(global_view[g_sel], code)
                local_views[s_sel] = symmetric_views(local_views[s_sel], code)
                x0[s_sel] = symmetric_points(x0[s_sel], code)
        views = ViewTensors(global_view, local_views, torch.from_numpy(self.global_half[rows]),
                            global_index=index)
        return Batch(x0=x0, views=views, horizon=h)


# ------------------------------------------------------------------------------ training
@dataclass(frozen=True)
class GeneralTrainResult:
    """Attributes:
        path: the checkpoint written.
        step: optimiser steps done.
        loss_history: ((step, mean loss), ...).
        stopped: "steps" (all done) or "time" (``minutes`` spent).
        checkpoint: the last checkpoint as written.
    """

    path: Path
    step: int
    loss_history: tuple[tuple[int, float], ...]
    stopped: str
    checkpoint: GeneralCheckpoint


def train_general(data: GroupedData, cfg: GeneralTrainConfig, *, out_path: str | os.PathLike,
                  steps: int, model_config: GeneralDenoiserConfig | None = None,
                  resume: bool = False, minutes: float | None = None,
                  checkpoint_minutes: float | None = 10.0, device: str = "cpu",
                  progress: bool = True, init_from: GeneralCheckpoint | None = None
                  ) -> GeneralTrainResult:
    """Train the map-conditioned denoiser and write its resumable checkpoint.

    Args:
        data: the dataset (:class:`GroupedData`).
        cfg: the recipe.
        out_path: the checkpoint, written every ``checkpoint_minutes`` and at the end.
        steps: total optimiser steps (a resumed run continues up to this number).
        model_config: the architecture (default: ``GeneralDenoiserConfig`` with the data's
            views and horizon); a resumed run takes the checkpoint's and refuses another.
        resume: continue from ``out_path``.
        minutes: stop (with a checkpoint) after this much wall time of this call's training.
        checkpoint_minutes: [min] between checkpoints (None: at the end only).
        device: "cpu", "cuda", ...
        progress: a tqdm bar with the loss and the ETA.
        init_from: start from this generalist's EMA weights (fine-tuning on one map,
            ``ecahd train-general --map ... --from general``; a fresh optimiser, its warm-up
            included), recorded in the checkpoint's ``data`` (``init_from``, ``init_step``).
    Raises:
        CheckpointError: ``resume`` from a missing, unreadable or foreign checkpoint, or an
            ``init_from`` of another model config.
        DatasetError: data that cannot train this model.
    """
    out_path = Path(out_path)
    device_t = torch.device(device)
    P = data.config.sparse_horizon
    start_step, history, elapsed_before = 0, [], 0.0
    ckpt = None
    if resume:
        ckpt = load_general_checkpoint(out_path, map_location="cpu")
        if ckpt.training_state is None:
            raise CheckpointError(f"cannot resume from '{out_path}': it holds no training state "
                                  f"(an inference-only checkpoint)")
        if model_config is not None and model_config != ckpt.model_config:
            raise CheckpointError(f"cannot resume from '{out_path}': its model config differs "
                                  f"from this run's")
        model_config = ckpt.model_config
        theirs = GeneralTrainConfig.from_dict(ckpt.train_config)
        if theirs != cfg:
            diff = sorted(k for k, v in cfg.to_dict().items() if ckpt.train_config.get(k) != v)
            raise CheckpointError(f"cannot resume from '{out_path}': its training recipe "
                                  f"differs in {', '.join(diff)}")
        if _without_directory(ckpt.data) != _without_directory(data.identity()):
            raise DatasetError(f"cannot resume from '{out_path}': it was trained on another "
                               f"dataset ({ckpt.data.get('directory')}, "
                               f"{ckpt.data.get('samples')} samples) than "
                               f"{str(data.directory)!r} ({len(data)} samples)")
    init = {}
    if init_from is not None and not resume:
        if model_config is not None and model_config != init_from.model_config:
            raise CheckpointError(f"cannot start from '{init_from.source}': its model config "
                                  f"differs from this run's")
        model_config = init_from.model_config
        init = {"init_from": str(init_from.source), "init_step": int(init_from.step)}
    model_config = model_config or GeneralDenoiserConfig(max_horizon=P, view=data.config.view)
    if model_config.view != data.config.view:
        raise DatasetError(f"{str(data.directory)!r} holds views of {data.config.view}; the "
                           f"model reads {model_config.view}")
    if P > model_config.max_horizon:
        raise DatasetError(f"{str(data.directory)!r} holds horizons up to {P}; the model's "
                           f"max_horizon is {model_config.max_horizon}")
    cond = START_GOAL
    horizons = tuple(h for h in data.horizons if (~condition_mask(h, cond)).any())
    if not horizons:
        raise DatasetError(f"{str(data.directory)!r}: every waypoint of its horizons is "
                           f"inpainted, nothing to learn")

    with torch.random.fork_rng(devices=[]):  # seeded initial weights; caller's RNG untouched
        torch.manual_seed(cfg.seed)
        model = MapConditionedDenoiser(model_config).to(device_t)
        if init:
            model.load_state_dict(init_from.ema_state_dict)
    ema = copy.deepcopy(model).eval().requires_grad_(False)
    schedule = NoiseSchedule(cfg.schedule).to(device_t)
    optimizer = torch.optim.AdamW(model.parameters(), lr=cfg.lr, betas=cfg.betas,
                                  weight_decay=cfg.weight_decay)
    if ckpt is not None:
        state = ckpt.training_state
        try:
            model.load_state_dict(state["model_state_dict"])
            ema.load_state_dict(ckpt.ema_state_dict)
            optimizer.load_state_dict(state["optimizer_state_dict"])
            torch.set_rng_state(state["torch_rng_state"])
        except (KeyError, RuntimeError, TypeError, ValueError) as exc:
            raise CheckpointError(f"cannot resume from '{out_path}': its training state does "
                                  f"not fit: {type(exc).__name__}: "
                                  f"{(str(exc).splitlines() or [''])[0]}") from exc
        start_step, history = ckpt.step, list(ckpt.loss_history)
        init = {k: ckpt.data[k] for k in ("init_from", "init_step") if k in ckpt.data}
        elapsed_before = float(state.get("elapsed_s", 0.0))
        log.info("resuming the generalist from %s at step %d", out_path, start_step)
    else:  # torch's global RNG (dropout, if any) from the seed too; a resumed run restores it
        torch.manual_seed(step_seed(cfg.seed, 0, _STREAM_GLOBAL))

    def make_checkpoint(step: int, elapsed: float) -> GeneralCheckpoint:
        return GeneralCheckpoint(
            model_config=model_config, schedule_config=cfg.schedule, conditioned_indices=cond,
            horizons=horizons, ema_state_dict=cpu_state(ema.state_dict()), step=step,
            train_config=cfg.to_dict(), data={**data.identity(), **init},
            loss_history=tuple(history),
            training_state={"model_state_dict": cpu_state(model.state_dict()),
                            "optimizer_state_dict": optimizer.state_dict(),
                            "torch_rng_state": torch.get_rng_state(),
                            "elapsed_s": elapsed})

    from tqdm import tqdm

    bar = tqdm(total=steps, initial=start_step, disable=not progress, desc="train general",
               unit="step", dynamic_ncols=True,
               mininterval=0.1 if sys.stderr.isatty() else 30.0)
    gen = torch.Generator()
    window, window_n = 0.0, 0
    model.train()
    t0 = last_save = time.perf_counter()
    step, stopped = start_step, "steps"
    while step < steps:
        gen.manual_seed(step_seed(cfg.seed, step, _STREAM_BATCH))
        # 1. a batch of K maps x M problems of one horizon h, augmented
        batch = data.draw(gen, cfg, horizons)
        loss = denoising_loss(model, schedule, batch, gen, device_t)
        for group in optimizer.param_groups:  # linear warm-up, then constant
            group["lr"] = cfg.lr * (min(1.0, (step + 1) / cfg.warmup_steps)
                                    if cfg.warmup_steps else 1.0)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        if cfg.grad_clip_norm is not None:
            nn.utils.clip_grad_norm_(model.parameters(), cfg.grad_clip_norm)
        optimizer.step()
        step += 1
        ema_update(ema, model, min(cfg.ema_decay, (1 + step) / (10 + step)))

        window += float(loss.detach())
        window_n += 1
        bar.update(1)
        now = time.perf_counter()
        out_of_time = minutes is not None and now - t0 >= 60.0 * minutes
        if out_of_time:
            stopped = "time"
        if step % cfg.log_every == 0 or step == steps or stopped != "steps":
            history.append((step, window / window_n))
            window, window_n = 0.0, 0
            bar.set_postfix(loss=f"{history[-1][1]:.4f}")
            log.info("train general: step %d/%d loss %.5f (%.2f s/step)", step, steps,
                     history[-1][1], (now - t0) / (step - start_step))
        if minutes is not None and step % 20 == 0 and step > start_step:  # the bar's ETA
            fit = step + int((60.0 * minutes - (now - t0)) * (step - start_step) / (now - t0))
            bar.total = max(step + 1, min(steps, fit))
            bar.refresh()
        if stopped != "steps":
            break
        if (checkpoint_minutes is not None and now - last_save >= 60.0 * checkpoint_minutes
                and step < steps):
            make_checkpoint(step, elapsed_before + now - t0).save(out_path)
            last_save = now
            log.info("checkpoint %s (step %d)", out_path, step)
    bar.close()
    checkpoint = make_checkpoint(step, elapsed_before + time.perf_counter() - t0)
    checkpoint.save(out_path)
    log.info("wrote %s (step %d, stopped by %s)", out_path, step, stopped)
    return GeneralTrainResult(path=out_path, step=step, loss_history=tuple(history),
                              stopped=stopped, checkpoint=checkpoint.with_source(out_path))


def denoising_loss(model: MapConditionedDenoiser, schedule: NoiseSchedule, batch: Batch,
                   generator: torch.Generator, device: torch.device | str = "cpu") -> Tensor:
    """The training objective on one batch (module docstring): t ~ U{0..K-1} and eps ~ N(0, I)
    from ``generator`` (CPU), x_t with the clean start and goal inpainted, the mean squared
    error of the predicted noise over the other waypoints. A scalar tensor."""
    device = torch.device(device)
    x0 = batch.x0.to(device)  # (B, h, 2)
    B, h, _ = x0.shape
    t = torch.randint(schedule.num_train_timesteps, (B,), generator=generator).to(device)
    noise = torch.randn(x0.shape, generator=generator).to(device)
    # 2. forward process, then inpaint the clean start and goal as the sampler will
    x_t = schedule.add_noise(x0, noise, t)
    x_t = apply_conditioning(x_t, {i: x0[:, i] for i in START_GOAL})
    # 3. MSE of the predicted noise over the free waypoints
    v = batch.views
    views = ViewTensors(v.global_view.to(device), v.local_views.to(device),
                        v.half_side.to(device), global_index=v.global_index.to(device))
    pred = model(x_t, t, views=views)  # (B, h, 2)
    free = (~condition_mask(h, START_GOAL, device=device)).nonzero().flatten()
    return (pred - noise).index_select(1, free).pow(2).mean()


@torch.no_grad()
def evaluate_loss(model: MapConditionedDenoiser, data: GroupedData, cfg: GeneralTrainConfig,
                  *, batches: int = 8, seed: int = 12345, device: str = "cpu") -> float:
    """The mean :func:`denoising_loss` of ``batches`` fixed batches (seeded by ``seed``: the
    same batches, timesteps and noise for every model), in eval mode."""
    schedule = NoiseSchedule(cfg.schedule).to(device)
    was_training = model.training
    model.eval()
    gen, total = torch.Generator(), 0.0
    for i in range(batches):
        gen.manual_seed(step_seed(seed, i, _STREAM_BATCH))
        batch = data.draw(gen, cfg)
        total += float(denoising_loss(model, schedule, batch, gen, device))
    model.train(was_training)
    return total / batches


def _without_directory(identity: dict[str, Any]) -> dict[str, Any]:
    """A dataset's identity but where it lies (a moved dataset is the same data)."""
    return {k: v for k, v in identity.items() if k not in ("directory", "init_from", "init_step")}


# ------------------------------------------------------------------------------ step time
def measure_step_time(*, grouped: bool, maps_per_batch: int = 16, problems_per_map: int = 8,
                      horizon: int = 10, repeats: int = 8,
                      config: GeneralDenoiserConfig | None = None) -> float:
    """[s] median of one training step (forward, backward, AdamW) of the default model at
    batch K x M on random views: ``grouped`` runs the global CNN on the K maps' views, else on
    one view per problem (as before the grouping). Uses the threads torch has."""
    config = config or GeneralDenoiserConfig(max_horizon=horizon)
    v, S, Sl = config.view, config.view.global_size, config.view.local_size
    K, B = maps_per_batch, maps_per_batch * problems_per_map
    gen = torch.Generator().manual_seed(0)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(0)
        model = MapConditionedDenoiser(config).train()
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-4)
    g = torch.rand(K, v.channels, S, S, generator=gen).round()
    local = torch.rand(B, 2, v.channels, Sl, Sl, generator=gen).round()
    index = torch.arange(K).repeat_interleave(problems_per_map)
    views = (ViewTensors(g, local, torch.full((K,), 10.0), global_index=index) if grouped else
             ViewTensors(g[index], local, torch.full((B,), 10.0)))
    x = torch.randn(B, horizon, 2, generator=gen)
    t = torch.randint(100, (B,), generator=gen)
    times = []
    for _ in range(repeats + 2):
        t0 = time.perf_counter()
        loss = model(x, t, views=views).pow(2).mean()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        times.append(time.perf_counter() - t0)
    return float(np.median(times[2:]))


if __name__ == "__main__":  # python -m ecahd_core.general.train: the docstring's step times
    torch.set_num_threads(1)
    before = measure_step_time(grouped=False)
    after = measure_step_time(grouped=True)
    print(f"one training step at batch 128 on 1 thread: a global view per problem "
          f"{before:.2f} s, 16 maps x 8 problems {after:.2f} s")
