"""Lane fields learnt from demonstrations and plans moved onto them (ecahd_core.lanes, issue 41).

A 20 x 8 m map with two corridors side by side (y 2.5..5.5 m and, behind a 0.5 m wall, y
6..7.5 m); demonstrations keep right in the wide one: eastwards at y 3.3, westwards at y 4.7."""
import json

import numpy as np
import pytest

from ecahd_core.collision import check_collision
from ecahd_core.errors import EcahdError
from ecahd_core.footprint import make_footprint
from ecahd_core.lanes import (LaneConfig, LaneField, ShapeConfig, demonstration_paths,
                              plot_lanes, shape_path)
from ecahd_core.maps import GridMap

RES = 0.05
EAST_Y, WEST_Y, CENTRE_Y = 3.3, 4.7, 4.0


def corridors() -> GridMap:
    data = np.full((int(8 / RES), int(20 / RES)), 100, dtype=np.int8)
    y = (np.arange(data.shape[0]) + 0.5) * RES
    x = (np.arange(data.shape[1]) + 0.5) * RES
    inside = (x > 0.5) & (x < 19.5)
    data[np.ix_((y > 2.5) & (y < 5.5), inside)] = 0
    data[np.ix_((y > 6.0) & (y < 7.5), inside)] = 0
    return GridMap(data=data, resolution=RES, origin=(0.0, 0.0), name="corridors")


def line(a, b, n: int = 60) -> np.ndarray:
    return np.linspace(a, b, n)


def keep_right_demos() -> list[np.ndarray]:
    out = []
    for k in range(6):  # a little spread, as a driver's
        dy = 0.05 * (k - 2.5)
        out.append(line((1.5, EAST_Y + dy), (18.5, EAST_Y + dy)))
        out.append(line((18.5, WEST_Y + dy), (1.5, WEST_Y + dy)))
    return out


@pytest.fixture(scope="module")
def grid():
    return corridors()


@pytest.fixture(scope="module")
def field(grid):
    return LaneField.fit(keep_right_demos(), grid, source="synthetic")


def test_the_field_holds_each_direction_where_it_was_driven(field):
    east, west = 0.0, np.pi
    at_east, at_west = np.array([10.0, EAST_Y]), np.array([10.0, WEST_Y])
    assert field.value(at_east, east) > 0.5 and field.value(at_west, west) > 0.5
    assert field.value(at_east, west) < 0.05 and field.value(at_west, east) < 0.05
    assert field.value(np.array([10.0, 6.75]), east) == 0.0  # never driven there
    # a heading between two bins reads both; broadcasting over points
    v = field.value(np.array([[10.0, EAST_Y], [10.0, WEST_Y]]), np.array([0.1, np.pi - 0.1]))
    assert v.shape == (2,) and np.all(v > 0.3)
    assert field.paths == 12 and field.length == pytest.approx(12 * 17.0, rel=1e-3)


@pytest.mark.parametrize("start, goal, lane_y", [((2.0, CENTRE_Y), (18.0, CENTRE_Y), EAST_Y),
                                                  ((18.0, CENTRE_Y), (2.0, CENTRE_Y), WEST_Y)])
def test_a_centre_line_plan_moves_onto_its_directions_lane(field, grid, start, goal, lane_y):
    fp = make_footprint("circle")
    res = shape_path(line(start, goal, 17), field, grid, fp)
    assert res.shaped and not res.kept_original
    p = res.path
    np.testing.assert_allclose(p[0], start)
    np.testing.assert_allclose(p[-1], goal)
    middle = p[(p[:, 0] > 5.0) & (p[:, 0] < 15.0)]
    assert len(middle) > 50
    np.testing.assert_allclose(middle[:, 1], lane_y, atol=0.1)
    assert res.max_offset == pytest.approx(abs(lane_y - CENTRE_Y), abs=0.1)
    assert check_collision(p, fp, grid).collision_free


def test_where_nobody_drove_and_never_over_a_wall_the_plan_stays(field, grid):
    fp = make_footprint("circle")
    # the narrow corridor: the lanes lie behind the wall, within reach but not reachable
    plan = line((2.0, 6.75), (18.0, 6.75), 17)
    res = shape_path(plan, field, grid, fp, ShapeConfig(reach=2.5))
    assert not res.shaped and not res.kept_original
    np.testing.assert_array_equal(res.path, plan)
    # a field fitted on the narrow corridor only leaves the wide one's plans alone
    other = LaneField.fit([line((1.5, 6.75), (18.5, 6.75))], grid)
    res = shape_path(line((2.0, CENTRE_Y), (18.0, CENTRE_Y), 17), other, grid, fp,
                     ShapeConfig(reach=2.5))
    assert not res.shaped


def test_a_shaped_plan_in_collision_is_not_used(field, grid):
    fp = make_footprint("circle")
    plan = line((2.0, CENTRE_Y), (18.0, CENTRE_Y), 17)
    # no clearance asked of the searched points: the lane is searched up to the wall itself
    wall_lanes = LaneField.fit([line((1.5, 2.55), (18.5, 2.55))], grid)
    loose = ShapeConfig(clearance=0.0)
    # the whole move (to y 2.55) collides, half of it (to y 3.275) is free
    res = shape_path(plan, wall_lanes, grid, fp, loose)
    assert res.shaped and res.max_offset == pytest.approx(0.5 * (CENTRE_Y - 2.55), abs=0.05)
    assert check_collision(res.path, fp, grid).collision_free
    # from y 3.1 both collide (the circle's radius is 0.4 m): the plan stays as it came
    near = line((2.0, 3.1), (18.0, 3.1), 17)
    res = shape_path(near, wall_lanes, grid, fp, loose)
    assert res.kept_original and not res.shaped
    np.testing.assert_array_equal(res.path, near)
    # with the footprint's clearance the same field only takes it as near as is free
    res = shape_path(plan, wall_lanes, grid, fp)
    assert res.shaped and check_collision(res.path, fp, grid).collision_free


def test_save_load_and_bad_files(field, grid, tmp_path):
    path = field.save(tmp_path / "lanes.npz")
    back = LaneField.load(path)
    np.testing.assert_array_equal(back.density, field.density)
    assert back.config == field.config and back.origin == field.origin
    assert (back.map_fingerprint, back.paths, back.source) == (field.map_fingerprint, 12,
                                                               "synthetic")
    back.check_map(grid)
    other = GridMap(data=grid.data[:, :200].copy(), resolution=RES, name="other")
    with pytest.raises(EcahdError, match="does not belong to map 'other'"):
        back.check_map(other)
    with pytest.raises(EcahdError, match="no such file"):
        LaneField.load(tmp_path / "missing.npz")
    cut = tmp_path / "cut.npz"
    cut.write_bytes(path.read_bytes()[:200])
    with pytest.raises(EcahdError, match=f"lane field {cut}: unreadable"):
        LaneField.load(cut)
    other_kind = tmp_path / "kind.npz"
    np.savez(other_kind, density=field.density, meta=json.dumps({"kind": "x", "version": 1}))
    with pytest.raises(EcahdError, match="expected 'ecahd-lanes'"):
        LaneField.load(other_kind)


def test_bad_settings_and_no_demonstrations(grid):
    with pytest.raises(EcahdError, match="bins must be an integer >= 4"):
        LaneConfig(bins=2)
    with pytest.raises(EcahdError, match="sigma must be a finite number > 0"):
        LaneConfig(sigma=float("nan"))
    with pytest.raises(EcahdError, match="reach must be a finite number > 0"):
        ShapeConfig(reach=0)
    with pytest.raises(EcahdError, match="no demonstration has any length"):
        LaneField.fit([np.zeros((3, 2)), np.array([[-50.0, -50.0], [-40.0, -50.0]])], grid)


class _Data:  # what demonstration_paths reads of an ExpertDataset
    def __init__(self, params, n=4):
        self.params, self.full, self.map_name = params, np.arange(n * 6.0).reshape(n, 3, 2), "m"


def test_demonstrations_of_a_dataset_never_the_experts():
    assert len(demonstration_paths(_Data({"source": "demonstrations"}))) == 4
    mixed = demonstration_paths(_Data({"mixed": {"demonstrations": 3, "expert": 1}}))
    assert len(mixed) == 3  # the demonstrations come first in a mix
    with pytest.raises(EcahdError, match="holds no demonstrations"):
        demonstration_paths(_Data({"seed": 0}))


def test_figure(field, grid, tmp_path):
    png = plot_lanes(field, grid, tmp_path / "lanes.png")
    assert png.stat().st_size > 10_000 and not list(tmp_path.glob("*.tmp"))


def test_waypoint_lanes_move_interior_waypoints_never_the_ends(field, grid):
    from ecahd_core.lanes import WaypointLanes

    lanes = WaypointLanes(field, grid, make_footprint("circle"))
    east = np.array([[2.0, CENTRE_Y], [6.0, CENTRE_Y], [10.0, CENTRE_Y], [14.0, CENTRE_Y],
                     [18.0, CENTRE_Y]])
    out = lanes(east)
    assert out.shape == east.shape and lanes.moved == 3
    np.testing.assert_array_equal(out[[0, -1]], east[[0, -1]])
    np.testing.assert_allclose(out[1:-1, 1], EAST_Y, atol=0.1)
    np.testing.assert_allclose(out[1:-1, 0], east[1:-1, 0])
    west = lanes(east[::-1])
    np.testing.assert_allclose(west[1:-1, 1], WEST_Y, atol=0.1)
    assert lanes(east[:2]).shape == (2, 2)  # nothing interior: as it came
    # a waypoint whose move would put a leg that was free into the wall stays: the lane of
    # a field fitted along the wall lies beyond the footprint's reach from (10, 3)
    near_wall = LaneField.fit([line((1.5, 2.6), (18.5, 2.6))], grid)
    strict = WaypointLanes(near_wall, grid, make_footprint("circle"), ShapeConfig(clearance=0.0))
    wp = np.array([[2.0, 3.5], [10.0, 3.5], [18.0, 3.5]])
    np.testing.assert_array_equal(strict(wp), wp)
    assert strict.refused == 1 and strict.moved == 0


def test_segment_refiner_moves_a_safe_local_plan_onto_the_lane(field, grid):
    from ecahd_core.cost import CollisionCost, CostConfig
    from ecahd_core.planning.dense import DenseConfig, DenseStage
    from ecahd_core.planning.local import SegmentRefiner

    fp = make_footprint("circle")
    cost = CollisionCost.build(grid, fp, CostConfig(margin=0.1))
    stage = DenseStage(None, costmap=cost.costmap, footprint_points=cost.footprint_points,
                       cost_config=cost.config, dense=DenseConfig(enabled=False))
    a, b = np.array([2.0, CENTRE_Y]), np.array([18.0, CENTRE_Y])
    plain = SegmentRefiner(stage, grid, fp)(a, b)
    assert not plain.shaped and np.allclose(plain.plan[:, 1], CENTRE_Y)
    res = SegmentRefiner(stage, grid, fp, lanes=field)(a, b)
    assert res.safe and res.shaped
    np.testing.assert_array_equal(res.plan[[0, -1]], [a, b])
    middle = res.plan[(res.plan[:, 0] > 5.0) & (res.plan[:, 0] < 15.0)]
    np.testing.assert_allclose(middle[:, 1], EAST_Y, atol=0.1)


def test_nodes_lanes_parameter(field, grid, tmp_path):
    """The nodes' ``lanes``: '' off; an unreadable file fails (start-up); a map it does not
    belong to: one error line, planned without lanes; an update of the same site: used."""
    from ecahd_ros.params import lanes_for, load_lanes

    class Log:
        def __init__(self):
            self.lines = []

        def error(self, text):
            self.lines.append(text)

    assert load_lanes("") is None
    with pytest.raises(EcahdError, match="no such file"):
        load_lanes(str(tmp_path / "none.npz"))
    loaded = load_lanes(str(field.save(tmp_path / "l.npz")))
    log = Log()
    assert lanes_for(loaded, grid, log) is loaded and not log.lines
    updated = grid.data.copy()
    updated[60:80, 180:200] = 100  # a 1 x 1 m block put in the corridor: the same site
    site = GridMap(data=updated, resolution=RES, name="corridors")
    assert lanes_for(loaded, site, log) is loaded and not log.lines
    other = GridMap(data=grid.data[:, :200].copy(), resolution=RES, name="other")
    assert lanes_for(loaded, other, log) is None
    assert len(log.lines) == 1 and "lanes off on this map" in log.lines[0]
    assert lanes_for(None, other, log) is None and len(log.lines) == 1


def test_eval_bag_reports_the_driven_habit(grid, tmp_path):
    from types import SimpleNamespace

    from ecahd_ros.eval_bag import driven_habit, habit_line

    def episode(xs, y):
        t = np.arange(len(xs)) * 0.1
        return SimpleNamespace(odom=np.stack([t, xs, np.full(len(xs), y), t * 0], axis=1))

    xs = np.linspace(2.0, 18.0, 161)
    right = SimpleNamespace(episodes=[episode(xs, EAST_Y), episode(xs[::-1], WEST_Y)],
                            grid=grid, footprint=make_footprint("circle"))
    habit = driven_habit(right)
    assert habit.right_share == pytest.approx(1.0) and habit.corridor_length > 30
    assert "right half of its corridors for 100.0% of 32 m" in habit_line(habit)
    left = SimpleNamespace(episodes=[episode(xs, WEST_Y)], grid=grid,
                           footprint=make_footprint("circle"))
    assert driven_habit(left).right_share == pytest.approx(0.0)
    none = SimpleNamespace(episodes=[], grid=grid, footprint=make_footprint("circle"))
    assert "no corridor" in habit_line(driven_habit(none))
    # --zones: the episodes whose driven path entered one (the east lane runs through this)
    from ecahd_core.scenario import read_zones

    (tmp_path / "z.yaml").write_text(
        "zones:\n  - {name: bay, polygon: [[9, 3], [11, 3], [11, 3.6], [9, 3.6]]}\n")
    habit = driven_habit(right, read_zones(tmp_path / "z.yaml"))
    assert habit.zone_entries == 1 and "1 of 2 episodes entered a zone" in habit_line(habit, True)


def hall() -> GridMap:
    """20 x 10 m open hall at 0.05 m, a one-cell wall frame."""
    data = np.zeros((200, 400), dtype=np.int8)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    return GridMap(data=data, resolution=RES, name="hall")


def test_keep_out_learnt_where_the_expert_goes_and_the_robot_never_did(tmp_path):
    from ecahd_core.astar import clearance_for_footprint, planner_for
    from ecahd_core.lanes import expert_routes

    grid, fp = hall(), make_footprint("circle")
    # the operators drive round a bay in the middle (x 8..12, y 3..7); A* would cross it
    demos, starts, goals = [], [], []
    for k in range(5):
        y = 4.6 + 0.2 * k
        route = np.array([(2.0, y), (6.0, 8.5), (14.0, 8.5), (18.0, y)])
        demos += [route, route[::-1]]
        starts += [route[0], route[-1]]
        goals += [route[-1], route[0]]
    expert = expert_routes(grid, fp, np.array(starts), np.array(goals))
    assert len(expert) == 10
    field = LaneField.fit(demos, grid, expert=expert, footprint=fp)
    keep = field.keep_out
    assert keep is not None and keep.shape == field.density.shape[1:]

    def at(x, y):
        return bool(keep[int(y / 0.1), int(x / 0.1)])

    assert at(10.0, 5.0) and at(8.0, 4.0) and at(12.0, 6.0)  # the bay
    assert not at(10.0, 8.5) and not at(2.0, 5.0) and not at(10.0, 1.0)  # driven, or far
    planning = field.with_keep_out(grid)
    assert planning.name == grid.name and planning.data.shape == grid.data.shape
    assert grid.is_free(np.array([10.0, 5.0]))  # the map itself is untouched
    assert not planning.is_free(np.array([10.0, 5.0])) and planning.is_free(np.array([10.0, 8.5]))
    around = planner_for(planning, clearance_for_footprint(fp)).plan((2.0, 5.0), (18.0, 5.0))
    assert not any(at(x, y) for x, y in around)  # A* on the planning map goes round the bay
    back = LaneField.load(field.save(tmp_path / "k.npz"))
    np.testing.assert_array_equal(back.keep_out, keep)
    # without the expert: no keep-out, the planning map is the map
    plain = LaneField.fit(demos, grid)
    assert plain.keep_out is None and plain.with_keep_out(grid) is grid
    with pytest.raises(EcahdError, match="needs the robot's footprint"):
        LaneField.fit(demos, grid, expert=expert)
