"""Noise schedule and DDIM sampling step (paper Sec. II-B, Eqs. 1-2; Algorithm 2 line 6).

No network lives here: the scheduler holds the schedule tensors and does the arithmetic, so it can
be checked line by line against the equations and tested with a dummy denoiser (the layout of
huggingface/diffusers ``schedulers/scheduling_ddim.py``).

Symbols (code name <- paper / DDIM paper, Song et al. 2021, "Denoising Diffusion Implicit Models"):
    K                        num_train_timesteps, the number of forward diffusion steps
    t                        a timestep index in 0..K-1. The paper counts k = K..1 with x_K pure
                             noise; here t = k - 1 (diffusers convention), and "t = -1" is the
                             clean data x_0.
    beta_t                   betas[t]
    alpha_t = 1 - beta_t     alphas[t]
    alpha_bar_t = prod alpha alphas_cumprod[t]   (DDIM's "alpha_t" is this cumulative product)
    eps_theta(x_t, t)        the denoiser output ``eps`` (noise prediction; Algorithm 2's s_theta,
                             possibly with the guidance term already added)
    eta                      DDIM stochasticity: 0 deterministic DDIM, 1 DDPM-like ancestral
    sigma_t                  the std of the noise added in a reverse step (Eq. 1's sigma_t)

Forward process (DDPM, Ho et al. 2020, Eq. 4): q(x_t | x_0) = N(sqrt(alpha_bar_t) x_0,
(1 - alpha_bar_t) I), so ``x_t = sqrt(alpha_bar_t) x_0 + sqrt(1 - alpha_bar_t) eps``.

Beta schedules:
    cosine  Nichol & Dhariwal 2021 (improved DDPM, Eq. 17), s = 0.008, betas clipped to 0.999;
            the same as jannerm/diffuser's ``cosine_beta_schedule``.
    linear  Ho et al. 2020's 1e-4..0.02 over 1000 steps, rescaled by 1000 / K so that the
            terminal signal level does not depend on K (with the unscaled endpoints and K = 100,
            alpha_bar_{K-1} would still be ~0.36: not noise).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from enum import Enum
from typing import Any

import torch
from torch import Tensor, nn

DEFAULT_NUM_TRAIN_TIMESTEPS = 100  # K
DEFAULT_CLIP_SAMPLE = 1.0  # |pred_x0| bound in normalised units (the map-bounds normaliser's range)
_COSINE_S = 0.008  # improved-DDPM offset
_MAX_BETA = 0.999  # improved-DDPM clip, avoids a singular last step


def parse_choice(cls, value, what: str):
    """``cls(value)`` for a str Enum ``cls``; a ValueError naming ``what`` and the allowed
    values otherwise."""
    try:
        return cls(value)
    except ValueError:
        allowed = ", ".join(repr(m.value) for m in cls)
        raise ValueError(f"unknown {what} {value!r}; allowed: {allowed}") from None


class BetaSchedule(str, Enum):
    """Allowed beta schedules."""

    COSINE = "cosine"
    LINEAR = "linear"

    @classmethod
    def parse(cls, value: "str | BetaSchedule") -> "BetaSchedule":
        return parse_choice(cls, value, "beta schedule")


@dataclass(frozen=True, kw_only=True)
class ScheduleConfig:
    """The forward process a model was trained with (stored in every checkpoint).

    Attributes:
        num_train_timesteps: K, the number of forward diffusion steps.
        beta_schedule: "cosine" or "linear".
    """

    num_train_timesteps: int = DEFAULT_NUM_TRAIN_TIMESTEPS
    beta_schedule: str = BetaSchedule.COSINE.value

    def __post_init__(self) -> None:
        K = self.num_train_timesteps
        if isinstance(K, bool) or int(K) != K or K < 2:
            raise ValueError(f"num_train_timesteps (K) must be an integer >= 2, "
                             f"got {self.num_train_timesteps}")
        object.__setattr__(self, "num_train_timesteps", int(self.num_train_timesteps))
        object.__setattr__(self, "beta_schedule", BetaSchedule.parse(self.beta_schedule).value)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "ScheduleConfig":
        return cls(**d)


def make_betas(config: ScheduleConfig) -> Tensor:
    """(K,) float64 betas of the configured schedule."""
    K = config.num_train_timesteps
    if config.beta_schedule == BetaSchedule.COSINE.value:
        steps = torch.arange(K + 1, dtype=torch.float64) / K
        alpha_bar = torch.cos((steps + _COSINE_S) / (1 + _COSINE_S) * math.pi / 2) ** 2
        betas = 1 - alpha_bar[1:] / alpha_bar[:-1]
        return betas.clamp(0.0, _MAX_BETA)
    scale = 1000.0 / K
    return torch.linspace(scale * 1e-4, min(scale * 2e-2, _MAX_BETA), K, dtype=torch.float64)


@dataclass(frozen=True)
class DDIMStepOutput:
    """Result of one reverse step.

    Attributes:
        prev_sample: (B, P, 2) x_{t_prev}, the sample for the next (less noisy) timestep.
        pred_x0: (B, P, 2) the clean trajectory x_0 predicted at this step (after clipping).
    """

    prev_sample: Tensor
    pred_x0: Tensor


class NoiseSchedule(nn.Module):
    """The DDPM forward process q(x_t | x_0) with K steps; schedule tensors are buffers, so
    ``.to(device)`` moves them with the model."""

    betas: Tensor
    alphas: Tensor
    alphas_cumprod: Tensor

    def __init__(self, config: ScheduleConfig | None = None) -> None:
        super().__init__()
        self.config = config or ScheduleConfig()
        betas = make_betas(self.config)
        alphas = 1.0 - betas
        # float64 for the product, float32 for use; not persistent: rebuilt from the config.
        self.register_buffer("betas", betas.float(), persistent=False)
        self.register_buffer("alphas", alphas.float(), persistent=False)
        self.register_buffer("alphas_cumprod", torch.cumprod(alphas, 0).float(), persistent=False)

    @property
    def num_train_timesteps(self) -> int:
        """K."""
        return self.config.num_train_timesteps

    def _at(self, values: Tensor, t: Tensor | int, like: Tensor) -> Tensor:
        """values[t] shaped to broadcast against ``like`` (B, ...): t is an int or (B,) long."""
        t = torch.as_tensor(t, device=values.device, dtype=torch.long)
        # checked where it costs no device synchronisation (CPU schedules, the tests)
        if t.device.type == "cpu" and ((t < 0).any() or (t >= self.num_train_timesteps).any()):
            raise ValueError(f"timesteps must lie in 0..{self.num_train_timesteps - 1}")
        out = values[t].to(device=like.device, dtype=like.dtype)
        return out.reshape(out.shape + (1,) * (like.dim() - out.dim()))

    def marginal(self, x0: Tensor, t: Tensor | int) -> tuple[Tensor, Tensor]:
        """Closed form of q(x_t | x_0) = N(mean, std^2 I).

        Args:
            x0: (B, P, 2) clean samples (normalised).
            t: (B,) long or int timestep in 0..K-1.
        Returns:
            mean (B, P, 2) = sqrt(alpha_bar_t) x0, std (B, 1, 1) = sqrt(1 - alpha_bar_t).
        """
        alpha_bar = self._at(self.alphas_cumprod, t, x0)
        return alpha_bar.sqrt() * x0, (1 - alpha_bar).sqrt()

    def add_noise(self, x0: Tensor, noise: Tensor, t: Tensor | int) -> Tensor:
        """Sample q(x_t | x_0): x_t = sqrt(alpha_bar_t) x0 + sqrt(1 - alpha_bar_t) noise.

        x0, noise: (B, P, 2); t: (B,) long or int. Returns x_t (B, P, 2).
        """
        if noise.shape != x0.shape:
            raise ValueError(f"noise {tuple(noise.shape)} must have the shape of x0 "
                             f"{tuple(x0.shape)}")
        mean, std = self.marginal(x0, t)
        return mean + std * noise

    def forward_step(self, x_prev: Tensor, noise: Tensor, t: Tensor | int) -> Tensor:
        """One Markov step of the forward chain, q(x_t | x_{t-1}) = N(sqrt(alpha_t) x_{t-1},
        beta_t I) (x_{-1} = x_0). Used to check :meth:`add_noise` against the chain."""
        alpha = self._at(self.alphas, t, x_prev)
        return alpha.sqrt() * x_prev + (1 - alpha).sqrt() * noise


class DDIMScheduler(NoiseSchedule):
    """DDIM reverse process over a subset of the K training timesteps.

    Usage::

        scheduler.set_timesteps(10)
        for t in scheduler.timesteps:
            eps = model(x, t)                       # (+ omega * grad J for guidance)
            x = scheduler.step(eps, t, x, eta=0.0, generator=g).prev_sample

    Timesteps are spaced "trailing" (Lin et al. 2024, "Common diffusion noise schedules and
    sample steps are flawed", Table 2): the first step is always t = K - 1 (the noisiest, where
    sampling starts from N(0, I)) and the last step jumps to the clean data (alpha_bar = 1).

    Args:
        config: the forward process (must match the model's training).
        clip_sample: bound for |pred_x0| in normalised units, or None for no clipping. Needed
            with eps-prediction: at t = K - 1 the cosine schedule has alpha_bar ~ 2e-7, so an
            eps error of 1e-3 moves pred_x0 by ~2 (1 / sqrt(alpha_bar) amplification); without
            the clip a barely trained model's samples explode. When it clips, eps is re-derived
            from the clipped pred_x0 (diffusers' ``use_clipped_model_output=True``), which keeps
            x bounded when a guidance gradient is added to eps at the noisiest steps (keeping
            the raw eps instead pushed guided oracle samples onto the clip bound).
    """

    def __init__(self, config: ScheduleConfig | None = None, *,
                 clip_sample: float | None = DEFAULT_CLIP_SAMPLE) -> None:
        super().__init__(config)
        if clip_sample is not None and not clip_sample > 0:
            raise ValueError(f"clip_sample must be positive or None, got {clip_sample}")
        self.clip_sample = clip_sample
        self._timesteps: tuple[int, ...] = ()
        self._prev: dict[int, int] = {}

    @property
    def timesteps(self) -> tuple[int, ...]:
        """The sampling timesteps, noisiest first (set by :meth:`set_timesteps`)."""
        return self._timesteps

    @property
    def num_inference_steps(self) -> int:
        return len(self._timesteps)

    def set_timesteps(self, num_inference_steps: int) -> tuple[int, ...]:
        """Choose n sampling steps, 1 <= n <= K: t_i = round(K - i K / n) - 1, i = 0..n-1."""
        K = self.num_train_timesteps
        n = num_inference_steps
        if int(n) != n or not 1 <= n <= K:
            raise ValueError(f"num_inference_steps must be an integer in 1..K={K}, got {n}")
        n = int(n)
        ts = [int(round(K - i * K / n)) - 1 for i in range(n)]
        if len(set(ts)) != n:  # cannot happen for n <= K, but the step below relies on it
            raise AssertionError(f"duplicate timesteps {ts}")
        self._timesteps = tuple(ts)
        self._prev = {t: (ts[i + 1] if i + 1 < n else -1) for i, t in enumerate(ts)}
        return self._timesteps

    def last_timesteps(self, n: int) -> tuple[int, ...]:
        """The last n timesteps of the current schedule, noisiest first (0 <= n <= the number
        of steps): where a warm-started sample, noised to the first of them, is denoised."""
        if not self._timesteps:
            raise RuntimeError("call set_timesteps(n) before last_timesteps()")
        S = len(self._timesteps)
        if isinstance(n, bool) or int(n) != n or not 0 <= n <= S:
            raise ValueError(f"the last n timesteps need n in 0..{S} (the schedule's steps), "
                             f"got {n}")
        return self._timesteps[S - int(n):]

    def warm_steps(self, fraction: float) -> int:
        """How many of the current schedule's steps a warm start of ``fraction`` (0..1 of the
        schedule, counted in steps) runs: round(fraction * S)."""
        if not self._timesteps:
            raise RuntimeError("call set_timesteps(n) before warm_steps()")
        if not 0.0 <= fraction <= 1.0:
            raise ValueError(f"a warm-start fraction must lie in 0..1, got {fraction}")
        return int(round(fraction * len(self._timesteps)))

    def previous_timestep(self, t: int) -> int:
        """The timestep after t in the current schedule (-1 = the clean data)."""
        if not self._timesteps:
            raise RuntimeError("call set_timesteps(n) before step()")
        try:
            return self._prev[int(t)]
        except KeyError:
            raise ValueError(f"timestep {t} is not in the current schedule "
                             f"{self._timesteps}") from None

    def step(self, eps: Tensor, t: int, x: Tensor, *, eta: float = 0.0,
             generator: torch.Generator | None = None) -> DDIMStepOutput:
        """One DDIM update x_t -> x_{t_prev} (Song et al. 2021, Eq. 12).

        Args:
            eps: (B, P, 2) predicted noise eps_theta(x_t, t) (guidance already added).
            t: the current timestep (an element of :attr:`timesteps`).
            x: (B, P, 2) the current sample x_t.
            eta: 0 deterministic DDIM ... 1 DDPM-like.
            generator: randomness for the eta > 0 noise (on x's device).
        """
        if eps.shape != x.shape:
            raise ValueError(f"eps {tuple(eps.shape)} and x {tuple(x.shape)} differ in shape")
        if eta < 0:
            raise ValueError(f"eta must be >= 0, got {eta}")
        # 1. previous timestep t_prev (-1 means x_0)
        t = int(t)
        t_prev = self.previous_timestep(t)

        # 2. alpha_bar_t and alpha_bar_{t_prev} (DDIM's alpha_t, alpha_{t-1}); alpha_bar_{-1} = 1
        alpha_bar_t = self.alphas_cumprod[t].to(x.dtype)
        alpha_bar_prev = (self.alphas_cumprod[t_prev].to(x.dtype) if t_prev >= 0
                          else torch.ones((), dtype=x.dtype, device=alpha_bar_t.device))
        beta_bar_t = 1 - alpha_bar_t  # 1 - alpha_bar_t

        # 3. predicted x_0 ("predicted x_0" in Eq. 12):
        #    x0_hat = (x_t - sqrt(1 - alpha_bar_t) eps) / sqrt(alpha_bar_t)
        pred_x0 = (x - beta_bar_t.sqrt() * eps) / alpha_bar_t.sqrt()

        # 4. clip x0_hat to the normalised range and re-derive eps from it:
        #    eps = (x_t - sqrt(alpha_bar_t) x0_hat) / sqrt(1 - alpha_bar_t)
        if self.clip_sample is not None:
            pred_x0 = pred_x0.clamp(-self.clip_sample, self.clip_sample)
            eps = (x - alpha_bar_t.sqrt() * pred_x0) / beta_bar_t.sqrt()

        # 5. sigma_t(eta) = eta sqrt((1 - a_prev) / (1 - a_t)) sqrt(1 - a_t / a_prev)   (Eq. 16)
        variance = (1 - alpha_bar_prev) / beta_bar_t * (1 - alpha_bar_t / alpha_bar_prev)
        sigma = eta * variance.clamp(min=0).sqrt()

        # 6. "direction pointing to x_t": sqrt(1 - a_prev - sigma^2) eps
        direction = (1 - alpha_bar_prev - sigma ** 2).clamp(min=0).sqrt() * eps

        # 7. x_{t_prev} = sqrt(a_prev) x0_hat + direction + sigma z,  z ~ N(0, I)   (Eq. 12)
        prev_sample = alpha_bar_prev.sqrt() * pred_x0 + direction
        if eta > 0 and t_prev >= 0:
            z = torch.randn(x.shape, generator=generator, device=x.device, dtype=x.dtype)
            prev_sample = prev_sample + sigma * z
        return DDIMStepOutput(prev_sample=prev_sample, pred_x0=pred_x0)
