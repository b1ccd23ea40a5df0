"""Training of the SD / DD / FD denoisers and their checkpoints (paper Sec. III-B, training).

Objective: noise prediction (DDPM, Ho et al. 2020). Per step: draw a horizon h with probability
proportional to its dataset size (one model learns every horizon, e.g. SD's 2..10; a horizon
whose every waypoint is inpainted, h = 2 with start and goal, has nothing to learn and is
skipped), a batch of
expert trajectories x_0 (normalised), timesteps t ~ U{0..K-1} and noise eps; form
x_t = sqrt(alpha_bar_t) x_0 + sqrt(1 - alpha_bar_t) eps, overwrite the inpainted waypoints of x_t
with their clean values, and minimise || eps_theta(x_t, t) - eps ||^2 over the other waypoints.
A network with ``DenoiserConfig.prediction = "sample"`` (the FD baseline, as Diffuser on maze2d)
minimises || x0_theta(x_t, t) - x_0 ||^2 instead and is sampled through
:class:`~ecahd_core.diffusion.denoiser.EpsilonFromSample`.

Why the inpainted waypoints are overwritten and left out of the loss: at sampling time the start
(and the goal, for goal-conditioned models) is reset to its clean value after every step
(:func:`~ecahd_core.diffusion.conditioning.apply_conditioning`), so the network only ever sees
those waypoints clean; training on the same input distribution avoids a train/test mismatch.
Once a waypoint is overwritten, x_t carries no trace of its noise, so the noise there cannot be
predicted: keeping it in the loss would add an irreducible term (variance 1) whose only effect is
gradient noise, and the sampler discards the prediction at those waypoints anyway. (The paper's
"weighting determined by a scheduling matrix" is not specified further; all other waypoints and
timesteps weigh the same here.)

Optimiser (paper): AdamW, lr 1e-4, betas (0.9, 0.999), weight decay 1e-2, linear warm-up (5000
steps in the paper; ``warmup_steps`` here, scaled to the run), constant afterwards. Sampling uses
an exponential moving average (EMA) of the weights.

Distributed: under ``torchrun`` (WORLD_SIZE > 1) the process group is initialised from the
environment (``env://``; gloo on CPU, nccl on CUDA), each rank draws from its own shard
``data[rank::world_size]`` of every horizon (what ``DistributedSampler`` does), ``batch_size``
is the global batch, and only rank 0 writes the checkpoint.

Randomness: every step re-seeds its generators from (seed, step, stream), so a run resumed from a
checkpoint continues exactly as the uninterrupted run would have (same world size).

Checkpoint: one ``torch.save`` file of plain data (dicts, lists, str, int, float, tensors) that
``torch.load(weights_only=True)`` reads; see :class:`Checkpoint`.
"""
from __future__ import annotations

import copy
import dataclasses
import logging
import os
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.distributed as dist
from torch import Tensor, nn
from torch.nn.parallel import DistributedDataParallel
from tqdm import tqdm

from ecahd_core.diffusion.conditioning import START_GOAL, apply_conditioning, condition_mask
from ecahd_core.diffusion.denoiser import DenoiserConfig, as_noise_predictor, build_denoiser
from ecahd_core.diffusion.normalizer import Normalizer
from ecahd_core.diffusion.scheduler import (DDIMScheduler, NoiseSchedule, ScheduleConfig,
                                            parse_choice)
from ecahd_core.errors import CheckpointError, DatasetError
from ecahd_core.threads import PRECISIONS

log = logging.getLogger(__name__)

CHECKPOINT_FORMAT = "ecahd-diffusion-checkpoint"
CHECKPOINT_VERSION = 1
_MAP_KEYS = ("map_name", "map_fingerprint")


class ModelKind(str, Enum):
    """Which of the three models a checkpoint holds."""

    SD = "sd"  # sparse global path (horizons 2..10)
    DD = "dd"  # dense local segment (P^l points)
    FD = "fd"  # full sequence

    @classmethod
    def parse(cls, value: "str | ModelKind") -> "ModelKind":
        return parse_choice(cls, value, "model kind")


@dataclass(frozen=True, kw_only=True)
class TrainConfig:
    """Training settings.

    Attributes:
        steps: total optimiser steps (a resumed run continues up to this number); with
            ``time_limit_s``, the most it may take.
        batch_size: global batch (split evenly over DDP ranks).
        lr, betas, weight_decay: AdamW (paper values by default).
        warmup_steps: linear learning-rate warm-up length (paper: 5000).
        ema_decay: EMA decay of the sampling weights; the effective decay is
            min(ema_decay, (1 + n) / (10 + n)) after n updates, so short runs are not dominated
            by the initial weights.
        seed: seed of the initial weights and every random draw.
        device: "cpu", "cuda", "cuda:1", ...; under DDP on CUDA each rank uses cuda:LOCAL_RANK.
        log_every: steps between logged (and recorded) mean losses.
        checkpoint_every: steps between intermediate checkpoints (0: only at the end).
        grad_clip_norm: global gradient-norm clip, or None.
        inpaint_goal: the last waypoint is inpainted too (goal-conditioned: SD, DD, FD); the first
            waypoint always is.
        schedule: the forward process (K, beta schedule).
        precision: "fp32", or "bf16": the forward pass and the loss under
            ``torch.autocast(bfloat16)`` (matrix products in bfloat16, weights, optimiser
            state and EMA in float32). On a CPU with native bfloat16 (AVX512-BF16 or AMX) a step
            of the SD recipe took 0.65x the float32 time (docs/RESULTS.md); without it,
            bfloat16 is emulated and slower. ``threads.resolve_precision`` picks for "auto".
        time_limit_s: [s] stop at the first step that ends this long after the first step
            began (under DDP: at the first ``log_every`` boundary past it, on every rank
            together), even short of ``steps``; None: run all ``steps``. The learning rate is
            constant after the warm-up, so a run stopped early is a shorter run of the same
            recipe. ``ecahd train-all --minutes`` uses it so that a machine slowed by other
            work trains fewer steps instead of overrunning, and a fast one more.
    """

    steps: int
    batch_size: int = 256
    lr: float = 1e-4
    betas: tuple[float, float] = (0.9, 0.999)
    weight_decay: float = 1e-2
    warmup_steps: int = 500
    ema_decay: float = 0.995
    seed: int = 0
    device: str = "cpu"
    log_every: int = 100
    checkpoint_every: int = 0
    grad_clip_norm: float | None = 1.0
    inpaint_goal: bool = True
    schedule: ScheduleConfig = field(default_factory=ScheduleConfig)
    precision: str = "fp32"
    time_limit_s: float | None = None

    def __post_init__(self) -> None:
        if self.precision not in PRECISIONS:
            raise ValueError(f"TrainConfig.precision must be one of {', '.join(PRECISIONS)}, "
                             f"got {self.precision!r}")
        for name in ("steps", "batch_size", "log_every"):
            if int(getattr(self, name)) != getattr(self, name) or getattr(self, name) < 1:
                raise ValueError(f"TrainConfig.{name} must be a positive integer, "
                                 f"got {getattr(self, name)!r}")
        for name in ("warmup_steps", "checkpoint_every", "seed"):
            if int(getattr(self, name)) != getattr(self, name) or getattr(self, name) < 0:
                raise ValueError(f"TrainConfig.{name} must be a non-negative integer, "
                                 f"got {getattr(self, name)!r}")
        if not self.lr > 0:
            raise ValueError(f"TrainConfig.lr must be positive, got {self.lr}")
        if self.time_limit_s is not None and not float(self.time_limit_s) > 0:
            raise ValueError(f"TrainConfig.time_limit_s must be positive or None, "
                             f"got {self.time_limit_s}")
        if not 0.0 <= self.ema_decay < 1.0:
            raise ValueError(f"TrainConfig.ema_decay must be in [0, 1), got {self.ema_decay}")
        object.__setattr__(self, "betas", tuple(float(b) for b in self.betas))
        if isinstance(self.schedule, Mapping):
            object.__setattr__(self, "schedule", ScheduleConfig.from_dict(self.schedule))

    @property
    def conditioned_indices(self) -> tuple[int, ...]:
        """Waypoints inpainted in training and sampling."""
        return START_GOAL if self.inpaint_goal else (0,)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["betas"] = list(self.betas)
        return d


@dataclass(frozen=True)
class Checkpoint:
    """A trained model as stored on disk.

    Attributes:
        kind: "sd", "dd" or "fd".
        model_config: the denoiser architecture.
        schedule_config: the forward process it was trained with.
        normalizer: metres <-> normalised.
        conditioned_indices: waypoints inpainted during training (sample with the same).
        horizons: the trajectory lengths it was trained on.
        ema_state_dict: the EMA weights (used for sampling).
        step: optimiser steps done.
        meta: free plain-data description (map name, map fingerprint, footprint, horizons,
            dataset sha256, ...), compared by :meth:`check`.
        train_config: the :class:`TrainConfig` as a dict.
        loss_history: ((step, mean loss over the last log_every steps), ...).
        training_state: raw weights + optimiser + LR-schedule state for resuming, or None in an
            inference-only checkpoint (a quarter of the size).
        source: the file it was loaded from, if any.
    """

    kind: str
    model_config: DenoiserConfig
    schedule_config: ScheduleConfig
    normalizer: Normalizer
    conditioned_indices: tuple[int, ...]
    horizons: tuple[int, ...]
    ema_state_dict: dict[str, Tensor]
    step: int
    meta: dict[str, Any]
    train_config: dict[str, Any]
    loss_history: tuple[tuple[int, float], ...] = ()
    training_state: dict[str, Any] | None = None
    source: Path | None = None

    # ------------------------------------------------------------------------------ storage
    def to_dict(self, *, include_training_state: bool = True) -> dict[str, Any]:
        payload = {
            "format": CHECKPOINT_FORMAT,
            "format_version": CHECKPOINT_VERSION,
            "kind": self.kind,
            "model_config": self.model_config.to_dict(),
            "schedule": self.schedule_config.to_dict(),
            "normalizer": self.normalizer.to_dict(),
            "conditioned_indices": list(self.conditioned_indices),
            "horizons": list(self.horizons),
            "ema_state_dict": self.ema_state_dict,
            "step": self.step,
            "meta": self.meta,
            "train_config": self.train_config,
            "loss_history": [list(x) for x in self.loss_history],
            "torch_version": str(torch.__version__),
        }
        if include_training_state and self.training_state is not None:
            payload["training_state"] = self.training_state
        return payload

    def save(self, path: str | os.PathLike, *, include_training_state: bool = True) -> Path:
        """Write atomically (temporary file + rename). ``include_training_state=False`` gives
        the inference-only file shipped with the package."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + ".tmp")
        torch.save(self.to_dict(include_training_state=include_training_state), tmp)
        os.replace(tmp, path)
        return path

    @classmethod
    def from_dict(cls, payload: Any, *, source: Path | None = None) -> "Checkpoint":
        where = f"checkpoint '{source}'" if source else "checkpoint"
        if not isinstance(payload, dict) or payload.get("format") != CHECKPOINT_FORMAT:
            raise CheckpointError(f"{where} is not an ECAHD diffusion checkpoint "
                                  f"(no format marker {CHECKPOINT_FORMAT!r})")
        version = payload.get("format_version")
        if version != CHECKPOINT_VERSION:
            raise CheckpointError(f"{where} has format version {version!r}; this code reads "
                                  f"version {CHECKPOINT_VERSION}. Retrain the model.")
        try:
            return cls(
                kind=ModelKind.parse(payload["kind"]).value,
                model_config=DenoiserConfig.from_dict(payload["model_config"]),
                schedule_config=ScheduleConfig.from_dict(payload["schedule"]),
                normalizer=Normalizer.from_dict(payload["normalizer"]),
                conditioned_indices=tuple(int(i) for i in payload["conditioned_indices"]),
                horizons=tuple(int(h) for h in payload["horizons"]),
                ema_state_dict=dict(payload["ema_state_dict"]),
                step=int(payload["step"]),
                meta=dict(payload["meta"]),
                train_config=dict(payload["train_config"]),
                loss_history=tuple((int(s), float(v)) for s, v in payload["loss_history"]),
                training_state=payload.get("training_state"),
                source=source)
        except (KeyError, TypeError, ValueError) as exc:
            raise CheckpointError(f"{where} is incomplete or malformed: "
                                  f"{type(exc).__name__}: {exc}") from exc

    # ---------------------------------------------------------------------------- identity
    def check(self, expect: Mapping[str, Any]) -> None:
        """Raise :class:`CheckpointError` unless the checkpoint is what the caller expects.

        ``expect["kind"]`` is compared with :attr:`kind`; every other key with :attr:`meta`
        (tuples and lists compare equal). All mismatches are reported together.
        """
        where = f"checkpoint '{self.source}'" if self.source else "checkpoint"
        problems = []
        for key, want in expect.items():
            if key == "kind":
                if ModelKind.parse(want).value != self.kind:
                    problems.append(f"it is a {self.kind!r} model, not {want!r}")
                continue
            if key in _MAP_KEYS:
                continue
            if key not in self.meta:
                problems.append(f"its meta records no {key!r} (has {sorted(self.meta)})")
            elif _plain(self.meta[key]) != _plain(want):
                problems.append(f"{key} is {self.meta[key]!r}, expected {want!r}")
        map_bad = [k for k in _MAP_KEYS if k in expect and
                   (k not in self.meta or _plain(self.meta[k]) != _plain(expect[k]))]
        if map_bad:
            problems.insert(0, "it was trained for map {!r} (fingerprint {}), not {!r} "
                               "(fingerprint {})".format(
                                   self.meta.get("map_name"), self.meta.get("map_fingerprint"),
                                   expect.get("map_name", self.meta.get("map_name")),
                                   expect.get("map_fingerprint", "not given")))
        if problems:
            raise CheckpointError(f"{where} does not match: " + "; ".join(problems))

    # ------------------------------------------------------------------------------ models
    def build_model(self, *, device: torch.device | str = "cpu") -> nn.Module:
        """The EMA denoiser of the checkpoint's architecture as eps_theta (an x_0-predicting
        network is wrapped in :class:`~ecahd_core.diffusion.denoiser.EpsilonFromSample`), in
        eval mode, with no parameter requiring gradients."""
        model = build_denoiser(self.model_config)
        try:
            model.load_state_dict(self.ema_state_dict)
        except RuntimeError as exc:
            raise CheckpointError(f"checkpoint '{self.source}': weights do not fit its model "
                                  f"config: {exc}") from exc
        model = model.to(device)
        alphas_cumprod = NoiseSchedule(self.schedule_config).alphas_cumprod
        return as_noise_predictor(model, alphas_cumprod).eval().requires_grad_(False)

    def build_scheduler(self, *, device: torch.device | str = "cpu", **kwargs: Any
                        ) -> DDIMScheduler:
        """A DDIM scheduler of the training schedule (kwargs: ``clip_sample``)."""
        return DDIMScheduler(self.schedule_config, **kwargs).to(device)


def load_checkpoint(path: str | os.PathLike, *, expect: Mapping[str, Any] | None = None,
                    map_location: torch.device | str = "cpu") -> Checkpoint:
    """Read a checkpoint (``torch.load(weights_only=True)``) and check it against ``expect``.

    Args:
        path: the file.
        expect: e.g. ``{"kind": "sd", "map_name": "maze2d-umaze", "map_fingerprint": fp}``.
        map_location: where tensors are loaded.
    Raises:
        CheckpointError: missing or unreadable file, another format or version, or a mismatch.
    """
    path = Path(path)
    payload = read_checkpoint_file(path, map_location=map_location)
    checkpoint = Checkpoint.from_dict(payload, source=path)
    if expect:
        checkpoint.check(expect)
    return checkpoint


def read_checkpoint_file(path: str | os.PathLike, *,
                         map_location: torch.device | str = "cpu") -> Any:
    """The plain data of a checkpoint file (``torch.load(weights_only=True)``).

    Raises:
        CheckpointError: one line naming the file: missing, unreadable, truncated or not a
            torch file.
    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"checkpoint '{path}' does not exist or is not a file")
    try:
        return torch.load(path, map_location=map_location, weights_only=True)
    except Exception as exc:  # torch.load raises many types (zip, pickle, EOF, unsafe content)
        first = (str(exc).strip().splitlines() or [""])[0]  # unpickling errors run to pages
        raise CheckpointError(f"cannot read checkpoint '{path}' (corrupt, truncated or not a "
                              f"torch file): {type(exc).__name__}: {first}") from exc


def _plain(value: Any) -> Any:
    """Plain-data form of ``value`` (tuples -> lists, numpy -> python) or ValueError."""
    if isinstance(value, np.generic):
        value = value.item()
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in (value.tolist() if isinstance(value, np.ndarray) else value)]
    if isinstance(value, Mapping):
        if not all(isinstance(k, str) for k in value):
            raise ValueError(f"meta dict keys must be strings, got {list(value)}")
        return {k: _plain(v) for k, v in value.items()}
    raise ValueError(f"meta values must be plain data (str, int, float, bool, None, lists, "
                     f"dicts), got {type(value).__name__}")


# -------------------------------------------------------------------------------- training
@dataclass(frozen=True)
class TrainResult:
    """Attributes:
        path: the checkpoint written by rank 0.
        step: optimiser steps done.
        loss_history: ((step, mean loss over the preceding log_every steps), ...), all ranks.
        ema_model: the EMA denoiser as eps_theta, in eval mode (what sampling uses).
        checkpoint: the checkpoint as written (rank 0), else None.
    """

    path: Path
    step: int
    loss_history: tuple[tuple[int, float], ...]
    ema_model: nn.Module
    checkpoint: Checkpoint | None


@dataclass(frozen=True)
class _DistInfo:
    rank: int
    world_size: int
    local_rank: int
    owns_group: bool


def _init_distributed(device: torch.device) -> _DistInfo:
    world = int(os.environ.get("WORLD_SIZE", "1"))
    local = int(os.environ.get("LOCAL_RANK", "0"))
    if world <= 1:
        return _DistInfo(0, 1, 0, False)
    if dist.is_initialized():
        return _DistInfo(dist.get_rank(), dist.get_world_size(), local, False)
    dist.init_process_group(backend="nccl" if device.type == "cuda" else "gloo",
                            init_method="env://")
    return _DistInfo(dist.get_rank(), dist.get_world_size(), local, True)


def step_seed(seed: int, step: int, stream: int) -> int:
    """A generator seed per (run seed, step, stream); stream 0 is shared by all ranks (also
    ``ecahd_core.general.train``'s)."""
    return ((seed * 1_000_003 + step) * 1_000_033 + stream) & 0x7FFF_FFFF_FFFF_FFFF


def _prepare_data(arrays: Mapping[int, Any], normalizer: Normalizer, max_horizon: int,
                  dist_info: _DistInfo, device: torch.device) -> dict[int, Tensor]:
    """{h: (N_h / world, h, 2)} normalised float32 shard of this rank on ``device``."""
    if not arrays:
        raise DatasetError("no training arrays given")
    shards, limit = {}, 0.0
    for h, arr in sorted(arrays.items()):
        arr = np.asarray(arr)
        if isinstance(h, bool) or int(h) != h or not 2 <= h <= max_horizon:
            raise DatasetError(f"horizon key {h!r} must be an integer in 2..{max_horizon}")
        if arr.ndim != 3 or arr.shape[1:] != (h, 2):
            raise DatasetError(f"arrays[{h}] must have shape (N, {h}, 2), got {arr.shape}")
        if arr.shape[0] < dist_info.world_size:
            raise DatasetError(f"arrays[{h}] has {arr.shape[0]} trajectories, fewer than the "
                               f"{dist_info.world_size} ranks")
        if not np.isfinite(arr).all():
            raise DatasetError(f"arrays[{h}] contains non-finite values")
        data = normalizer.normalize(torch.as_tensor(arr, dtype=torch.float32))
        limit = max(limit, float(data.abs().max()))
        shards[int(h)] = data[dist_info.rank::dist_info.world_size].contiguous().to(device)
    if limit > 1.0:
        log.warning("training data reaches %.3f in normalised units: beyond the sampler's "
                    "pred_x0 clip of 1.0; use a normaliser that covers the data", limit)
    return shards


@torch.no_grad()
def ema_update(ema: nn.Module, model: nn.Module, decay: float) -> None:
    torch._foreach_lerp_(list(ema.parameters()), [p.detach() for p in model.parameters()],
                         1.0 - decay)
    for b_ema, b in zip(ema.buffers(), model.buffers()):
        b_ema.copy_(b)


def train(model_config: DenoiserConfig, arrays: Mapping[int, Any], normalizer: Normalizer,
          train_config: TrainConfig, *, kind: str, out_path: str | os.PathLike,
          meta: Mapping[str, Any] | None = None, resume_from: str | os.PathLike | None = None,
          progress: bool = True, map_image: Any | None = None) -> TrainResult:
    """Train a denoiser and write its checkpoint.

    Args:
        model_config: the architecture (max_horizon >= every horizon in ``arrays``).
        arrays: {h: (N_h, h, 2) [m] expert trajectories}, e.g. SD's 2..10.
        normalizer: metres -> normalised (e.g. ``Normalizer.from_bounds(*grid.bounds)``).
        train_config: optimiser, steps, seed, device.
        kind: "sd", "dd" or "fd".
        out_path: checkpoint file to write (also every ``checkpoint_every`` steps).
        meta: plain-data identity stored in the checkpoint (map name and fingerprint,
            footprint, horizons, dataset sha256, ...).
        resume_from: a checkpoint with training state of the same run to continue from; its
            kind, configs, normaliser and meta must match.
        progress: show a tqdm bar (rank 0).
        map_image: (H, W) occupancy in [0, 1] shared by all samples; required exactly when
            ``model_config.use_map_encoder``.
    Returns:
        :class:`TrainResult`.
    """
    kind = ModelKind.parse(kind).value
    meta = _plain(dict(meta or {}))
    device = torch.device(train_config.device)
    dist_info = _init_distributed(device)
    if device.type == "cuda" and dist_info.world_size > 1 and device.index is None:
        device = torch.device(device.type, dist_info.local_rank)
    try:
        return _train(model_config, arrays, normalizer, train_config, kind=kind,
                      out_path=Path(out_path), meta=meta, resume_from=resume_from,
                      progress=progress, map_image=map_image, device=device, dist_info=dist_info)
    finally:
        if dist_info.owns_group:
            dist.destroy_process_group()


def _train(model_config: DenoiserConfig, arrays: Mapping[int, Any], normalizer: Normalizer,
           cfg: TrainConfig, *, kind: str, out_path: Path, meta: dict[str, Any],
           resume_from: str | os.PathLike | None, progress: bool, map_image: Any | None,
           device: torch.device, dist_info: _DistInfo) -> TrainResult:
    rank, world = dist_info.rank, dist_info.world_size
    if cfg.batch_size % world:
        raise ValueError(f"batch_size {cfg.batch_size} is not divisible by {world} ranks")
    local_batch = cfg.batch_size // world
    cond_indices = cfg.conditioned_indices

    data = _prepare_data(arrays, normalizer, model_config.max_horizon, dist_info, device)
    horizons = tuple(data)
    # waypoints that carry a loss: (n_free,) indices per horizon (index_select, no device sync)
    free = {h: (~condition_mask(h, cond_indices)).nonzero().flatten().to(device) for h in horizons}
    # A horizon whose every waypoint is inpainted (h = 2 with start and goal) has nothing to
    # learn: the sampler returns its conditions whatever the network says. It is not drawn.
    learnable = [h for h in horizons if len(free[h])]
    if not learnable:
        raise DatasetError(f"every waypoint of horizons {list(horizons)} is inpainted "
                           f"(indices {list(cond_indices)}): nothing to learn")
    if len(learnable) < len(horizons):
        log.info("not training on fully inpainted horizons %s",
                 sorted(set(horizons) - set(learnable)))
    sizes = torch.tensor([len(np.asarray(arrays[h])) for h in learnable], dtype=torch.float64)
    model_kwargs = {}
    if model_config.use_map_encoder != (map_image is not None):
        raise ValueError("pass map_image exactly when model_config.use_map_encoder is True")
    if map_image is not None:
        image = torch.as_tensor(np.asarray(map_image), dtype=torch.float32, device=device)
        model_kwargs["map_image"] = image.reshape(1, 1, *image.shape[-2:])

    with torch.random.fork_rng(devices=[]):  # seeded initial weights; caller's RNG untouched
        torch.manual_seed(cfg.seed)
        model = build_denoiser(model_config).to(device)
    ema = copy.deepcopy(model).eval().requires_grad_(False)
    schedule = NoiseSchedule(cfg.schedule).to(device)
    K = schedule.num_train_timesteps
    predict_sample = model_config.prediction == "sample"
    optimizer = torch.optim.AdamW(model.parameters(), lr=cfg.lr, betas=cfg.betas,
                                  weight_decay=cfg.weight_decay)
    warmup = cfg.warmup_steps
    lr_schedule = torch.optim.lr_scheduler.LambdaLR(
        optimizer, lambda s: min(1.0, (s + 1) / warmup) if warmup > 0 else 1.0)
    start_step, history = 0, []
    if resume_from is not None:
        start_step, history = _restore(resume_from, model=model, ema=ema, optimizer=optimizer,
                                       lr_schedule=lr_schedule, kind=kind,
                                       model_config=model_config, cfg=cfg,
                                       normalizer=normalizer, meta=meta)
    net: nn.Module = model
    if world > 1:
        net = DistributedDataParallel(model, device_ids=[device.index] if device.type == "cuda"
                                      else None)

    def make_checkpoint(step: int) -> Checkpoint:
        return Checkpoint(
            kind=kind, model_config=model_config, schedule_config=cfg.schedule,
            normalizer=normalizer, conditioned_indices=cond_indices, horizons=horizons,
            ema_state_dict=cpu_state(ema.state_dict()), step=step, meta=meta,
            train_config=cfg.to_dict(), loss_history=tuple(history),
            training_state={"model_state_dict": cpu_state(model.state_dict()),
                            "optimizer_state_dict": optimizer.state_dict(),
                            "lr_scheduler_state_dict": lr_schedule.state_dict()})

    # shared_gen (CPU): the horizon, identical on every rank; local_gen (on the training
    # device, so no host-to-device copies): indices, timesteps and noise of this rank
    shared_gen, local_gen = torch.Generator(), torch.Generator(device=device)
    bar = tqdm(total=cfg.steps, initial=start_step, disable=not (progress and rank == 0),
               desc=f"train {kind}", dynamic_ncols=True)
    window_loss, window_n = torch.zeros((), device=device), 0
    autocast = torch.autocast(device.type, dtype=torch.bfloat16,
                              enabled=cfg.precision == "bf16")
    model.train()
    n_updates, t_loop = start_step, time.perf_counter()
    for step in range(start_step, cfg.steps):
        shared_gen.manual_seed(step_seed(cfg.seed, step, 0))
        local_gen.manual_seed(step_seed(cfg.seed, step, 1 + rank))
        # 1. horizon ~ dataset sizes (same on every rank), batch from this rank's shard
        h = learnable[int(torch.multinomial(sizes, 1, generator=shared_gen))]
        shard = data[h]
        idx = torch.randint(len(shard), (local_batch,), generator=local_gen, device=device)
        x0 = shard[idx]  # (b, h, 2)
        t = torch.randint(K, (local_batch,), generator=local_gen, device=device)
        noise = torch.randn(x0.shape, generator=local_gen, device=device)
        # 2. forward process, then inpaint the clean start (/goal) as the sampler will
        x_t = schedule.add_noise(x0, noise, t)
        x_t = apply_conditioning(x_t, {i: x0[:, i] for i in cond_indices})
        # 3. MSE of the prediction (eps, or x_0 for prediction="sample") over the free
        #    waypoints only
        target = x0 if predict_sample else noise
        with autocast:
            pred = net(x_t, t, **model_kwargs)
        loss = (pred.float() - target).index_select(1, free[h]).pow(2).mean()
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        if cfg.grad_clip_norm is not None:
            nn.utils.clip_grad_norm_(model.parameters(), cfg.grad_clip_norm)
        optimizer.step()
        lr_schedule.step()
        n_updates = step + 1
        ema_update(ema, model, min(cfg.ema_decay, (1 + n_updates) / (10 + n_updates)))

        window_loss += loss.detach()
        window_n += 1
        bar.update(1)
        out_of_time = _out_of_time(cfg, n_updates, start_step, t_loop, bar, world, device)
        if n_updates % cfg.log_every == 0 or n_updates == cfg.steps or out_of_time:
            mean = window_loss / window_n
            if world > 1:
                dist.all_reduce(mean)
                mean = mean / world
            history.append((n_updates, float(mean)))
            window_loss, window_n = torch.zeros((), device=device), 0
            bar.set_postfix(loss=f"{history[-1][1]:.4f}", lr=f"{lr_schedule.get_last_lr()[0]:.1e}")
            log.info("train %s: step %d/%d loss %.5f", kind, n_updates, cfg.steps, history[-1][1])
        if (cfg.checkpoint_every and n_updates % cfg.checkpoint_every == 0
                and n_updates < cfg.steps and rank == 0):
            make_checkpoint(n_updates).save(out_path)
        if out_of_time:
            log.info("train %s: time limit %.0f s reached at step %d of at most %d", kind,
                     cfg.time_limit_s, n_updates, cfg.steps)
            break
    bar.close()

    final_step = n_updates
    checkpoint = None
    if rank == 0:
        checkpoint = make_checkpoint(final_step)
        checkpoint.save(out_path)
        checkpoint = dataclasses.replace(checkpoint, source=out_path)
        log.info("wrote %s (step %d)", out_path, final_step)
    if world > 1:
        dist.barrier()
    return TrainResult(path=out_path, step=final_step, loss_history=tuple(history),
                       ema_model=as_noise_predictor(ema, schedule.alphas_cumprod),
                       checkpoint=checkpoint)


def _out_of_time(cfg: TrainConfig, n_updates: int, start_step: int, t_loop: float, bar: tqdm,
                 world: int, device: torch.device) -> bool:
    """Whether a run with ``cfg.time_limit_s`` stops after step ``n_updates``; keeps the
    progress bar's total at the steps the limit leaves room for, at the rate so far. Under DDP
    the ranks decide together at ``log_every`` boundaries."""
    if cfg.time_limit_s is None or n_updates >= cfg.steps:
        return False
    if world > 1 and n_updates % cfg.log_every:
        return False
    elapsed = time.perf_counter() - t_loop
    done = n_updates - start_step
    stop = elapsed >= cfg.time_limit_s
    if world > 1:
        flag = torch.tensor(float(stop), device=device)
        dist.all_reduce(flag, op=dist.ReduceOp.MAX)
        stop = bool(flag.item())
    if not stop and done % 20 == 0:
        fit = n_updates + int((cfg.time_limit_s - elapsed) * done / max(elapsed, 1e-9))
        bar.total = min(cfg.steps, max(fit, n_updates + 1))
        bar.refresh()
    return stop


def cpu_state(state: Mapping[str, Tensor]) -> dict[str, Tensor]:
    return {k: v.detach().to("cpu", copy=True) for k, v in state.items()}


def _restore(path: str | os.PathLike, *, model: nn.Module, ema: nn.Module,
             optimizer: torch.optim.Optimizer, lr_schedule: Any, kind: str,
             model_config: DenoiserConfig, cfg: TrainConfig, normalizer: Normalizer,
             meta: dict[str, Any]) -> tuple[int, list]:
    """Load a training checkpoint of the same run into the fresh objects; (step, history)."""
    ckpt = load_checkpoint(path, expect={"kind": kind, **meta})
    pairs = (("model config", model_config, ckpt.model_config),
             ("schedule", cfg.schedule, ckpt.schedule_config),
             ("normaliser", normalizer, ckpt.normalizer),
             ("conditioned waypoints", cfg.conditioned_indices, ckpt.conditioned_indices))
    mismatches = [name for name, ours, theirs in pairs if ours != theirs]
    if mismatches:
        raise CheckpointError(f"cannot resume from '{path}': its {', '.join(mismatches)} "
                              f"differ from this run's")
    if ckpt.training_state is None:
        raise CheckpointError(f"cannot resume from '{path}': it holds no training state "
                              f"(an inference-only checkpoint)")
    state = ckpt.training_state
    model.load_state_dict(state["model_state_dict"])
    ema.load_state_dict(ckpt.ema_state_dict)
    optimizer.load_state_dict(state["optimizer_state_dict"])  # moves its tensors to the params
    lr_schedule.load_state_dict(state["lr_scheduler_state_dict"])
    log.info("resuming %s from %s at step %d", kind, path, ckpt.step)
    return ckpt.step, list(ckpt.loss_history)
