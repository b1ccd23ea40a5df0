"""Per-dimension affine normaliser between the map frame [m] and the diffusion space (~[-1, 1]).

    z = (x - centre) / scale          normalize:   metres -> diffusion space
    x = z * scale + centre            unnormalize: diffusion space -> metres

A map-bounds normaliser (:meth:`Normalizer.from_bounds`) sends the mapped rectangle exactly onto
[-1, 1]^2, so every reachable waypoint lies inside the range the DDIM scheduler clips
``pred_x0`` to. Note the two axes are scaled independently: distances are not preserved, which is
why guidance gradients go through :meth:`Normalizer.grad_to_normalized` (the chain rule) rather
than being used as they are.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import torch
from torch import Tensor


@dataclass(frozen=True)
class Normalizer:
    """Affine map between metres and the normalised diffusion space, one (centre, scale) per axis.

    Attributes:
        centre: (2,) map-frame point [m] sent to the origin of the diffusion space.
        scale: (2,) half-extent [m] per axis sent to 1 (positive, finite).
    """

    centre: tuple[float, float]
    scale: tuple[float, float]

    def __post_init__(self) -> None:
        centre = tuple(float(v) for v in torch.as_tensor(self.centre).reshape(-1).tolist())
        scale = tuple(float(v) for v in torch.as_tensor(self.scale).reshape(-1).tolist())
        if len(centre) != 2 or len(scale) != 2:
            raise ValueError(f"centre and scale must have 2 entries (x, y), got {centre}, {scale}")
        if not all(math.isfinite(v) for v in centre):
            raise ValueError(f"centre must be finite, got {centre}")
        if not all(math.isfinite(v) and v > 0 for v in scale):
            raise ValueError(f"scale must be positive and finite, got {scale}")
        object.__setattr__(self, "centre", centre)
        object.__setattr__(self, "scale", scale)

    # ------------------------------------------------------------------------ constructors
    @classmethod
    def from_bounds(cls, xmin: float, ymin: float, xmax: float, ymax: float) -> "Normalizer":
        """The normaliser sending the rectangle [xmin, xmax] x [ymin, ymax] [m] onto [-1, 1]^2
        (e.g. ``Normalizer.from_bounds(*grid.bounds)``)."""
        if not (xmax > xmin and ymax > ymin):
            raise ValueError(f"bounds must satisfy xmax > xmin and ymax > ymin, got "
                             f"({xmin}, {ymin}, {xmax}, {ymax})")
        return cls(centre=((xmin + xmax) / 2, (ymin + ymax) / 2),
                   scale=((xmax - xmin) / 2, (ymax - ymin) / 2))

    def to_dict(self) -> dict[str, Any]:
        """Plain-data form stored in checkpoints."""
        return {"centre": list(self.centre), "scale": list(self.scale)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Normalizer":
        try:
            return cls(centre=d["centre"], scale=d["scale"])
        except (KeyError, TypeError) as exc:
            raise ValueError(f"not a normaliser dict (needs 'centre' and 'scale'): {d!r}") from exc

    # ---------------------------------------------------------------------------- transforms
    def _tensors(self, like: Tensor) -> tuple[Tensor, Tensor]:
        centre = torch.tensor(self.centre, dtype=like.dtype, device=like.device)
        scale = torch.tensor(self.scale, dtype=like.dtype, device=like.device)
        return centre, scale

    def normalize(self, x: Tensor) -> Tensor:
        """x: (..., 2) [m] -> (..., 2) normalised."""
        centre, scale = self._tensors(x)
        return (x - centre) / scale

    def unnormalize(self, z: Tensor) -> Tensor:
        """z: (..., 2) normalised -> (..., 2) [m]."""
        centre, scale = self._tensors(z)
        return z * scale + centre

    def grad_to_normalized(self, grad_metres: Tensor) -> Tensor:
        """Chain rule for a cost J evaluated in metres: with x = z * scale + centre,
        dJ/dz = dJ/dx * scale (element-wise). grad_metres: (..., 2) -> (..., 2)."""
        _, scale = self._tensors(grad_metres)
        return grad_metres * scale
