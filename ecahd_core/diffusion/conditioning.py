"""State inpainting: overwrite known waypoints of a trajectory (jannerm/diffuser
``models/helpers.py`` ``apply_conditioning``; paper Sec. III-B "state inpainting between the
start and goal").

One pure function used everywhere: on the initial noise, after every denoising step, and at the
end of sampling; the training loss uses :func:`condition_mask` built from the same index rule.
Conditions are ``{index: value}`` with Python-style indices, so a start/goal problem is
``{0: start, -1: goal}`` whatever the horizon.
"""
from __future__ import annotations

from collections.abc import Iterable, Mapping

import torch
from torch import Tensor

from ecahd_core.errors import TrajectoryError

Conditions = Mapping[int, Tensor]
"""{waypoint index (negative counts from the end): (B, 2) or (2,) value}."""

START_GOAL = (0, -1)
"""The indices inpainted for a start/goal problem."""


def resolve_index(index: int, horizon: int) -> int:
    """A waypoint index in -P..P-1 as a position in 0..P-1."""
    if not -horizon <= index < horizon:
        raise TrajectoryError(f"condition index {index} is outside a horizon of {horizon} "
                              f"waypoints (allowed {-horizon}..{horizon - 1})")
    return index % horizon


def apply_conditioning(x: Tensor, conditions: Conditions) -> Tensor:
    """Return a copy of x with the conditioned waypoints set to their values.

    Args:
        x: (B, P, 2) trajectories.
        conditions: {index: (B, 2) or (2,)} in the same space as x (normalised in the sampler).
    Returns:
        (B, P, 2); x itself is not modified.
    """
    if x.dim() != 3 or x.shape[-1] != 2:
        raise TrajectoryError(f"x must have shape (B, P, 2), got {tuple(x.shape)}")
    B, P, _ = x.shape
    out = x.clone()
    for index, value in conditions.items():
        p = resolve_index(int(index), P)
        value = torch.as_tensor(value, dtype=x.dtype, device=x.device)
        if value.shape not in ((2,), (B, 2)):
            raise TrajectoryError(f"condition {index} must have shape (2,) or ({B}, 2), "
                                  f"got {tuple(value.shape)}")
        out[:, p] = value
    return out


def condition_mask(horizon: int, indices: Iterable[int], *, device: torch.device | str = "cpu"
                   ) -> Tensor:
    """(P,) bool, True at the inpainted waypoints."""
    mask = torch.zeros(horizon, dtype=torch.bool, device=device)
    for index in indices:
        mask[resolve_index(int(index), horizon)] = True
    return mask


def expand_conditions(conditions: Conditions, repeats: int) -> dict[int, Tensor]:
    """Repeat per-problem conditions for N candidates each: (B, 2) -> (B * N, 2), problem-major
    (row b * N + i is candidate i of problem b), so ``out.view(B, N, P, 2)`` separates them.
    (2,) values are shared by every row and returned unchanged."""
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    out = {}
    for index, value in conditions.items():
        value = torch.as_tensor(value)
        out[index] = value if value.dim() == 1 else value.repeat_interleave(repeats, dim=0)
    return out
