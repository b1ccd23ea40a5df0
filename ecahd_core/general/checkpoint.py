"""The generalist SD's checkpoint (issue 40): one ``torch.save`` file of plain data that
``torch.load(weights_only=True)`` reads, like ``diffusion.training.Checkpoint`` but its own kind,
because the model reads views and its waypoints live in view coordinates (no normaliser, no map
identity: it is meant for every map).

Stored (:meth:`GeneralCheckpoint.to_dict`):

    format, format_version     "ecahd-general-checkpoint", 1
    kind                       "general-sd"
    model_config               ``GeneralDenoiserConfig.to_dict()``: the Transformer, the map
                               encoders and, under "view", the ``ViewConfig`` the planner must
                               make its views with: enough to rebuild the model
    schedule                   the forward process (``ScheduleConfig``)
    conditioned_indices        waypoints inpainted in training (start and goal: [0, -1])
    horizons                   the trajectory lengths it learnt
    ema_state_dict             the EMA weights (what sampling uses)
    step                       optimiser steps done
    train_config               ``GeneralTrainConfig.to_dict()``
    data                       the dataset's identity: directory, builder config, samples, maps
    loss_history               [[step, mean loss of the preceding log_every steps], ...]
    training_state             (resumable files only) raw weights, AdamW state, torch's global
                               RNG state and the training wall time so far [s]
"""
from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

from ecahd_core.diffusion.scheduler import DDIMScheduler, ScheduleConfig
from ecahd_core.diffusion.training import read_checkpoint_file
from ecahd_core.errors import CheckpointError
from ecahd_core.general.model import GeneralDenoiserConfig, MapConditionedDenoiser

GENERAL_CHECKPOINT_FORMAT = "ecahd-general-checkpoint"
GENERAL_CHECKPOINT_VERSION = 1
GENERAL_KIND = "general-sd"


@dataclass(frozen=True)
class GeneralCheckpoint:
    """A generalist model as stored on disk (module docstring for each field).

    Attributes:
        model_config: the architecture, views included.
        schedule_config: the forward process it was trained with.
        conditioned_indices: waypoints inpainted in training (sample with the same).
        horizons: the trajectory lengths it learnt.
        ema_state_dict: the EMA weights.
        step: optimiser steps done.
        train_config: the training recipe as a dict.
        data: the dataset's identity (plain data).
        loss_history: ((step, mean loss), ...).
        training_state: for resuming, or None in an inference-only file.
        source: the file it was read from, if any.
    """

    model_config: GeneralDenoiserConfig
    schedule_config: ScheduleConfig
    conditioned_indices: tuple[int, ...]
    horizons: tuple[int, ...]
    ema_state_dict: dict[str, Tensor]
    step: int
    train_config: dict[str, Any]
    data: dict[str, Any]
    loss_history: tuple[tuple[int, float], ...] = ()
    training_state: dict[str, Any] | None = None
    source: Path | None = None

    def to_dict(self, *, include_training_state: bool = True) -> dict[str, Any]:
        payload = {
            "format": GENERAL_CHECKPOINT_FORMAT,
            "format_version": GENERAL_CHECKPOINT_VERSION,
            "kind": GENERAL_KIND,
            "model_config": self.model_config.to_dict(),
            "schedule": self.schedule_config.to_dict(),
            "conditioned_indices": list(self.conditioned_indices),
            "horizons": list(self.horizons),
            "ema_state_dict": self.ema_state_dict,
            "step": self.step,
            "train_config": self.train_config,
            "data": self.data,
            "loss_history": [list(x) for x in self.loss_history],
            "torch_version": str(torch.__version__),
        }
        if include_training_state and self.training_state is not None:
            payload["training_state"] = self.training_state
        return payload

    def save(self, path: str | os.PathLike, *, include_training_state: bool = True) -> Path:
        """Write atomically (temporary file + rename): a kill while writing leaves the previous
        file whole. ``include_training_state=False``: the inference-only file to ship."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + ".tmp")
        torch.save(self.to_dict(include_training_state=include_training_state), tmp)
        os.replace(tmp, path)
        return path

    @classmethod
    def from_dict(cls, payload: Any, *, source: Path | None = None) -> "GeneralCheckpoint":
        where = f"checkpoint '{source}'" if source else "checkpoint"
        if not isinstance(payload, dict) or payload.get("format") != GENERAL_CHECKPOINT_FORMAT:
            raise CheckpointError(f"{where} is not an ECAHD generalist checkpoint (no format "
                                  f"marker {GENERAL_CHECKPOINT_FORMAT!r})")
        version = payload.get("format_version")
        if version != GENERAL_CHECKPOINT_VERSION:
            raise CheckpointError(f"{where} has format version {version!r}; this code reads "
                                  f"version {GENERAL_CHECKPOINT_VERSION}. Retrain the model.")
        try:
            return cls(
                model_config=GeneralDenoiserConfig.from_dict(payload["model_config"]),
                schedule_config=ScheduleConfig.from_dict(payload["schedule"]),
                conditioned_indices=tuple(int(i) for i in payload["conditioned_indices"]),
                horizons=tuple(int(h) for h in payload["horizons"]),
                ema_state_dict=dict(payload["ema_state_dict"]),
                step=int(payload["step"]),
                train_config=dict(payload["train_config"]),
                data=dict(payload["data"]),
                loss_history=tuple((int(s), float(v)) for s, v in payload["loss_history"]),
                training_state=payload.get("training_state"),
                source=source)
        except (KeyError, TypeError, ValueError) as exc:
            raise CheckpointError(f"{where} is incomplete or malformed: "
                                  f"{type(exc).__name__}: {exc}") from exc

    def with_source(self, source: Path) -> "GeneralCheckpoint":
        return dataclasses.replace(self, source=source)

    def build_model(self, *, device: torch.device | str = "cpu") -> MapConditionedDenoiser:
        """The EMA denoiser, eval mode, no parameter requiring gradients."""
        model = MapConditionedDenoiser(self.model_config)
        try:
            model.load_state_dict(self.ema_state_dict)
        except RuntimeError as exc:
            raise CheckpointError(f"checkpoint '{self.source}': weights do not fit its model "
                                  f"config: {exc}") from exc
        return model.to(device).eval().requires_grad_(False)

    def build_scheduler(self, *, device: torch.device | str = "cpu", **kwargs: Any
                        ) -> DDIMScheduler:
        """A DDIM scheduler of the training schedule (kwargs: ``clip_sample``)."""
        return DDIMScheduler(self.schedule_config, **kwargs).to(device)


def load_general_checkpoint(path: str | os.PathLike, *,
                            map_location: torch.device | str = "cpu") -> GeneralCheckpoint:
    """Read a generalist checkpoint.

    Raises:
        CheckpointError: one line naming the file: missing, unreadable, truncated, another
            format or version, or incomplete.
    """
    path = Path(path)
    return GeneralCheckpoint.from_dict(read_checkpoint_file(path, map_location=map_location),
                                       source=path)
