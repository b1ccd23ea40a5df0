"""Generated building maps (ecahd_core.mapgen): deterministic, every kind with free, occupied and
unknown cells, warehouse racks with unknown interiors, office doors of the stated width, one
connected free region that the A* expert can cross, a Nav2 round trip, input errors, the CLI."""
import math

import cv2
import numpy as np
import pytest

from ecahd_core.astar import AStarPlanner
from ecahd_core.errors import EcahdError, MapError
from ecahd_core.mapgen import (ROBOT_RADIUS, MapGenConfig, MapKind, generate, generate_map)
from ecahd_core.maps import load_nav2_yaml, save_nav2_yaml
from ecahd_ros.cli import main

KINDS = [k.value for k in MapKind]
SMALL = dict(width=12.0, height=10.0, resolution=0.05)  # 240 x 200 cells: fast


@pytest.fixture(scope="module")
def small_maps():
    return {kind: generate(MapGenConfig(kind=kind, seed=0, **SMALL)) for kind in KINDS}


def test_same_seed_same_map_byte_for_byte(tmp_path):
    config = MapGenConfig(kind="office", width=16.0, height=12.0, resolution=0.05, seed=3)
    save_nav2_yaml(generate_map(config), tmp_path / "a.yaml")
    save_nav2_yaml(generate_map(config), tmp_path / "b.yaml")
    assert (tmp_path / "a.pgm").read_bytes() == (tmp_path / "b.pgm").read_bytes()
    other = generate_map(MapGenConfig(kind="office", width=16.0, height=12.0, resolution=0.05,
                                      seed=4))
    assert not np.array_equal(other.data, generate_map(config).data)


@pytest.mark.parametrize("kind", KINDS)
def test_each_kind_has_free_occupied_unknown(small_maps, kind):
    gen = small_maps[kind]
    grid = gen.grid
    assert grid.name == f"{kind}-12x10-0.05-s0"
    assert grid.data.shape == (200, 240) and grid.origin == (0.0, 0.0)
    values = set(np.unique(grid.data).tolist())
    assert values == {-1, 0, 100}
    assert 0.3 < np.mean(grid.data == 0) < 0.95
    # outside the building hull: the map's outermost ring is (almost all) unknown
    ring = np.concatenate([grid.data[0], grid.data[-1], grid.data[:, 0], grid.data[:, -1]])
    assert np.mean(ring == -1) > 0.8


def test_warehouse_racks_have_unknown_interiors_inside_occupied_outlines():
    grid = generate_map(MapGenConfig(kind="warehouse", width=20.0, height=16.0, resolution=0.05,
                                     seed=0))
    unknown = (grid.data == -1).astype(np.uint8)
    n, labels = cv2.connectedComponents(unknown, connectivity=4)
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    racks = 0
    for k in range(1, n):
        region = labels == k
        if region.sum() * grid.resolution ** 2 < 2.0:  # speckle, not a rack (racks >= 6 m^2)
            continue
        border = (cv2.dilate(region.astype(np.uint8), cross) > 0) & ~region
        if region[0].any() or region[-1].any() or region[:, 0].any() or region[:, -1].any():
            continue  # the unknown outside the building
        assert np.all(grid.data[border] == 100), "a rack interior touches free space"
        racks += 1
    assert racks >= 3


def _clear_width(grid, door) -> float:
    """[m] the narrowest free run through the door centre along the wall, over the rows (or
    columns) that cross the wall."""
    row, col = (int(v) for v in grid.world_to_cell(np.asarray(door.centre)))
    runs = []
    for k in range(-4, 5):
        line = grid.data[row + k, :] if door.along_x else grid.data[:, col + k]
        i = col if door.along_x else row
        if line[i] != 0:
            continue
        a, b = i, i
        while line[a - 1] == 0:
            a -= 1
        while line[b + 1] == 0:
            b += 1
        runs.append(b - a + 1)
    return min(runs) * grid.resolution


@pytest.mark.parametrize("seed", [0, 1])
def test_office_doors_are_0p8_to_1m_wide_on_the_grid(seed):
    gen = generate(MapGenConfig(kind="office", width=20.0, height=16.0, resolution=0.05,
                                seed=seed))
    assert len(gen.doors) >= 6
    for door in gen.doors:
        assert 0.8 - 1e-9 <= door.width <= 1.0 + 1e-9
        assert _clear_width(gen.grid, door) == pytest.approx(door.width, abs=1e-9)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_free_space_is_one_region_and_every_room_is_reachable(kind, seed):
    gen = generate(MapGenConfig(kind=kind, width=14.0, height=11.0, resolution=0.05, seed=seed))
    grid = gen.grid
    # guarantee 1: one 4-connected free region (label 0 is the background)
    n, _ = cv2.connectedComponents((grid.data == 0).astype(np.uint8), connectivity=4)
    assert n == 2
    # guarantees 2 and 3: A* with the robot's clearance reaches every anchor from every other,
    # and every cell with clearance >= 0.4 m + a quarter cell lies in that one region
    planner = AStarPlanner(grid, ROBOT_RADIUS)
    rows, cols = grid.world_to_cell(gen.anchors)
    assert len(gen.anchors) >= 1
    main_label = planner.components[rows[0], cols[0]]
    assert main_label != 0
    assert np.all(planner.components[rows, cols] == main_label)
    core = planner.cell_clearance >= ROBOT_RADIUS + 0.25 * grid.resolution
    assert np.all(planner.components[core] == main_label)


@pytest.mark.parametrize("kind", KINDS)
def test_astar_crosses_each_small_map(small_maps, kind):
    grid = small_maps[kind].grid
    planner = AStarPlanner(grid, ROBOT_RADIUS)
    rows, cols = np.nonzero(planner.components == np.bincount(planner.components[planner.mask]).argmax())
    xy = grid.cell_to_world(rows, cols)
    start, goal = xy[np.argmin(xy.sum(axis=1))], xy[np.argmax(xy.sum(axis=1))]
    assert np.linalg.norm(goal - start) > 6.0  # far apart on a 12 x 10 m map
    path = planner.plan(start, goal)
    assert np.allclose(path[0], start) and np.allclose(path[-1], goal)
    length = float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))
    assert length >= np.linalg.norm(goal - start) - 1e-9


def test_nav2_round_trip_keeps_free_occupied_unknown(small_maps, tmp_path):
    grid = small_maps["warehouse"].grid
    path = save_nav2_yaml(grid, tmp_path / "my.yaml")
    back = load_nav2_yaml(path)
    assert np.array_equal(back.data, grid.data)  # 205 grey reloads as unknown (-1)
    assert back.resolution == grid.resolution and back.origin == grid.origin
    assert back.fingerprint() == grid.fingerprint()


@pytest.mark.parametrize("kwargs, match", [
    (dict(kind="castle"), "unknown map kind 'castle'; allowed: 'warehouse', 'office', 'depot'"),
    (dict(width=0.0), r"width must be in \(0, 60\]"),
    (dict(height=-3.0), r"height must be in \(0, 60\]"),
    (dict(width=61.0), r"width must be in \(0, 60\]"),
    (dict(height=7.5), "too small for a office"),
    (dict(width=math.nan), "width must be a finite number"),
    (dict(height="10"), "height must be a finite number"),
    (dict(resolution=0.005), r"resolution must be in \[0.01, 0.2\]"),
    (dict(resolution=0.25), r"resolution must be in \[0.01, 0.2\]"),
    (dict(resolution=math.nan), "resolution must be in"),
    (dict(width=60.0, height=60.0, resolution=0.01), "at most 4000 per side"),
    (dict(seed=-1), "seed must be an integer >= 0"),
    (dict(seed=1.5), "seed must be an integer >= 0"),
])
def test_bad_config_raises_map_error(kwargs, match):
    args = dict(kind="office", width=12.0, height=10.0, resolution=0.05, seed=0) | kwargs
    with pytest.raises(MapError, match=match):
        MapGenConfig(**args)
    assert issubclass(MapError, EcahdError)


def test_cli_generate_writes_nav2_map_and_png(tmp_path, capsys):
    out = tmp_path / "sub" / "x.yaml"  # the folder is created
    assert main(["map", "generate", "--kind", "depot", "--size", "12", "10", "--resolution",
                 "0.05", "--seed", "2", "--out", str(out), "--png", str(tmp_path / "x.png")]) == 0
    line = capsys.readouterr().out.splitlines()[0]
    assert "depot-12x10-0.05-s2" in line and "% free" in line and "% unknown" in line
    assert "fingerprint" in line and "generated in" in line
    assert out.exists() and out.with_suffix(".pgm").exists() and (tmp_path / "x.png").exists()
    expected = generate_map(MapGenConfig(kind="depot", width=12, height=10, resolution=0.05,
                                         seed=2))
    assert np.array_equal(load_nav2_yaml(out).data, expected.data)


@pytest.mark.parametrize("argv, message", [
    (["--kind", "castle", "--size", "12", "10"], "unknown map kind 'castle'"),
    (["--kind", "office", "--size", "12", "nan"], "finite number"),
    (["--kind", "office", "--size", "5", "10"], "too small"),
    (["--size", "12", "10"], "needs --kind"),
])
def test_cli_generate_bad_input_exits_2(tmp_path, capsys, argv, message):
    assert main(["map", "generate", *argv, "--out", str(tmp_path / "x.yaml")]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "x.yaml").exists()


def test_cli_describe_form_rejects_generate_options(capsys):
    assert main(["map", "maze2d-umaze", "--kind", "office"]) == 2
    assert "--kind belongs to 'ecahd map generate'" in capsys.readouterr().err
