"""Training recipes, the train commands, checkpoint identity checks, best-of-N selection."""
import numpy as np
import pytest

from ecahd_core.dataset import ExpertDataset, generate_dataset
from ecahd_core.errors import CheckpointError, EcahdError
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import builtin_map
from ecahd_core.model_zoo import RECIPES, load_model, model_meta, training_arrays
from ecahd_core.planning.sparse import select_best
from ecahd_ros.cli import main


@pytest.fixture(scope="module")
def umaze_data(tmp_path_factory):
    path = tmp_path_factory.mktemp("data") / "umaze.npz"
    ds = generate_dataset(builtin_map("maze2d-umaze"), pairs=12, seed=3, min_distance=1.5,
                          progress=False)
    ds.save(path)
    return ExpertDataset.load(path), path


@pytest.fixture(scope="module")
def tiny_sd(umaze_data, tmp_path_factory):
    _, data = umaze_data
    out = tmp_path_factory.mktemp("ckpt") / "sd.pt"
    ship = out.with_name("sd_ship.pt")
    assert main(["train", "sd", "--data", str(data), "--out", str(out), "--ship", str(ship),
                 "--steps", "3", "--batch-size", "8", "--warmup", "1", "--no-progress"]) == 0
    return out, ship


def test_training_arrays_views(umaze_data):
    ds, _ = umaze_data
    sd = training_arrays("sd", ds)
    assert sorted(sd) == list(range(2, 11))
    for h, arr in sd.items():
        # suffix view + whole-path view, both start-to-goal of h points
        assert arr.shape == (2 * ds.num_pairs, h, 2)
        assert np.allclose(arr[ds.num_pairs:, 0], ds.starts, atol=1e-5)
        assert np.allclose(arr[:, -1], np.concatenate([ds.goals, ds.goals]), atol=1e-5)
    assert training_arrays("dd", ds)[4].shape == (9 * ds.num_pairs, 4, 2)
    assert training_arrays("fd", ds)[100].shape == (ds.num_pairs, 100, 2)
    with pytest.raises(CheckpointError, match="unknown model kind"):
        training_arrays("xd", ds)


def test_meta_records_identity(umaze_data):
    ds, _ = umaze_data
    meta = model_meta("sd", ds)
    assert meta["map_name"] == "maze2d-umaze" and meta["dataset_sha256"] == ds.sha256
    assert meta["clearance"] == pytest.approx(0.4) and meta["sample_steps"] == RECIPES["sd"].sample_steps
    # SD records how far apart the expert's waypoints lie: median path length / (P^g - 1)
    lengths = np.linalg.norm(np.diff(ds.full, axis=1), axis=-1).sum(axis=1)
    assert meta["expert_spacing"] == pytest.approx(
        np.median(lengths) / (ds.params["sparse_horizon"] - 1), abs=1e-4)
    assert "expert_spacing" not in model_meta("dd", ds)


def test_sd_reads_its_expert_spacing(tiny_sd):
    from ecahd_core.planning.sparse import SparseDiffusion

    out, _ = tiny_sd
    ckpt = load_model("sd", builtin_map("maze2d-umaze"), path=out)
    assert SparseDiffusion(ckpt).expert_spacing == pytest.approx(ckpt.meta["expert_spacing"])
    ckpt.meta.pop("expert_spacing")  # a checkpoint from before it was recorded
    assert SparseDiffusion(ckpt).expert_spacing is None


def test_train_command_writes_full_and_shipped_checkpoints(tiny_sd):
    out, ship = tiny_sd
    grid = builtin_map("maze2d-umaze")
    full = load_model("sd", grid, path=out)
    shipped = load_model("sd", grid, path=ship)
    assert full.training_state is not None and shipped.training_state is None
    assert ship.stat().st_size < out.stat().st_size
    assert full.step == 3


@pytest.mark.slow
def test_resume_continues(tiny_sd, umaze_data, tmp_path):
    out, _ = tiny_sd
    _, data = umaze_data
    more = tmp_path / "sd5.pt"
    assert main(["train", "sd", "--data", str(data), "--out", str(more), "--resume", str(out),
                 "--steps", "5", "--batch-size", "8", "--warmup", "1", "--no-progress"]) == 0
    assert load_model("sd", builtin_map("maze2d-umaze"), path=more).step == 5


def test_wrong_map_robot_horizon_raise(tiny_sd):
    _, ship = tiny_sd
    with pytest.raises(CheckpointError, match="trained for map 'maze2d-umaze'"):
        load_model("sd", builtin_map("maze2d-medium"), path=ship)
    with pytest.raises(CheckpointError, match="not 'dd'|is a 'sd' model"):
        load_model("dd", builtin_map("maze2d-umaze"), path=ship)
    big = make_footprint("circle", radius=0.45)
    with pytest.raises(CheckpointError, match="0.400 m clearance"):
        load_model("sd", builtin_map("maze2d-umaze"), path=ship, footprint=big)
    with pytest.raises(CheckpointError, match="horizons"):
        load_model("sd", builtin_map("maze2d-umaze"), path=ship, horizon=12)
    # smaller robots are fine
    load_model("sd", builtin_map("maze2d-umaze"), path=ship, footprint=make_footprint("humanoid"),
               horizon=10)


def test_missing_or_corrupt_checkpoint(tmp_path):
    with pytest.raises(CheckpointError, match="no 'sd' model for map 'maze2d-umaze'"):
        load_model("sd", builtin_map("maze2d-umaze"))
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(CheckpointError, match="cannot read"):
        load_model("sd", builtin_map("maze2d-umaze"), path=bad)


def test_select_best_paper_rule():
    goal = np.array([5.0, 0.0])
    # 0: reaches the goal (ends at it), length 5 + a detour of 2 -> 7
    # 1: reaches, straight, length 5
    # 2: shortest (length 1) but ends 4 m from the goal: not reaching
    c = np.array([
        [[0, 0], [0, 1], [5, 1], [5, 0]],
        [[0, 0], [2, 0], [4, 0], [5, 0]],
        [[0, 0], [0.5, 0], [0.75, 0], [1, 0]],
    ], dtype=float)
    assert select_best(c, goal) == 1
    # none reaches (goal far away): the shortest overall
    assert select_best(c, np.array([50.0, 50.0])) == 2
    # collision-aware: candidate 1 collides, 0 does not -> 0 despite being longer
    assert select_best(c, goal, rule="collision_aware",
                       collision_costs=np.array([0.0, 3.0, 0.0])) == 0
    with pytest.raises(EcahdError, match="shortest_reaching"):
        select_best(c, goal, rule="best")


@pytest.fixture(scope="module")
def umaze_models(tmp_path_factory):
    """The folder of the inference-only SD, DD and FD models that ``ecahd train-all`` makes on
    the small maze at a thousandth of the recipes' steps (dataset + 3 models, the slowest part
    of this file: made once, for the tests that need trained files)."""
    root = tmp_path_factory.mktemp("train_all")
    assert main(["train-all", "--map", "maze2d-umaze", "--pairs", "6", "--steps-scale", "0.001",
                 "--work-dir", str(root / "work"), "--out-dir", str(root / "models"),
                 "--no-progress", "--kinds", "sd", "dd", "fd"]) == 0
    return root / "models"


@pytest.mark.slow
def test_train_all_tiny(umaze_models):
    # the whole recipe at a thousandth of its steps on the small maze: dataset + 3 models
    assert sorted(p.name for p in umaze_models.iterdir()) == [
        "maze2d-umaze_dd.pt", "maze2d-umaze_fd.pt", "maze2d-umaze_sd.pt"]
    grid = builtin_map("maze2d-umaze")
    for kind in ("sd", "dd", "fd"):
        ckpt = load_model(kind, grid, path=umaze_models / f"maze2d-umaze_{kind}.pt")
        assert ckpt.training_state is None and ckpt.meta["dataset_pairs"] == 6


def test_train_all_trains_sd_and_dd_by_default():
    import argparse

    from ecahd_core.commands.train import add_all_arguments

    parser = argparse.ArgumentParser()
    add_all_arguments(parser)
    assert parser.parse_args([]).kinds == ["sd", "dd"]  # what ECAHD needs; FD on request


@pytest.mark.slow
def test_train_all_fits_its_steps_to_a_time_budget(tmp_path, capsys, monkeypatch):
    import re

    from ecahd_core.commands import train
    from ecahd_core.commands.train import BUDGET_FILL, STEP_CAP, budget_scale

    assert budget_scale(100.0, {"sd": 30.0, "dd": 20.0}) == pytest.approx(2 * BUDGET_FILL)
    with pytest.raises(EcahdError, match="budget is spent"):
        budget_scale(-5.0, {"sd": 30.0})
    args = ["train-all", "--map", "maze2d-umaze", "--pairs", "6", "--work-dir",
            str(tmp_path / "work"), "--out-dir", str(tmp_path / "models"), "--no-progress"]

    def steps_of(out):
        found = re.search(r"budget: recipes' steps x ([0-9.e+-]+) \(SD (\d+), DD (\d+)", out)
        assert found, out
        taken = {k: int(re.search(rf"^{k}: (\d+) steps", out, re.M)[1]) for k in ("sd", "dd")}
        return float(found[1]), {"sd": int(found[2]), "dd": int(found[3])}, taken

    # the step-time probe reads a slow machine (0.8 s a step): 12 s leave a few steps of every
    # recipe by the estimate, one factor on every recipe; the machine is in fact far faster
    # (room for a slow first step, and for a machine busy with other work: at 0.4 s a step a
    # loaded machine once fell one step short), so each model trains on to the cap (STEP_CAP x
    # its estimate), not past it
    monkeypatch.setattr(train, "seconds_per_step", lambda *a, **k: 0.8)
    assert main(args + ["--minutes", "0.2"]) == 0
    scale, estimated, taken = steps_of(capsys.readouterr().out)
    assert 0 < scale < BUDGET_FILL * 12 / (0.8 * RECIPES["sd"].steps)
    for k in ("sd", "dd"):
        assert abs(estimated[k] - RECIPES[k].steps * scale) <= 1 + 0.01 * estimated[k]
        assert estimated[k] <= taken[k] <= int(estimated[k] * STEP_CAP)
    # the probe reads a far faster machine than this (1e-5 s a step): the time limit, not the
    # estimate, stops each model, and train-all still ends within its budget
    monkeypatch.setattr(train, "seconds_per_step", lambda *a, **k: 1e-5)
    assert main(args + ["--minutes", "0.05"]) == 0
    scale, estimated, taken = steps_of(capsys.readouterr().out)
    assert all(0 < taken[k] < estimated[k] for k in ("sd", "dd")), (estimated, taken)
    assert main(args + ["--minutes", "1", "--steps-scale", "2"]) == 2  # one or the other


@pytest.mark.slow
def test_models_are_found_through_ecahd_models(umaze_models, tmp_path, monkeypatch):
    from ecahd_core.model_zoo import MODELS_DIR, model_search_path, shipped_path

    grid = builtin_map("maze2d-umaze")
    monkeypatch.delenv("ECAHD_MODELS", raising=False)
    with pytest.raises(CheckpointError, match="no 'sd' model for map 'maze2d-umaze'.*ECAHD_MODELS"):
        load_model("sd", grid)
    monkeypatch.setenv("ECAHD_MODELS", f"{tmp_path / 'empty'}:{umaze_models}")
    assert model_search_path() == [tmp_path / "empty", umaze_models, MODELS_DIR]
    assert shipped_path("maze2d-umaze", "sd") == umaze_models / "maze2d-umaze_sd.pt"
    assert load_model("sd", grid).meta["dataset_pairs"] == 6
    # the package's own models stay found behind the others
    assert shipped_path("maze2d-large", "sd") == MODELS_DIR / "maze2d-large_sd.pt"


def test_dd_batch_keeps_the_tokens_per_step_for_longer_local_plans():
    from ecahd_core.model_zoo import recipe

    dd, sd = recipe("dd"), recipe("sd")
    assert dd.batch_for(4) == dd.batch_size == 256  # the paper's P^l: unchanged
    assert dd.batch_for(15) == round(256 * 5 / 16) == 80
    assert dd.batch_for(1000) == 32
    assert sd.batch_for(10) == sd.batch_size  # SD's batch is not scaled


def test_sd_gets_fourier_bands_down_to_half_a_metre_on_a_building_map_only():
    from ecahd_core.maps import GridMap
    from ecahd_core.model_zoo import FOURIER_PERIOD, fourier_bands, recipe

    office = GridMap(data=np.zeros((1200, 1000), dtype=np.int8), resolution=0.05)  # 50 x 60 m
    bands = fourier_bands(office, FOURIER_PERIOD)
    finest = 2 * 30.0 / 2 ** (bands - 1)  # [m] the period of the last band (half-extent 30 m)
    assert bands == 7 and FOURIER_PERIOD <= finest < 2 * FOURIER_PERIOD
    assert recipe("sd").denoiser_config(10, office).fourier_bands == bands
    assert recipe("dd").denoiser_config(4, office).fourier_bands == 0
    assert recipe("sd").denoiser_config(10).fourier_bands == 0
    # maze2d-large keeps the paper's embedding (and its tables' models)
    assert fourier_bands(builtin_map("maze2d-large"), FOURIER_PERIOD) == 0
    assert recipe("sd").denoiser_config(10, builtin_map("maze2d-large")).fourier_bands == 0


@pytest.mark.slow
def test_train_gives_sd_fourier_features_on_a_building_map_and_none_with_period_0(tmp_path):
    import torch

    yaml_path, data = tmp_path / "depot.yaml", tmp_path / "depot.npz"
    # 12 x 12 m at 0.05 m/cell: 57 600 cells, over the 50 000 of a building's map
    assert main(["map", "generate", "--kind", "depot", "--size", "12", "12", "--resolution",
                 "0.05", "--seed", "3", "--out", str(yaml_path)]) == 0
    assert main(["dataset", "--map", str(yaml_path), "--pairs", "4", "--min-distance", "2",
                 "--out", str(data), "--no-progress"]) == 0
    tiny = ["--steps", "2", "--batch-size", "4", "--warmup", "1", "--no-progress"]
    bands = {}
    for period in (None, "0"):
        out = tmp_path / f"sd_{period}.pt"
        extra = [] if period is None else ["--fourier-period", period]
        assert main(["train", "sd", "--data", str(data), "--out", str(out), *tiny, *extra]) == 0
        bands[period] = torch.load(out, weights_only=True)["model_config"]["fourier_bands"]
    assert bands == {None: 5, "0": 0}  # floor(log2(12 m / 0.5 m)) + 1 = 5
    assert main(["train", "sd", "--data", str(data), "--out", str(tmp_path / "x.pt"), *tiny,
                 "--fourier-period", "-1"]) == 2
