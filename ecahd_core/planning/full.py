"""The Diffuser-style Full Diffusion baseline (FD, the paper's Tables I and III): one dense
trajectory from start to goal, optionally guided by J."""
from __future__ import annotations

import numpy as np
import torch

from ecahd_core.errors import EcahdError


class FullDiffusion:
    """The Diffuser-style baseline (FD): one 100-point trajectory from start to goal, optionally
    guided by J over the whole sequence.

    Args:
        checkpoint: a loaded FD checkpoint.
        guidance: guide by J (goal distance + swept-footprint collision) at every step.
        cost: J's CollisionCost, needed with guidance.
        guidance_weight, num_steps, eta: as for SD.
    """

    def __init__(self, checkpoint, *, guidance: bool = False, cost=None,
                 guidance_weight: float = 1.0, num_steps: int | None = None, eta: float = 0.0,
                 guidance_space: str = "eps", device: str = "cpu") -> None:
        from ecahd_core.diffusion import DiffusionSampler, SamplerConfig
        from ecahd_core.model_zoo import sample_steps

        if guidance and cost is None:
            raise EcahdError("FD guidance needs the cost J (a CollisionCost)")
        self.horizon = max(checkpoint.horizons)
        self.guidance, self.cost = guidance, cost
        self.sampler = DiffusionSampler.from_checkpoint(checkpoint, device=device, config=SamplerConfig(
            num_steps=num_steps or sample_steps(checkpoint), eta=eta,
            guidance_weight=guidance_weight, guidance_space=guidance_space))

    def plan(self, start, goal, *, generator: torch.Generator | None = None) -> np.ndarray:
        """start, goal: (2,) [m] -> (horizon, 2) [m]."""
        start_t = torch.as_tensor(np.asarray(start, dtype=np.float32))
        goal_t = torch.as_tensor(np.asarray(goal, dtype=np.float32))
        guide = None
        if self.guidance:
            from ecahd_core.guidance import CostJGuide

            guide = CostJGuide.of(self.cost, goal_t)
        out = self.sampler.sample(batch=1, horizon=self.horizon,
                                  conditions={0: start_t, -1: goal_t}, generator=generator,
                                  guide=guide)
        return out.trajectories[0].numpy().astype(np.float64)

