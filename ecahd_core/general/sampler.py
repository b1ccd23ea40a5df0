"""The generalist SD as Algorithm 1's sampler: :class:`GeneralSampler` has the
:class:`~ecahd_core.diffusion.DiffusionSampler` interface that
:class:`~ecahd_core.planning.sparse.SparseDiffusion` calls (``sample(batch=, horizon=,
conditions={0: start, -1: goal}, ...)`` in metres), so everything SD does round its sampler
(best of N, J's collision-aware selection, placement, leg repair, densify, warm starts, J
guidance) works unchanged with a model that sees the map.

Per call: the distinct (start, goal) rows of the batch (one for SD's N candidates of one
problem; K for densify's K legs) get their views (``views.make_views`` on the map's summed-area
table, built once per map) and their map memory (``MapConditionedDenoiser.encode``, once per
distinct problem, gathered per row). Each row's waypoints live in its own view's coordinates:
:class:`RowNormalizer` is the per-row affine map (u = (p - c) / h) in the place of the per-map
model's map-bounds :class:`~ecahd_core.diffusion.normalizer.Normalizer`, so inpainting, warm
starts and J's guidance gradients (chain rule: dJ/du = h dJ/dp) go through the same code.
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np
import torch
from torch import Tensor

from ecahd_core.diffusion.sampler import DiffusionSampler, SamplerConfig, sample
from ecahd_core.errors import PlanningError, TrajectoryError
from ecahd_core.general.model import MapMemory
from ecahd_core.general.views import OccupancyIntegral, make_views


class RowNormalizer:
    """A per-row affine map between metres and view coordinates: u = (p - c_b) / h_b.

    Args:
        centre: (B, 2) [m] each row's view centre.
        half_side: (B,) [m] each row's view half side.
    """

    def __init__(self, centre: Tensor, half_side: Tensor) -> None:
        self.centre = centre  # (B, 2)
        self.half = half_side[:, None]  # (B, 1)

    def _shape(self, x: Tensor) -> tuple[Tensor, Tensor]:
        """(B, 2) or (B, P, 2) -> the centre and half side broadcast to it."""
        if x.shape[0] != self.centre.shape[0] or x.dim() not in (2, 3) or x.shape[-1] != 2:
            raise TrajectoryError(f"points must be ({self.centre.shape[0]}, 2) or "
                                  f"({self.centre.shape[0]}, P, 2) for this batch, got "
                                  f"{tuple(x.shape)}")
        c, h = self.centre.to(x.dtype), self.half.to(x.dtype)
        return (c, h) if x.dim() == 2 else (c[:, None], h[:, None])

    def normalize(self, x: Tensor) -> Tensor:
        c, h = self._shape(x)
        return (x - c) / h

    def unnormalize(self, z: Tensor) -> Tensor:
        c, h = self._shape(z)
        return z * h + c

    def grad_to_normalized(self, grad_metres: Tensor) -> Tensor:
        _, h = self._shape(grad_metres)
        return grad_metres * h


def condition_ends(conditions: Mapping[int, Any], batch: int, horizon: int, device,
                   missing: str) -> dict[int, Tensor]:
    """Sampling conditions {index: (2,) or (batch, 2) [m]} -> {index in 0..horizon-1:
    (batch, 2) float32}; PlanningError ``missing`` unless the first (0) and last (horizon - 1)
    are among them (the generalists' samplers are made round a row's two ends)."""
    ends = {}
    for index, value in conditions.items():
        if not -horizon <= int(index) < horizon:
            raise TrajectoryError(f"condition index {index} is outside a horizon of {horizon}")
        ends[int(index) % horizon] = torch.as_tensor(value, dtype=torch.float32,
                                                     device=device).expand(batch, 2)
    if 0 not in ends or horizon - 1 not in ends:
        raise PlanningError(missing)
    return ends


def gather_memory(memory: MapMemory, index: Tensor) -> MapMemory:
    """The memory of U problems -> that of B rows (``index`` (B,) long in 0..U-1)."""
    return MapMemory(keys=tuple(k.index_select(0, index) for k in memory.keys),
                     values=tuple(v.index_select(0, index) for v in memory.values))


class GeneralSampler(DiffusionSampler):
    """The generalist model on one map, with :class:`DiffusionSampler`'s ``sample``.

    Args:
        checkpoint: a :class:`~ecahd_core.general.checkpoint.GeneralCheckpoint`.
        grid: the GridMap it plans on (its views are made from it; a fused map's scanned
            obstacles are the planner's business, as with the per-map model).
        device: where the model runs.
        config: sampling settings (steps, eta, guidance, precision).
    """

    def __init__(self, checkpoint, grid, *, device: torch.device | str = "cpu",
                 config: SamplerConfig | None = None) -> None:
        super().__init__(checkpoint.build_model(device=device),
                         checkpoint.build_scheduler(), None, config)
        self.checkpoint = checkpoint
        self.grid = grid
        self.view_config = checkpoint.model_config.view
        self.integral = OccupancyIntegral.from_grid(grid)  # once per map (6 ms at 1200^2)

    def sample(self, *, batch: int, horizon: int, conditions: Mapping[int, Any],
               generator: torch.Generator | None = None, guide=None, guide_steps=None,
               return_intermediates: bool = False, model_kwargs: Mapping[str, Any] | None = None,
               warm_start: Any = None, warm_fraction: float | None = None):
        """As :meth:`DiffusionSampler.sample`, in metres; ``conditions`` must hold the start
        (index 0) and the goal (index -1 or horizon - 1), (2,) or (batch, 2) [m], since they
        decide what the model sees. Raises PlanningError when a view cannot be made (a problem
        wider than the model's views)."""
        if model_kwargs:
            raise ValueError("the generalist's only model input is its map memory")
        device = self.device
        ends = condition_ends(conditions, batch, horizon, device,
                              "the generalist SD needs the start (index 0) and the goal "
                              "(index -1) as conditions: its views are made round them")
        starts, goals = ends[0], ends[horizon - 1]
        if not (torch.isfinite(starts).all() and torch.isfinite(goals).all()):
            raise TrajectoryError("start or goal is not finite")
        rows = torch.cat([starts, goals], dim=1).cpu().numpy().astype(np.float64)  # (B, 4)
        problems, inverse = np.unique(rows, axis=0, return_inverse=True)  # (U, 4), (B,)
        views = make_views(self.integral, problems[:, :2], problems[:, 2:], self.view_config)
        with torch.inference_mode():
            memory = self.model.encode(views)  # (U, ...)
        index = torch.as_tensor(inverse.reshape(-1), dtype=torch.long, device=device)
        if len(problems) > 1:
            memory = gather_memory(memory, index)  # (B, ...); one problem: broadcast
        frame = views.frame
        normalizer = RowNormalizer(
            torch.as_tensor(frame.centre, dtype=torch.float32, device=device)[index],
            torch.as_tensor(frame.half_side, dtype=torch.float32, device=device)[index])
        conditions = ends
        if warm_start is not None:
            warm_start = torch.as_tensor(warm_start, dtype=torch.float32, device=device) \
                .expand(batch, horizon, 2)
        warm_steps, guide_steps = self.steps(warm_start, warm_fraction, guide_steps)
        c = self.config
        return sample(self.model, self.scheduler, normalizer, batch=batch, horizon=horizon,
                      conditions=conditions, num_steps=c.num_steps, eta=c.eta,
                      generator=generator, guide=guide, guidance_weight=c.guidance_weight,
                      guide_steps=guide_steps, max_guide_norm=c.max_guide_norm,
                      guidance_space=c.guidance_space,
                      return_intermediates=return_intermediates,
                      model_kwargs={"memory": memory}, warm_start=warm_start,
                      warm_steps=warm_steps)
