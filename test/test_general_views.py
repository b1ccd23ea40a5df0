"""The generalist SD's foundation (issue 40): the map views (ecahd_core.general.views), the
map-conditioned denoiser (ecahd_core.general.model) and the sharded dataset
(ecahd_core.general.data). Hand-built grids; expected pixels derived in the comments."""
import numpy as np
import pytest
import torch

from ecahd_core.diffusion.denoiser import DenoiserConfig
from ecahd_core.errors import DatasetError, EcahdError, PlanningError
from ecahd_core.general.data import GeneralDataConfig, GeneralDataset, build
from ecahd_core.general.model import (GeneralDenoiserConfig, MapConditionedDenoiser,
                                      ViewTensors)
from ecahd_core.general.views import (FRACTION_LEVELS, OccupancyIntegral, ViewConfig,
                                      make_views, view_frames)
from ecahd_core.maps import FREE, OCCUPIED, GridMap
from ecahd_core.mapgen import MapGenConfig, generate_map

PROBLEM = ViewConfig(extent="problem")


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def wall_grid(origin=(0.0, 0.0)) -> GridMap:
    """10 x 10 m at 0.1 m/cell, free but for a wall in column 50: x in [5.0, 5.1) + origin."""
    data = np.full((100, 100), FREE, dtype=np.int8)
    data[:, 50] = OCCUPIED
    return GridMap(data=data, resolution=0.1, origin=origin)


def test_wall_appears_at_the_expected_global_pixel():
    # S (3, 5), G (7, 5): box 4 m wide, margin max(2, 0.25 * 4) = 2 m -> side max(8, 4 + 4) = 8 m
    # on (5, 5): the view spans x, y in [1, 9], 0.125 m/px. Column c covers
    # [1 + 0.125 c, 1 + 0.125 (c + 1)): the wall [5.0, 5.1) is in column 32 = [5.0, 5.125) only
    # (column 31 ends where the wall starts). Column 32 overlaps cells 50 and 51 (one a wall)
    # and each row overlaps 2 cell rows: fraction 2 / 4.
    views = make_views(wall_grid(), [3.0, 5.0], [7.0, 5.0], PROBLEM)
    assert views.global_view.shape == (1, 2, 64, 64)
    assert views.local_views.shape == (1, 2, 2, 32, 32)
    np.testing.assert_allclose(views.frame.centre, [[5.0, 5.0]])
    np.testing.assert_allclose(views.frame.half_side, [4.0])
    any_, frac = views.global_view[0]
    assert np.flatnonzero(any_.any(axis=0)).tolist() == [32]
    assert any_[:, 32].all()
    np.testing.assert_allclose(frac[:, 32], round(0.5 * FRACTION_LEVELS) / FRACTION_LEVELS)
    # the local view round G (7, 5) spans x in [5.4, 8.6): no wall; round S neither
    assert not views.local_views.any()


def test_wall_in_a_local_view_and_off_map_is_occupied():
    # G (6, 5): its local view spans x in [4.4, 7.6) at 0.1 m/px; column 6 = [5.0, 5.1) is
    # exactly the wall cell
    views = make_views(wall_grid(), [3.0, 5.0], [6.0, 5.0], PROBLEM)
    goal_any = views.local_views[0, 1, 0]
    assert np.flatnonzero(goal_any.any(axis=0)).tolist() == [6]
    np.testing.assert_array_equal(views.local_views[0, 1, 1, :, 6], 1.0)
    # S (0.5, 0.5), G (2.5, 0.5): side 8 m on (1.5, 0.5): x in [-2.5, 5.5], y in [-3.5, 4.5].
    # Columns 0..19 (x < 0) and rows 0..27 (y < 0) are off the map: occupied, fraction 1
    views = make_views(wall_grid(), [0.5, 0.5], [2.5, 0.5], PROBLEM)
    any_, frac = views.global_view[0]
    assert (frac[:, :20] == 1).all() and (frac[:28, :] == 1).all()
    assert not any_[28:, 20:60].any()  # on the map, left of the wall (x in [0, 5)): free
    assert any_[28:, 60].all()  # column 60 = [5.0, 5.125): the wall


def test_world_view_round_trip_and_map_extent():
    grid = wall_grid()
    rng = np.random.default_rng(0)
    starts, goals = rng.uniform(0.5, 9.5, (5, 2)), rng.uniform(0.5, 9.5, (5, 2))
    for config in (PROBLEM, ViewConfig()):
        frame = view_frames(starts, goals, config, bounds=grid.bounds)
        pts = rng.uniform(-20, 20, (5, 7, 2))
        np.testing.assert_allclose(frame.to_world(frame.to_view(pts)), pts, atol=1e-9, rtol=0)
        u = frame.to_view(np.stack([starts, goals], axis=1))
        assert (np.abs(u) <= 1).all()
    # "map" extent: the whole 10 m map plus 2 m each side, on the map's centre
    frame = view_frames(starts, goals, ViewConfig(), bounds=grid.bounds)
    np.testing.assert_allclose(frame.centre, np.full((5, 2), 5.0))
    np.testing.assert_allclose(frame.half_side, 7.0)


@pytest.mark.parametrize("config", [PROBLEM, ViewConfig()], ids=["problem", "map"])
def test_views_do_not_depend_on_the_map_origin(config):
    grid = generate_map(MapGenConfig(kind="office", width=12, height=10, resolution=0.1, seed=3))
    shift = np.array([123.45, -67.8])
    moved = GridMap(data=grid.data, resolution=grid.resolution, origin=tuple(shift))
    free = grid.free_cell_centres()
    rng = np.random.default_rng(1)
    starts, goals = free[rng.integers(len(free), size=4)], free[rng.integers(len(free), size=4)]
    a = make_views(grid, starts, goals, config)
    b = make_views(moved, starts + shift, goals + shift, config)
    np.testing.assert_array_equal(a.global_view, b.global_view)
    np.testing.assert_array_equal(a.local_views, b.local_views)
    pts = rng.uniform(0, 10, (4, 3, 2))
    np.testing.assert_allclose(a.frame.to_view(pts), b.frame.to_view(pts + shift), atol=1e-9)


def test_bad_input_is_an_ecahd_error_naming_the_problem():
    grid = wall_grid()
    with pytest.raises(PlanningError, match=r"starts\[1\] has non-finite"):
        make_views(grid, [[1.0, 1.0], [np.nan, 2.0]], [[2.0, 2.0], [3.0, 3.0]])
    with pytest.raises(EcahdError, match="over the 9 m"):  # 6 m apart: 6 + 2 x 2 = 10 m > 9
        make_views(grid, [1.0, 1.0], [7.0, 1.0], ViewConfig(max_side=9.0, extent="problem"))
    with pytest.raises(PlanningError, match="differ in shape"):
        make_views(grid, [[1.0, 1.0]], [[2.0, 2.0], [3.0, 3.0]])
    # a map larger than max_side falls back to the problem's view (10 + 4 m > 9 m)
    frame = view_frames([1.0, 1.0], [3.0, 1.0], ViewConfig(max_side=9.0), bounds=grid.bounds)
    np.testing.assert_allclose(frame.half_side, [4.0])
    with pytest.raises(ValueError, match="extent must be one of"):
        ViewConfig(extent="room")


# ------------------------------------------------------------------------------------- model
def tiny_config(**kw) -> GeneralDenoiserConfig:
    return GeneralDenoiserConfig(max_horizon=10, d_model=32, n_layers=2, n_heads=2, ff_mult=2,
                                 global_channels=(8, 8, 16), local_channels=(8, 8, 8), **kw)


def tiny_model(**kw) -> MapConditionedDenoiser:
    torch.manual_seed(0)
    return MapConditionedDenoiser(tiny_config(**kw)).eval()


def test_model_output_shape_and_config_round_trip():
    config = tiny_config(fourier_bands=2)
    assert GeneralDenoiserConfig.from_dict(config.to_dict()) == config
    model = MapConditionedDenoiser(config)
    views = make_views(wall_grid(), [[3.0, 5.0]] * 3, [[7.0, 5.0]] * 3)
    x = torch.randn(3, 7, 2)
    assert model(x, torch.tensor([0, 5, 9]), views=views).shape == (3, 7, 2)
    memory = model.encode(views)
    assert memory.keys[0].shape == (3, 2, config.memory_tokens, 16)
    assert config.memory_tokens == 64 + 8 + 1
    with pytest.raises(ValueError, match="exactly one of views and memory"):
        model(x, 0)
    with pytest.raises(ValueError, match="GeneralDenoiserConfig needs"):
        GeneralDenoiserConfig(max_horizon=10, use_map_encoder=True)


def test_map_tokens_change_the_output():
    model = tiny_model()
    empty = GridMap(data=np.zeros((100, 100), dtype=np.int8), resolution=0.1)
    x, t = torch.randn(2, 10, 2), torch.tensor([3, 3])
    with torch.no_grad():
        eps_wall = model(x, t, views=make_views(wall_grid(), [[3.0, 5.0]] * 2, [[7.0, 5.0]] * 2))
        eps_empty = model(x, t, views=make_views(empty, [[3.0, 5.0]] * 2, [[7.0, 5.0]] * 2))
    assert (eps_wall - eps_empty).abs().max() > 1e-4


@pytest.mark.parametrize("grad", [False, True], ids=["inference", "training-path"])
def test_encode_once_equals_views_every_step(grad):
    model = tiny_model()
    one = make_views(wall_grid(), [3.0, 5.0], [6.0, 5.0])  # one problem, N candidates
    x = torch.randn(4, 10, 2)
    with torch.set_grad_enabled(grad):
        memory = model.encode(one)
        for t in (9, 5, 0):
            a = model(x, t, memory=memory)  # memory of batch 1, broadcast
            b = model(x, t, views=ViewTensors.from_views(one))
            tiled = ViewTensors.from_views(one)
            c = model(x, t, views=ViewTensors(tiled.global_view.expand(4, -1, -1, -1),
                                              tiled.local_views.expand(4, -1, -1, -1, -1),
                                              tiled.half_side.expand(4)))
            torch.testing.assert_close(a, b, rtol=0, atol=0)
            torch.testing.assert_close(a, c, rtol=1e-5, atol=1e-6)


def test_inference_fast_path_matches_the_modules():
    model = tiny_model()
    views = make_views(wall_grid(), [3.0, 5.0], [6.0, 5.0])
    x = torch.randn(4, 10, 2)
    with torch.no_grad():
        fast = model(x, 4, views=views)
    slow = model(x, 4, views=views)  # gradients on: nn modules
    torch.testing.assert_close(fast, slow, rtol=1e-5, atol=1e-5)


# ----------------------------------------------------------------------------------- dataset
def tiny_data_config(**kw) -> GeneralDataConfig:
    return GeneralDataConfig(**{**dict(maps=2, maps_per_shard=1, pairs_per_map=3, sizes=(10.0,),
                                       resolution=0.1, seed=7), **kw})


def test_tiny_dataset_builds_resumes_and_stays_in_view(tmp_path):
    config = tiny_data_config()
    first = build(tmp_path, config, progress=False)
    assert (first.shards_written, first.shards_skipped) == (2, 0)
    stamps = [p.stat().st_mtime_ns for p in sorted(tmp_path.glob("shard-*.npz"))]
    second = build(tmp_path, config, progress=False)
    assert (second.shards_written, second.shards_skipped, second.samples) == (0, 2, 0)
    assert [p.stat().st_mtime_ns for p in sorted(tmp_path.glob("shard-*.npz"))] == stamps

    data = GeneralDataset.load(tmp_path)
    assert len(data) == 2 * 2 * 3  # maps x (whole problem + a shorter horizon) x pairs
    assert [m["kind"] for m in data.maps] == ["warehouse", "office"]
    assert data.config == config
    P = config.sparse_horizon
    assert set(data.horizon[:3].tolist()) == {P} and (data.horizon[3:6] < P).all()
    for i, h in enumerate(data.horizon):
        wp = data.waypoints[i]
        assert np.isfinite(wp[:h]).all() and np.isnan(wp[h:]).all()
        assert (np.abs(wp[:h]) <= 1).all()
    # the stored views are those make_views gives for each sample's start and goal
    grid = generate_map(config.map_config(0))
    frame = data.views(np.arange(6)).frame
    ends = frame.to_world(np.nan_to_num(data.waypoints[:6]))  # (6, P, 2) [m]
    goals = ends[np.arange(6), data.horizon[:6] - 1]
    again = make_views(grid, ends[:, 0], goals, config.view)
    np.testing.assert_array_equal(data.views(np.arange(6)).global_view, again.global_view)
    np.testing.assert_array_equal(data.views(np.arange(6)).local_views, again.local_views)
    assert grid.is_free(ends[:, 0]).all()


def test_dataset_directory_of_another_config_is_refused(tmp_path):
    build(tmp_path, tiny_data_config(maps=1), progress=False)
    with pytest.raises(DatasetError, match="another config"):
        build(tmp_path, tiny_data_config(maps=1, pairs_per_map=4), progress=False)
    with pytest.raises(DatasetError, match="no generalist shards"):
        GeneralDataset.load(tmp_path / "empty")
