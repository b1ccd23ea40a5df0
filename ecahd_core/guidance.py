"""Guidance by the cost J (Algorithm 2 line 5: eps + omega * grad(dist_cost + collision_cost)).

:class:`CostJGuide` is the guide object the sampler calls (``ecahd_core.diffusion.guides``):
it evaluates J = dist_cost + collision_cost of ``ecahd_core.cost`` under ``enable_grad`` on a
detached copy of the trajectories and returns the cost and its gradient in metres.
"""
from __future__ import annotations

import torch
from torch import Tensor

from ecahd_core.cost import CostConfig, trajectory_cost
from ecahd_core.costmap import CostMap
from ecahd_core.diffusion.guides import GuideOutput


class CostJGuide:
    """J of a batch of trajectories towards per-row goals.

    Args:
        costmap: the collision cost map M.
        footprint_points: (R, 2) robot-frame sample points R [m].
        goal: (B, 2) or (2,) the goal each row is pulled towards [m] (for DD the local goal
            t^g[1], for SD / FD the global goal G).
        config: mode, N_interp, sigma_dist / sigma_col.
    """

    def __init__(self, costmap: CostMap, footprint_points, goal, config: CostConfig | None = None):
        self.config = config or CostConfig()
        self.costmap = costmap
        self.footprint_points = torch.as_tensor(footprint_points, dtype=costmap.dtype,
                                                device=costmap.device)
        self.goal = torch.as_tensor(goal, dtype=costmap.dtype, device=costmap.device)
        self._kwargs = self.config.cost_kwargs()

    @classmethod
    def of(cls, cost, goal) -> "CostJGuide":
        """J of a :class:`~ecahd_core.cost.CollisionCost` (cost map, footprint points, config)
        towards ``goal`` ((2,) or (B, 2) [m])."""
        return cls(cost.costmap, cost.footprint_points, goal, cost.config)

    def terms(self, traj: Tensor):
        """CostTerms (dist_cost (B,), collision_cost (B,)) without gradients."""
        with torch.no_grad():
            return trajectory_cost(traj, self.goal, self.footprint_points, self.costmap,
                                   **self._kwargs)

    def __call__(self, traj: Tensor) -> GuideOutput:
        """traj: (B, P, 2) [m] -> GuideOutput(cost (B,), grad (B, P, 2))."""
        with torch.enable_grad():
            x = traj.detach().to(self.costmap.dtype).requires_grad_(True)
            terms = trajectory_cost(x, self.goal, self.footprint_points, self.costmap,
                                    **self._kwargs)
            cost = terms.dist_cost + terms.collision_cost
            (grad,) = torch.autograd.grad(cost.sum(), x)
        return GuideOutput(cost=cost.detach(), grad=grad.to(traj.dtype))
