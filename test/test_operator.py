"""The scripted operator (``ecahd_core.operator``) and ``ecahd record-demos``: the habit
metric on hand-built corridors, keep-right paths on a generated office (collision-free by the
exact checker, on the right half where A* is not), zone paths that never enter the zone, and a
recorded bag that ``ecahd dataset --from-bags`` turns into demonstrations."""
import math

import numpy as np
import pytest

from ecahd_core.astar import sample_free_points
from ecahd_core.collision import check_collision
from ecahd_core.dataset import ExpertDataset
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import GridMap, save_nav2_yaml
from ecahd_core.mapgen import MapGenConfig, generate_map
from ecahd_core.operator import (DriveConfig, Operator, OperatorConfig, OperatorError,
                                 drive_route, habit_metrics, zone_grid)
from ecahd_core.scenario import ScenarioError, Zone, parse_zones, read_zones, write_scenario
from ecahd_ros.cli import main

CIRCLE = make_footprint("circle")  # r = 0.4 m: a corridor is wider than 1.6 m


def _corridor(width_cells: int) -> GridMap:
    """A corridor along x, 20 m long, ``width_cells`` free cells of 0.1 m wide (rows 10 ..
    10 + width - 1, y = 1.0 .. 1.0 + width / 10), walls above and below."""
    data = np.full((width_cells + 20, 200), 100, dtype=np.int8)
    data[10:10 + width_cells, :] = 0
    return GridMap(data=data, resolution=0.1, name=f"corridor{width_cells}")


# ---------------------------------------------------------------------------- the metric
def test_the_right_half_depends_on_the_direction_of_travel():
    grid = _corridor(30)  # 3 m wide, y 1..4: a corridor (1.6 < 3 <= 4 m)
    south = np.array([[2.0, 1.8], [18.0, 1.8]])  # y 1.8: 0.8 m from the lower wall
    m = habit_metrics([south], grid, CIRCLE)
    # eastbound the lower wall is on the right: all 16 m on the right half
    assert m.corridor_length == pytest.approx(16.0) and m.right_share == pytest.approx(1.0)
    m = habit_metrics([south[::-1]], grid, CIRCLE)  # westbound: on the left half
    assert m.right_share == pytest.approx(0.0)
    # one each way: half
    assert habit_metrics([south, south[::-1]], grid, CIRCLE).right_share == pytest.approx(0.5)


def test_too_narrow_and_too_wide_are_no_corridor():
    path = np.array([[2.0, 1.7], [18.0, 1.7]])
    # 1.5 m: narrower than two diameters (1.6 m); 4.5 m: open floor (> 4 m)
    for cells in (15, 45):
        m = habit_metrics([path], _corridor(cells), CIRCLE)
        assert m.corridor_length == 0 and math.isnan(m.right_share)
        assert m.length == pytest.approx(16.0)
    assert habit_metrics([path], _corridor(17), CIRCLE).corridor_length == pytest.approx(16.0)


def test_a_path_enters_a_zone_when_a_point_of_it_lies_inside():
    grid = _corridor(30)
    zone = Zone("bay", np.array([[9.0, 2.5], [11.0, 2.5], [11.0, 4.0], [9.0, 4.0]]))
    below, through = np.array([[2.0, 1.8], [18.0, 1.8]]), np.array([[2.0, 1.8], [18.0, 3.4]])  # y 2.6 at x 10
    m = habit_metrics([below, through], grid, CIRCLE, [zone])
    assert m.zone_entries == 1 and m.zone_share == 0.5


# ------------------------------------------------------------------------------- zones
def test_zones_round_trip_through_the_scenario_file(tmp_path):
    zone = Zone("bay", np.array([[1.0, 1.0], [3.0, 1.0], [3.0, 2.0]]))
    path = write_scenario(tmp_path / "s.yaml", [], [zone])
    (back,) = read_zones(path)
    assert back.name == "bay" and np.allclose(back.polygon, zone.polygon)
    with pytest.raises(ScenarioError, match="zone 0 .*at least 3"):
        parse_zones({"zones": [{"polygon": [[0, 0], [1, 1]]}]})
    with pytest.raises(ScenarioError, match="unknown scenario key"):
        parse_zones({"zone": []})


def test_a_zone_on_walls_only_is_refused():
    with pytest.raises(OperatorError, match="no free cell"):
        zone_grid(_corridor(30), [Zone("wall", np.array([[2.0, 0.1], [4.0, 0.1], [4.0, 0.8]]))])


# ----------------------------------------------------------------------- on an office
@pytest.fixture(scope="module")
def office() -> GridMap:
    return generate_map(MapGenConfig("office", 30, 20, 0.05, 0))


def _pairs(grid, mask, n: int, seed: int) -> list:
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        a, b = sample_free_points(rng, mask, grid, 2)
        if np.linalg.norm(a - b) >= 3.0:
            out.append((a, b))
    return out


def test_keep_right_paths_are_free_and_on_the_right_where_a_star_is_not(office):
    op = Operator(office, CIRCLE)
    routes = [op.plan(a, b) for a, b in _pairs(office, op.mask, 40, seed=0)]
    for r in routes:
        assert check_collision(r.path, CIRCLE, office).collision_free
    ours = habit_metrics([r.path for r in routes], office, CIRCLE)
    astar = habit_metrics([r.astar for r in routes], office, CIRCLE)
    # measured on this office (40 pairs, seed 0): operator 85.1% of 265 m of corridor, A*
    # 48.9% of 274 m; on 60 pairs of offices 0 / 1 / 2: 86.5 / 72.5 / 88.9% against A*'s
    # 53.7 / 48.0 / 53.0% (office 1's main corridor is 1.5 m, no corridor: its "corridors"
    # are narrow rooms, entered through a door in their middle). Margins of 5 and 9-11 points.
    assert ours.corridor_length > 150
    assert ours.right_share >= 0.80
    assert 0.40 <= astar.right_share <= 0.60
    assert sum(r.offset for r in routes) == len(routes)


def test_zone_paths_never_enter_the_zone(office):
    # a 4 x 3 m block of the office's open floor round a point A* routes cross
    zone = Zone("bay", np.array([[4.0, 6.0], [8.0, 6.0], [8.0, 9.0], [4.0, 9.0]]))
    op = Operator(office, CIRCLE, [zone], OperatorConfig(keep_right=False))
    routes = [op.plan(a, b) for a, b in _pairs(office, op.mask, 40, seed=1)]
    ours = habit_metrics([r.path for r in routes], office, CIRCLE, [zone])
    astar = habit_metrics([r.astar for r in routes], office, CIRCLE, [zone])
    assert ours.zone_entries == 0
    assert astar.zone_entries >= 4  # measured: 8 of 40 shortest paths cross it
    for r in routes:  # the footprint stays out too
        assert check_collision(r.path, CIRCLE, op.planning_grid).collision_free


def test_driving_follows_the_route_and_stops(office):
    op = Operator(office, CIRCLE)
    (a, b), = _pairs(office, op.mask, 1, seed=3)
    route = op.plan(a, b)
    cfg = DriveConfig()
    d = drive_route(route.path, (*a, 0.0), cfg)
    assert d.reached
    assert np.linalg.norm(d.poses[d.moving_ticks - 1, :2] - b) <= cfg.goal_tolerance
    assert np.all(np.abs(d.twists[:, 0]) <= cfg.max_v + 1e-9)
    step = np.linalg.norm(np.diff(d.poses[:, :2], axis=0), axis=1)
    assert step.max() <= cfg.max_v / cfg.rate + 1e-9
    still = d.poses[d.moving_ticks:]
    assert len(still) == cfg.stop_time * cfg.rate and np.ptp(still, axis=0).max() == 0


# ------------------------------------------------------------------------------ the bag
def test_a_recorded_bag_yields_demonstrations(tmp_path, office, capsys):
    site = save_nav2_yaml(office, tmp_path / "office.yaml")
    bag, png = tmp_path / "bag", tmp_path / "routes.png"
    assert main(["record-demos", "--map", str(site), "--hours", "0.05", "--out", str(bag),
                 "--seed", "2", "--png", str(png), "--no-progress"]) == 0
    text = capsys.readouterr().out
    hours = float(text.split("recorded ")[1].split(" h")[0])
    assert 0.05 <= hours < 0.1 and "0 route(s) not reached" in text  # the last route ends
    assert png.stat().st_size > 10_000 and not (tmp_path / "bag.partial").exists()
    out = tmp_path / "demos.npz"
    assert main(["dataset", "--from-bags", str(bag), "--map", str(site), "--out",
                 str(out)]) == 0
    text = capsys.readouterr().out
    assert "from /odom" in text and "0.0% in walls" in text
    ds = ExpertDataset.load(out)
    assert ds.params["demonstrations"] >= 3
    assert ds.params["counts"]["collision"] == 0
    # the demonstrations keep the habit: their driven paths on the right half
    m = habit_metrics([f for f in ds.full], office, CIRCLE)
    assert m.right_share >= 0.75


def test_bad_input_is_one_line_and_exit_code_2(tmp_path, capsys):
    site = save_nav2_yaml(_corridor(30), tmp_path / "c.yaml")
    assert main(["record-demos", "--map", str(site), "--habit", "zone", "--out",
                 str(tmp_path / "b")]) == 2
    assert "needs --zones" in capsys.readouterr().err
    (tmp_path / "b").mkdir()
    assert main(["record-demos", "--map", str(site), "--out", str(tmp_path / "b")]) == 2
    assert "exists" in capsys.readouterr().err
