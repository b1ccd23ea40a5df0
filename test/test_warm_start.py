"""Warm-started re-planning (ours): the sampler noised from a known trajectory to the last steps
of the DDIM schedule (dummy denoisers), the scheduler's helpers, and the shipped SD's re-plans."""
import numpy as np
import pytest
import torch

from ecahd_core.cost import CollisionCost, CostConfig
from ecahd_core.diffusion.normalizer import Normalizer
from ecahd_core.diffusion.sampler import DiffusionSampler, SamplerConfig, sample
from ecahd_core.diffusion.scheduler import DDIMScheduler
from ecahd_core.errors import EcahdError, TrajectoryError
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import builtin_map
from ecahd_core.model_zoo import load_model
from ecahd_core.planning.dense import DenseConfig
from ecahd_core.planning.hierarchical import HierarchicalPlanner
from ecahd_core.planning.sparse import SparseConfig, SparseDiffusion

NORMALIZER = Normalizer.from_bounds(0.0, 0.0, 4.0, 2.0)  # centre (2, 1), scale (2, 1)
START, GOAL = torch.tensor([0.5, 0.4]), torch.tensor([3.5, 1.6])
# a previous plan (6, 2) [m]: its ends differ from START / GOAL on purpose
PREVIOUS = torch.tensor([[0.6, 0.3], [1.0, 0.8], [1.6, 1.0], [2.2, 1.2], [2.9, 1.4], [3.4, 1.7]])


class CountingDenoiser:
    """eps = 0.1 * x: a smooth, deterministic dummy; records every call's timesteps."""

    def __init__(self):
        self.calls = []

    def __call__(self, x, t):
        self.calls.append(t.tolist())
        return 0.1 * x


class OracleDenoiser:
    """Knows the clean trajectory x0 (normalised (P, 2)) and returns the exact noise."""

    def __init__(self, scheduler, x0):
        self.scheduler, self.x0 = scheduler, x0

    def __call__(self, x, t):
        a = self.scheduler.alphas_cumprod[t][:, None, None]
        return (x - a.sqrt() * self.x0) / (1 - a).sqrt()


def warm(model, steps, *, batch=3, eta=1.0, seed=0, **kw):
    return sample(model, DDIMScheduler(), NORMALIZER, batch=batch, horizon=6,
                  conditions={0: START, -1: GOAL}, num_steps=10, eta=eta,
                  generator=torch.Generator().manual_seed(seed), warm_start=PREVIOUS,
                  warm_steps=steps, **kw)


# ------------------------------------------------------------------------------- scheduler
def test_last_timesteps_and_warm_steps_of_the_schedule():
    s = DDIMScheduler()
    s.set_timesteps(10)
    assert s.last_timesteps(3) == (29, 19, 9)  # trailing spacing: 99, 89, ..., 9
    assert s.last_timesteps(10) == s.timesteps and s.last_timesteps(0) == ()
    # round(fraction * S) steps: 0.25 of 10 -> 2 (banker's rounding of 2.5), 0.3 -> 3
    assert [s.warm_steps(f) for f in (0.0, 0.25, 0.3, 0.5, 1.0)] == [0, 2, 3, 5, 10]
    with pytest.raises(ValueError, match="0..10"):
        s.last_timesteps(11)
    with pytest.raises(ValueError, match="0..1"):
        s.warm_steps(1.5)
    with pytest.raises(RuntimeError, match="set_timesteps"):
        DDIMScheduler().last_timesteps(2)


# --------------------------------------------------------------------------------- sampler
def test_warm_start_with_no_step_returns_the_start_trajectory_with_its_conditions():
    model = CountingDenoiser()
    out = warm(model, 0)
    assert model.calls == [] and out.timesteps == ()
    expected = PREVIOUS.clone()
    expected[0], expected[-1] = START, GOAL
    for row in out.trajectories:  # float32 round trip through the normalised space
        torch.testing.assert_close(row, expected, atol=1e-6, rtol=0)
    assert torch.equal(out.trajectories[:, 0], START.expand(3, 2))
    assert torch.equal(out.trajectories[:, -1], GOAL.expand(3, 2))


@pytest.mark.parametrize("steps", [1, 3, 5, 10])
def test_warm_start_runs_only_the_last_steps_and_conditions_hold_at_every_step(steps):
    model = CountingDenoiser()
    out = warm(model, steps, return_intermediates=True)
    schedule = (99, 89, 79, 69, 59, 49, 39, 29, 19, 9)
    assert out.timesteps == schedule[10 - steps:]
    assert [c[0] for c in model.calls] == list(out.timesteps)  # one call per step run
    assert len(model.calls) < 10 or steps == 10  # fewer denoiser calls than from noise
    assert out.intermediates.shape == (steps + 1, 3, 6, 2)
    assert torch.equal(out.intermediates[:, :, 0], START.expand(steps + 1, 3, 2))
    assert torch.equal(out.intermediates[:, :, -1], GOAL.expand(steps + 1, 3, 2))
    assert torch.equal(out.pred_x0[:, :, 0], START.expand(steps, 3, 2))
    assert torch.isfinite(out.trajectories).all()


def test_warm_start_noise_grows_with_the_fraction():
    # z_{t_j} = sqrt(abar) x_w + sqrt(1 - abar) eps: the first sample drifts further from x_w
    # the earlier (noisier) t_j is
    x_w = NORMALIZER.normalize(PREVIOUS)
    drift = []
    for steps in (2, 5, 9):
        out = warm(CountingDenoiser(), steps, batch=64, return_intermediates=True)
        z = NORMALIZER.normalize(out.intermediates[0])[:, 1:-1]  # interior, normalised
        drift.append(float((z - x_w[1:-1]).square().mean()))
    assert drift[0] < drift[1] < drift[2]


def test_oracle_denoiser_recovers_the_warm_start_deterministically():
    # with the exact noise and eta 0, DDIM returns the clean trajectory it was noised from
    scheduler = DDIMScheduler()
    x0 = NORMALIZER.normalize(PREVIOUS)
    x0[0], x0[-1] = NORMALIZER.normalize(START), NORMALIZER.normalize(GOAL)
    out = sample(OracleDenoiser(scheduler, x0), scheduler, NORMALIZER, batch=2, horizon=6,
                 conditions={0: START, -1: GOAL}, num_steps=10, eta=0.0,
                 generator=torch.Generator().manual_seed(0), warm_start=PREVIOUS, warm_steps=4)
    torch.testing.assert_close(out.normalized, x0.expand(2, 6, 2), atol=1e-5, rtol=0)


def test_warm_start_is_reproducible_and_validated():
    a, b = warm(CountingDenoiser(), 4, seed=3), warm(CountingDenoiser(), 4, seed=3)
    assert torch.equal(a.trajectories, b.trajectories)
    assert not torch.equal(a.trajectories, warm(CountingDenoiser(), 4, seed=4).trajectories)
    kw = dict(batch=3, horizon=6, conditions={0: START, -1: GOAL}, num_steps=10)
    with pytest.raises(TrajectoryError, match=r"\(6, 2\) or \(3, 6, 2\)"):
        sample(CountingDenoiser(), DDIMScheduler(), NORMALIZER, warm_start=PREVIOUS[:5],
               warm_steps=2, **kw)
    with pytest.raises(TrajectoryError, match="not finite"):
        sample(CountingDenoiser(), DDIMScheduler(), NORMALIZER,
               warm_start=torch.full((6, 2), float("nan")), warm_steps=2, **kw)
    with pytest.raises(ValueError, match="go together"):
        sample(CountingDenoiser(), DDIMScheduler(), NORMALIZER, warm_start=PREVIOUS, **kw)
    with pytest.raises(ValueError, match="0..10"):
        sample(CountingDenoiser(), DDIMScheduler(), NORMALIZER, warm_start=PREVIOUS,
               warm_steps=11, **kw)


def test_diffusion_sampler_takes_a_fraction_and_caps_guide_last():
    model = CountingDenoiser()
    sampler = DiffusionSampler(model, DDIMScheduler(), NORMALIZER,
                               SamplerConfig(num_steps=10, guide_last=4))
    out = sampler.sample(batch=2, horizon=6, conditions={0: START, -1: GOAL},
                         generator=torch.Generator().manual_seed(0), warm_start=PREVIOUS,
                         warm_fraction=0.3)
    assert out.timesteps == (29, 19, 9) and len(model.calls) == 3
    with pytest.raises(ValueError, match="go together"):
        sampler.sample(batch=2, horizon=6, conditions={0: START}, warm_fraction=0.3)


# ------------------------------------------------------------------------- the shipped SD
GRID = builtin_map("maze2d-large")
S, G = np.array([1.5, 1.5]), np.array([10.5, 7.5])


@pytest.fixture(scope="module")
def shipped():
    fp = make_footprint("circle")
    cc = CostConfig()
    cost = CollisionCost(costmap=cc.make_costmap(GRID),
                         footprint_points=torch.as_tensor(fp.points, dtype=torch.float32), config=cc)
    return fp, cc, cost, load_model("sd", GRID, footprint=fp)


def make_sd(shipped, warm_fraction):
    fp, cc, cost, ckpt = shipped
    return SparseDiffusion(ckpt, SparseConfig(selection="collision_aware",
                                              warm_fraction=warm_fraction), cost=cost)


@pytest.mark.parametrize("fraction", [0.25, 0.5])
def test_shipped_sd_warm_replan_is_finite_and_exact_at_both_ends(shipped, fraction):
    cold = make_sd(shipped, 0.0).plan(S, G, generator=torch.Generator().manual_seed(0))
    here = cold.waypoints[1] + np.array([0.05, -0.04])  # the robot near waypoint 1
    sd = make_sd(shipped, fraction)
    plan = sd.replan(here, G, cold.waypoints, horizon=9, generator=torch.Generator().manual_seed(1))
    assert plan.candidates.shape == (10, 9, 2) and np.isfinite(plan.candidates).all()
    assert np.array_equal(plan.candidates[:, 0], np.broadcast_to(here.astype(np.float32), (10, 2)))
    assert np.array_equal(plan.candidates[:, -1], np.broadcast_to(G.astype(np.float32), (10, 2)))
    assert np.array_equal(plan.waypoints[0], here.astype(np.float32))
    # explicit warm start through plan() is the same call
    again = sd.plan(here, G, horizon=9, generator=torch.Generator().manual_seed(1),
                    warm_start=np.vstack([here, cold.waypoints[2:]]))
    assert np.array_equal(again.candidates, plan.candidates)


def test_shipped_sd_replan_without_warm_start_is_plan_from_noise(shipped):
    sd = make_sd(shipped, 0.0)
    previous = sd.plan(S, G, generator=torch.Generator().manual_seed(0)).waypoints
    a = sd.replan(previous[1], G, previous, horizon=9, generator=torch.Generator().manual_seed(2))
    b = sd.plan(previous[1], G, horizon=9, generator=torch.Generator().manual_seed(2))
    assert np.array_equal(a.candidates, b.candidates)
    # warm starts on, but no previous plan (a goal's first plan) or one too short: from noise
    warm_sd = make_sd(shipped, 0.5)
    c = warm_sd.replan(S, G, None, generator=torch.Generator().manual_seed(0))
    d = sd.plan(S, G, generator=torch.Generator().manual_seed(0))
    assert np.array_equal(c.candidates, d.candidates)
    e = warm_sd.replan(previous[1], G, previous[:5], horizon=9,
                       generator=torch.Generator().manual_seed(2))
    assert np.array_equal(e.candidates, b.candidates)
    with pytest.raises(EcahdError, match="0 is off"):
        sd.plan(S, G, horizon=4, warm_start=previous[-4:])  # warm starts off
    with pytest.raises(EcahdError, match=r"\(4, 2\)"):
        warm_sd.plan(S, G, horizon=4, warm_start=previous)
    with pytest.raises(EcahdError, match="0..1"):
        SparseConfig(warm_fraction=1.5)


def test_algorithm1_with_warm_starts_shrinks_the_horizon_and_joins_start_to_goal(shipped):
    fp, cc, cost, ckpt = shipped
    sd = SparseDiffusion(ckpt, SparseConfig(num_candidates=4, warm_fraction=0.3))
    hd = HierarchicalPlanner(sd, load_model("dd", GRID, footprint=fp), costmap=cost.costmap,
                             footprint_points=fp.points, cost_config=cc,
                             dense=DenseConfig(polish_steps=0))
    plan = hd.plan(S, G, generator=torch.Generator().manual_seed(0))
    assert [len(g) for g in plan.global_plans] == list(range(10, 1, -1))
    assert np.allclose(plan.trajectory[0], S) and np.allclose(plan.trajectory[-1], G, atol=1e-5)
    # every re-plan started from the previous plan's rest: with 3 of 10 steps it stays close
    for prev, new in zip(plan.global_plans[:-2], plan.global_plans[1:-1]):
        assert np.abs(new[1:-1] - prev[2:-1]).max() < 1.5  # interior points
