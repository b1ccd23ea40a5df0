"""The Transformer denoiser eps_theta(x_t, t) of Fig. 2(a), shared by the SD, DD and FD models.

Tokens (B, 1 [+1] + P, d_model):
    [cond]      sinusoidal(t) -> MLP, plus a learned embedding of the horizon length P. The
                diffusion step is given as its own token rather than added to every waypoint so
                the waypoint tokens keep a clean "position + state" content and attention decides
                how much each waypoint uses the step (diffusion_policy's
                ``TransformerForDiffusion`` also feeds time as a token).
    [map]       optional (``use_map_encoder``): a small ResNet's pooled feature of a (B, 1, H, W)
                occupancy image (the paper's "shallow CNN (ResNet-18)", scaled down).
    [waypoints] Linear(2 -> d_model) of each normalised point + a learned position embedding
                (rows 0..max_horizon-1).
Encoder: ``nn.TransformerEncoder`` (batch_first, pre-norm, GELU, no attention mask: every token
sees every other), final LayerNorm, Linear(d_model -> 2) on the waypoint tokens.

Output: the NOISE eps (B, P, 2), not x_0 and not the score. Algorithm 2 line 5 adds
omega * grad J to the network output before the DDIM step; with eps-prediction that addition is
classifier guidance (score = -eps / sqrt(1 - alpha_bar_t), so eps + omega grad J is the score of
p(x) exp(-omega' J)) and the DDIM step then moves the sample down the cost. Eps-prediction is also
the paper's "noise-prediction objective" (Sec. III-B, training).

One model serves every horizon 2..max_horizon (SD's shrinking horizon): the horizon embedding
tells the network how long the trajectory is, the position embedding where each waypoint sits.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, Protocol

import torch
from torch import Tensor, nn


class Denoiser(Protocol):
    """What the sampler needs from a model: ``model(x, t, **model_kwargs) -> eps``, with
    x (B, P, 2) normalised, t (B,) long timesteps, eps (B, P, 2)."""

    def __call__(self, x: Tensor, t: Tensor, **kwargs: Any) -> Tensor: ...


@dataclass(frozen=True, kw_only=True)
class DenoiserConfig:
    """Architecture of :class:`TransformerDenoiser` (stored in every checkpoint).

    Attributes:
        max_horizon: the longest trajectory P the model accepts (size of the position table).
        d_model: token width.
        n_layers: Transformer encoder layers.
        n_heads: attention heads (must divide d_model).
        ff_mult: feed-forward width = ff_mult * d_model.
        dropout: dropout inside the encoder layers (training only).
        use_map_encoder: add a map token from a (B, 1, H, W) occupancy image.
    """

    max_horizon: int
    d_model: int = 128
    n_layers: int = 4
    n_heads: int = 4
    ff_mult: int = 4
    dropout: float = 0.0
    use_map_encoder: bool = False

    def __post_init__(self) -> None:
        for name in ("max_horizon", "d_model", "n_layers", "n_heads", "ff_mult"):
            value = getattr(self, name)
            if isinstance(value, bool) or int(value) != value or value < 1:
                raise ValueError(f"DenoiserConfig.{name} must be a positive integer, got {value!r}")
            object.__setattr__(self, name, int(value))
        if self.max_horizon < 2:
            raise ValueError(f"DenoiserConfig.max_horizon must be >= 2, got {self.max_horizon}")
        if self.d_model % self.n_heads:
            raise ValueError(f"DenoiserConfig.d_model ({self.d_model}) must be divisible by "
                             f"n_heads ({self.n_heads})")
        if not 0.0 <= self.dropout < 1.0:
            raise ValueError(f"DenoiserConfig.dropout must be in [0, 1), got {self.dropout}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "DenoiserConfig":
        return cls(**d)


def sinusoidal_embedding(t: Tensor, dim: int, *, max_period: float = 10_000.0) -> Tensor:
    """Transformer sinusoidal embedding of timesteps. t: (B,) -> (B, dim)."""
    half = dim // 2
    freqs = torch.exp(-math.log(max_period)
                      * torch.arange(half, dtype=torch.float32, device=t.device) / half)
    args = t.float()[:, None] * freqs[None]  # (B, half)
    emb = torch.cat([torch.sin(args), torch.cos(args)], dim=-1)
    if dim % 2:
        emb = torch.nn.functional.pad(emb, (0, 1))
    return emb


class _BasicBlock(nn.Module):
    """ResNet basic block (He et al. 2016) with GroupNorm: the map batch is often one image
    repeated, where BatchNorm statistics would be meaningless."""

    def __init__(self, c_in: int, c_out: int, stride: int) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(c_in, c_out, 3, stride=stride, padding=1, bias=False)
        self.norm1 = nn.GroupNorm(min(8, c_out), c_out)
        self.conv2 = nn.Conv2d(c_out, c_out, 3, padding=1, bias=False)
        self.norm2 = nn.GroupNorm(min(8, c_out), c_out)
        self.skip = (nn.Identity() if stride == 1 and c_in == c_out else nn.Sequential(
            nn.Conv2d(c_in, c_out, 1, stride=stride, bias=False),
            nn.GroupNorm(min(8, c_out), c_out)))
        self.act = nn.ReLU()

    def forward(self, x: Tensor) -> Tensor:
        h = self.act(self.norm1(self.conv1(x)))
        h = self.norm2(self.conv2(h))
        return self.act(h + self.skip(x))


class MapEncoder(nn.Module):
    """A small ResNet (stem + 3 strided basic blocks, 16-32-64 channels, global average pool):
    (B, 1, H, W) occupancy in [0, 1] -> (B, d_model)."""

    def __init__(self, d_model: int, channels: tuple[int, ...] = (16, 32, 64)) -> None:
        super().__init__()
        self.stem = nn.Sequential(nn.Conv2d(1, channels[0], 3, padding=1, bias=False),
                                  nn.GroupNorm(min(8, channels[0]), channels[0]), nn.ReLU())
        blocks, c_in = [], channels[0]
        for c_out in channels:
            blocks.append(_BasicBlock(c_in, c_out, stride=2))
            c_in = c_out
        self.blocks = nn.Sequential(*blocks)
        self.proj = nn.Linear(c_in, d_model)

    def forward(self, image: Tensor) -> Tensor:
        if image.dim() != 4 or image.shape[1] != 1:
            raise ValueError(f"map image must have shape (B, 1, H, W), got {tuple(image.shape)}")
        h = self.blocks(self.stem(image))  # (B, C, H / 8, W / 8)
        return self.proj(h.mean(dim=(2, 3)))  # (B, d_model)


class TransformerDenoiser(nn.Module):
    """eps_theta(x_t, t): (B, P, 2) normalised noisy trajectory + (B,) timesteps -> (B, P, 2)
    predicted noise. See the module docstring for the token layout."""

    def __init__(self, config: DenoiserConfig) -> None:
        super().__init__()
        self.config = config
        d = config.d_model
        self.point_embed = nn.Linear(2, d)
        self.pos_embed = nn.Parameter(torch.zeros(1, config.max_horizon, d))
        self.horizon_embed = nn.Embedding(config.max_horizon + 1, d)
        self.time_mlp = nn.Sequential(nn.Linear(d, d * 2), nn.GELU(), nn.Linear(d * 2, d))
        self.map_encoder = MapEncoder(d) if config.use_map_encoder else None
        layer = nn.TransformerEncoderLayer(
            d_model=d, nhead=config.n_heads, dim_feedforward=config.ff_mult * d,
            dropout=config.dropout, activation="gelu", batch_first=True, norm_first=True)
        self.encoder = nn.TransformerEncoder(layer, num_layers=config.n_layers,
                                             norm=nn.LayerNorm(d), enable_nested_tensor=False)
        self.head = nn.Linear(d, 2)
        nn.init.normal_(self.pos_embed, std=0.02)
        nn.init.normal_(self.horizon_embed.weight, std=0.02)

    @property
    def num_prefix_tokens(self) -> int:
        return 2 if self.map_encoder is not None else 1

    def encode_map(self, image: Tensor) -> Tensor:
        """(B, 1, H, W) occupancy image -> (B, d_model) map feature (compute once per plan and
        pass as ``map_feature`` to every denoising step)."""
        if self.map_encoder is None:
            raise ValueError("this denoiser was built with use_map_encoder=False")
        return self.map_encoder(image)

    def forward(self, x: Tensor, t: Tensor | int, *, map_image: Tensor | None = None,
                map_feature: Tensor | None = None) -> Tensor:
        """Predict the noise.

        Args:
            x: (B, P, 2) noisy normalised trajectories, 2 <= P <= max_horizon.
            t: (B,) long timesteps in 0..K-1 (or an int shared by the batch).
            map_image: (B or 1, 1, H, W) occupancy in [0, 1]; only with use_map_encoder.
            map_feature: (B or 1, d_model) precomputed :meth:`encode_map` output instead.
        Returns:
            eps: (B, P, 2).
        """
        if x.dim() != 3 or x.shape[-1] != 2:
            raise ValueError(f"x must have shape (B, P, 2), got {tuple(x.shape)}")
        B, P, _ = x.shape
        if not 1 <= P <= self.config.max_horizon:
            raise ValueError(f"horizon {P} is outside 1..max_horizon={self.config.max_horizon}")
        t = torch.as_tensor(t, device=x.device)
        if t.dim() == 0:
            t = t.expand(B)
        if t.shape != (B,):
            raise ValueError(f"t must be an int or have shape ({B},), got {tuple(t.shape)}")

        tokens = self.point_embed(x) + self.pos_embed[:, :P]  # (B, P, d)
        horizon = torch.full((B,), P, dtype=torch.long, device=x.device)
        cond = self.time_mlp(sinusoidal_embedding(t, self.config.d_model)) \
            + self.horizon_embed(horizon)  # (B, d)
        prefix = [cond[:, None]]
        if self.map_encoder is not None:
            if map_feature is None:
                if map_image is None:
                    raise ValueError("use_map_encoder=True: pass map_image or map_feature")
                map_feature = self.map_encoder(map_image)
            prefix.append(map_feature.expand(B, -1)[:, None])
        elif map_image is not None or map_feature is not None:
            raise ValueError("this denoiser was built with use_map_encoder=False; "
                             "do not pass a map")
        h = torch.cat(prefix + [tokens], dim=1)  # (B, prefix + P, d)
        h = self.encoder(h)
        return self.head(h[:, -P:])  # (B, P, 2)


def count_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())
