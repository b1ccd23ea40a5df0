"""The denoisers eps_theta(x_t, t): the Transformer of Fig. 2(a) (SD and DD) and a temporal
1D-convolution U-Net (the Diffuser-style FD baseline). :func:`build_denoiser` makes either from a
:class:`DenoiserConfig` (``architecture``); every checkpoint stores that config.

Transformer tokens (B, 1 [+1] + P, d_model):
    [cond]      sinusoidal(t) -> MLP, plus a learned embedding of the horizon length P. The
                diffusion step is given as its own token rather than added to every waypoint so
                the waypoint tokens keep a clean "position + state" content and attention decides
                how much each waypoint uses the step (diffusion_policy's
                ``TransformerForDiffusion`` also feeds time as a token).
    [map]       optional (``use_map_encoder``): a small ResNet's pooled feature of a (B, 1, H, W)
                occupancy image (the paper's "shallow CNN (ResNet-18)", scaled down).
    [waypoints] Linear(2 [+ 4 F] -> d_model) of each normalised point (with ``fourier_bands``
                F > 0: and its Fourier features, sin and cos of pi 2^k z per coordinate,
                k < F) + a learned position embedding (rows 0..max_horizon-1).
Encoder: ``nn.TransformerEncoder`` (batch_first, pre-norm, GELU, no attention mask: every token
sees every other), final LayerNorm, Linear(d_model -> 2) on the waypoint tokens.

Output: the NOISE eps (B, P, 2), not x_0 and not the score. Algorithm 2 line 5 adds
omega * grad J to the network output before the DDIM step; with eps-prediction that addition is
classifier guidance (score = -eps / sqrt(1 - alpha_bar_t), so eps + omega grad J is the score of
p(x) exp(-omega' J)) and the DDIM step then moves the sample down the cost. Eps-prediction is also
the paper's "noise-prediction objective" (Sec. III-B, training).

One model serves every horizon 2..max_horizon (SD's shrinking horizon): the horizon embedding
tells the network how long the trajectory is, the position embedding where each waypoint sits.

Temporal U-Net (:class:`TemporalUnetDenoiser`; jannerm/diffuser ``models/temporal.py``
``TemporalUnet``, scaled for a CPU): the trajectory is a (B, 2, P) signal. Each level has two
residual blocks (Conv1d k -> GroupNorm -> Mish, twice, with the time embedding added after the
first conv) and halves P with a stride-2 conv; the way up doubles P with a transposed conv and
concatenates the skip of the same level. Time: sinusoidal(t) -> Linear -> Mish -> Linear, added
(after Mish -> Linear) in every block. Convolutions are local, so neighbouring waypoints are
smooth from the start of training; the receptive field of the default (32, 64, 128), k = 5
spans more than 100 waypoints, so the goal reaches the start. P is padded at the end (edge
value) to a multiple of 2^(levels - 1) and cropped back.

Prediction target (``DenoiserConfig.prediction``): "epsilon" as above, or "sample": the network
outputs the clean trajectory x_0 (Diffuser's maze2d models, ``predict_epsilon=False``), and
:class:`EpsilonFromSample` turns it into eps for the sampler. With eps-prediction the last DDIM
step leaves sqrt(1 - alpha_bar) * (eps - eps_hat) in the sample: independent jitter of each
waypoint, which on 100 waypoints 0.15 m apart doubled the path length of a briefly trained FD
model (measured: 2.3 x A* at eta 0 against 1.2 x for x_0 prediction after the same 3000 steps);
an x_0 prediction is as smooth as the network makes it.
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


ARCHITECTURES = ("transformer", "temporal_unet")
PREDICTIONS = ("epsilon", "sample")


@dataclass(frozen=True, kw_only=True)
class DenoiserConfig:
    """Architecture of a denoiser (stored in every checkpoint; :func:`build_denoiser`).

    A checkpoint written before ``architecture`` existed has none of the U-Net fields and loads
    as the Transformer it is.

    Attributes:
        max_horizon: the longest trajectory P the model accepts (size of the position table).
        architecture: "transformer" (:class:`TransformerDenoiser`) or "temporal_unet"
            (:class:`TemporalUnetDenoiser`).
        d_model: token width (transformer).
        n_layers: Transformer encoder layers (transformer).
        n_heads: attention heads, must divide d_model (transformer).
        ff_mult: feed-forward width = ff_mult * d_model (transformer).
        dropout: dropout inside the encoder layers, training only (transformer).
        use_map_encoder: add a map token from a (B, 1, H, W) occupancy image (transformer).
        unet_channels: channels of each U-Net level, finest first; P is halved between levels
            (temporal_unet). The first is also the time-embedding width.
        unet_kernel_size: odd temporal kernel of the U-Net convolutions (temporal_unet).
        prediction: what the network outputs: "epsilon", the noise (the paper's objective), or
            "sample", the clean trajectory x_0 (Diffuser's maze2d setting,
            ``predict_epsilon=False``). Samplers always receive eps: a "sample" network is
            wrapped in :class:`EpsilonFromSample` (``Checkpoint.build_model`` does this).
        fourier_bands: F (transformer; ours, beyond the paper): each waypoint's embedding also
            sees sin(pi 2^k z) and cos(pi 2^k z) of its normalised coordinates z, k < F
            (Tancik et al. 2020, "Fourier features let networks learn high frequency
            functions"). A linear embedding of coordinates normalised by a 60 m map leaves
            the network to build a door's 1 m from smooth functions of z; 0: the paper's
            Linear(2 -> d_model).
    """

    max_horizon: int
    architecture: str = "transformer"
    d_model: int = 128
    n_layers: int = 4
    n_heads: int = 4
    ff_mult: int = 4
    dropout: float = 0.0
    use_map_encoder: bool = False
    unet_channels: tuple[int, ...] = (32, 64, 128)
    unet_kernel_size: int = 5
    prediction: str = "epsilon"
    fourier_bands: int = 0

    def __post_init__(self) -> None:
        for name, allowed in (("architecture", ARCHITECTURES), ("prediction", PREDICTIONS)):
            if getattr(self, name) not in allowed:
                raise ValueError(f"DenoiserConfig.{name} must be one of "
                                 f"{', '.join(repr(a) for a in allowed)}, "
                                 f"got {getattr(self, name)!r}")
        for name in ("max_horizon", "d_model", "n_layers", "n_heads", "ff_mult",
                     "unet_kernel_size"):
            object.__setattr__(self, name, _positive_int(f"DenoiserConfig.{name}",
                                                         getattr(self, name)))
        if isinstance(self.fourier_bands, bool) or int(self.fourier_bands) != self.fourier_bands \
                or not 0 <= self.fourier_bands <= 16:
            raise ValueError(f"DenoiserConfig.fourier_bands must be an integer in 0..16, "
                             f"got {self.fourier_bands!r}")
        object.__setattr__(self, "fourier_bands", int(self.fourier_bands))
        if self.fourier_bands and self.architecture != "transformer":
            raise ValueError("DenoiserConfig.fourier_bands is only supported by the "
                             "'transformer' architecture")
        if self.max_horizon < 2:
            raise ValueError(f"DenoiserConfig.max_horizon must be >= 2, got {self.max_horizon}")
        if self.d_model % self.n_heads:
            raise ValueError(f"DenoiserConfig.d_model ({self.d_model}) must be divisible by "
                             f"n_heads ({self.n_heads})")
        if not 0.0 <= self.dropout < 1.0:
            raise ValueError(f"DenoiserConfig.dropout must be in [0, 1), got {self.dropout}")
        if isinstance(self.unet_channels, (str, bytes)) or not len(self.unet_channels):
            raise ValueError(f"DenoiserConfig.unet_channels must be a non-empty sequence of "
                             f"positive integers, got {self.unet_channels!r}")
        object.__setattr__(self, "unet_channels", tuple(
            _positive_int("DenoiserConfig.unet_channels", c) for c in self.unet_channels))
        if self.unet_kernel_size % 2 == 0:
            raise ValueError(f"DenoiserConfig.unet_kernel_size must be odd, "
                             f"got {self.unet_kernel_size}")
        if self.architecture == "temporal_unet" and self.use_map_encoder:
            raise ValueError("DenoiserConfig.use_map_encoder is only supported by the "
                             "'transformer' architecture")

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["unet_channels"] = list(self.unet_channels)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "DenoiserConfig":
        return cls(**d)


def _positive_int(name: str, value: Any) -> int:
    if isinstance(value, bool) or int(value) != value or value < 1:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


_FREQS: dict[tuple[int, float, torch.device], Tensor] = {}  # sinusoidal frequencies, per device


def _frequencies(half: int, max_period: float, device: torch.device) -> Tensor:
    """(half,) exp(-log(max_period) * i / half), computed once per (half, max_period, device)."""
    key = (half, float(max_period), device)
    freqs = _FREQS.get(key)
    if freqs is None:
        with torch.inference_mode(False), torch.no_grad():  # a plain tensor, usable anywhere
            freqs = torch.exp(-math.log(max_period)
                              * torch.arange(half, dtype=torch.float32, device=device) / half)
        _FREQS[key] = freqs
    return freqs


def sinusoidal_embedding(t: Tensor, dim: int, *, max_period: float = 10_000.0) -> Tensor:
    """Transformer sinusoidal embedding of timesteps. t: (B,) -> (B, dim)."""
    half = dim // 2
    freqs = _frequencies(half, max_period, t.device)
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
    """A small ResNet (stem + one strided basic block per entry of ``channels``, default
    16-32-64, then a global average pool): (B, in_channels, H, W) occupancy in [0, 1] ->
    (B, d_model). :meth:`feature_map` gives the features before the pool (the generalist's
    patch tokens, ``ecahd_core.general.model``)."""

    def __init__(self, d_model: int, channels: tuple[int, ...] = (16, 32, 64), *,
                 in_channels: int = 1) -> None:
        super().__init__()
        self.in_channels = in_channels
        self.stem = nn.Sequential(nn.Conv2d(in_channels, channels[0], 3, padding=1, bias=False),
                                  nn.GroupNorm(min(8, channels[0]), channels[0]), nn.ReLU())
        blocks, c_in = [], channels[0]
        for c_out in channels:
            blocks.append(_BasicBlock(c_in, c_out, stride=2))
            c_in = c_out
        self.blocks = nn.Sequential(*blocks)
        self.proj = nn.Linear(c_in, d_model)

    def feature_map(self, image: Tensor) -> Tensor:
        """(B, in_channels, H, W) -> (B, C, H / 2^n, W / 2^n), n = len(channels), C the last
        channel count (not projected to d_model)."""
        if image.dim() != 4 or image.shape[1] != self.in_channels:
            raise ValueError(f"map image must have shape (B, {self.in_channels}, H, W), "
                             f"got {tuple(image.shape)}")
        return self.blocks(self.stem(image))

    def forward(self, image: Tensor) -> Tensor:
        h = self.feature_map(image)  # (B, C, H / 8, W / 8)
        return self.proj(h.mean(dim=(2, 3)))  # (B, d_model)


class TransformerDenoiser(nn.Module):
    """eps_theta(x_t, t): (B, P, 2) normalised noisy trajectory + (B,) timesteps -> (B, P, 2)
    predicted noise. See the module docstring for the token layout."""

    def __init__(self, config: DenoiserConfig) -> None:
        super().__init__()
        if config.architecture != "transformer":
            raise ValueError(f"TransformerDenoiser needs architecture 'transformer', "
                             f"got {config.architecture!r}")
        self.config = config
        d = config.d_model
        self.point_embed = nn.Linear(2 + 4 * config.fourier_bands, d)
        # pi 2^k, k < F: the Fourier features' angular frequencies (a buffer: moves with .to())
        self.register_buffer("fourier_freqs", math.pi * 2.0 ** torch.arange(
            config.fourier_bands, dtype=torch.float32), persistent=False)
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
        t = check_inputs(x, t, self.config.max_horizon)
        B, P, _ = x.shape
        cond, tokens = self.embed(x, t)  # (B, 1, d), (B, P, d)
        prefix = [cond]
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
        h = self._encode(h)
        return self.head(h[:, -P:])  # (B, P, 2)

    def embed(self, x: Tensor, t: Tensor) -> tuple[Tensor, Tensor]:
        """The condition token and the waypoint tokens: x (B, P, 2), t (B,) ->
        (cond (B, 1, d), tokens (B, P, d)) (module docstring, "Transformer tokens")."""
        B, P, _ = x.shape
        tokens = self.point_embed(self.point_features(x)) + self.pos_embed[:, :P]  # (B, P, d)
        horizon = torch.full((B,), P, dtype=torch.long, device=x.device)
        cond = self.time_mlp(sinusoidal_embedding(t, self.config.d_model)) \
            + self.horizon_embed(horizon)  # (B, d)
        return cond[:, None], tokens

    def point_features(self, x: Tensor) -> Tensor:
        """(B, P, 2) normalised points -> (B, P, 2 + 4 F): the points, then sin and cos of
        each coordinate times each of the F frequencies (``fourier_bands``; F = 0: x itself)."""
        if not self.config.fourier_bands:
            return x
        ang = x[..., None] * self.fourier_freqs.to(x.dtype)  # (B, P, 2, F)
        return torch.cat([x, ang.sin().flatten(-2), ang.cos().flatten(-2)], dim=-1)

    def _encode(self, h: Tensor, before_layer=None) -> Tensor:
        """``self.encoder(h)``, (B, T, d) -> (B, T, d). ``before_layer(i, h) -> h``, if given,
        runs before encoder layer i (the generalist's cross-attention to the map,
        ``ecahd_core.general.model``); it receives h in the layers' dtype and returns it in
        the same. Without gradients in eval mode the
        encoder's layers run torch's fused ``_transformer_encoder_layer_fwd``
        (``nn.TransformerEncoderLayer``'s inference fast path); this calls that kernel and the
        final LayerNorm directly with the arguments the modules would pass, skipping their
        per-call eligibility checks (~15% of an SD step on a CPU), so the output is bit for bit
        the module's in float32 (in bfloat16 after :meth:`set_inference_precision`: the layers
        compute in it, the final LayerNorm in float32 again). Any other case (training,
        gradients, autocast, fast path disabled, hooks) goes through the modules."""
        args = None
        if not (self.training or torch.is_grad_enabled() or torch.is_autocast_enabled()
                or not torch.backends.mha.get_fastpath_enabled()):
            args = self._fast_encoder_args()
        if args is None:
            if before_layer is None:
                return self.encoder(h)
            for i, layer in enumerate(self.encoder.layers):  # what nn.TransformerEncoder does
                h = layer(before_layer(i, h))
            return self.encoder.norm(h)
        layers, norm = args
        dtype = h.dtype
        h = h.to(self.inference_dtype)
        for i, layer_args in enumerate(layers):
            if before_layer is not None:
                h = before_layer(i, h)
            h = torch._transformer_encoder_layer_fwd(h, *layer_args)
        return nn.functional.layer_norm(h.to(dtype), *norm)

    @property
    def inference_dtype(self) -> torch.dtype:
        """The dtype the encoder layers compute in on the inference fast path (float32 unless
        :meth:`set_inference_precision` chose bfloat16)."""
        return self.__dict__.get("_inference_dtype", torch.float32)

    def set_inference_precision(self, precision: str) -> str:
        """"fp32" or "bf16": the dtype of the encoder layers' fused inference kernel (weights
        copied to it once; embeddings, final LayerNorm and head stay float32; training and
        gradients always run float32). "auto": bf16 where the CPU computes it natively
        (``threads.native_bf16``). Returns the precision chosen."""
        from ecahd_core.threads import resolve_precision

        device = next(self.parameters()).device
        precision = resolve_precision(precision, device)
        self.__dict__["_inference_dtype"] = (torch.bfloat16 if precision == "bf16"
                                             else torch.float32)
        self.__dict__.pop("_fast_args", None)
        return precision

    def _fast_encoder_args(self) -> tuple | None:
        """The encoder's arguments of the fused layer kernel and of its final LayerNorm, or
        None where the fast path does not apply (the modules decide then). Cached; the cache
        is dropped when the module's tensors are moved or converted (``_apply``) and whenever
        a hook is attached (checked on every call) or a state dict is loaded."""
        if any(m._forward_hooks or m._forward_pre_hooks for m in self._encoder_modules):
            return None
        cached = self.__dict__.get("_fast_args")
        if cached is not None:
            return cached
        dtype = self.inference_dtype

        def cast(w: Tensor) -> Tensor:  # the kernel's weights in the inference dtype
            return w.detach().to(dtype) if w.dtype != dtype else w

        layers = []
        for layer in self.encoder.layers:
            attn = layer.self_attn
            if not (attn.batch_first and attn.in_proj_bias is not None
                    and attn._qkv_same_embed_dim and layer.activation_relu_or_gelu
                    and layer.norm1.eps == layer.norm2.eps and attn.num_heads % 2 == 0):
                return None
            layers.append((
                attn.embed_dim, attn.num_heads, cast(attn.in_proj_weight),
                cast(attn.in_proj_bias), cast(attn.out_proj.weight), cast(attn.out_proj.bias),
                layer.activation_relu_or_gelu == 2, layer.norm_first, layer.norm1.eps,
                cast(layer.norm1.weight), cast(layer.norm1.bias), cast(layer.norm2.weight),
                cast(layer.norm2.bias), cast(layer.linear1.weight), cast(layer.linear1.bias),
                cast(layer.linear2.weight), cast(layer.linear2.bias), None, None))  # no mask
        norm = self.encoder.norm
        if not isinstance(norm, nn.LayerNorm):
            return None
        cached = (tuple(layers), (norm.normalized_shape, norm.weight, norm.bias, norm.eps))
        self.__dict__["_fast_args"] = cached
        return cached

    @property
    def _encoder_modules(self) -> tuple[nn.Module, ...]:
        mods = self.__dict__.get("_encoder_mods")
        if mods is None:
            mods = tuple(self.encoder.modules())
            self.__dict__["_encoder_mods"] = mods
        return mods

    def _apply(self, fn, recurse: bool = True):
        self.__dict__.pop("_fast_args", None)  # tensors may be replaced by .to() / .float()
        return super()._apply(fn, recurse)

    def _load_from_state_dict(self, *args, **kwargs) -> None:
        self.__dict__.pop("_fast_args", None)  # load_state_dict(assign=True) replaces them
        super()._load_from_state_dict(*args, **kwargs)


def check_inputs(x: Tensor, t: Tensor | int, max_horizon: int) -> Tensor:
    """Validate a denoiser's inputs x (B, P, 2) and t; return t as (B,) on x's device."""
    if x.dim() != 3 or x.shape[-1] != 2:
        raise ValueError(f"x must have shape (B, P, 2), got {tuple(x.shape)}")
    B, P, _ = x.shape
    if not 1 <= P <= max_horizon:
        raise ValueError(f"horizon {P} is outside 1..max_horizon={max_horizon}")
    t = torch.as_tensor(t, device=x.device)
    if t.dim() == 0:
        t = t.expand(B)
    if t.shape != (B,):
        raise ValueError(f"t must be an int or have shape ({B},), got {tuple(t.shape)}")
    return t


class _Conv1dBlock(nn.Sequential):
    """Conv1d (same length) -> GroupNorm -> Mish: (B, c_in, L) -> (B, c_out, L)."""

    def __init__(self, c_in: int, c_out: int, kernel_size: int) -> None:
        super().__init__(nn.Conv1d(c_in, c_out, kernel_size, padding=kernel_size // 2),
                         nn.GroupNorm(math.gcd(8, c_out), c_out), nn.Mish())


class _ResidualTemporalBlock(nn.Module):
    """Diffuser's ``ResidualTemporalBlock``: two conv blocks, the time embedding added between
    them, and a 1x1-conv residual. (B, c_in, L), (B, time_dim) -> (B, c_out, L)."""

    def __init__(self, c_in: int, c_out: int, time_dim: int, kernel_size: int) -> None:
        super().__init__()
        self.block1 = _Conv1dBlock(c_in, c_out, kernel_size)
        self.block2 = _Conv1dBlock(c_out, c_out, kernel_size)
        self.time_proj = nn.Sequential(nn.Mish(), nn.Linear(time_dim, c_out))
        self.skip = nn.Conv1d(c_in, c_out, 1) if c_in != c_out else nn.Identity()

    def forward(self, x: Tensor, temb: Tensor) -> Tensor:
        h = self.block1(x) + self.time_proj(temb)[:, :, None]  # (B, c_out, L)
        return self.block2(h) + self.skip(x)


class TemporalUnetDenoiser(nn.Module):
    """eps_theta(x_t, t) as a temporal 1D-convolution U-Net (Diffuser's ``TemporalUnet``):
    (B, P, 2) normalised noisy trajectory + (B,) timesteps -> (B, P, 2) predicted noise. See the
    module docstring for the layout."""

    def __init__(self, config: DenoiserConfig) -> None:
        super().__init__()
        if config.architecture != "temporal_unet":
            raise ValueError(f"TemporalUnetDenoiser needs architecture 'temporal_unet', "
                             f"got {config.architecture!r}")
        self.config = config
        channels, k = config.unet_channels, config.unet_kernel_size
        time_dim = channels[0]
        self.time_mlp = nn.Sequential(nn.Linear(time_dim, 4 * time_dim), nn.Mish(),
                                      nn.Linear(4 * time_dim, time_dim))
        self.downs = nn.ModuleList()
        c_prev = 2
        for i, c in enumerate(channels):
            last = i == len(channels) - 1
            self.downs.append(nn.ModuleList([
                _ResidualTemporalBlock(c_prev, c, time_dim, k),
                _ResidualTemporalBlock(c, c, time_dim, k),
                nn.Identity() if last else nn.Conv1d(c, c, 3, stride=2, padding=1)]))
            c_prev = c
        self.mid = nn.ModuleList([_ResidualTemporalBlock(c_prev, c_prev, time_dim, k),
                                  _ResidualTemporalBlock(c_prev, c_prev, time_dim, k)])
        self.ups = nn.ModuleList()
        for c in reversed(channels[:-1]):
            self.ups.append(nn.ModuleList([
                nn.ConvTranspose1d(c_prev, c_prev, 4, stride=2, padding=1),
                _ResidualTemporalBlock(c_prev + c, c, time_dim, k),
                _ResidualTemporalBlock(c, c, time_dim, k)]))
            c_prev = c
        self.final = nn.Sequential(_Conv1dBlock(c_prev, c_prev, k), nn.Conv1d(c_prev, 2, 1))

    @property
    def length_multiple(self) -> int:
        """The U-Net runs on lengths that are a multiple of this (2^(levels - 1))."""
        return 2 ** (len(self.config.unet_channels) - 1)

    def forward(self, x: Tensor, t: Tensor | int) -> Tensor:
        """Predict the noise.

        Args:
            x: (B, P, 2) noisy normalised trajectories, 1 <= P <= max_horizon.
            t: (B,) long timesteps in 0..K-1 (or an int shared by the batch).
        Returns:
            eps: (B, P, 2).
        """
        t = check_inputs(x, t, self.config.max_horizon)
        B, P, _ = x.shape
        temb = self.time_mlp(sinusoidal_embedding(t, self.config.unet_channels[0]))  # (B, T)
        pad = -P % self.length_multiple
        h = x.transpose(1, 2)  # (B, 2, P)
        if pad:
            h = nn.functional.pad(h, (0, pad), mode="replicate")  # (B, 2, L), L = P + pad
        skips = []
        for block1, block2, down in self.downs:
            h = block2(block1(h, temb), temb)
            skips.append(h)  # (B, c_i, L / 2^i)
            h = down(h)
        for block in self.mid:
            h = block(h, temb)
        skips.pop()  # the deepest level feeds the middle directly
        for up, block1, block2 in self.ups:
            h = torch.cat([up(h), skips.pop()], dim=1)  # (B, c_{i+1} + c_i, L / 2^i)
            h = block2(block1(h, temb), temb)
        return self.final(h)[:, :, :P].transpose(1, 2)  # (B, P, 2)


def build_denoiser(config: DenoiserConfig) -> nn.Module:
    """The network ``config.architecture`` names, freshly initialised (torch's global RNG). It
    outputs ``config.prediction``; see :class:`EpsilonFromSample` for eps."""
    if config.architecture == "temporal_unet":
        return TemporalUnetDenoiser(config)
    return TransformerDenoiser(config)


class EpsilonFromSample(nn.Module):
    """An x_0-predicting network (``prediction="sample"``) presented as eps_theta, what the
    sampler and guidance expect: eps = (x_t - sqrt(alpha_bar_t) x0_hat) / sqrt(1 - alpha_bar_t).
    The DDIM step inverts this exactly, so its pred_x0 is the network's x0_hat.

    Args:
        model: the network, (B, P, 2), (B,) -> x0_hat (B, P, 2).
        alphas_cumprod: (K,) alpha_bar of the training schedule.
    """

    def __init__(self, model: nn.Module, alphas_cumprod: Tensor) -> None:
        super().__init__()
        self.model = model
        self.register_buffer("alphas_cumprod", alphas_cumprod.detach().clone().float(),
                             persistent=False)

    @property
    def config(self) -> DenoiserConfig:
        return self.model.config

    def forward(self, x: Tensor, t: Tensor | int, **kwargs: Any) -> Tensor:
        t = check_inputs(x, t, self.model.config.max_horizon)
        x0 = self.model(x, t, **kwargs)  # (B, P, 2)
        alpha_bar = self.alphas_cumprod[t].to(x.dtype)[:, None, None]  # (B, 1, 1)
        return (x - alpha_bar.sqrt() * x0) / (1 - alpha_bar).sqrt()


def as_noise_predictor(model: nn.Module, alphas_cumprod: Tensor) -> nn.Module:
    """``model`` itself if it predicts eps, else wrapped in :class:`EpsilonFromSample`."""
    if model.config.prediction == "sample":
        return EpsilonFromSample(model, alphas_cumprod.to(next(model.parameters()).device))
    return model


def count_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())
