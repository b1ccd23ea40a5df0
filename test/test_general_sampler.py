"""The generalist SD as Algorithm 1's sampler (ecahd_core.general.sampler): SparseDiffusion plans
with a map-conditioned checkpoint through the per-map SD's code (best of N, J's selection,
placement, densify, warm starts); rows of one batch that are different problems get their own
views and memory; ``load_sd`` tells the two kinds of checkpoint apart. A tiny untrained model:
these tests check the plumbing, not the plans' quality (``ecahd bench planning --model``)."""
import numpy as np
import pytest
import torch

from ecahd_core.diffusion.scheduler import ScheduleConfig
from ecahd_core.errors import CheckpointError, PlanningError
from ecahd_core.footprint import make_footprint
from ecahd_core.general.checkpoint import GeneralCheckpoint
from ecahd_core.general.model import GeneralDenoiserConfig, MapConditionedDenoiser
from ecahd_core.general.sampler import GeneralSampler, RowNormalizer
from ecahd_core.general.views import make_views
from ecahd_core.maps import builtin_map
from ecahd_core.model_zoo import GENERAL, load_sd
from ecahd_core.planning.sparse import SparseConfig, SparseDiffusion

START, GOAL = (1.5, 1.5), (6.5, 5.5)  # free cells of maze2d-large


pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def tiny_general(tmp_path_factory):
    """An untrained tiny generalist checkpoint file (seeded weights)."""
    torch.manual_seed(0)
    config = GeneralDenoiserConfig(max_horizon=10, d_model=32, n_layers=2, n_heads=2, ff_mult=2,
                                   global_channels=(8, 8, 16), local_channels=(8, 8, 8))
    model = MapConditionedDenoiser(config)
    ckpt = GeneralCheckpoint(model_config=config, schedule_config=ScheduleConfig(),
                             conditioned_indices=(0, -1), horizons=tuple(range(2, 11)),
                             ema_state_dict=model.state_dict(), step=0, train_config={},
                             data={})
    return ckpt.save(tmp_path_factory.mktemp("general") / "g.pt",
                     include_training_state=False)


def test_row_normalizer_round_trip_and_chain_rule():
    n = RowNormalizer(torch.tensor([[1.0, 2.0], [10.0, -5.0]]), torch.tensor([2.0, 8.0]))
    x = torch.tensor([[[3.0, 2.0], [1.0, 4.0]], [[18.0, -5.0], [10.0, 3.0]]])  # (2, 2, 2)
    u = n.normalize(x)
    assert torch.allclose(u, torch.tensor([[[1.0, 0.0], [0.0, 1.0]], [[1.0, 0.0], [0.0, 1.0]]]))
    assert torch.allclose(n.unnormalize(u), x)
    assert torch.allclose(n.normalize(x[:, 0]), u[:, 0])  # (B, 2) conditions
    assert torch.allclose(n.grad_to_normalized(torch.ones(2, 2, 2))[:, 0, 0],
                          torch.tensor([2.0, 8.0]))
    with pytest.raises(Exception, match=r"\(2, 2\) or \(2, P, 2\)"):
        n.normalize(torch.zeros(3, 2))


def test_sparse_diffusion_plans_with_the_generalist(tiny_general):
    grid = builtin_map("maze2d-large")
    robot = make_footprint("circle")
    sd = SparseDiffusion.for_map(grid, robot, SparseConfig(), model=str(tiny_general))
    assert sd.general and isinstance(sd.sampler, GeneralSampler)
    assert sd.expert_spacing is None
    plans = [sd.plan(START, GOAL, generator=torch.Generator().manual_seed(3), densify=False)
             for _ in range(2)]
    for plan in plans:
        assert plan.candidates.shape == (10, 10, 2)
        np.testing.assert_allclose(plan.candidates[:, 0], np.tile(START, (10, 1)), atol=1e-5)
        np.testing.assert_allclose(plan.candidates[:, -1], np.tile(GOAL, (10, 1)), atol=1e-5)
        assert np.isfinite(plan.waypoints).all()
    np.testing.assert_array_equal(plans[0].candidates, plans[1].candidates)  # seeded
    # a warm re-plan from the previous plan runs (the warm start goes through the views' frame)
    again = sd.replan(START, GOAL, plans[0].candidates[0], generator=torch.Generator())
    assert np.isfinite(again.waypoints).all()


def test_rows_of_different_problems_get_their_own_views(tiny_general):
    """A batch of two problems: row 0 is what a batch of problem 0 alone gives for the same
    noise (each row its own views, memory and frame)."""
    grid = builtin_map("maze2d-large")
    sd = SparseDiffusion.for_map(grid, make_footprint("circle"), model=str(tiny_general))
    a = np.array([START, (2.5, 3.5)], dtype=np.float32)
    b = np.array([GOAL, (10.5, 1.5)], dtype=np.float32)

    def run(starts, goals):
        return sd.sampler.sample(batch=2, horizon=6, conditions={0: starts, -1: goals},
                                 generator=torch.Generator().manual_seed(5)).trajectories

    mixed = run(a, b)
    alone = run(a[[0, 0]], b[[0, 0]])
    torch.testing.assert_close(mixed[0], alone[0], rtol=1e-4, atol=1e-4)
    assert not torch.allclose(mixed[1], alone[1])
    np.testing.assert_allclose(mixed[:, 0].numpy(), a, atol=1e-5)
    np.testing.assert_allclose(mixed[:, -1].numpy(), b, atol=1e-5)
    # the views are those make_views gives for the problem
    views = make_views(grid, a, b, sd.sampler.view_config)
    assert views.global_view.shape[0] == 2


def test_load_sd_tells_the_kinds_apart_and_names_bad_files(tiny_general, tmp_path,
                                                             monkeypatch):
    grid = builtin_map("maze2d-large")
    assert isinstance(load_sd(grid, path=tiny_general), GeneralCheckpoint)
    per_map = load_sd(grid)  # the map's own shipped SD
    assert not isinstance(per_map, GeneralCheckpoint)
    with pytest.raises(CheckpointError, match="not 12"):
        load_sd(grid, path=tiny_general, horizon=12)
    broken = tmp_path / "broken.pt"
    broken.write_bytes(tiny_general.read_bytes()[:1000])
    with pytest.raises(CheckpointError, match="broken.pt"):
        load_sd(grid, path=broken)
    monkeypatch.setattr("ecahd_core.model_zoo.MODELS_DIR", tmp_path)
    monkeypatch.setenv("ECAHD_MODELS", "")
    with pytest.raises(CheckpointError, match="general_sd.pt"):
        load_sd(grid, path=GENERAL)


def test_a_problem_wider_than_the_views_is_named(tiny_general):
    from ecahd_core.maps import GridMap

    grid = GridMap(np.zeros((200, 1200), dtype=np.int8), 0.1, (0.0, 0.0), name="long")
    sd = SparseDiffusion.for_map(grid, make_footprint("circle"), model=str(tiny_general))
    with pytest.raises(PlanningError, match="over the 96 m"):
        sd.plan((1.0, 10.0), (119.0, 10.0))


def test_a_map_without_a_model_of_its_own_gets_the_generalist(tiny_general, tmp_path,
                                                               monkeypatch):
    """No model named and none for the map: the generalist on the search path serves it (SD
    and the nodes' start-up check); a map with its own per-map model keeps it."""
    import shutil

    from ecahd_core.model_zoo import check_model, is_general

    models = tmp_path / "models"
    models.mkdir()
    shutil.copy(tiny_general, models / "general_sd.pt")
    monkeypatch.setenv("ECAHD_MODELS", str(models))
    umaze = builtin_map("maze2d-umaze")  # no per-map model ships for it
    assert isinstance(load_sd(umaze), GeneralCheckpoint)
    assert check_model("sd", "maze2d-umaze", horizon=10) == models / "general_sd.pt"
    assert is_general("sd", "", "maze2d-umaze") and not is_general("sd", "", "maze2d-large")
    assert not isinstance(load_sd(builtin_map("maze2d-large")), GeneralCheckpoint)
