"""Expert data generation and the versioned .npz format (ecahd_core.dataset, paper Sec. IV-A)."""
import argparse
import hashlib

import numpy as np
import pytest

from ecahd_core.astar import AStarPlanner
from ecahd_core.commands import dataset as dataset_command
from ecahd_core.dataset import (CORNERS_ABOVE_SPACING, DATASET_VERSION, EXACT_MAX_CELLS,
                                ExpertDataset, chunk_count, corner_waypoints, expert_sample,
                                file_sha256, generate_dataset, points_at_arclength,
                                resample_by_arclength, split_by_arclength, waypoint_rule_for)
from ecahd_core.errors import DatasetError, TrajectoryError
from ecahd_core.mapgen import MapGenConfig, generate_map
from ecahd_core.maps import builtin_map

N_PAIRS = 6
PG, PL, FULL = 10, 4, 100


@pytest.fixture(scope="module")
def grid():
    return builtin_map("maze2d-large")


@pytest.fixture(scope="module")
def ds(grid):
    return generate_dataset(grid, pairs=N_PAIRS, seed=3, progress=False)


# ------------------------------------------------------------------------------ resampling
def test_resample_l_shaped_path():
    # legs of 2 m along x then 2 m along y: 5 points every 1 m of arc length
    path = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]])
    np.testing.assert_allclose(resample_by_arclength(path, 5),
                               [[0, 0], [1, 0], [2, 0], [2, 1], [2, 2]], atol=1e-12)
    np.testing.assert_allclose(points_at_arclength(path, [0.5, 3.5, 9.0]),
                               [[0.5, 0], [2, 1.5], [2, 2]], atol=1e-12)


def test_resample_keeps_exact_end_points_and_handles_repeats():
    path = np.array([[0.1, 0.3], [0.1, 0.3], [1.7, 2.9], [4.4, 0.2], [4.4, 0.2]])
    out = resample_by_arclength(path, 7)
    assert out.shape == (7, 2)
    assert np.array_equal(out[0], path[0]) and np.array_equal(out[-1], path[-1])
    steps = np.linalg.norm(np.diff(out, axis=0), axis=1)
    assert np.all(steps <= steps.max()) and np.all(np.isfinite(out))


def test_resample_zero_length_and_bad_input():
    point = np.array([[1.0, 2.0]])
    np.testing.assert_array_equal(resample_by_arclength(point, 4), np.tile(point, (4, 1)))
    np.testing.assert_array_equal(resample_by_arclength(np.tile(point, (3, 1)), 3),
                                  np.tile(point, (3, 1)))
    with pytest.raises(TrajectoryError, match="n >= 2"):
        resample_by_arclength(point, 1)
    with pytest.raises(TrajectoryError, match="shape"):
        resample_by_arclength(np.zeros((3, 3)), 4)
    with pytest.raises(TrajectoryError, match="NaN"):
        resample_by_arclength(np.array([[0.0, 0.0], [np.nan, 1.0]]), 4)


def test_expert_sample_views():
    # a straight 9 m path: sparse waypoints every 1 m, dense points every 1/3 m
    path = np.array([[0.0, 0.0], [9.0, 0.0]])
    s = expert_sample(path, sparse_horizon=10, dense_points=4, full_points=100)
    np.testing.assert_allclose(s.sparse[:, 0], np.arange(10.0), atol=1e-12)
    np.testing.assert_allclose(s.sparse_h[3][:, 0], [7.0, 8.0, 9.0], atol=1e-12)
    np.testing.assert_allclose(s.dense[4, :, 0], [4.0, 4 + 1 / 3, 4 + 2 / 3, 5.0], atol=1e-12)
    assert s.full.shape == (100, 2) and s.length == pytest.approx(9.0)


def test_corner_waypoints_keep_corners_and_split_the_longest_legs():
    # an L: 6 m east, 2 m north; the corner stays, 3 extra points go to the long leg
    path = np.array([[0.0, 0.0], [3.0, 0.0], [6.0, 0.0], [6.0, 2.0]])  # (3, 0) is collinear
    w = corner_waypoints(path, 6)
    np.testing.assert_allclose(w, [[0, 0], [1.5, 0], [3, 0], [4.5, 0], [6, 0], [6, 2]],
                               atol=1e-12)
    # every straight leg between two waypoints lies on the path
    assert np.all((w[:, 1] == 0) | (w[:, 0] == 6))
    # more corners than waypoints: the flattest corner goes first
    zig = np.array([[0.0, 0.0], [1.0, 0.05], [2.0, 0.0], [3.0, 2.0], [4.0, 0.0]])
    np.testing.assert_allclose(corner_waypoints(zig, 4), [[0, 0], [2, 0], [3, 2], [4, 0]])
    np.testing.assert_allclose(corner_waypoints(np.array([[1.0, 1.0]]), 3), np.ones((3, 2)))
    with pytest.raises(TrajectoryError, match="n >= 2"):
        corner_waypoints(path, 1)


def test_expert_sample_corners_rule():
    path = np.array([[0.0, 0.0], [6.0, 0.0], [6.0, 3.0]])
    s = expert_sample(path, sparse_horizon=4, dense_points=4, full_points=50, waypoints="corners")
    np.testing.assert_allclose(s.sparse, [[0, 0], [3, 0], [6, 0], [6, 3]], atol=1e-12)
    np.testing.assert_allclose(s.sparse_h[2], [[6, 0], [6, 3]], atol=1e-12)
    # the dense view stays the arc-length one (DD learns the paper's segments)
    even = expert_sample(path, sparse_horizon=4, dense_points=4, full_points=50)
    np.testing.assert_allclose(s.dense, even.dense)
    with pytest.raises(DatasetError, match="waypoints"):
        expert_sample(path, waypoints="evenly")


# ----------------------------------------------------------------------------- generation
def test_shapes(ds):
    assert ds.num_pairs == N_PAIRS and ds.sparse_horizon == PG and ds.dense_points == PL
    assert ds.sparse.shape == (N_PAIRS, PG, 2)
    assert sorted(ds.sparse_h) == list(range(2, PG + 1))
    for h, arr in ds.sparse_h.items():
        assert arr.shape == (N_PAIRS, h, 2)
    assert ds.dense.shape == (N_PAIRS * (PG - 1), PL, 2)
    assert ds.full.shape == (N_PAIRS, FULL, 2)
    assert ds.starts.shape == ds.goals.shape == (N_PAIRS, 2)
    assert ds.lengths.shape == (N_PAIRS,)
    assert all(a.dtype == np.float32 for a in (ds.sparse, ds.dense, ds.full, ds.starts))


def test_end_points_and_lengths(ds):
    for arr in (ds.sparse, ds.full):
        assert np.array_equal(arr[:, 0], ds.starts) and np.array_equal(arr[:, -1], ds.goals)
    assert np.all(ds.lengths >= 3.0)
    # the full view follows the path, so its polyline is no longer than the path
    full_len = np.linalg.norm(np.diff(ds.full, axis=1), axis=2).sum(axis=1)
    assert np.all(full_len <= ds.lengths * (1 + 1e-5))
    assert np.all(full_len >= np.linalg.norm(ds.goals - ds.starts, axis=1) - 1e-5)


def test_shorter_horizons_continue_from_the_sparse_waypoints(ds):
    for h, arr in ds.sparse_h.items():
        k = PG - h  # waypoints already reached
        assert np.array_equal(arr[:, 0], ds.sparse[:, k])
        assert np.array_equal(arr[:, -1], ds.goals)
        # evenly spaced sparse waypoints: the rest of the path in h points is the sparse tail
        np.testing.assert_allclose(arr, ds.sparse[:, k:], atol=1e-4)


def test_dense_segments_chain_the_sparse_waypoints(ds):
    dense = ds.dense.reshape(N_PAIRS, PG - 1, PL, 2)
    assert np.array_equal(dense[:, :, 0], ds.sparse[:, :-1])
    assert np.array_equal(dense[:, :, -1], ds.sparse[:, 1:])
    # P^l points evenly spaced by arc length: no chord longer than length / (9 * 3)
    chords = np.linalg.norm(np.diff(dense, axis=2), axis=3)
    assert np.all(chords <= ds.lengths[:, None, None] / ((PG - 1) * (PL - 1)) + 1e-5)


def test_points_lie_in_the_clearance_free_space(ds):
    grid = ds.grid()
    planner = AStarPlanner(grid, ds.params["clearance"])
    for arr in (ds.full, ds.dense, ds.starts):
        rows, cols = grid.world_to_cell(arr.astype(np.float64))
        assert np.all(planner.mask[rows, cols])
    assert all(planner.point_clearance(p) >= 0.4 - 1e-6 for p in np.concatenate([ds.starts, ds.goals]))


def test_seeded_generation_is_reproducible(grid, ds, tmp_path):
    again = generate_dataset(grid, pairs=N_PAIRS, seed=3, progress=False)
    for name in ("sparse", "dense", "full", "starts", "goals", "lengths"):
        assert np.array_equal(getattr(again, name), getattr(ds, name))
    assert again.params == ds.params
    # byte-for-byte identical files
    assert file_sha256(ds.save(tmp_path / "a.npz")) == file_sha256(again.save(tmp_path / "b.npz"))
    other = generate_dataset(grid, pairs=N_PAIRS, seed=4, progress=False)
    assert not np.array_equal(other.starts, ds.starts)


def test_generation_parameters_are_checked(grid):
    with pytest.raises(DatasetError, match="pairs"):
        generate_dataset(grid, pairs=0, seed=0, progress=False)
    with pytest.raises(DatasetError, match="sparse_horizon"):
        generate_dataset(grid, pairs=1, seed=0, sparse_horizon=1, progress=False)
    with pytest.raises(DatasetError, match="min_distance"):
        generate_dataset(grid, pairs=1, seed=0, min_distance=float("nan"), progress=False)
    with pytest.raises(DatasetError, match="kept only 0 of 2 pairs"):
        generate_dataset(grid, pairs=2, seed=0, min_distance=100.0, max_attempts=20,
                         progress=False)
    with pytest.raises(DatasetError, match="no cell"):
        generate_dataset(grid, pairs=1, seed=0, footprint_spec="[[1, 1], [-1, 1], [-1, -1], [1, -1]]",
                         progress=False)


def test_maze2d_large_data_are_those_of_the_shipped_models(ds):
    # The shipped models learnt from the exact expert's data (docs/RESULTS.md: `ecahd train-all
    # --map maze2d-large`, dataset SHA-256 60fbc68c...). Small maps keep that expert and its
    # draws; this digest was computed with the code that made the shipped dataset.
    assert ds.grid().height * ds.grid().width <= EXACT_MAX_CELLS
    assert ds.params["expert"] == "astar+shortcut" and "expert_block" not in ds.params
    digest = hashlib.sha256()
    for name in ("sparse", "dense", "full", "starts", "goals", "lengths"):
        digest.update(np.ascontiguousarray(getattr(ds, name)).tobytes())
    assert digest.hexdigest() == "d6ab9827508e4d70928798bcb62a13e8ba25595932117f4af80c12617daff58a"
    assert ds.params["attempts"] == 7


# ---------------------------------------------------------------------------- coarse expert
@pytest.fixture(scope="module")
def office():
    # 16 x 12 m at 0.05 m/cell: 320 x 240 = 76 800 cells, above EXACT_MAX_CELLS
    return generate_map(MapGenConfig("office", 16, 12, 0.05, 5))


@pytest.fixture(scope="module")
def office_ds(office):
    return generate_dataset(office, pairs=8, seed=2, workers=1, progress=False)


def test_large_maps_get_the_coarse_expert(office, office_ds):
    assert office.height * office.width > EXACT_MAX_CELLS
    p = office_ds.params
    assert p["expert"] == "coarse-astar+shortcut" and p["expert_block"] == 6  # 0.3 m blocks
    assert office_ds.num_pairs == 8 and np.all(office_ds.lengths >= 3.0)
    planner = AStarPlanner(office, p["clearance"])
    for arr in (office_ds.full, office_ds.starts, office_ds.goals):
        rows, cols = office.world_to_cell(arr.reshape(-1, 2).astype(np.float64))
        assert np.all(planner.mask[rows, cols])
    # all pairs in one region of the clearance-free space
    rows, cols = office.world_to_cell(office_ds.starts.astype(np.float64))
    assert len(np.unique(planner.components[rows, cols])) == 1


def test_corner_waypoints_legs_follow_the_expert(office, office_ds, ds):
    from ecahd_core.collision import check_collision
    from ecahd_core.footprint import circle_footprint

    corners = generate_dataset(office, pairs=8, seed=2, workers=1, progress=False,
                               waypoints="corners")
    assert corners.params["waypoints"] == "corners"
    # the expert keeps the clearance, and every straight leg between two corner waypoints lies
    # on its path: a point (a 1 mm circle) crosses no wall along the sparse plans
    point = circle_footprint(1e-3)
    for sparse in corners.sparse.astype(np.float64):
        assert check_collision(sparse, point, office).collision_free
    for h in range(2, corners.sparse_horizon + 1):
        np.testing.assert_array_equal(corners.sparse_h[h], corners.sparse[:, -h:])
    # "auto" on these short paths and on maze2d-large: the paper's rule, files as before
    spacing = np.median(office_ds.lengths) / (office_ds.sparse_horizon - 1)
    assert spacing <= CORNERS_ABOVE_SPACING
    assert "waypoints" not in office_ds.params and "waypoints" not in ds.params
    np.testing.assert_array_equal(corners.dense, office_ds.dense)  # DD's data: the same
    np.testing.assert_array_equal(corners.starts, office_ds.starts)
    with pytest.raises(DatasetError, match="waypoints"):
        generate_dataset(office, pairs=1, seed=0, waypoints="even", progress=False)


def test_auto_waypoint_rule_follows_the_median_spacing():
    assert waypoint_rule_for([9.0, 13.0, 20.0], 10) == "arclength"  # 13 / 9 = 1.44 m
    assert waypoint_rule_for([9.0, 14.0, 20.0], 10) == "corners"  # 14 / 9 = 1.56 m
    assert waypoint_rule_for([3.0, 4.0], 3) == "corners"  # 3.5 / 2 = 1.75 m


def test_coarse_expert_data_do_not_depend_on_the_worker_count(office, office_ds, tmp_path):
    two = generate_dataset(office, pairs=8, seed=2, workers=2, progress=False)
    assert two.params == office_ds.params
    assert file_sha256(two.save(tmp_path / "two.npz")) == \
        file_sha256(office_ds.save(tmp_path / "one.npz"))
    exact = generate_dataset(office, pairs=2, seed=2, expert="exact", progress=False)
    assert exact.params["expert"] == "astar+shortcut"
    with pytest.raises(DatasetError, match="expert"):
        generate_dataset(office, pairs=1, seed=0, expert="fast", progress=False)
    with pytest.raises(DatasetError, match="workers"):
        generate_dataset(office, pairs=1, seed=0, workers=0, progress=False)


# ----------------------------------------------------------------------- waypoint spacing
def test_split_by_arclength():
    # legs of 2 m along x then 2 m along y, in 2 pieces: the cut is the corner, in 3 pieces the
    # cuts lie 4/3 m and 8/3 m along the path
    path = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]])
    a, b = split_by_arclength(path, 2)
    np.testing.assert_allclose(a, [[0, 0], [2, 0]])
    np.testing.assert_allclose(b, [[2, 0], [2, 2]])
    pieces = split_by_arclength(path, 3)
    np.testing.assert_allclose([p[-1] for p in pieces], [[4 / 3, 0], [2, 2 / 3], [2, 2]])
    np.testing.assert_allclose(pieces[1], [[4 / 3, 0], [2, 0], [2, 2 / 3]])
    assert all(np.array_equal(p[-1], q[0]) for p, q in zip(pieces, pieces[1:]))
    with pytest.raises(TrajectoryError, match="k >= 1"):
        split_by_arclength(path, 0)
    # P^g = 10 waypoints at most 1.5 m apart: one piece up to 13.5 m, two up to 27 m
    assert [chunk_count(L, 10, 1.5) for L in (3.0, 13.5, 13.6, 27.0, 27.1)] == [1, 1, 2, 2, 3]
    assert chunk_count(100.0, 10, None) == 1


def test_max_spacing_cuts_long_paths(office, office_ds):
    cut = generate_dataset(office, pairs=8, seed=2, workers=1, max_spacing=0.5, progress=False)
    spacing = cut.lengths / (PG - 1)  # sparse waypoints are evenly spaced by arc length
    assert np.all(spacing <= 0.5 + 1e-5)
    assert cut.params["max_spacing"] == 0.5 and cut.params["split_paths"] >= 1
    assert cut.params["attempts"] < office_ds.params["attempts"]  # pieces of one path count
    assert np.array_equal(cut.starts[0], office_ds.starts[0])  # the first piece starts there
    # consecutive pieces of one path: one's goal is the next one's start
    assert any(np.array_equal(g, s) for g, s in zip(cut.goals[:-1], cut.starts[1:]))
    assert "max_spacing" not in office_ds.params
    with pytest.raises(DatasetError, match="max_spacing"):
        generate_dataset(office, pairs=1, seed=0, max_spacing=0.0, progress=False)


# ---------------------------------------------------------------------------------- files
def test_save_load_round_trip(ds, tmp_path):
    path = ds.save(tmp_path / "sub" / "expert.npz")
    assert path == tmp_path / "sub" / "expert.npz" and path.is_file()
    loaded = ExpertDataset.load(path)
    for name in ("sparse", "dense", "full", "starts", "goals", "lengths", "map_data"):
        assert np.array_equal(getattr(loaded, name), getattr(ds, name)), name
    for h in ds.sparse_h:
        assert np.array_equal(loaded.sparse_h[h], ds.sparse_h[h])
    assert loaded.params == ds.params
    assert loaded.params["seed"] == 3 and loaded.params["footprint_spec"] == "circle"
    assert loaded.params["clearance"] == pytest.approx(0.4)
    assert loaded.map_name == "maze2d-large"
    assert loaded.grid().fingerprint() == builtin_map("maze2d-large").fingerprint()
    assert loaded.sha256 == file_sha256(path) == ds.sha256
    assert len(loaded.sha256) == 64


def _rewrite(src, dst, **changes):
    with np.load(src) as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays.update(changes)
    np.savez(dst, **arrays)
    return dst


def test_wrong_version_raises(ds, tmp_path):
    good = ds.save(tmp_path / "good.npz")
    bad = _rewrite(good, tmp_path / "v2.npz", version=np.asarray(DATASET_VERSION + 1))
    with pytest.raises(DatasetError, match=f"version {DATASET_VERSION + 1}.*reads version "
                                           f"{DATASET_VERSION}"):
        ExpertDataset.load(bad)


def test_missing_file_raises(tmp_path):
    with pytest.raises(DatasetError, match="does not exist"):
        ExpertDataset.load(tmp_path / "nope.npz")
    with pytest.raises(DatasetError, match="does not exist"):
        file_sha256(tmp_path / "nope.npz")


def test_files_that_are_not_datasets_raise(ds, tmp_path):
    other = tmp_path / "other.npz"
    np.savez(other, a=np.zeros(3))
    with pytest.raises(DatasetError, match="not an ECAHD expert dataset"):
        ExpertDataset.load(other)
    text = tmp_path / "text.npz"
    text.write_text("hello")
    with pytest.raises(DatasetError, match="not an .npz"):
        ExpertDataset.load(text)
    single = tmp_path / "single.npy"
    np.save(single, np.zeros(3))
    with pytest.raises(DatasetError, match="single .npy"):
        ExpertDataset.load(single)
    good = ds.save(tmp_path / "good.npz")
    with np.load(good) as npz:
        edited = npz["map_data"].copy()
    edited[0, 0] = 0  # a wall cell made free
    with pytest.raises(DatasetError, match="fingerprint"):
        ExpertDataset.load(_rewrite(good, tmp_path / "edited.npz", map_data=edited))
    with pytest.raises(DatasetError, match="dense has shape"):
        ExpertDataset.load(_rewrite(good, tmp_path / "short.npz", dense=ds.dense[:-1]))


# -------------------------------------------------------------------------------- command
def test_command_writes_a_dataset(tmp_path, capsys):
    parser = argparse.ArgumentParser()
    dataset_command.add_arguments(parser)
    out = tmp_path / "umaze.npz"
    args = parser.parse_args(["--map", "maze2d-umaze", "--pairs", "3", "--seed", "1",
                              "--out", str(out), "--no-progress"])
    assert dataset_command.run(args) == 0
    loaded = ExpertDataset.load(out)
    assert loaded.num_pairs == 3 and loaded.map_name == "maze2d-umaze"
    text = capsys.readouterr().out
    assert "kept 3 pairs" in text and "MB" in text and str(out) in text
    assert "sparse waypoints: arclength rule, 10 per path" in text
