"""Sampling loop (inpainting, guidance, batching) and its parts: normaliser, conditioning,
the Transformer and temporal U-Net denoisers."""
import pytest
import torch

from ecahd_core.diffusion.conditioning import (apply_conditioning, condition_mask,
                                               expand_conditions)
from ecahd_core.diffusion.denoiser import (DenoiserConfig, EpsilonFromSample,
                                           TemporalUnetDenoiser, TransformerDenoiser,
                                           as_noise_predictor, build_denoiser)
from ecahd_core.diffusion.guides import CostGuide, GuideOutput
from ecahd_core.diffusion.normalizer import Normalizer
from ecahd_core.diffusion.sampler import DiffusionSampler, SamplerConfig, sample
from ecahd_core.diffusion.scheduler import DDIMScheduler
from ecahd_core.errors import TrajectoryError

# A 4 m x 2 m map: centre (2, 1), scale (2, 1) -- anisotropic on purpose (chain rule).
NORMALIZER = Normalizer.from_bounds(0.0, 0.0, 4.0, 2.0)


def tiny_model(**kw):
    torch.manual_seed(0)
    cfg = DenoiserConfig(max_horizon=10, d_model=32, n_layers=2, n_heads=4, **kw)
    return TransformerDenoiser(cfg).eval()


class OracleDenoiser:
    """Knows the clean trajectory x0 (normalised, (B, P, 2)) and returns the exact noise."""

    def __init__(self, scheduler, x0):
        self.scheduler, self.x0, self.calls = scheduler, x0, []

    def __call__(self, x, t):
        self.calls.append(tuple(x.shape))
        a = self.scheduler.alphas_cumprod[t][:, None, None]
        return (x - a.sqrt() * self.x0) / (1 - a).sqrt()


# ------------------------------------------------------------------------------- normaliser
def test_normalizer_bounds_round_trip_and_dict():
    n = NORMALIZER
    corners = torch.tensor([[0.0, 0.0], [4.0, 2.0], [2.0, 1.0]])
    torch.testing.assert_close(n.normalize(corners),
                               torch.tensor([[-1.0, -1.0], [1.0, 1.0], [0.0, 0.0]]))
    x = torch.randn(3, 5, 2)
    torch.testing.assert_close(n.unnormalize(n.normalize(x)), x)
    assert Normalizer.from_dict(n.to_dict()) == n
    with pytest.raises(ValueError, match="scale"):
        Normalizer(centre=(0, 0), scale=(1, 0))
    with pytest.raises(ValueError, match="xmax > xmin"):
        Normalizer.from_bounds(1, 0, 1, 1)


def test_normalizer_gradient_chain_rule_matches_autograd():
    z = torch.randn(2, 4, 2, requires_grad=True)
    cost = lambda x: (x[..., 0] ** 2 + 3 * x[..., 1]).sum()  # noqa: E731  J in metres
    (dz,) = torch.autograd.grad(cost(NORMALIZER.unnormalize(z)), z)
    x = NORMALIZER.unnormalize(z).detach().requires_grad_(True)
    (dx,) = torch.autograd.grad(cost(x), x)
    torch.testing.assert_close(NORMALIZER.grad_to_normalized(dx), dz)


# ----------------------------------------------------------------------------- conditioning
def test_apply_conditioning_is_pure_and_takes_negative_indices():
    x = torch.zeros(3, 5, 2)
    goal = torch.tensor([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]])
    out = apply_conditioning(x, {0: torch.tensor([9.0, 8.0]), -1: goal})
    assert torch.equal(x, torch.zeros(3, 5, 2))  # input untouched
    assert torch.equal(out[:, 0], torch.tensor([[9.0, 8.0]] * 3))
    assert torch.equal(out[:, 4], goal)
    assert torch.equal(out[:, 1:4], torch.zeros(3, 3, 2))
    assert condition_mask(5, (0, -1)).tolist() == [True, False, False, False, True]
    with pytest.raises(TrajectoryError, match="outside a horizon of 5"):
        apply_conditioning(x, {5: goal})
    with pytest.raises(TrajectoryError, match=r"\(2,\) or \(3, 2\)"):
        apply_conditioning(x, {0: torch.zeros(2, 2)})


def test_expand_conditions_is_problem_major():
    starts = torch.tensor([[0.0, 0.0], [1.0, 1.0]])
    out = expand_conditions({0: starts, -1: torch.tensor([5.0, 5.0])}, 3)
    assert out[0].tolist() == [[0.0, 0.0]] * 3 + [[1.0, 1.0]] * 3
    assert out[-1].tolist() == [5.0, 5.0]


# -------------------------------------------------------------------------------- denoiser
@pytest.mark.parametrize("horizon", [2, 5, 10])
def test_denoiser_handles_every_horizon_up_to_max(horizon):
    model = tiny_model()
    eps = model(torch.randn(3, horizon, 2), torch.tensor([0, 50, 99]))
    assert eps.shape == (3, horizon, 2)
    with pytest.raises(ValueError, match="max_horizon"):
        model(torch.randn(3, 11, 2), 5)


def test_denoiser_inference_path_is_the_modules_bit_for_bit():
    # without gradients in eval mode the encoder runs the fused layer kernel directly; the
    # module path (what training and gradient calls use) gives the same bits
    model = tiny_model()
    x, t = torch.randn(4, 7, 2), torch.tensor([0, 30, 60, 99])
    with torch.inference_mode():
        fast = model(x, t)
    module = TransformerDenoiser(model.config).eval()
    module.load_state_dict(model.state_dict())
    module._fast_encoder_args = lambda: None  # force the modules
    with torch.no_grad():
        assert torch.equal(module(x, t), fast)
        assert torch.equal(model(x, t), fast)  # no_grad takes the fast path too
    calls = []
    handle = model.encoder.layers[1].register_forward_hook(lambda *a: calls.append(1))
    with torch.inference_mode():
        assert torch.equal(model(x, t), fast) and calls == [1]  # a hook: the modules run
    handle.remove()
    # new weights (assign=True replaces the tensors) and a new dtype drop the cached arguments
    other = tiny_model()
    with torch.no_grad():
        for p in other.parameters():
            p.add_(0.01)
    model.load_state_dict(other.state_dict(), assign=True)
    with torch.inference_mode():
        assert torch.equal(model(x, t), other(x, t))
    assert "_fast_args" in model.__dict__
    model.float()  # .to() / .float() may replace the tensors: the cache goes
    assert "_fast_args" not in model.__dict__


def test_bf16_inference_is_close_to_float32_and_switches_back():
    model = tiny_model()
    x, t = torch.randn(4, 7, 2), torch.tensor([0, 30, 60, 99])
    with torch.inference_mode():
        fp32 = model(x, t)
        assert model.set_inference_precision("bf16") == "bf16"
        assert model.inference_dtype == torch.bfloat16
        bf16 = model(x, t)
        assert bf16.dtype == torch.float32 and not torch.equal(bf16, fp32)
        torch.testing.assert_close(bf16, fp32, rtol=0.05, atol=0.05)
        assert model.set_inference_precision("fp32") == "fp32"
        assert torch.equal(model(x, t), fp32)
    model.set_inference_precision("bf16")
    with torch.enable_grad():  # gradients: the float32 modules, not the bf16 kernel
        torch.testing.assert_close(model(x, t).detach(), fp32, rtol=1e-5, atol=1e-5)
    sampler = DiffusionSampler(model, DDIMScheduler(), NORMALIZER, SamplerConfig(precision="bf16"))
    assert sampler.precision == "bf16" and model.inference_dtype == torch.bfloat16
    with pytest.raises(ValueError, match="precision"):
        SamplerConfig(precision="fp16")


def test_denoiser_config_is_validated_and_keyword_only():
    with pytest.raises(TypeError):
        DenoiserConfig(10)  # keyword-only
    with pytest.raises(ValueError, match="divisible"):
        DenoiserConfig(max_horizon=10, d_model=30, n_heads=4)
    cfg = DenoiserConfig(max_horizon=10)
    assert DenoiserConfig.from_dict(cfg.to_dict()) == cfg


def unet_config(**kw):
    kw = {"max_horizon": 100, "unet_channels": (8, 16, 32), "unet_kernel_size": 3, **kw}
    return DenoiserConfig(architecture="temporal_unet", **kw)


@pytest.mark.parametrize("horizon", [1, 2, 3, 5, 7, 100])
def test_temporal_unet_keeps_every_horizon(horizon):
    # 3 levels: lengths that are not a multiple of 4 are padded inside and cropped back
    torch.manual_seed(0)
    model = TemporalUnetDenoiser(unet_config()).eval()
    assert model.length_multiple == 4
    x = torch.randn(3, horizon, 2)
    eps = model(x, torch.tensor([0, 50, 99]))
    assert eps.shape == (3, horizon, 2) and torch.isfinite(eps).all()
    assert torch.equal(model(x, 7), model(x, torch.full((3,), 7)))  # int t = shared t
    with pytest.raises(ValueError, match="max_horizon"):
        model(torch.randn(3, 101, 2), 5)
    with pytest.raises(ValueError, match=r"\(B, P, 2\)"):
        model(torch.randn(3, horizon, 3), 5)


def test_temporal_unet_default_size_runs_100_points():
    # the FD recipe's size: (32, 64, 128), k = 5 -> 1,027,490 parameters
    torch.manual_seed(0)
    model = build_denoiser(DenoiserConfig(max_horizon=100, architecture="temporal_unet"))
    assert isinstance(model, TemporalUnetDenoiser)
    assert sum(p.numel() for p in model.parameters()) == 1_027_490
    assert model(torch.randn(2, 100, 2), torch.tensor([3, 90])).shape == (2, 100, 2)


def test_temporal_unet_output_depends_on_time_and_both_ends():
    # the time embedding reaches the output, and the receptive field spans 100 points: moving
    # the goal (last point) changes eps at the first free waypoint
    torch.manual_seed(0)
    model = TemporalUnetDenoiser(unet_config(unet_kernel_size=5)).eval()
    x = torch.randn(1, 100, 2)
    assert not torch.allclose(model(x, 5), model(x, 95))
    moved = x.clone()
    moved[0, -1] += 1.0
    assert not torch.allclose(model(x, 5)[0, 1], model(moved, 5)[0, 1])


def test_build_denoiser_picks_the_architecture():
    assert type(build_denoiser(DenoiserConfig(max_horizon=10, d_model=32, n_layers=1))) \
        is TransformerDenoiser
    assert type(build_denoiser(unet_config())) is TemporalUnetDenoiser
    with pytest.raises(ValueError, match="needs architecture 'temporal_unet'"):
        TemporalUnetDenoiser(DenoiserConfig(max_horizon=10))
    with pytest.raises(ValueError, match="needs architecture 'transformer'"):
        TransformerDenoiser(unet_config())


def test_denoiser_config_architecture_fields():
    cfg = unet_config(unet_channels=[8, 16])  # a list (as read from a checkpoint) -> tuple
    assert cfg.unet_channels == (8, 16)
    assert cfg.to_dict()["unet_channels"] == [8, 16]
    assert DenoiserConfig.from_dict(cfg.to_dict()) == cfg
    # a checkpoint written before the field existed is a Transformer
    old = DenoiserConfig(max_horizon=10).to_dict()
    for key in ("architecture", "unet_channels", "unet_kernel_size", "prediction"):
        del old[key]
    assert DenoiserConfig.from_dict(old) == DenoiserConfig(max_horizon=10)
    assert DenoiserConfig.from_dict(old).prediction == "epsilon"
    with pytest.raises(ValueError, match="'transformer', 'temporal_unet'"):
        DenoiserConfig(max_horizon=10, architecture="unet")
    with pytest.raises(ValueError, match="'epsilon', 'sample'"):
        DenoiserConfig(max_horizon=10, prediction="x0")
    with pytest.raises(ValueError, match="odd"):
        unet_config(unet_kernel_size=4)
    with pytest.raises(ValueError, match="unet_channels"):
        unet_config(unet_channels=())
    with pytest.raises(ValueError, match="unet_channels"):
        unet_config(unet_channels=(8, 0))
    with pytest.raises(ValueError, match="only supported by the 'transformer'"):
        unet_config(use_map_encoder=True)


class FixedSample(torch.nn.Module):
    """A 'sample'-predicting network that always answers x0 (B, P, 2)."""

    def __init__(self, x0):
        super().__init__()
        self.x0 = x0
        self.scale = torch.nn.Parameter(torch.ones(()))  # a parameter, for the device
        self.config = DenoiserConfig(max_horizon=x0.shape[1], prediction="sample")

    def forward(self, x, t):
        return self.x0 * self.scale


@pytest.mark.parametrize("t", [0, 9, 50, 99])
def test_epsilon_from_sample_is_inverted_by_the_ddim_step(t):
    # eps = (x_t - sqrt(a) x0_hat) / sqrt(1 - a); DDIM's pred_x0 recovers x0_hat
    scheduler = DDIMScheduler(clip_sample=None)
    scheduler.set_timesteps(100)
    x0 = torch.rand(2, 7, 2) - 0.5
    model = as_noise_predictor(FixedSample(x0), scheduler.alphas_cumprod)
    assert isinstance(model, EpsilonFromSample) and model.config.prediction == "sample"
    x = torch.randn(2, 7, 2)
    eps = model(x, t)
    a = scheduler.alphas_cumprod[t]
    torch.testing.assert_close(eps, (x - a.sqrt() * x0) / (1 - a).sqrt())
    pred_x0 = scheduler.step(eps, t, x).pred_x0
    # float32 rounding of x is amplified by 1 / sqrt(alpha_bar): ~2000 at t = 99 (measured
    # error there 1.7e-4), ~1 elsewhere
    torch.testing.assert_close(pred_x0, x0, atol=1e-3 if t == 99 else 2e-5, rtol=0)
    # an eps network is returned as it is
    eps_net = tiny_model()
    assert as_noise_predictor(eps_net, scheduler.alphas_cumprod) is eps_net


def test_denoiser_with_map_encoder_runs_forward():
    model = tiny_model(use_map_encoder=True)
    x, t = torch.randn(4, 6, 2), torch.full((4,), 10)
    image = (torch.rand(1, 1, 40, 56) > 0.7).float()
    eps = model(x, t, map_image=image)  # one map broadcast to the batch
    assert eps.shape == (4, 6, 2)
    feature = model.encode_map(image)
    assert feature.shape == (1, 32)
    torch.testing.assert_close(model(x, t, map_feature=feature), eps)
    eps_batch = model(x, t, map_image=image.expand(4, -1, -1, -1))
    torch.testing.assert_close(eps_batch, eps, rtol=1e-4, atol=1e-5)
    with pytest.raises(ValueError, match="map_image or map_feature"):
        model(x, t)
    with pytest.raises(ValueError, match="use_map_encoder=False"):
        tiny_model()(x, t, map_image=image)
    # through the sampler, with the map encoded once
    out = sample(model, DDIMScheduler(), NORMALIZER, batch=4, horizon=6,
                 conditions={0: torch.tensor([0.5, 0.5])}, num_steps=3,
                 generator=torch.Generator().manual_seed(0), model_kwargs={"map_feature": feature})
    assert out.trajectories.shape == (4, 6, 2)


# --------------------------------------------------------------------------------- sampling
def test_inpainted_states_are_exact_in_the_output():
    model, scheduler = tiny_model(), DDIMScheduler()
    starts = torch.tensor([[0.3, 0.1], [3.9, 1.7], [1.234567, 0.7654321]])
    goal = torch.tensor([2.2, 1.9])
    out = sample(model, scheduler, NORMALIZER, batch=3, horizon=7,
                 conditions={0: starts, -1: goal}, num_steps=5, eta=0.7,
                 generator=torch.Generator().manual_seed(0), return_intermediates=True)
    assert out.trajectories.shape == (3, 7, 2)
    assert torch.equal(out.trajectories[:, 0], starts)
    assert torch.equal(out.trajectories[:, -1], goal.expand(3, 2))
    assert out.intermediates.shape == (6, 3, 7, 2) and out.pred_x0.shape == (5, 3, 7, 2)
    assert torch.equal(out.intermediates[:, :, 0], starts.expand(6, 3, 2))
    assert torch.equal(out.intermediates[-1], out.trajectories)
    assert out.timesteps == (99, 79, 59, 39, 19)


def test_sampling_is_reproducible_for_a_seed():
    model, scheduler = tiny_model(), DDIMScheduler()
    kw = dict(batch=2, horizon=5, conditions={0: torch.tensor([1.0, 1.0])}, num_steps=4, eta=1.0)
    a = sample(model, scheduler, NORMALIZER, generator=torch.Generator().manual_seed(7), **kw)
    b = sample(model, scheduler, NORMALIZER, generator=torch.Generator().manual_seed(7), **kw)
    c = sample(model, scheduler, NORMALIZER, generator=torch.Generator().manual_seed(8), **kw)
    assert torch.equal(a.trajectories, b.trajectories)
    assert not torch.equal(a.trajectories, c.trajectories)


def test_candidates_times_problems_in_one_forward_per_step():
    scheduler = DDIMScheduler()
    B, N, P = 3, 4, 6
    starts = torch.tensor([[0.5, 0.5], [1.0, 1.5], [3.5, 0.2]])
    goals = torch.tensor([[3.5, 1.5], [2.0, 0.5], [0.5, 1.8]])
    x0 = NORMALIZER.normalize(starts[:, None] + (goals - starts)[:, None]
                              * torch.linspace(0, 1, P)[None, :, None])  # (B, P, 2)
    oracle = OracleDenoiser(scheduler, x0.repeat_interleave(N, dim=0))
    out = sample(oracle, scheduler, NORMALIZER, batch=B * N, horizon=P,
                 conditions=expand_conditions({0: starts, -1: goals}, N), num_steps=8,
                 eta=1.0, generator=torch.Generator().manual_seed(0))
    assert oracle.calls == [(B * N, P, 2)] * 8  # one batched forward per DDIM step
    per_problem = out.trajectories.view(B, N, P, 2)
    assert torch.equal(per_problem[:, :, 0], starts[:, None].expand(B, N, 2))
    torch.testing.assert_close(per_problem, NORMALIZER.unnormalize(x0)[:, None].expand(B, N, P, 2),
                               rtol=0, atol=1e-4)


WALL_X = 2.5  # [m]: the 'wall' is x > 2.5


def wall_cost(traj):
    """J = sum over waypoints of relu(x - WALL_X)^2, traj (B, P, 2) [m] -> (B,)."""
    return torch.relu(traj[..., 0] - WALL_X).pow(2).sum(-1)


def wall_problem():
    # The oracle's clean trajectories run from x = 0.5 to x = 3.5 m through the wall.
    scheduler = DDIMScheduler()
    B, P = 6, 8
    y = torch.linspace(0.2, 1.8, B)
    xs = torch.linspace(0.5, 3.5, P)
    x0_m = torch.stack([xs.expand(B, P), y[:, None].expand(B, P)], dim=-1)  # (B, P, 2) [m]
    oracle = OracleDenoiser(scheduler, NORMALIZER.normalize(x0_m))
    return scheduler, oracle, x0_m, dict(batch=B, horizon=P, conditions={0: x0_m[:, 0]},
                                         num_steps=10, eta=0.0)


def test_guidance_moves_samples_out_of_the_wall():
    scheduler, oracle, x0_m, kw = wall_problem()
    plain = sample(oracle, scheduler, NORMALIZER, generator=torch.Generator().manual_seed(0), **kw)
    torch.testing.assert_close(plain.trajectories, x0_m, rtol=0, atol=1e-4)  # in the wall
    guided = sample(oracle, scheduler, NORMALIZER, generator=torch.Generator().manual_seed(0),
                    guide=CostGuide(wall_cost), guidance_weight=1.0, **kw)
    before, after = wall_cost(plain.trajectories), wall_cost(guided.trajectories)
    assert (after < before).all()
    assert after.sum() < 0.5 * before.sum()  # measured: 8.08 -> 2.57
    assert guided.guided_steps == tuple(range(10)) and guided.guide_costs.shape == (10, 6)
    # the start stays exact; y is untouched (the cost does not depend on it)
    assert torch.equal(guided.trajectories[:, 0], x0_m[:, 0])
    torch.testing.assert_close(guided.trajectories[..., 1], x0_m[..., 1], rtol=0, atol=1e-4)


def test_guide_steps_choose_where_guidance_applies():
    scheduler, oracle, _, kw = wall_problem()
    gen = lambda: torch.Generator().manual_seed(0)  # noqa: E731
    plain = sample(oracle, scheduler, NORMALIZER, generator=gen(), **kw)
    none = sample(oracle, scheduler, NORMALIZER, generator=gen(), guide=CostGuide(wall_cost),
                  guide_steps=set(), **kw)
    assert none.guided_steps == () and none.guide_costs is None
    torch.testing.assert_close(none.trajectories, plain.trajectories, rtol=0, atol=0)
    last = sample(oracle, scheduler, NORMALIZER, generator=gen(), guide=CostGuide(wall_cost),
                  guide_steps={-1, -2}, **kw)
    assert last.guided_steps == (8, 9)
    late = sample(oracle, scheduler, NORMALIZER, generator=gen(), guide=CostGuide(wall_cost),
                  guide_steps=lambda i, t: t < 50, **kw)
    assert late.guided_steps == (5, 6, 7, 8, 9)
    with pytest.raises(ValueError, match="outside 0..9"):
        sample(oracle, scheduler, NORMALIZER, guide=CostGuide(wall_cost), guide_steps={10}, **kw)


def test_guidance_gradients_never_reach_the_model():
    model = tiny_model()
    assert all(p.requires_grad for p in model.parameters())
    seen = []

    def guide(traj):
        seen.append((torch.is_grad_enabled(), traj.requires_grad, traj.grad_fn))
        return CostGuide(wall_cost)(traj)

    out = sample(model, DDIMScheduler(), NORMALIZER, batch=2, horizon=5,
                 conditions={0: torch.tensor([0.5, 1.0])}, num_steps=4, guide=guide,
                 generator=torch.Generator().manual_seed(0))
    assert seen == [(True, False, None)] * 4  # grad on, but on a detached copy
    assert all(p.grad is None for p in model.parameters())
    assert out.trajectories.grad_fn is None and not out.trajectories.requires_grad


def test_unguided_sampling_runs_in_inference_mode():
    model = tiny_model()
    out = sample(model, DDIMScheduler(), NORMALIZER, batch=2, horizon=5,
                 conditions={0: torch.tensor([0.5, 1.0])}, num_steps=2)
    assert out.trajectories.is_inference()


def test_bad_guide_output_and_bad_conditions_are_reported():
    model, scheduler = tiny_model(), DDIMScheduler()
    kw = dict(batch=2, horizon=5, num_steps=2)
    bad_guide = lambda traj: GuideOutput(cost=torch.zeros(2), grad=torch.zeros(2, 4, 2))  # noqa
    with pytest.raises(TrajectoryError, match="guide returned"):
        sample(model, scheduler, NORMALIZER, conditions={0: torch.zeros(2)}, guide=bad_guide, **kw)
    with pytest.raises(TrajectoryError, match="not finite"):
        sample(model, scheduler, NORMALIZER, conditions={0: torch.tensor([float("nan"), 0.0])},
               **kw)
    with pytest.raises(TrajectoryError, match=r"\(2,\) or \(2, 2\)"):
        sample(model, scheduler, NORMALIZER, conditions={0: torch.zeros(3, 2)}, **kw)


def test_diffusion_sampler_wraps_sample():
    model = tiny_model()
    sampler = DiffusionSampler(model, DDIMScheduler(), NORMALIZER, SamplerConfig(num_steps=3))
    out = sampler.sample(batch=2, horizon=4, conditions={0: torch.tensor([1.0, 1.0])},
                         generator=torch.Generator().manual_seed(0))
    ref = sample(model, DDIMScheduler(), NORMALIZER, batch=2, horizon=4,
                 conditions={0: torch.tensor([1.0, 1.0])}, num_steps=3,
                 generator=torch.Generator().manual_seed(0))
    assert torch.equal(out.trajectories, ref.trajectories)
    assert sampler.device == torch.device("cpu")


def test_guide_norm_cap_bounds_huge_gradients():
    # A cost scaled by 1e6 has gradients of ~1e6 in eps units: raw, it throws samples to the
    # clip bound; capped at 1 per waypoint, the result equals guiding with the direction of the
    # gradient at unit size and stays near the data.
    scheduler, oracle, x0_m, kw = wall_problem()
    huge = CostGuide(lambda t: 1e6 * wall_cost(t))
    raw = sample(oracle, scheduler, NORMALIZER, generator=torch.Generator().manual_seed(0),
                 guide=huge, guidance_weight=1.0, max_guide_norm=None, **kw)
    capped = sample(oracle, scheduler, NORMALIZER, generator=torch.Generator().manual_seed(0),
                    guide=huge, guidance_weight=1.0, max_guide_norm=1.0, **kw)
    z_raw = NORMALIZER.normalize(raw.trajectories)
    z_cap = NORMALIZER.normalize(capped.trajectories)
    assert z_raw.abs().amax() > 0.99  # at the clip bound
    assert (wall_cost(capped.trajectories) < wall_cost(x0_m)).all()  # still moved out
    assert (z_cap - NORMALIZER.normalize(x0_m)).abs().amax() < 0.5
