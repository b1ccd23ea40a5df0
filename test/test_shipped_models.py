"""The models shipped in the package: they load without network, sample exactly between start
and goal, and drive `ecahd plan --method sd` and `ecahd bench sampling`."""
import json

import numpy as np
import pytest
import torch

from ecahd_core.diffusion import DiffusionSampler
from ecahd_core.diffusion.denoiser import (EpsilonFromSample, TemporalUnetDenoiser,
                                           TransformerDenoiser)
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import builtin_map
from ecahd_core.model_zoo import MODELS_DIR, RECIPES, load_model, sample_steps, shipped_path
from ecahd_ros.cli import main

GRID = builtin_map("maze2d-large")


def test_all_three_ship_under_20_mb():
    paths = [shipped_path("maze2d-large", k) for k in ("sd", "dd", "fd")]
    assert all(p.is_file() for p in paths), sorted(MODELS_DIR.iterdir())
    assert sum(p.stat().st_size for p in paths) < 20e6


@pytest.mark.parametrize("kind, horizon", [("sd", 10), ("sd", 5), ("dd", 4), ("fd", 100)])
def test_shipped_model_samples_between_start_and_goal(kind, horizon):
    ckpt = load_model(kind, GRID, footprint=make_footprint("quadruped"), horizon=horizon)
    sampler = DiffusionSampler.from_checkpoint(ckpt)
    start, goal = torch.tensor([1.5, 1.5]), torch.tensor([2.5, 3.5])
    out = sampler.sample(batch=3, horizon=horizon, conditions={0: start, -1: goal},
                         generator=torch.Generator().manual_seed(0))
    traj = out.trajectories
    assert traj.shape == (3, horizon, 2) and torch.isfinite(traj).all()
    assert torch.equal(traj[:, 0], start.expand(3, 2)) and torch.equal(traj[:, -1], goal.expand(3, 2))
    # waypoints stay on the map
    xmin, ymin, xmax, ymax = GRID.bounds
    assert traj[..., 0].min() >= xmin - 0.5 and traj[..., 0].max() <= xmax + 0.5
    assert traj[..., 1].min() >= ymin - 0.5 and traj[..., 1].max() <= ymax + 0.5


def test_plan_sd_command(tmp_path):
    rec = tmp_path / "sd.json"
    assert main(["plan", "--method", "sd", "--robot", "circle", "--png", str(tmp_path / "sd.png"),
                 "--json", str(rec)]) == 0
    r = json.loads(rec.read_text())
    wp = np.array(r["waypoints"])
    assert wp.shape == (10, 2) and r["method"] == "sd"
    assert np.allclose(wp[0], [1.5, 1.5]) and np.allclose(wp[-1], [10.5, 7.5])
    assert r["timings_ms"]["sd"] > 0


@pytest.mark.slow
def test_bench_sampling_json(tmp_path):
    out = tmp_path / "s.json"
    assert main(["bench", "sampling", "--repeats", "1", "--json", str(out)]) == 0
    r = json.loads(out.read_text())
    for key in ("sd_best_of_10_ms", "dd_plan_ms", "dd_step_ms", "fd_ms", "fd_guided_ms"):
        assert r[key] > 0
    assert set(r["dd_step_breakdown_ms"]) == {"denoiser", "cost_forward", "gradient", "update"}


def test_bench_sd_quality_small(tmp_path):
    out = tmp_path / "q.json"
    assert main(["bench", "sd-quality", "--problems", "4", "--json", str(out)]) == 0
    r = json.loads(out.read_text())
    assert r["problems"] == 4 and 0.0 <= r["collision_free_point"] <= 1.0
    assert r["goal_reached"] == 1.0  # the goal is inpainted: the last waypoint is the goal


@pytest.mark.parametrize("method, guidance", [("ecahd", None), ("hd", "--no-guidance"),
                                              ("fd", "--guidance")])
def test_plan_hierarchical_and_fd(tmp_path, method, guidance):
    rec = tmp_path / "r.json"
    argv = ["plan", "--method", method, "--robot", "quadruped", "--start", "1.5", "1.5",
            "--goal", "6.5", "5.5", "--candidates", "4", "--png", str(tmp_path / "r.png"),
            "--json", str(rec)] + ([guidance] if guidance else [])
    assert main(argv) == 0
    r = json.loads(rec.read_text())
    traj = np.array(r["trajectory"])
    assert np.allclose(traj[0], [1.5, 1.5]) and np.allclose(traj[-1], [6.5, 5.5], atol=1e-5)
    assert r["method"] == method and r["dd_calls"] >= 0 and r["timings_ms"]["total"] > 0


@pytest.mark.parametrize("kind, architecture", [("sd", "transformer"), ("dd", "transformer"),
                                                ("fd", "temporal_unet")])
def test_shipped_models_are_what_the_recipes_build(kind, architecture):
    # `ecahd train-all` reproduces the shipped files: same architecture, size and budget. (SD
    # and DD were written before DenoiserConfig.architecture existed and load as Transformers.)
    ckpt = load_model(kind, GRID)
    r = RECIPES[kind]
    assert ckpt.model_config.architecture == architecture
    assert ckpt.model_config == r.denoiser_config(max(ckpt.horizons))
    model = ckpt.build_model()
    if ckpt.model_config.prediction == "sample":  # FD predicts x_0, sampled as eps
        assert isinstance(model, EpsilonFromSample)
        model = model.model
    assert type(model) is {"transformer": TransformerDenoiser,
                           "temporal_unet": TemporalUnetDenoiser}[architecture]
    assert (ckpt.step, ckpt.train_config["batch_size"]) == (r.steps, r.batch_size)
    assert (ckpt.train_config["lr"], ckpt.train_config["ema_decay"]) == (r.lr, r.ema_decay)
    assert sample_steps(ckpt) == r.sample_steps


def test_every_shipped_model_together_under_30_mb_and_the_generalists_plan_anywhere():
    """Issue 40: all shipped models <= 30 MB; the generalists ship and serve a map that has no
    model of its own (maze2d-umaze): a plan from start to goal, ECAHD's dense path through
    SD + the segment-frame DD."""
    from ecahd_core.general.checkpoint import GeneralCheckpoint
    from ecahd_core.model_zoo import general_path, load_dd, load_sd
    from ecahd_core.planning.hierarchical import HierarchicalPlanner
    from ecahd_core.planning.sparse import SparseDiffusion

    assert sum(p.stat().st_size for p in MODELS_DIR.glob("*.pt")) <= 30e6
    assert general_path("sd").parent == MODELS_DIR and general_path("dd").parent == MODELS_DIR
    umaze = builtin_map("maze2d-umaze")
    assert isinstance(load_sd(umaze), GeneralCheckpoint)
    assert load_dd(umaze).meta["frame"] == "segment"
    robot = make_footprint("circle")
    sd = SparseDiffusion.for_map(umaze, robot)
    hd = HierarchicalPlanner.for_map(umaze, robot, sd)
    start, goal = np.array([1.5, 1.5]), np.array([1.5, 3.5])
    plan = hd.plan(start, goal, generator=torch.Generator().manual_seed(0))
    assert np.allclose(plan.trajectory[0], start) and np.allclose(plan.trajectory[-1], goal)
