"""Conditional sampling with inpainting and cost guidance (Algorithm 2 lines 1-9; Eqs. 1-2).

The loop, per DDIM timestep t_k (noisiest first), in the NORMALISED space z:

    z_K ~ N(0, I);  z_K <- inpaint(z_K)                                     (line 2)
    for k:
        eps = eps_theta(z_k, t_k)                                           (line 5, network)
        if guided at k:
            J, dJ/dx = guide(unnormalize(z_k))     # cost in metres         (line 4)
            eps <- eps + omega * dJ/dz,  dJ/dz = dJ/dx * scale              (line 5)
        z_{k-1}, z0_hat = DDIM(eps, t_k, z_k, eta)                          (line 6)
        z_{k-1} <- inpaint(z_{k-1})
    return unnormalize(z_0)                                                 (line 8)

Gradient space: the guide differentiates J with respect to waypoints in metres; the sampler needs
the gradient with respect to the normalised sample it updates. With x = z * scale + centre the
chain rule gives dJ/dz = dJ/dx * scale per axis (:meth:`Normalizer.grad_to_normalized`), so omega
acts on normalised units (the same omega gives a larger step on a larger map for the same J).

Sign: eps-prediction, so adding +omega grad J to eps lowers J: the predicted x_0 is
(z - sqrt(1 - alpha_bar) eps) / sqrt(alpha_bar), which moves by -omega sqrt(1 - alpha_bar) /
sqrt(alpha_bar) grad J.

Gradients: without a guide the whole loop runs under ``torch.inference_mode()``; with a guide it
runs under ``torch.no_grad()`` and only the guide's J evaluation runs under ``enable_grad`` on a
detached copy of the sample, so no graph ever reaches the network parameters.

Warm start (ours, for re-planning; ``warm_start`` and ``warm_steps``): instead of z_K ~ N(0, I),
a known trajectory x_w (e.g. the rest of the previous plan) is normalised, inpainted and noised
to the timestep t_j of the last ``warm_steps`` DDIM steps by the forward process (SDEdit, Meng et
al. 2022): z_{t_j} = sqrt(alpha_bar_{t_j}) x_w + sqrt(1 - alpha_bar_{t_j}) eps, eps ~ N(0, I)
(:meth:`NoiseSchedule.add_noise`), then only those steps run, inpainting as above. 0 steps
returns x_w with its conditions imposed; all steps is sampling from (almost) pure noise.

Batching: ``batch`` rows are denoised in one forward pass per step. For N candidates of B
problems, give per-row conditions (B * N, 2), e.g. from
:func:`~ecahd_core.diffusion.conditioning.expand_conditions` (problem-major rows).
"""
from __future__ import annotations

from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import torch
from torch import Tensor, nn

from ecahd_core.diffusion.conditioning import apply_conditioning, resolve_index
from ecahd_core.diffusion.denoiser import Denoiser
from ecahd_core.diffusion.guides import Guide, GuideOutput
from ecahd_core.diffusion.normalizer import Normalizer
from ecahd_core.diffusion.scheduler import DDIMScheduler
from ecahd_core.errors import TrajectoryError
from ecahd_core.threads import PRECISION_CHOICES

if TYPE_CHECKING:
    from ecahd_core.diffusion.training import Checkpoint

DEFAULT_NUM_STEPS = 10  # DDIM sampling steps (of K = 100 training steps)
DEFAULT_GUIDANCE_WEIGHT = 1.0  # omega
DEFAULT_MAX_GUIDE_NORM = 1.0  # cap of the per-waypoint guidance gradient norm (eps units)
GUIDANCE_SPACES = ("eps", "x0")

GuideSteps = Callable[[int, int], bool] | Collection[int]
"""Where guidance is applied: a callable ``(step_index, timestep) -> bool`` or a collection of
step indices (0 = the first, noisiest step; negative counts from the last)."""


@dataclass(frozen=True)
class SampleOutput:
    """Result of :func:`sample`.

    Attributes:
        trajectories: (B, P, 2) [m] the final samples, conditions exact.
        normalized: (B, P, 2) the same in the normalised space.
        timesteps: the DDIM timesteps run, noisiest first (S of them; with a warm start the
            last S of the schedule).
        guided_steps: the step indices at which guidance was applied.
        guide_costs: (G, B) J at each guided step (evaluated on z_k), or None without a guide.
        intermediates: (S + 1, B, P, 2) [m] z_K then every z after each step, or None.
        pred_x0: (S, B, P, 2) [m] the x_0 predicted at each step, or None.
    """

    trajectories: Tensor
    normalized: Tensor
    timesteps: tuple[int, ...]
    guided_steps: tuple[int, ...] = ()
    guide_costs: Tensor | None = None
    intermediates: Tensor | None = None
    pred_x0: Tensor | None = None


def _device_of(model: Any, scheduler: DDIMScheduler) -> torch.device:
    """The model's device (from its parameters), else the scheduler's."""
    if isinstance(model, nn.Module):
        for p in model.parameters():
            return p.device
    return scheduler.alphas_cumprod.device


def _guided_predicate(guide_steps: GuideSteps | None, n: int) -> Callable[[int, int], bool]:
    if guide_steps is None:
        return lambda i, t: True
    if callable(guide_steps):
        return guide_steps
    indices = set()
    for i in guide_steps:
        if not -n <= int(i) < n:
            raise ValueError(f"guide step index {i} is outside 0..{n - 1} ({n} sampling steps)")
        indices.add(int(i) % n)
    return lambda i, t: i in indices


def _condition_tensors(conditions: Mapping[int, Any], batch: int, horizon: int,
                       device: torch.device) -> dict[int, Tensor]:
    """{index: (2,) or (B, 2) float32 [m]} on ``device``, validated."""
    out = {}
    for index, value in conditions.items():
        resolve_index(int(index), horizon)
        value = torch.as_tensor(value, dtype=torch.float32, device=device)
        if value.shape not in ((2,), (batch, 2)):
            raise TrajectoryError(f"condition {index} must have shape (2,) or ({batch}, 2) "
                                  f"[m], got {tuple(value.shape)}")
        if not torch.isfinite(value).all():
            raise TrajectoryError(f"condition {index} is not finite: {value.tolist()}")
        out[int(index)] = value
    return out


def sample(model: Denoiser, scheduler: DDIMScheduler, normalizer: Normalizer, *, batch: int,
           horizon: int, conditions: Mapping[int, Any], num_steps: int = DEFAULT_NUM_STEPS,
           eta: float = 0.0, generator: torch.Generator | None = None,
           guide: Guide | None = None, guidance_weight: float = DEFAULT_GUIDANCE_WEIGHT,
           guide_steps: GuideSteps | None = None, return_intermediates: bool = False,
           model_kwargs: Mapping[str, Any] | None = None,
           max_guide_norm: float | None = DEFAULT_MAX_GUIDE_NORM,
           guidance_space: str = "eps", warm_start: Any = None,
           warm_steps: int | None = None) -> SampleOutput:
    """Sample ``batch`` trajectories of ``horizon`` waypoints with inpainting and optional guidance.

    Args:
        model: eps_theta, called as ``model(z (B, P, 2), t (B,), **model_kwargs)``; put it in
            eval mode.
        scheduler: the DDIM scheduler of the model's training schedule.
        normalizer: the model's normaliser (metres <-> normalised).
        batch: B, the number of rows sampled together.
        horizon: P, waypoints per trajectory.
        conditions: {index: (B, 2) or (2,) [m]}, e.g. {0: start, -1: goal}.
        num_steps: DDIM steps, 1..K.
        eta: DDIM stochasticity (0 = deterministic given the initial noise).
        generator: randomness for the initial noise and eta > 0 (on the model's device).
        guide: cost J as a :class:`~ecahd_core.diffusion.guides.Guide` (metres), or None.
        guidance_weight: omega of Algorithm 2 line 5.
        max_guide_norm: the guidance gradient dJ/dz of each row is scaled down (never up) so
            that its largest per-waypoint norm is at most this; None leaves it raw. J sums
            thousands of cost-map lookups, so raw gradients reach 1e3-1e4 in eps units and any
            fixed omega either does nothing in free space or throws samples to the clip bound
            near walls; capped, omega is the largest eps shift guidance may cause per step.
        guidance_space: "eps" (Algorithm 2 line 5 as written: J at the noisy sample z_k, eps
            shifted by omega * dJ/dz) or "x0": J evaluated at the denoiser's clean estimate
            x0_hat (inpainted, in metres), and eps shifted by omega_k * dJ/dz with
            omega_k = omega * sqrt(alpha_bar_k / (1 - alpha_bar_k)), so that every step moves
            x0_hat by omega (times the capped gradient) instead of a vanishing amount at the
            last, least noisy steps. Same form eps + omega_k grad J, a step-dependent weight.
        guide_steps: at which steps to guide (default: all), see :data:`GuideSteps`.
        return_intermediates: also return every z_k and predicted x_0.
        model_kwargs: extra model inputs, e.g. {"map_feature": (1, d_model)}.
        warm_start: (P, 2) or (B, P, 2) [m] a trajectory to start from instead of pure noise
            (see the module docstring), or None.
        warm_steps: with ``warm_start``, how many of the last DDIM steps of the ``num_steps``
            schedule to run (0..num_steps); the start is noised to the first of them.
    Returns:
        :class:`SampleOutput`.
    """
    if guidance_space not in GUIDANCE_SPACES:
        raise ValueError(f"guidance_space {guidance_space!r} is not one of {list(GUIDANCE_SPACES)}")
    if batch < 1 or horizon < 2:
        raise ValueError(f"need batch >= 1 and horizon >= 2, got batch={batch}, horizon={horizon}")
    if (warm_start is None) != (warm_steps is None):
        raise ValueError("warm_start and warm_steps go together")
    device = _device_of(model, scheduler)
    model_kwargs = dict(model_kwargs or {})
    timesteps = scheduler.set_timesteps(num_steps)
    if warm_steps is not None:
        timesteps = scheduler.last_timesteps(warm_steps)
    is_guided = _guided_predicate(guide_steps, len(timesteps)) if guide is not None else None
    # No graph at all without a guide; with one, only the J evaluation below re-enables grad.
    context = torch.inference_mode() if guide is None else torch.no_grad()

    with context:
        cond_m = _condition_tensors(conditions, batch, horizon, device)  # [m]
        cond = {i: normalizer.normalize(v) for i, v in cond_m.items()}  # normalised

        def to_metres(zk: Tensor) -> Tensor:  # (B, P, 2) -> (B, P, 2) [m]
            # conditions re-imposed in metres: bit-exact, unlike the float32 round trip
            return apply_conditioning(normalizer.unnormalize(zk), cond_m)

        if warm_start is None:
            z = torch.randn((batch, horizon, 2), generator=generator, device=device)  # z_K
        else:
            z = _warm_start_sample(warm_start, timesteps, scheduler, normalizer, cond_m,
                                   batch, horizon, device, generator)  # z_{t_j}
        z = apply_conditioning(z, cond)
        xs, x0s, costs, guided = [z], [], [], []
        t_batches = torch.tensor(timesteps, dtype=torch.long, device=device)[:, None]  # (S, 1)
        for i, t in enumerate(timesteps):
            t_batch = t_batches[i].expand(batch)  # (B,)
            eps = model(z, t_batch, **model_kwargs)  # (B, P, 2)
            if is_guided is not None and is_guided(i, t):
                weight = guidance_weight
                at = z
                if guidance_space == "x0":
                    a_bar = scheduler.alphas_cumprod[t].to(z.dtype)
                    at = (z - (1 - a_bar).sqrt() * eps) / a_bar.sqrt()  # x0_hat (normalised)
                    if scheduler.clip_sample is not None:
                        at = at.clamp(-scheduler.clip_sample, scheduler.clip_sample)
                    weight = guidance_weight * float((a_bar / (1 - a_bar)).sqrt())
                out = _evaluate_guide(guide, to_metres(at), batch, horizon)
                g = normalizer.grad_to_normalized(out.grad)  # dJ/dz (B, P, 2)
                if max_guide_norm is not None:
                    peak = g.norm(dim=-1).amax(dim=-1).clamp_min(1e-12)  # (B,)
                    g = g * (max_guide_norm / peak).clamp(max=1.0)[:, None, None]
                eps = eps + weight * g
                costs.append(out.cost)
                guided.append(i)
            step = scheduler.step(eps, t, z, eta=eta, generator=generator)
            z = apply_conditioning(step.prev_sample, cond)
            if return_intermediates:
                xs.append(z)
                x0s.append(apply_conditioning(step.pred_x0, cond))
        return SampleOutput(
            trajectories=to_metres(z), normalized=z,
            timesteps=timesteps, guided_steps=tuple(guided),
            guide_costs=torch.stack(costs) if costs else None,
            intermediates=torch.stack([to_metres(v) for v in xs]) if return_intermediates else None,
            pred_x0=torch.stack([to_metres(v) for v in x0s]) if return_intermediates else None)


def _warm_start_sample(warm_start: Any, timesteps: tuple[int, ...], scheduler: DDIMScheduler,
                       normalizer: Normalizer, cond_m: Mapping[int, Tensor], batch: int,
                       horizon: int, device: torch.device,
                       generator: torch.Generator | None) -> Tensor:
    """The warm start x_w (P, 2) or (B, P, 2) [m], conditions imposed, normalised and noised
    to ``timesteps[0]`` (q(x_t | x_0)); unchanged when no step is left. -> (B, P, 2)."""
    x = torch.as_tensor(warm_start, dtype=torch.float32, device=device)
    if x.shape not in ((horizon, 2), (batch, horizon, 2)):
        raise TrajectoryError(f"warm_start must have shape ({horizon}, 2) or "
                              f"({batch}, {horizon}, 2) [m], got {tuple(x.shape)}")
    if not torch.isfinite(x).all():
        raise TrajectoryError("warm_start is not finite")
    x0 = normalizer.normalize(apply_conditioning(x.expand(batch, horizon, 2), cond_m))
    if not timesteps:
        return x0
    noise = torch.randn((batch, horizon, 2), generator=generator, device=device)
    return scheduler.add_noise(x0, noise, timesteps[0])


def _evaluate_guide(guide: Guide, traj_m: Tensor, batch: int, horizon: int) -> GuideOutput:
    """J and dJ/dx on a detached copy of the sample, with gradients enabled only here."""
    with torch.enable_grad():
        out = guide(traj_m.detach().clone())
    if out.cost.shape != (batch,) or out.grad.shape != (batch, horizon, 2):
        raise TrajectoryError(f"guide returned cost {tuple(out.cost.shape)} and grad "
                              f"{tuple(out.grad.shape)}; expected ({batch},) and "
                              f"({batch}, {horizon}, 2)")
    if not torch.isfinite(out.grad).all():
        raise TrajectoryError("guide returned a non-finite gradient")
    return GuideOutput(cost=out.cost.detach(), grad=out.grad.detach())


@dataclass(frozen=True, kw_only=True)
class SamplerConfig:
    """Sampling settings of a :class:`DiffusionSampler`.

    Attributes:
        num_steps: DDIM steps (1..K).
        eta: DDIM stochasticity.
        guidance_weight: omega.
        max_guide_norm: cap of the per-waypoint guidance gradient norm (see :func:`sample`).
        guide_last: guide only the last this-many DDIM steps (None: all steps).
        guidance_space: "eps" or "x0" (see :func:`sample`).
        precision: "fp32", "bf16" or "auto": what a Transformer denoiser's encoder layers compute
            in (``TransformerDenoiser.set_inference_precision``; other denoisers stay float32).
            On an AVX512-BF16 CPU bf16 made the shipped SD's best-of-10 1.3-1.4x and a batch of
            256 plans 1.9x as fast, with the same plan quality (docs/RESULTS.md); "auto" is
            bf16 only where the CPU computes it natively.
    """

    num_steps: int = DEFAULT_NUM_STEPS
    eta: float = 0.0
    guidance_weight: float = DEFAULT_GUIDANCE_WEIGHT
    max_guide_norm: float | None = DEFAULT_MAX_GUIDE_NORM
    guide_last: int | None = None
    guidance_space: str = "eps"
    precision: str = "fp32"

    def __post_init__(self) -> None:
        if self.precision not in PRECISION_CHOICES:
            raise ValueError(f"precision must be one of {', '.join(PRECISION_CHOICES)}, "
                             f"got {self.precision!r}")
        if int(self.num_steps) != self.num_steps or self.num_steps < 1:
            raise ValueError(f"num_steps must be a positive integer, got {self.num_steps}")
        if self.eta < 0:
            raise ValueError(f"eta must be >= 0, got {self.eta}")


class DiffusionSampler:
    """A model with its scheduler, normaliser and sampling settings: ``sampler.sample(...)``.

    Args:
        model: eps_theta (eval mode).
        scheduler: DDIM scheduler of the model's training schedule (moved to the model's device).
        normalizer: the model's normaliser.
        config: sampling settings.
    """

    def __init__(self, model: Denoiser, scheduler: DDIMScheduler, normalizer: Normalizer,
                 config: SamplerConfig | None = None) -> None:
        self.model = model
        self.scheduler = scheduler.to(_device_of(model, scheduler))
        self.normalizer = normalizer
        self.config = config or SamplerConfig()
        setter = getattr(model, "set_inference_precision", None)
        self.precision = setter(self.config.precision) if setter is not None else "fp32"

    @classmethod
    def from_checkpoint(cls, checkpoint: "Checkpoint", *, device: torch.device | str = "cpu",
                        config: SamplerConfig | None = None) -> "DiffusionSampler":
        """The EMA model of a loaded checkpoint, in eval mode on ``device``."""
        return cls(checkpoint.build_model(device=device), checkpoint.build_scheduler(),
                   checkpoint.normalizer, config)

    @property
    def device(self) -> torch.device:
        return _device_of(self.model, self.scheduler)

    def steps(self, warm_start: Any, warm_fraction: float | None,
              guide_steps: GuideSteps | None) -> tuple[int | None, GuideSteps | None]:
        """(warm steps, guided steps) of a call: the last ``warm_fraction`` of the schedule
        for a warm start (None: all steps from noise), and ``config.guide_last`` as steps
        where ``guide_steps`` is not given."""
        warm_steps = None
        if (warm_start is None) != (warm_fraction is None):
            raise ValueError("warm_start and warm_fraction go together")
        if warm_fraction is not None:
            self.scheduler.set_timesteps(self.config.num_steps)
            warm_steps = self.scheduler.warm_steps(warm_fraction)
        if guide_steps is None and self.config.guide_last:
            last = self.config.guide_last  # of the schedule: a warm start may run fewer steps
            last = last if warm_steps is None else min(last, warm_steps)
            guide_steps = set(range(-last, 0)) if last else None
        return warm_steps, guide_steps

    def sample(self, *, batch: int, horizon: int, conditions: Mapping[int, Any],
               generator: torch.Generator | None = None, guide: Guide | None = None,
               guide_steps: GuideSteps | None = None, return_intermediates: bool = False,
               model_kwargs: Mapping[str, Any] | None = None, warm_start: Any = None,
               warm_fraction: float | None = None) -> SampleOutput:
        """:func:`sample` with this sampler's model and settings. A warm start (``warm_start``
        (P, 2) or (B, P, 2) [m]) runs the last ``warm_fraction`` (0..1) of the DDIM schedule."""
        warm_steps, guide_steps = self.steps(warm_start, warm_fraction, guide_steps)
        return sample(self.model, self.scheduler, self.normalizer, batch=batch, horizon=horizon,
                      conditions=conditions, num_steps=self.config.num_steps, eta=self.config.eta,
                      generator=generator, guide=guide,
                      guidance_weight=self.config.guidance_weight,
                      guide_steps=guide_steps,
                      max_guide_norm=self.config.max_guide_norm,
                      guidance_space=self.config.guidance_space,
                      return_intermediates=return_intermediates, model_kwargs=model_kwargs,
                      warm_start=warm_start, warm_steps=warm_steps)
