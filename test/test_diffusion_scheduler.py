"""Noise schedule and DDIM step: closed forms, determinism, an oracle denoiser, timestep bounds."""
import math

import pytest
import torch

from ecahd_core.diffusion.scheduler import DDIMScheduler, NoiseSchedule, ScheduleConfig

K = 100


def oracle_eps(scheduler, x0):
    """A perfect denoiser for the single clean sample x0: the noise that turns x0 into x_t,
    eps = (x_t - sqrt(alpha_bar_t) x0) / sqrt(1 - alpha_bar_t)."""
    def eps(x_t, t):
        a = scheduler.alphas_cumprod[t]
        return (x_t - a.sqrt() * x0) / (1 - a).sqrt()
    return eps


@pytest.mark.parametrize("schedule", ["cosine", "linear"])
@pytest.mark.parametrize("k", [20, 100])
def test_schedule_is_a_valid_forward_process(schedule, k):
    s = NoiseSchedule(ScheduleConfig(num_train_timesteps=k, beta_schedule=schedule))
    assert s.betas.shape == (k,)
    assert (s.betas > 0).all() and (s.betas < 1).all()
    torch.testing.assert_close(s.alphas_cumprod, torch.cumprod(1 - s.betas.double(), 0).float())
    assert (s.alphas_cumprod.diff() < 0).all()  # strictly more noise each step
    assert s.alphas_cumprod[0] > 0.99  # first step barely noisy
    assert s.alphas_cumprod[-1] < 1e-3  # last step is (almost) pure noise, whatever K


def test_cosine_schedule_matches_improved_ddpm():
    # alpha_bar after t + 1 steps = f(t + 1) / f(0), f(u) = cos^2((u / K + s) / (1 + s) * pi / 2)
    # (Nichol & Dhariwal 2021, Eq. 17); the last entry is clipped by beta <= 0.999.
    s = NoiseSchedule(ScheduleConfig(num_train_timesteps=K, beta_schedule="cosine"))
    f = lambda u: math.cos((u / K + 0.008) / 1.008 * math.pi / 2) ** 2  # noqa: E731
    for t in (0, 10, 50, 90, 98):
        assert s.alphas_cumprod[t].item() == pytest.approx(f(t + 1) / f(0), rel=1e-5, abs=1e-7)


def test_add_noise_matches_closed_form_exactly():
    s = NoiseSchedule()
    x0 = torch.tensor([[[0.5, -0.25], [1.0, 0.0]]]).repeat(3, 1, 1)  # (3, 2, 2)
    noise = torch.tensor([[[1.0, 2.0], [-1.0, 0.5]]]).repeat(3, 1, 1)
    t = torch.tensor([0, 49, 99])
    x_t = s.add_noise(x0, noise, t)
    for b in range(3):
        a = s.alphas_cumprod[t[b]]
        torch.testing.assert_close(x_t[b], a.sqrt() * x0[b] + (1 - a).sqrt() * noise[b])
    mean, std = s.marginal(x0, t)
    assert std.shape == (3, 1, 1)
    torch.testing.assert_close(mean + std * noise, x_t)


def test_markov_chain_matches_closed_form_marginal():
    # Run q(x_t | x_{t-1}) step by step on many samples and compare the empirical moments with
    # q(x_t | x_0) = N(sqrt(alpha_bar_t) x0, (1 - alpha_bar_t) I). With n = 200k samples the
    # standard error of the mean is ~0.0022 and of the std ~0.0016, so 0.01 is > 4 sigma.
    s = NoiseSchedule()
    g = torch.Generator().manual_seed(0)
    n = 200_000
    x0 = torch.full((n, 1, 2), 0.8)
    x = x0
    for t in range(K):
        x = s.forward_step(x, torch.randn(x.shape, generator=g), t)
        if t in (0, 5, 30, 60, 99):
            mean, std = s.marginal(x0[:1], t)
            assert x.mean().item() == pytest.approx(mean.flatten()[0].item(), abs=0.01)
            assert x.std().item() == pytest.approx(std.item(), abs=0.01)


def test_unknown_schedule_lists_allowed_values():
    with pytest.raises(ValueError, match="'cosine', 'linear'"):
        ScheduleConfig(beta_schedule="quadratic")
    with pytest.raises(ValueError, match="K"):
        ScheduleConfig(num_train_timesteps=1)


@pytest.mark.parametrize("n", [1, 2, 3, 7, 10, 33, 99, 100])
def test_set_timesteps_spacing(n):
    s = DDIMScheduler()
    ts = s.set_timesteps(n)
    assert len(ts) == n and s.timesteps == ts
    assert ts[0] == K - 1  # always start from the noisiest step
    assert all(a > b for a, b in zip(ts, ts[1:]))  # strictly decreasing
    assert 0 <= ts[-1] < math.ceil(K / n)
    assert s.previous_timestep(ts[-1]) == -1


def test_set_timesteps_bounds():
    s = DDIMScheduler()
    assert s.set_timesteps(K) == tuple(range(K - 1, -1, -1))
    assert s.set_timesteps(10) == (99, 89, 79, 69, 59, 49, 39, 29, 19, 9)
    for bad in (0, -1, K + 1, 2.5):
        with pytest.raises(ValueError, match="1..K=100"):
            s.set_timesteps(bad)
    with pytest.raises(ValueError, match="not in the current schedule"):
        s.step(torch.zeros(1, 2, 2), 50, torch.zeros(1, 2, 2))
    with pytest.raises(RuntimeError, match="set_timesteps"):
        DDIMScheduler().step(torch.zeros(1, 2, 2), 99, torch.zeros(1, 2, 2))


def test_ddim_step_matches_hand_computed_update():
    # One eta = 0 step from t = 99 to t_prev = 89 (10 steps), no clipping:
    # x0_hat = (x - sqrt(1 - a_t) eps) / sqrt(a_t); x_prev = sqrt(a_p) x0_hat + sqrt(1 - a_p) eps.
    s = DDIMScheduler(clip_sample=None)
    s.set_timesteps(10)
    x = torch.tensor([[[0.3, -1.2], [0.7, 0.1]]])
    eps = torch.tensor([[[0.2, -1.0], [0.5, 0.4]]])
    a_t, a_p = s.alphas_cumprod[99].double(), s.alphas_cumprod[89].double()
    x0_hat = (x.double() - (1 - a_t).sqrt() * eps) / a_t.sqrt()
    expected = a_p.sqrt() * x0_hat + (1 - a_p).sqrt() * eps
    out = s.step(eps, 99, x, eta=0.0)
    torch.testing.assert_close(out.pred_x0, x0_hat.float(), rtol=1e-4, atol=1e-4)
    torch.testing.assert_close(out.prev_sample, expected.float(), rtol=1e-4, atol=1e-4)


def test_clip_sample_bounds_pred_x0():
    s = DDIMScheduler(clip_sample=1.0)
    s.set_timesteps(10)
    out = s.step(torch.full((2, 3, 2), -5.0), 99, torch.zeros(2, 3, 2))
    assert out.pred_x0.abs().max() <= 1.0


def _run(scheduler, eps_fn, x, n, eta, seed):
    g = torch.Generator().manual_seed(seed)
    scheduler.set_timesteps(n)
    for t in scheduler.timesteps:
        x = scheduler.step(eps_fn(x, t), t, x, eta=eta, generator=g).prev_sample
    return x


@pytest.mark.parametrize("eta", [0.0, 1.0])
def test_ddim_is_deterministic_for_a_seed(eta):
    s = DDIMScheduler()
    w = torch.randn(2, 2, generator=torch.Generator().manual_seed(1))
    dummy = lambda x, t: torch.tanh(x @ w) * (t + 1) / K  # noqa: E731  a fixed dummy denoiser
    x_init = torch.randn(4, 6, 2, generator=torch.Generator().manual_seed(2))
    a = _run(s, dummy, x_init, 10, eta, seed=3)
    b = _run(s, dummy, x_init, 10, eta, seed=3)
    assert torch.equal(a, b)
    c = _run(s, dummy, x_init, 10, eta, seed=4)
    assert torch.equal(a, c) == (eta == 0.0)  # eta = 0 uses no randomness after x_K


@pytest.mark.parametrize("n", [1, 3, 10, 100])
@pytest.mark.parametrize("eta", [0.0, 0.5, 1.0])
@pytest.mark.parametrize("schedule", ["cosine", "linear"])
def test_oracle_denoiser_recovers_x0(n, eta, schedule):
    s = DDIMScheduler(ScheduleConfig(beta_schedule=schedule))
    x0 = torch.tensor([[[0.1, -0.4], [0.5, 0.9], [-0.8, 0.2]]]).repeat(2, 1, 1)
    eps = oracle_eps(s, x0)
    g = torch.Generator().manual_seed(0)
    x = torch.randn(x0.shape, generator=g)
    s.set_timesteps(n)
    for t in s.timesteps:
        out = s.step(eps(x, t), t, x, eta=eta, generator=g)
        torch.testing.assert_close(out.pred_x0, x0, rtol=0, atol=2e-3)
        x = out.prev_sample
    torch.testing.assert_close(x, x0, rtol=0, atol=2e-3)


def test_schedule_tensors_are_buffers_that_follow_to():
    s = DDIMScheduler()
    names = {name for name, _ in s.named_buffers()}
    assert {"betas", "alphas", "alphas_cumprod"} <= names
    assert s.state_dict() == {}  # rebuilt from the config, not stored
    assert s.to(torch.float64).alphas_cumprod.dtype == torch.float64
