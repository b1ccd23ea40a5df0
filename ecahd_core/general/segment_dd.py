"""The generalist DD (issue 40): Dense Diffusion in each segment's own frame, so one model serves
every map.

DD draws the P^l points of one segment t^g_p -> t^g_{p+1} (Algorithm 1 line 15), and J's
guidance bends them round what the cost map holds (Algorithm 2). The per-map DD learns its
segments in the map's coordinates (a map-bounds normaliser), so it is tied to one building. Here
every segment is seen in its own frame: the start a at the origin, the end b at (1, 0),

    u = R^T (p - a) / L,    p = a + L R u,    L = |b - a|,  R = [e1 e2], e1 = (b - a) / L,

so the model learns the shape of an expert's local path between two waypoints whatever the
map, its size, its origin and the segment's heading; the map enters through J's guidance, as in
the paper. The data are the dense segments of ``dataset.generate_dataset`` (the per-map DD's,
arc length between the sparse waypoints) on generated maps of every family, mirrored across
the segment's axis (the expert has no side).

:class:`SegmentSampler` is a :class:`~ecahd_core.diffusion.DiffusionSampler` whose normaliser
is made per call from the batch's conditions (start index 0, end index -1): the checkpoint's
own normaliser (segment-frame coordinates -> the diffusion space) after
:class:`SegmentNormalizer`, so inpainting, J's guidance (chain rule dJ/du = L R^T dJ/dp) and
the scheduler are the per-map DD's code.

The checkpoint is an ordinary DD checkpoint (``diffusion.training.Checkpoint``, kind "dd")
whose meta says ``frame: "segment"`` and ``map_name: "*"``: ``model_zoo.load_dd`` loads it for
any map.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import torch
from torch import Tensor

from ecahd_core.diffusion.normalizer import Normalizer
from ecahd_core.diffusion.sampler import DiffusionSampler, sample
from ecahd_core.errors import TrajectoryError

log = logging.getLogger(__name__)

SEGMENT_FRAME = "segment"  # the meta "frame" of a segment-frame DD checkpoint
ANY_MAP = "*"  # its meta "map_name"
MIN_LENGTH = 1e-6  # [m] a shorter segment keeps e1 = (1, 0) and this length
# segment-frame coordinates -> the diffusion space: u1 in [-0.35, 1.35] and u2 in [-0.85, 0.85]
# onto [-1, 1] (the expert's segments of 4 generated maps: u1 in [-0.17, 1.31], |u2| <= 0.61,
# 99.9% of |u2| <= 0.44)
SEGMENT_NORMALIZER = Normalizer(centre=(0.5, 0.0), scale=(0.85, 0.85))


def segment_axes(a, b) -> tuple[np.ndarray, np.ndarray]:
    """(e1 (N, 2), L (N,)) of segments a -> b, a, b: (N, 2) [m] (numpy)."""
    d = np.asarray(b, dtype=np.float64) - np.asarray(a, dtype=np.float64)
    L = np.linalg.norm(d, axis=-1)
    e1 = np.where(L[:, None] > MIN_LENGTH, d / np.maximum(L, MIN_LENGTH)[:, None], [1.0, 0.0])
    return e1, np.maximum(L, MIN_LENGTH)


def to_segment_frame(paths) -> np.ndarray:
    """(N, P, 2) [m] dense segments -> (N, P, 2) in each one's frame (first point (0, 0), last
    (1, 0))."""
    paths = np.asarray(paths, dtype=np.float64)
    e1, L = segment_axes(paths[:, 0], paths[:, -1])
    e2 = np.stack([-e1[:, 1], e1[:, 0]], axis=-1)
    rel = paths - paths[:, :1]
    return np.stack([(rel * e1[:, None]).sum(-1), (rel * e2[:, None]).sum(-1)], axis=-1) \
        / L[:, None, None]


class SegmentNormalizer:
    """Per-row: metres -> the segment's frame -> the diffusion space (``inner``).

    Args:
        a, b: (B, 2) [m] the rows' segment starts and ends.
        inner: the checkpoint's normaliser of segment-frame coordinates.
    """

    def __init__(self, a: Tensor, b: Tensor, inner: Normalizer) -> None:
        d = b - a
        L = d.norm(dim=-1, keepdim=True)  # (B, 1)
        ok = L > MIN_LENGTH
        e1 = torch.where(ok, d / L.clamp_min(MIN_LENGTH), torch.tensor([1.0, 0.0]).to(d))
        self.a, self.L = a, L.clamp_min(MIN_LENGTH)
        self.R = torch.stack([e1, torch.stack([-e1[:, 1], e1[:, 0]], dim=-1)], dim=-1)  # (B,2,2)
        self.inner = inner

    def _rows(self, x: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        B = self.a.shape[0]
        if x.shape[0] != B or x.dim() not in (2, 3) or x.shape[-1] != 2:
            raise TrajectoryError(f"points must be ({B}, 2) or ({B}, P, 2) for this batch, "
                                  f"got {tuple(x.shape)}")
        a, L, R = self.a.to(x.dtype), self.L.to(x.dtype), self.R.to(x.dtype)
        if x.dim() == 3:
            return a[:, None], L[:, None], R
        return a, L, R

    def normalize(self, x: Tensor) -> Tensor:
        a, L, R = self._rows(x)
        u = ((x - a).unsqueeze(-2) @ R.view(R.shape[0], *(1,) * (x.dim() - 2), 2, 2)) \
            .squeeze(-2) / L  # R^T (p - a) / L as a row vector times R
        return self.inner.normalize(u)

    def unnormalize(self, z: Tensor) -> Tensor:
        a, L, R = self._rows(z)
        u = self.inner.unnormalize(z)
        Rt = R.transpose(-1, -2).reshape(R.shape[0], *(1,) * (z.dim() - 2), 2, 2)
        return a + L * (u.unsqueeze(-2) @ Rt).squeeze(-2)

    def grad_to_normalized(self, grad_metres: Tensor) -> Tensor:
        _, L, R = self._rows(grad_metres)
        g = (grad_metres.unsqueeze(-2) @ R.view(R.shape[0], *(1,) * (grad_metres.dim() - 2),
                                                2, 2)).squeeze(-2) * L  # dJ/du
        return self.inner.grad_to_normalized(g)


class SegmentSampler(DiffusionSampler):
    """A segment-frame DD checkpoint's sampler: ``sample`` in metres, as the per-map DD's."""

    def sample(self, *, batch: int, horizon: int, conditions: Mapping[int, Any],
               generator: torch.Generator | None = None, guide=None, guide_steps=None,
               return_intermediates: bool = False, model_kwargs: Mapping[str, Any] | None = None,
               warm_start: Any = None, warm_fraction: float | None = None):
        from ecahd_core.general.sampler import condition_ends

        ends = condition_ends(conditions, batch, horizon, self.device,
                              "a segment-frame DD needs the segment's start (index 0) and end "
                              "(index -1) as conditions")
        normalizer = SegmentNormalizer(ends[0], ends[horizon - 1], self.normalizer)
        warm_steps, guide_steps = self.steps(warm_start, warm_fraction, guide_steps)
        c = self.config
        return sample(self.model, self.scheduler, normalizer, batch=batch, horizon=horizon,
                      conditions=ends,
                      num_steps=c.num_steps, eta=c.eta, generator=generator, guide=guide,
                      guidance_weight=c.guidance_weight, guide_steps=guide_steps,
                      max_guide_norm=c.max_guide_norm, guidance_space=c.guidance_space,
                      return_intermediates=return_intermediates, model_kwargs=model_kwargs,
                      warm_start=warm_start, warm_steps=warm_steps)


def is_segment_frame(checkpoint) -> bool:
    return getattr(checkpoint, "meta", {}).get("frame") == SEGMENT_FRAME


# ------------------------------------------------------------------------------- training
@dataclass(frozen=True)
class SegmentData:
    """Segment-frame training data.

    Attributes:
        segments: (N, P^l, 2) float32, each in its own frame, mirrored copies included.
        maps: generated maps used.
        dropped: segments shorter than ``min_length`` [m] (no direction to learn).
        seconds: wall time.
    """

    segments: np.ndarray
    maps: int
    dropped: int
    seconds: float


def build_segment_data(maps: int, *, seed: int = 0, pairs_per_map: int = 100,
                       min_length: float = 0.2, progress: bool = True) -> SegmentData:
    """Dense expert segments of ``maps`` generated maps (the generalist dataset's map schedule,
    ``GeneralDataConfig(seed=seed).map_config(j)``), in their frames, mirrored."""
    from tqdm import tqdm

    from ecahd_core.dataset import generate_dataset
    from ecahd_core.errors import DatasetError
    from ecahd_core.general.data import GeneralDataConfig
    from ecahd_core.mapgen import generate_map

    t0 = time.perf_counter()
    config = GeneralDataConfig(maps=maps, seed=seed)
    parts, dropped = [], 0
    for j in tqdm(range(maps), desc="segment data", unit="map", disable=not progress):
        mc = config.map_config(j)
        try:
            expert = generate_dataset(generate_map(mc), pairs=pairs_per_map, seed=mc.seed,
                                      footprint_spec=config.robot, progress=False, workers=1)
        except DatasetError as exc:
            log.warning("map %s: no expert data: %s", mc.name, exc)
            continue
        dense = expert.dense.reshape(-1, *expert.dense.shape[-2:])  # (N (P^g - 1), P^l, 2)
        length = np.linalg.norm(dense[:, -1] - dense[:, 0], axis=-1)
        dropped += int((length < min_length).sum())
        parts.append(to_segment_frame(dense[length >= min_length]))
    if not parts:
        raise DatasetError("no expert segments: every generated map failed")
    u = np.concatenate(parts)
    mirrored = u * np.array([1.0, -1.0])
    return SegmentData(segments=np.concatenate([u, mirrored]).astype(np.float32), maps=maps,
                       dropped=dropped, seconds=time.perf_counter() - t0)


def train_segment_dd(out: str | Path, data: SegmentData, recipe, *, seed: int = 0,
                     steps: int | None = None, minutes: float | None = None,
                     robot: str = "circle", progress: bool = True):
    """Train the segment-frame DD on ``data`` with ``recipe`` (the per-map DD's,
    ``model_zoo.recipe("dd")``) and write its checkpoint to ``out`` (inference-only)."""
    from ecahd_core.diffusion import TrainConfig, train
    from ecahd_core.footprint import make_footprint

    r = recipe
    P = int(data.segments.shape[1])
    tc = TrainConfig(steps=steps or r.steps, batch_size=r.batch_for(P),
                     warmup_steps=r.warmup_steps, lr=r.lr, ema_decay=r.ema_decay, seed=seed,
                     log_every=100, time_limit_s=None if minutes is None else 60.0 * minutes)
    meta = {"frame": SEGMENT_FRAME, "map_name": ANY_MAP, "map_fingerprint": ANY_MAP,
            "robot": robot, "clearance": float(make_footprint(robot).circumscribed_radius),
            "sample_steps": int(r.sample_steps), "segments": int(len(data.segments)),
            "maps": int(data.maps), "seed": int(seed)}
    result = train(r.denoiser_config(P), {P: data.segments}, SEGMENT_NORMALIZER, tc, kind="dd",
                   out_path=out, meta=meta, progress=progress)
    result.checkpoint.save(out, include_training_state=False)
    return result
