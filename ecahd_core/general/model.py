"""The map-conditioned denoiser of the generalist SD (issue 40): eps_theta(x_t, t | views), the
Transformer of :mod:`ecahd_core.diffusion.denoiser` whose waypoint tokens also attend to spatial
tokens of the map (``ecahd_core.general.views``).

Tokens:
    self-attention (as :class:`~ecahd_core.diffusion.denoiser.TransformerDenoiser`, its pieces
    inherited): [cond] sinusoidal(t) -> MLP + horizon embedding, then [waypoints] Linear of each
    point in the view's normalised coordinates u in [-1, 1]^2 (+ Fourier features, as there) +
    a learned position embedding. (B, 1 + P, d).
    map memory (M = 64 + 2 S_g^2 + 1 tokens, 73 by default), computed by :meth:`encode`:
      [global]  a small ResNet (``MapEncoder``'s, 2 input channels, 32-64-96 channels, three
                stride-2 stages) over the (C, 64, 64) global view -> an 8 x 8 grid of patch
                features, each Linear -> d, + a learned 2D position embedding (64 rows): patch
                (i, j) covers 8 x 8 pixels, 1/8 of the view per side.
      [local]   a second small ResNet (16-32-64) over each (C, 32, 32) local view (shared by
                start and goal) -> 4 x 4 -> average-pooled to S_g x S_g (2 x 2) -> Linear -> d,
                + a learned embedding per (start | goal, cell): 8 tokens.
      [scale]   Linear(1 -> d) of log(half side [m]) of the global view: the view is
                normalised, so this is the only place the model learns metres per u.
      then a LayerNorm.

Cross-attention, not prepending: before each of the n_layers encoder layers (self-attention +
feed-forward, torch's fused inference kernel as in ``TransformerDenoiser._encode``), the 1 + P
tokens attend to the memory: h = h + W_o softmax(q K_i^T / sqrt(d_h)) V_i with q = W_q LN(h).
K_i, V_i of every layer depend on the map only, so :meth:`encode` computes them once per plan
and each denoising step costs the (1 + P)-token Transformer plus (1 + P) x M attention scores
per layer. Prepending the 73 map tokens to self-attention would run the feed-forward and
attention of 84 tokens at every step (about 7x the per-step work at P = 10) and the map
tokens, which attend to the noisy waypoints, could not be cached. The memory is computed for
one view per problem (B) or one for the whole batch (SD's N candidates of one problem share it:
batch 1, broadcast).

Output: eps (B, P, 2) in view coordinates (``prediction`` "epsilon"; "sample" as in
``denoiser.py``). The sampler, inpainting and guidance are those of ``ecahd_core.diffusion``;
the planner maps waypoints with ``ViewFrame.to_view`` / ``to_world``.

Measured (2026-12-06, this 2-core machine with other work on it, 1 thread, float32, eval, no
grad; ``python -m ecahd_core.general.model``, median of 200): the defaults (d = 128, 4 layers,
4 heads) have 1.46 M parameters (5.8 MB in float32, 2.9 MB in float16); :meth:`encode` of one
problem 3.6-4.5 ms; one denoising step at batch 10, P = 10 with that memory broadcast
4.4-5.1 ms, beside 3.2-3.6 ms for a ``TransformerDenoiser`` of the same size without a map
(five runs each).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn

from ecahd_core.diffusion.denoiser import (DenoiserConfig, MapEncoder, TransformerDenoiser,
                                           check_inputs, count_parameters)
from ecahd_core.general.views import MapViews, ViewConfig


@dataclass(frozen=True, kw_only=True)
class GeneralDenoiserConfig(DenoiserConfig):
    """Architecture of the map-conditioned denoiser: a ``DenoiserConfig`` (transformer; its
    one-token ``use_map_encoder`` off) plus the views it reads and its map encoders.

    Attributes:
        view: the :class:`~ecahd_core.general.views.ViewConfig` the model was built for (the
            planner must make its views with it).
        global_channels: channels of the global view's ResNet stages; the patch grid is
            S / 2^len (8 x 8 for S = 64 and 3 stages).
        local_channels: channels of the local views' ResNet stages.
        local_grid: S_g, each local view gives S_g x S_g tokens.
    """

    view: ViewConfig = field(default_factory=ViewConfig)
    global_channels: tuple[int, ...] = (32, 64, 96)
    local_channels: tuple[int, ...] = (16, 32, 64)
    local_grid: int = 2

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.architecture != "transformer" or self.use_map_encoder:
            raise ValueError("GeneralDenoiserConfig needs architecture 'transformer' and "
                             "use_map_encoder=False (its map tokens replace the pooled one)")
        if isinstance(self.view, dict):
            object.__setattr__(self, "view", ViewConfig(**self.view))
        for name in ("global_channels", "local_channels"):
            value = getattr(self, name)
            if isinstance(value, (str, bytes)) or not len(value) or any(
                    isinstance(c, bool) or int(c) != c or c < 1 for c in value):
                raise ValueError(f"GeneralDenoiserConfig.{name} must be a non-empty sequence "
                                 f"of positive integers, got {value!r}")
            object.__setattr__(self, name, tuple(int(c) for c in value))
        S, Sl = self.view.global_size, self.view.local_size
        for what, size, stages in (("global", S, len(self.global_channels)),
                                   ("local", Sl, len(self.local_channels))):
            if size % 2 ** stages:
                raise ValueError(f"the {what} view's {size} px must be a multiple of "
                                 f"2^{stages} (its ResNet's stride-2 stages)")
        if isinstance(self.local_grid, bool) or int(self.local_grid) != self.local_grid \
                or not 1 <= self.local_grid <= Sl // 2 ** len(self.local_channels):
            raise ValueError(f"GeneralDenoiserConfig.local_grid must be an integer in "
                             f"1..{Sl // 2 ** len(self.local_channels)}, got {self.local_grid!r}")

    @property
    def patch_grid(self) -> int:
        """Global patch tokens per side."""
        return self.view.global_size // 2 ** len(self.global_channels)

    @property
    def memory_tokens(self) -> int:
        """M: global patches + local tokens + the scale token."""
        return self.patch_grid ** 2 + 2 * self.local_grid ** 2 + 1

    def to_dict(self) -> dict[str, Any]:
        d = super().to_dict()
        d["view"] = {f.name: getattr(self.view, f.name) for f in fields(ViewConfig)}
        d["global_channels"] = list(self.global_channels)
        d["local_channels"] = list(self.local_channels)
        return d


@dataclass(frozen=True)
class ViewTensors:
    """A batch of views as the model reads them.

    Problems that share a global view (every problem of a map with the default "map" extent)
    may share one row of ``global_view``: ``global_index`` maps each problem to its row, and
    :meth:`MapConditionedDenoiser.encode` runs the global CNN once per row (training batches
    of K maps x M problems, ``ecahd_core.general.train``).

    Attributes:
        global_view: (U, C, S, S) float; U = Bm without ``global_index``.
        local_views: (Bm, 2, C, S_l, S_l) float (start, goal).
        half_side: (U,) float [m], the global view's half side (a property of the global view).
        global_index: (Bm,) long in 0..U-1, problem -> its global view's row; None: row i is
            problem i.
    """

    global_view: Tensor
    local_views: Tensor
    half_side: Tensor
    global_index: Tensor | None = None

    @property
    def batch(self) -> int:
        """Bm, the problems."""
        return int(self.local_views.shape[0])

    @classmethod
    def from_views(cls, views: MapViews, device: torch.device | str = "cpu") -> "ViewTensors":
        return cls(torch.as_tensor(views.global_view, dtype=torch.float32, device=device),
                   torch.as_tensor(views.local_views, dtype=torch.float32, device=device),
                   torch.as_tensor(views.frame.half_side, dtype=torch.float32, device=device))


@dataclass(frozen=True)
class MapMemory:
    """The map's keys and values for every cross-attention layer (:meth:`encode`'s output).

    Attributes:
        keys, values: n_layers tensors (Bm, n_heads, M, d / n_heads) each.
    """

    keys: tuple[Tensor, ...]
    values: tuple[Tensor, ...]

    @property
    def batch(self) -> int:
        return int(self.keys[0].shape[0])


class _CrossAttention(nn.Module):
    """Pre-norm multi-head cross-attention of tokens to a cached memory:
    h (B, T, d), K, V (B or 1, heads, M, d_h) -> h + W_o attn(W_q LN(h), K, V)."""

    def __init__(self, d: int, n_heads: int) -> None:
        super().__init__()
        self.n_heads = n_heads
        self.norm = nn.LayerNorm(d)
        self.q = nn.Linear(d, d)
        self.kv = nn.Linear(d, 2 * d)
        self.out = nn.Linear(d, d)

    def keys_values(self, memory: Tensor) -> tuple[Tensor, Tensor]:
        """(Bm, M, d) memory -> K, V (Bm, heads, M, d_h)."""
        Bm, M, d = memory.shape
        kv = self.kv(memory).view(Bm, M, 2, self.n_heads, d // self.n_heads)
        k, v = kv.permute(2, 0, 3, 1, 4).unbind(0)  # (Bm, heads, M, d_h) each
        return k.contiguous(), v.contiguous()

    def forward(self, h: Tensor, k: Tensor, v: Tensor) -> Tensor:
        B, T, d = h.shape
        q = self.q(self.norm(h)).view(B, T, self.n_heads, d // self.n_heads).transpose(1, 2)
        if k.shape[0] != B:
            k, v = k.expand(B, -1, -1, -1), v.expand(B, -1, -1, -1)
        a = nn.functional.scaled_dot_product_attention(q, k, v)  # (B, heads, T, d_h)
        return h + self.out(a.transpose(1, 2).reshape(B, T, d))


class MapConditionedDenoiser(TransformerDenoiser):
    """eps_theta(x_t, t | map views): (B, P, 2) noisy trajectories in view coordinates + (B,)
    timesteps + the problems' views -> (B, P, 2) predicted noise (module docstring)."""

    def __init__(self, config: GeneralDenoiserConfig) -> None:
        if not isinstance(config, GeneralDenoiserConfig):
            raise ValueError(f"MapConditionedDenoiser needs a GeneralDenoiserConfig, "
                             f"got {type(config).__name__}")
        super().__init__(config)
        d, C = config.d_model, config.view.channels
        self.global_encoder = MapEncoder(d, config.global_channels, in_channels=C)
        self.local_encoder = MapEncoder(d, config.local_channels, in_channels=C)
        self.global_pos = nn.Parameter(torch.zeros(1, config.patch_grid ** 2, d))
        self.local_pos = nn.Parameter(torch.zeros(1, 2 * config.local_grid ** 2, d))
        self.scale_embed = nn.Linear(1, d)
        self.memory_norm = nn.LayerNorm(d)
        self.cross = nn.ModuleList(_CrossAttention(d, config.n_heads)
                                   for _ in range(config.n_layers))
        nn.init.normal_(self.global_pos, std=0.02)
        nn.init.normal_(self.local_pos, std=0.02)

    def encode(self, views: ViewTensors | MapViews) -> MapMemory:
        """The map memory of Bm problems' views (once per plan; pass it to every step).

        Args:
            views: :class:`ViewTensors` (or numpy :class:`MapViews`), batch Bm; with a
                ``global_index`` the global CNN runs once per distinct global view (U rows)
                and its tokens are gathered for each problem: the same memory as with the U
                views repeated per problem, at U / Bm of the global CNN's cost.
        Returns:
            :class:`MapMemory`, keys and values (Bm, n_heads, M, d / n_heads) per layer.
        """
        device = self.pos_embed.device
        if isinstance(views, MapViews):
            views = ViewTensors.from_views(views, device)
        cfg = self.config
        g, loc, half, index = views.global_view, views.local_views, views.half_side, \
            views.global_index
        Bm, U = loc.shape[0], g.shape[0]
        C, S, Sl = cfg.view.channels, cfg.view.global_size, cfg.view.local_size
        if g.shape != (U, C, S, S) or loc.shape != (Bm, 2, C, Sl, Sl) or half.shape != (U,):
            raise ValueError(f"views must be global (U, {C}, {S}, {S}), local (Bm, 2, {C}, "
                             f"{Sl}, {Sl}) and half_side (U,); got {tuple(g.shape)}, "
                             f"{tuple(loc.shape)}, {tuple(half.shape)}")
        if index is None and U != Bm:
            raise ValueError(f"{U} global views for {Bm} problems need a global_index")
        if index is not None and (index.shape != (Bm,) or index.dtype != torch.long):
            raise ValueError(f"global_index must be a (Bm,) = ({Bm},) long tensor, got "
                             f"{tuple(index.shape)} {index.dtype}")
        pg = self.global_encoder.feature_map(g.to(device))  # (U, Cg, 8, 8)
        patches = self.global_encoder.proj(pg.flatten(2).transpose(1, 2)) \
            + self.global_pos  # (U, 64, d)
        scale = self.scale_embed(half.to(device).float().clamp_min(1e-3).log()[:, None])
        pl = self.local_encoder.feature_map(loc.to(device).flatten(0, 1))  # (2Bm, Cl, 4, 4)
        pl = nn.functional.adaptive_avg_pool2d(pl, cfg.local_grid)  # (2Bm, Cl, Sg, Sg)
        local = self.local_encoder.proj(pl.flatten(2).transpose(1, 2))  # (2Bm, Sg^2, d)
        local = local.reshape(Bm, 2 * cfg.local_grid ** 2, -1) + self.local_pos  # (Bm, 2Sg^2, d)
        if index is None:
            memory = self.memory_norm(torch.cat([patches, local, scale[:, None]], dim=1))
            kv = [layer.keys_values(memory) for layer in self.cross]  # (Bm, heads, M, d_h)
            return MapMemory(keys=tuple(k for k, _ in kv), values=tuple(v for _, v in kv))
        # the norm and K, V are per token: those of the global tokens (patches, scale) are
        # computed once per global view, then gathered per problem in the memory's order
        n_patch = patches.shape[1]
        shared = self.memory_norm(torch.cat([patches, scale[:, None]], dim=1))  # (U, 65, d)
        own = self.memory_norm(local)  # (Bm, 2Sg^2, d)
        index = index.to(device)
        keys, values = [], []
        for layer in self.cross:
            kg, vg = layer.keys_values(shared)  # (U, heads, 65, d_h)
            kl, vl = layer.keys_values(own)  # (Bm, heads, 2Sg^2, d_h)
            kg, vg = kg.index_select(0, index), vg.index_select(0, index)  # (Bm, heads, 65, d_h)
            keys.append(torch.cat([kg[:, :, :n_patch], kl, kg[:, :, n_patch:]], dim=2))
            values.append(torch.cat([vg[:, :, :n_patch], vl, vg[:, :, n_patch:]], dim=2))
        return MapMemory(keys=tuple(keys), values=tuple(values))  # (Bm, heads, M, d_h) each

    def forward(self, x: Tensor, t: Tensor | int, *, views: ViewTensors | MapViews | None = None,
                memory: MapMemory | None = None) -> Tensor:
        """Predict the noise.

        Args:
            x: (B, P, 2) noisy trajectories in view coordinates, 2 <= P <= max_horizon.
            t: (B,) long timesteps in 0..K-1 (or an int shared by the batch).
            views: the problems' views, batch B or 1 (encoded at this call; problems that
                share a global view may share its row, ``ViewTensors.global_index``), or
            memory: their :meth:`encode` output, batch B or 1 (computed once per plan).
        Returns:
            eps: (B, P, 2).
        """
        t = check_inputs(x, t, self.config.max_horizon)
        B, P, _ = x.shape
        if (views is None) == (memory is None):
            raise ValueError("pass exactly one of views and memory")
        if memory is None:
            memory = self.encode(views)
        if memory.batch not in (1, B):
            raise ValueError(f"the map memory has batch {memory.batch}; the trajectories "
                             f"need 1 or {B}")
        cond, tokens = self.embed(x, t)  # (B, 1, d), (B, P, d)
        h = torch.cat([cond, tokens], dim=1)  # (B, 1 + P, d)

        def cross(i: int, h: Tensor) -> Tensor:
            k, v = memory.keys[i], memory.values[i]
            if h.dtype != k.dtype:  # bf16 encoder layers: the cross-attention stays float32
                return self.cross[i](h.to(k.dtype), k, v).to(h.dtype)
            return self.cross[i](h, k, v)

        h = self._encode(h, before_layer=cross)
        return self.head(h[:, -P:])  # (B, P, 2)


def build_general_denoiser(config: GeneralDenoiserConfig) -> MapConditionedDenoiser:
    """The map-conditioned denoiser, freshly initialised (torch's global RNG)."""
    return MapConditionedDenoiser(config)


@dataclass(frozen=True)
class StepTiming:
    """What :func:`measure_step` measured (median of ``repeats``)."""

    parameters: int
    encode_ms: float
    step_ms: float
    baseline_step_ms: float


def measure_step(config: GeneralDenoiserConfig | None = None, *, batch: int = 10,
                 horizon: int = 10, repeats: int = 200) -> StepTiming:
    """Time :meth:`~MapConditionedDenoiser.encode` of one problem and one denoising step at
    ``batch`` x ``horizon`` with that memory broadcast, beside a ``TransformerDenoiser`` of the
    same size without a map; eval, no grad, float32, on the threads torch has."""
    config = config or GeneralDenoiserConfig(max_horizon=horizon)
    torch.manual_seed(0)
    model = build_general_denoiser(config).eval()
    base = TransformerDenoiser(DenoiserConfig(
        max_horizon=config.max_horizon, d_model=config.d_model, n_layers=config.n_layers,
        n_heads=config.n_heads, ff_mult=config.ff_mult,
        fourier_bands=config.fourier_bands)).eval()
    v, S, Sl = config.view, config.view.global_size, config.view.local_size
    views = ViewTensors(torch.rand(1, v.channels, S, S).round(),
                        torch.rand(1, 2, v.channels, Sl, Sl).round(), torch.tensor([10.0]))
    x = torch.randn(batch, horizon, 2)
    t = torch.full((batch,), 5, dtype=torch.long)

    def median_ms(fn) -> float:
        for _ in range(10):
            fn()
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            fn()
            times.append(time.perf_counter() - t0)
        return 1e3 * float(np.median(times))

    with torch.no_grad():
        memory = model.encode(views)
        return StepTiming(parameters=count_parameters(model),
                          encode_ms=median_ms(lambda: model.encode(views)),
                          step_ms=median_ms(lambda: model(x, t, memory=memory)),
                          baseline_step_ms=median_ms(lambda: base(x, t)))


if __name__ == "__main__":  # python -m ecahd_core.general.model: the docstring's numbers
    torch.set_num_threads(1)
    r = measure_step()
    print(f"parameters {r.parameters:,} ({4 * r.parameters / 1e6:.1f} MB float32); encode "
          f"{r.encode_ms:.2f} ms; step (B=10, P=10) {r.step_ms:.2f} ms; without a map "
          f"{r.baseline_step_ms:.2f} ms")
