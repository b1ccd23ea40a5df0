"""The guide interface of the sampler (jannerm/diffuser ``sampling/guides.py``; Algorithm 2
lines 4-5).

A guide is any object with ``__call__(traj) -> GuideOutput``: given trajectories in metres it
returns the cost J per trajectory and its gradient with respect to those metres. The sampler calls
it under ``torch.enable_grad()`` on a detached copy of the sample (never through the network) and
turns the gradient into the normalised space itself. The cost J of Algorithm 2 stays a plain torch
function; :class:`CostGuide` makes a guide from such a function by autograd.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import torch
from torch import Tensor


@dataclass(frozen=True)
class GuideOutput:
    """Attributes:
        cost: (B,) J of each trajectory.
        grad: (B, P, 2) dJ/dtraj [cost units / m].
    """

    cost: Tensor
    grad: Tensor


class Guide(Protocol):
    def __call__(self, traj: Tensor) -> GuideOutput:
        """traj: (B, P, 2) [m] -> GuideOutput(cost (B,), grad (B, P, 2))."""
        ...


class CostGuide:
    """A guide from a differentiable cost: ``cost_fn(traj (B, P, 2) [m]) -> (B,)``.

    The gradient of each row's cost only depends on that row, so grad = d(sum_b J_b)/d traj.
    """

    def __init__(self, cost_fn: Callable[[Tensor], Tensor]) -> None:
        self.cost_fn = cost_fn

    def __call__(self, traj: Tensor) -> GuideOutput:
        B = traj.shape[0]
        with torch.enable_grad():
            traj = traj.detach().requires_grad_(True)
            cost = self.cost_fn(traj)
            if cost.shape != (B,):
                raise ValueError(f"cost_fn must return shape ({B},), got {tuple(cost.shape)}")
            (grad,) = torch.autograd.grad(cost.sum(), traj)
        return GuideOutput(cost=cost.detach(), grad=grad)
