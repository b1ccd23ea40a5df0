"""Training and checkpoints: a toy model learns straight lines, checkpoints round-trip and refuse
the wrong map, resuming is exact, and DDP runs on two CPU processes."""
import math
import os
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import torch

from ecahd_core.diffusion.denoiser import (DenoiserConfig, EpsilonFromSample,
                                           TemporalUnetDenoiser, TransformerDenoiser,
                                           build_denoiser, count_parameters)
from ecahd_core.diffusion.normalizer import Normalizer
from ecahd_core.diffusion.sampler import sample
from ecahd_core.diffusion.scheduler import DDIMScheduler, ScheduleConfig
from ecahd_core.diffusion.training import (CHECKPOINT_VERSION, Checkpoint, TrainConfig,
                                           load_checkpoint, train)
from ecahd_core.errors import CheckpointError, DatasetError
from ecahd_core.threads import native_bf16, resolve_precision

MAP_BOUNDS = (0.0, 0.0, 4.0, 4.0)  # [m] a 4 m x 4 m empty 'map'
NORMALIZER = Normalizer.from_bounds(*MAP_BOUNDS)
META = {"map_name": "toy-4x4", "map_fingerprint": "0123456789abcdef", "footprint": "circle",
        "horizons": [4, 6], "dataset_sha256": "deadbeef"}


def straight_lines(rng, n, horizon):
    """(n, horizon, 2) [m]: evenly spaced points from a random start to a random goal, both in
    [0.2, 3.8]^2 (normalised: [-0.9, 0.9]^2)."""
    start, goal = rng.uniform(0.2, 3.8, (2, n, 2))
    a = np.linspace(0.0, 1.0, horizon)[None, :, None]
    return (start[:, None] + (goal - start)[:, None] * a).astype(np.float32)


def toy_arrays(seed=0, n=512, horizons=(4, 6)):
    rng = np.random.default_rng(seed)
    return {h: straight_lines(rng, n, h) for h in horizons}


def chord_deviation(traj, start, goal):
    """Per trajectory, the largest distance [m] of a waypoint from the line start-goal.
    traj (B, P, 2), start/goal (B, 2) -> (B,)."""
    d = goal - start
    normal = torch.stack([-d[:, 1], d[:, 0]], dim=-1) / d.norm(dim=-1, keepdim=True)
    return ((traj - start[:, None]) * normal[:, None]).sum(-1).abs().max(dim=-1).values


def tiny_config(max_horizon=6, d_model=32, n_layers=2):
    return DenoiserConfig(max_horizon=max_horizon, d_model=d_model, n_layers=n_layers, n_heads=4,
                          ff_mult=2)


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    """A tiny model trained on straight lines of 4 and 6 waypoints (about 5-10 s on 2 cores)."""
    path = tmp_path_factory.mktemp("toy") / "dd.pt"
    cfg = TrainConfig(steps=1000, batch_size=128, lr=3e-3, warmup_steps=20, ema_decay=0.99,
                      seed=0, log_every=50)
    result = train(tiny_config(), toy_arrays(), NORMALIZER, cfg, kind="dd", out_path=path,
                   meta=META, progress=False)
    return result


def toy_problems(n=64, seed=1):
    rng = np.random.default_rng(seed)
    start, goal = (torch.tensor(v, dtype=torch.float32) for v in rng.uniform(0.2, 3.8, (2, n, 2)))
    return start, goal


@pytest.mark.slow
def test_training_lowers_loss_and_learns_straight_lines(toy):
    losses = [loss for _, loss in toy.loss_history]
    assert toy.step == 1000 and len(losses) == 20
    # measured: 0.405 over the first 50 steps, ~0.02 over the last 50
    assert losses[-1] < 0.15 * losses[0]
    start, goal = toy_problems()
    for horizon in (4, 6):
        kw = dict(batch=64, horizon=horizon, conditions={0: start, -1: goal}, num_steps=10)
        dev = chord_deviation(sample(toy.ema_model, DDIMScheduler(), NORMALIZER, eta=0.0,
                                     generator=torch.Generator().manual_seed(0), **kw
                                     ).trajectories, start, goal)
        # Chords average 1.9 m. eta = 0, measured: median 0.02 / 0.04 m, 90 % 0.04 / 0.07 m
        # (h = 4 / 6); about 1 % of deterministic samples of this barely trained model stay
        # stuck on the clip bound (max ~1.2-1.8 m), so the tail is not asserted here.
        assert dev.median() < 0.1 and dev.quantile(0.9) < 0.2
        dev = chord_deviation(sample(toy.ema_model, DDIMScheduler(), NORMALIZER, eta=1.0,
                                     generator=torch.Generator().manual_seed(0), **kw
                                     ).trajectories, start, goal)
        assert dev.max() < 0.5  # eta = 1, measured max: 0.09 / 0.23 m


@pytest.mark.slow
def test_checkpoint_round_trip_gives_identical_samples(toy, tmp_path):
    ckpt = load_checkpoint(toy.path, expect={"kind": "dd", **META})
    assert ckpt.step == 1000 and ckpt.kind == "dd" and ckpt.horizons == (4, 6)
    assert ckpt.normalizer == NORMALIZER and ckpt.schedule_config == ScheduleConfig()
    assert ckpt.conditioned_indices == (0, -1) and ckpt.meta == META
    assert ckpt.training_state is not None
    raw = torch.load(toy.path, weights_only=True)  # plain content only
    assert raw["format_version"] == CHECKPOINT_VERSION

    start, goal = toy_problems(8)
    kw = dict(batch=8, horizon=6, conditions={0: start, -1: goal}, num_steps=10, eta=0.5)
    ref = sample(toy.ema_model, DDIMScheduler(), NORMALIZER,
                 generator=torch.Generator().manual_seed(3), **kw)
    got = sample(ckpt.build_model(), ckpt.build_scheduler(), ckpt.normalizer,
                 generator=torch.Generator().manual_seed(3), **kw)
    assert torch.equal(ref.trajectories, got.trajectories)

    # The inference-only file (what the package ships) holds the EMA weights only.
    small = ckpt.save(tmp_path / "dd_infer.pt", include_training_state=False)
    assert small.stat().st_size < 0.4 * toy.path.stat().st_size
    light = load_checkpoint(small)
    assert light.training_state is None
    got = sample(light.build_model(), light.build_scheduler(), light.normalizer,
                 generator=torch.Generator().manual_seed(3), **kw)
    assert torch.equal(ref.trajectories, got.trajectories)


@pytest.mark.parametrize("prediction", ["epsilon", "sample"])
def test_temporal_unet_checkpoint_round_trip(tmp_path, prediction):
    # FD's architecture: trained a few steps, written, read back as the same U-Net; an
    # x_0-predicting one is sampled through EpsilonFromSample
    cfg = DenoiserConfig(max_horizon=10, architecture="temporal_unet", unet_channels=(8, 16),
                         unet_kernel_size=3, prediction=prediction)
    result = train(cfg, toy_arrays(n=32, horizons=(10,)), NORMALIZER,
                   TrainConfig(steps=4, batch_size=8, warmup_steps=1, log_every=2, seed=0),
                   kind="fd", out_path=tmp_path / "fd.pt", meta=META, progress=False)
    wrapper = EpsilonFromSample if prediction == "sample" else TemporalUnetDenoiser
    assert type(result.ema_model) is wrapper
    raw = torch.load(result.path, weights_only=True)
    assert raw["model_config"]["architecture"] == "temporal_unet"
    assert raw["model_config"]["unet_channels"] == [8, 16]
    assert raw["model_config"]["prediction"] == prediction
    assert not any(k.startswith("model.") for k in raw["ema_state_dict"])  # the bare network
    light = load_checkpoint(result.path).save(tmp_path / "fd_infer.pt",
                                              include_training_state=False)
    ckpt = load_checkpoint(light, expect={"kind": "fd"})
    assert ckpt.model_config == cfg
    model = ckpt.build_model()
    assert type(model) is wrapper and not model.training
    assert not any(p.requires_grad for p in model.parameters())

    start, goal = toy_problems(4)
    kw = dict(batch=4, horizon=10, conditions={0: start, -1: goal}, num_steps=5, eta=1.0)
    ref = sample(result.ema_model, DDIMScheduler(), NORMALIZER,
                 generator=torch.Generator().manual_seed(3), **kw)
    got = sample(model, ckpt.build_scheduler(), ckpt.normalizer,
                 generator=torch.Generator().manual_seed(3), **kw)
    assert torch.equal(ref.trajectories, got.trajectories)


def test_fourier_features_are_the_points_then_sin_and_cos_of_each_band():
    model = build_denoiser(DenoiserConfig(max_horizon=6, d_model=16, n_layers=1, n_heads=2,
                                          ff_mult=2, fourier_bands=3))
    assert model.point_embed.in_features == 2 + 4 * 3
    x = torch.tensor([[[0.25, -0.5], [1.0, 0.0]]])
    feats = model.point_features(x)  # (1, 2, 14)
    ang = torch.tensor([[0.25 * math.pi * f for f in (1, 2, 4)] + [-0.5 * math.pi * f for f in (1, 2, 4)],
                        [1.0 * math.pi * f for f in (1, 2, 4)] + [0.0] * 3])
    torch.testing.assert_close(feats[0], torch.cat([x[0], ang.sin(), ang.cos()], dim=-1))
    # without bands the embedding is the paper's Linear(2 -> d_model) of the point itself
    plain = build_denoiser(tiny_config())
    assert plain.point_embed.in_features == 2 and plain.point_features(x) is x


@pytest.mark.parametrize("bad", [-1, 17, 1.5, True])
def test_fourier_bands_are_checked(bad):
    with pytest.raises(ValueError, match="fourier_bands"):
        DenoiserConfig(max_horizon=6, fourier_bands=bad)
    with pytest.raises(ValueError, match="fourier_bands"):
        DenoiserConfig(max_horizon=6, architecture="temporal_unet", fourier_bands=2)


def test_fourier_checkpoint_round_trip_gives_identical_samples(tmp_path):
    cfg = DenoiserConfig(max_horizon=6, d_model=16, n_layers=1, n_heads=2, ff_mult=2,
                         fourier_bands=4)
    result = train(cfg, toy_arrays(n=32), NORMALIZER,
                   TrainConfig(steps=4, batch_size=8, warmup_steps=1, log_every=2, seed=0),
                   kind="sd", out_path=tmp_path / "sd.pt", meta=META, progress=False)
    raw = torch.load(result.path, weights_only=True)
    assert raw["model_config"]["fourier_bands"] == 4
    light = load_checkpoint(result.path).save(tmp_path / "sd_infer.pt",
                                              include_training_state=False)
    ckpt = load_checkpoint(light)
    assert ckpt.model_config == cfg
    start, goal = toy_problems(4)
    kw = dict(batch=4, horizon=6, conditions={0: start, -1: goal}, num_steps=5, eta=1.0)
    ref = sample(result.ema_model, DDIMScheduler(), NORMALIZER,
                 generator=torch.Generator().manual_seed(3), **kw)
    got = sample(ckpt.build_model(), ckpt.build_scheduler(), ckpt.normalizer,
                 generator=torch.Generator().manual_seed(3), **kw)
    assert torch.equal(ref.trajectories, got.trajectories)


@pytest.mark.slow
def test_checkpoint_without_architecture_loads_as_transformer(toy, tmp_path):
    # checkpoints written before DenoiserConfig.architecture existed (the shipped SD and DD)
    payload = torch.load(toy.path, weights_only=True)
    for key in ("architecture", "unet_channels", "unet_kernel_size", "prediction"):
        del payload["model_config"][key]
    old = tmp_path / "old.pt"
    torch.save(payload, old)
    ckpt = load_checkpoint(old)
    assert ckpt.model_config.architecture == "transformer"
    assert ckpt.model_config == load_checkpoint(toy.path).model_config
    model = ckpt.build_model()
    assert isinstance(model, TransformerDenoiser)
    x = torch.randn(2, 6, 2)
    torch.testing.assert_close(model(x, 10), toy.ema_model(x, 10), rtol=0, atol=0)


@pytest.mark.slow
def test_checkpoint_of_another_map_or_kind_is_refused(toy):
    with pytest.raises(CheckpointError, match="trained for map 'toy-4x4' \\(fingerprint "
                                              "0123456789abcdef\\), not 'maze2d-umaze'"):
        load_checkpoint(toy.path, expect={"map_name": "maze2d-umaze",
                                          "map_fingerprint": "ffffffffffffffff"})
    with pytest.raises(CheckpointError, match="trained for map"):  # same name, other layout
        load_checkpoint(toy.path, expect={"map_name": "toy-4x4", "map_fingerprint": "00"})
    with pytest.raises(CheckpointError, match="it is a 'dd' model, not 'sd'"):
        load_checkpoint(toy.path, expect={"kind": "sd"})
    with pytest.raises(CheckpointError, match="footprint is 'circle', expected 'humanoid'"):
        load_checkpoint(toy.path, expect={"footprint": "humanoid"})
    with pytest.raises(CheckpointError, match="records no 'robot'"):
        load_checkpoint(toy.path, expect={"robot": "go1"})
    load_checkpoint(toy.path, expect={"horizons": (4, 6)})  # tuples and lists compare equal


@pytest.mark.slow
def test_unreadable_checkpoints_raise_checkpoint_error(toy, tmp_path):
    with pytest.raises(CheckpointError, match="does not exist"):
        load_checkpoint(tmp_path / "missing.pt")
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"not a checkpoint at all")
    with pytest.raises(CheckpointError, match="corrupt"):
        load_checkpoint(garbage)
    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(toy.path.read_bytes()[:5000])
    with pytest.raises(CheckpointError, match="corrupt"):
        load_checkpoint(truncated)
    other = tmp_path / "other.pt"
    torch.save({"weights": torch.zeros(3)}, other)
    with pytest.raises(CheckpointError, match="not an ECAHD diffusion checkpoint"):
        load_checkpoint(other)
    payload = torch.load(toy.path, weights_only=True)
    payload["format_version"] = CHECKPOINT_VERSION + 1
    torch.save(payload, other)
    with pytest.raises(CheckpointError, match=f"format version {CHECKPOINT_VERSION + 1}"):
        load_checkpoint(other)
    del payload["ema_state_dict"]
    payload["format_version"] = CHECKPOINT_VERSION
    torch.save(payload, other)
    with pytest.raises(CheckpointError, match="incomplete or malformed"):
        load_checkpoint(other)


def test_resume_continues_exactly_from_the_saved_step(tmp_path):
    arrays = toy_arrays(n=64)
    model_cfg = tiny_config(d_model=16, n_layers=1)
    common = dict(batch_size=16, lr=1e-3, warmup_steps=5, ema_decay=0.9, seed=3, log_every=5)
    kw = dict(kind="sd", meta=META, progress=False)
    straight = train(model_cfg, arrays, NORMALIZER, TrainConfig(steps=30, **common),
                     out_path=tmp_path / "straight.pt", **kw)
    first = train(model_cfg, arrays, NORMALIZER, TrainConfig(steps=15, **common),
                  out_path=tmp_path / "part.pt", **kw)
    assert first.step == 15 and load_checkpoint(first.path).step == 15
    resumed = train(model_cfg, arrays, NORMALIZER, TrainConfig(steps=30, **common),
                    out_path=tmp_path / "resumed.pt", resume_from=first.path, **kw)
    assert resumed.step == 30 and load_checkpoint(resumed.path).step == 30
    assert [s for s, _ in resumed.loss_history] == [5, 10, 15, 20, 25, 30]
    assert resumed.loss_history == straight.loss_history
    for (name, a), b in zip(straight.ema_model.state_dict().items(),
                            resumed.ema_model.state_dict().values()):
        torch.testing.assert_close(a, b, rtol=0, atol=0, msg=name)

    with pytest.raises(CheckpointError, match="model config"):
        train(tiny_config(d_model=32, n_layers=1), arrays, NORMALIZER,
              TrainConfig(steps=30, **common), out_path=tmp_path / "x.pt",
              resume_from=first.path, **kw)
    with pytest.raises(CheckpointError, match="trained for map"):
        train(model_cfg, arrays, NORMALIZER, TrainConfig(steps=30, **common),
              out_path=tmp_path / "x.pt", resume_from=first.path, kind="sd",
              meta={**META, "map_name": "maze2d-large"}, progress=False)
    light = load_checkpoint(first.path).save(tmp_path / "light.pt", include_training_state=False)
    with pytest.raises(CheckpointError, match="no training state"):
        train(model_cfg, arrays, NORMALIZER, TrainConfig(steps=30, **common),
              out_path=tmp_path / "x.pt", resume_from=light, **kw)


def test_a_time_limit_stops_training_early_and_keeps_a_whole_checkpoint(tmp_path):
    """time_limit_s stops the loop once that many seconds have passed: far short of ``steps``,
    with the last (partial) loss window recorded and the checkpoint at the step reached; the
    steps taken are those of the same run without a limit (the same losses)."""
    arrays = toy_arrays(n=64)
    model_cfg = tiny_config(d_model=16, n_layers=1)
    common = dict(batch_size=16, lr=1e-3, warmup_steps=5, ema_decay=0.9, seed=3, log_every=50)
    kw = dict(kind="sd", meta=META, progress=False)
    limited = train(model_cfg, arrays, NORMALIZER,
                    TrainConfig(steps=10 ** 7, time_limit_s=0.3, **common),
                    out_path=tmp_path / "limited.pt", **kw)
    assert 0 < limited.step < 10 ** 7
    assert load_checkpoint(limited.path).step == limited.step
    assert limited.loss_history[-1][0] == limited.step
    full = train(model_cfg, arrays, NORMALIZER, TrainConfig(steps=limited.step, **common),
                 out_path=tmp_path / "full.pt", **kw)
    assert full.loss_history == limited.loss_history
    with pytest.raises(ValueError, match="time_limit_s"):
        TrainConfig(steps=1, time_limit_s=0)


@pytest.mark.slow
def test_bf16_training_runs_under_autocast_and_keeps_float32_weights(tmp_path):
    """precision="bf16": the forward pass runs in bfloat16 (so the weights differ from the
    float32 run's), the loss falls as in float32, and weights and EMA stay float32."""
    arrays = toy_arrays(n=128)
    common = dict(steps=60, batch_size=32, lr=3e-3, warmup_steps=5, ema_decay=0.9, seed=1,
                  log_every=20)
    kw = dict(kind="sd", meta=META, progress=False)
    runs = {p: train(tiny_config(d_model=16, n_layers=1), arrays, NORMALIZER,
                     TrainConfig(precision=p, **common), out_path=tmp_path / f"{p}.pt", **kw)
            for p in ("fp32", "bf16")}
    for p, run in runs.items():
        ckpt = load_checkpoint(run.path)
        assert ckpt.train_config["precision"] == p
        assert all(v.dtype == torch.float32 for v in ckpt.ema_state_dict.values()
                   if v.is_floating_point())
        losses = [loss for _, loss in run.loss_history]
        assert np.isfinite(losses).all() and losses[-1] < 0.7 * losses[0], (p, losses)
    a, b = (runs[p].ema_model.state_dict() for p in ("fp32", "bf16"))
    assert any(not torch.equal(a[k], b[k]) for k in a)
    fp32, bf16 = (runs[p].loss_history[-1][1] for p in ("fp32", "bf16"))
    assert bf16 == pytest.approx(fp32, rel=0.3)


def test_precision_choice():
    assert resolve_precision("fp32") == "fp32" and resolve_precision("bf16") == "bf16"
    assert resolve_precision("auto") == ("bf16" if native_bf16("cpu") else "fp32")
    assert resolve_precision("auto", "meta") == "fp32"
    with pytest.raises(ValueError, match="precision"):
        resolve_precision("fp16")
    with pytest.raises(ValueError, match="TrainConfig.precision"):
        TrainConfig(steps=1, precision="fp16")


def test_bad_training_input_is_reported(tmp_path):
    with pytest.raises(TypeError):
        TrainConfig(100)  # keyword-only
    with pytest.raises(ValueError, match="steps"):
        TrainConfig(steps=0)
    cfg = TrainConfig(steps=1, batch_size=4)
    kw = dict(out_path=tmp_path / "x.pt", progress=False)
    with pytest.raises(ValueError, match="'sd', 'dd', 'fd'"):
        train(tiny_config(), toy_arrays(n=8), NORMALIZER, cfg, kind="xd", **kw)
    with pytest.raises(DatasetError, match=r"shape \(N, 4, 2\)"):
        train(tiny_config(), {4: np.zeros((8, 5, 2))}, NORMALIZER, cfg, kind="sd", **kw)
    with pytest.raises(DatasetError, match="2..6"):
        train(tiny_config(), {8: np.zeros((8, 8, 2))}, NORMALIZER, cfg, kind="sd", **kw)
    with pytest.raises(DatasetError, match="nothing to learn"):
        train(tiny_config(), {2: np.zeros((8, 2, 2))}, NORMALIZER, cfg, kind="sd", **kw)
    with pytest.raises(ValueError, match="plain data"):
        train(tiny_config(), toy_arrays(n=8), NORMALIZER, cfg, kind="sd",
              meta={"grid": object()}, **kw)


def test_fully_inpainted_horizon_is_not_trained_on(tmp_path):
    # SD's horizon 2 is [start, goal]: no waypoint carries a loss (an empty mean would be NaN).
    arrays = toy_arrays(n=32, horizons=(2, 3))
    cfg = TrainConfig(steps=20, batch_size=8, log_every=5, seed=0)
    result = train(tiny_config(d_model=16, n_layers=1), arrays, NORMALIZER, cfg, kind="sd",
                   out_path=tmp_path / "sd.pt", progress=False)
    assert all(np.isfinite(loss) for _, loss in result.loss_history)
    assert load_checkpoint(result.path).horizons == (2, 3)
    # without goal inpainting horizon 2 has one free waypoint and is trained on
    cfg = TrainConfig(steps=5, batch_size=8, log_every=5, seed=0, inpaint_goal=False)
    result = train(tiny_config(d_model=16, n_layers=1), {2: arrays[2]}, NORMALIZER, cfg,
                   kind="sd", out_path=tmp_path / "sd_start.pt", progress=False)
    assert np.isfinite(result.loss_history[-1][1])
    assert load_checkpoint(result.path).conditioned_indices == (0,)


def test_default_models_fit_the_size_budget(tmp_path):
    # The three recipes' inference checkpoints (SD horizon 10, DD 4, FD 100) must stay under
    # 20 MB together.
    from ecahd_core.model_zoo import RECIPES

    total = 0
    for kind, horizon in (("sd", 10), ("dd", 4), ("fd", 100)):
        cfg = RECIPES[kind].denoiser_config(horizon)
        model = build_denoiser(cfg)
        assert count_parameters(model) < 1_100_000
        ckpt = Checkpoint(kind=kind, model_config=cfg, schedule_config=ScheduleConfig(),
                          normalizer=NORMALIZER, conditioned_indices=(0, -1),
                          horizons=(horizon,), ema_state_dict=model.state_dict(), step=0,
                          meta={}, train_config={})
        total += ckpt.save(tmp_path / f"{kind}.pt", include_training_state=False).stat().st_size
    assert total < 20e6  # measured: ~8.7 MB (SD 3.5, DD 1.1, FD U-Net 4.2)


DDP_SCRIPT = textwrap.dedent("""
    import os, sys
    import numpy as np
    import torch
    from ecahd_core.diffusion.denoiser import DenoiserConfig
    from ecahd_core.diffusion.normalizer import Normalizer
    from ecahd_core.diffusion.training import TrainConfig, train

    data = np.load(sys.argv[1])
    arrays = {int(k[1:]): data[k] for k in data.files}
    result = train(DenoiserConfig(max_horizon=6, d_model=16, n_layers=1, n_heads=2, ff_mult=2),
                   arrays, Normalizer.from_bounds(0, 0, 4, 4),
                   TrainConfig(steps=6, batch_size=8, warmup_steps=2, log_every=3, seed=0),
                   kind="dd", out_path=sys.argv[2], meta={"map_name": "toy-4x4"},
                   progress=False)
    checksum = sum(float(p.double().sum()) for p in result.ema_model.parameters())
    rank = os.environ["RANK"]
    with open(sys.argv[3] + rank, "w") as f:  # one report per rank (stdout interleaves)
        f.write(f"rank={rank} wrote={result.checkpoint is not None} "
                f"step={result.step} checksum={checksum:.10f}")
""")


def _free_port():
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_ddp_on_two_cpu_processes_writes_one_checkpoint(tmp_path):
    script = tmp_path / "ddp_train.py"
    script.write_text(DDP_SCRIPT)
    np.savez(tmp_path / "data.npz", **{f"h{h}": a for h, a in toy_arrays(n=32).items()})
    out = tmp_path / "ddp.pt"
    env = dict(os.environ, OMP_NUM_THREADS="1")
    for attempt in range(2):
        cmd = [sys.executable, "-m", "torch.distributed.run", "--nnodes", "1",
               "--nproc_per_node", "2", "--master_addr", "127.0.0.1", "--master_port",
               str(_free_port()), str(script), str(tmp_path / "data.npz"), str(out),
               str(tmp_path / "report")]
        proc = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True,
                              timeout=180)
        # gloo on 2 cores now and then aborts a rank at exit (std::terminate, SIGABRT; once
        # in six CI runs on 2026-12-03): one more run then, any other failure fails at once
        if proc.returncode == 0 or "terminate called without an active exception" not in (
                proc.stdout + proc.stderr):
            break
    assert proc.returncode == 0, proc.stdout + proc.stderr
    lines = [(tmp_path / f"report{rank}").read_text() for rank in (0, 1)]
    assert [line.split()[:3] for line in lines] == [["rank=0", "wrote=True", "step=6"],
                                                    ["rank=1", "wrote=False", "step=6"]]
    # gradients are all-reduced: both ranks hold the same weights despite different shards
    assert lines[0].split()[3] == lines[1].split()[3]
    ckpt = load_checkpoint(out, expect={"kind": "dd", "map_name": "toy-4x4"})
    assert ckpt.step == 6 and ckpt.horizons == (4, 6)
    assert not list(Path(tmp_path).glob("*.tmp"))
