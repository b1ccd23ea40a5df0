"""Scenario files (ecahd_core.scenario, no rclpy, no pybullet): the YAML format, one error line
per bad entry with the others kept, moving obstacles back and forth, footprints, round trip."""
import math

import numpy as np
import pytest

from ecahd_core.errors import EcahdError
from ecahd_core.scenario import (Obstacle, ScenarioError, load_scenario, obstacle_footprints,
                                 parse_obstacles, read_scenario, write_scenario)

EXAMPLE = """\
obstacles:
  - {shape: box, x: 4.5, y: 5.5, yaw: 0.0, size: [0.4, 0.6]}
  - {shape: cylinder, x: 6.5, y: 5.3, radius: 0.25}
  - {shape: cylinder, radius: 0.3, path: [[1.5, 3.5], [1.5, 5.5]], speed: 0.4}   # moving
"""


def test_the_documented_example_loads(tmp_path):
    path = tmp_path / "scenario.yaml"
    path.write_text(EXAMPLE)
    box, cyl, mover = load_scenario(path)
    assert box == Obstacle("box", 4.5, 5.5, 0.0, (0.4, 0.6))
    assert cyl == Obstacle("cylinder", 6.5, 5.3, radius=0.25)
    assert not box.moving and not cyl.moving
    assert mover.moving and (mover.x, mover.y) == (1.5, 3.5)  # starts at path[0]
    assert (mover.radius, mover.speed, mover.path) == (0.3, 0.4, ((1.5, 3.5), (1.5, 5.5)))


@pytest.mark.parametrize("entry, reason", [
    ({"shape": "cone", "x": 1, "y": 1}, "shape must be one of box, cylinder, got 'cone'"),
    ({"x": 1, "y": 1, "radius": 0.2}, "missing field 'shape'"),
    ({"shape": "cylinder", "x": 1, "radius": 0.2}, "missing field 'y'"),
    ({"shape": "box", "x": 1, "y": 1}, "missing field 'size'"),
    ({"shape": "cylinder", "x": 1, "y": 1}, "missing field 'radius'"),
    ({"shape": "cylinder", "x": float("nan"), "y": 1, "radius": 0.2}, "x must be finite"),
    ({"shape": "box", "x": 1, "y": 1, "yaw": float("inf"), "size": [1, 1]}, "yaw must be finite"),
    ({"shape": "cylinder", "x": "one", "y": 1, "radius": 0.2}, "x must be a number"),
    ({"shape": "cylinder", "x": True, "y": 1, "radius": 0.2}, "x must be a number"),
    ({"shape": "cylinder", "x": 1, "y": 1, "radius": 0.0}, "radius must be > 0"),
    ({"shape": "cylinder", "x": 1, "y": 1, "radius": -0.3}, "radius must be > 0"),
    ({"shape": "box", "x": 1, "y": 1, "size": [0.4, 0.0]}, "size must be > 0"),
    ({"shape": "box", "x": 1, "y": 1, "size": [0.4]}, "size must be [x, y]"),
    ({"shape": "box", "x": 1, "y": 1, "size": [0.4, float("nan")]}, "must be finite"),
    ({"shape": "box", "x": 1, "y": 1, "radius": 0.2, "size": [1, 1]}, "not radius"),
    ({"shape": "cylinder", "x": 1, "y": 1, "raduis": 0.2}, "unknown field(s) raduis"),
    ({"shape": "cylinder", "radius": 0.2, "path": [[1, 1]], "speed": 0.5},
     "at least 2 points"),
    ({"shape": "cylinder", "radius": 0.2, "path": [[1, 1], [1, 1]], "speed": 0.5},
     "zero length"),
    ({"shape": "cylinder", "radius": 0.2, "path": [[1, 1], [2, 1]]}, "missing field 'speed'"),
    ({"shape": "cylinder", "radius": 0.2, "path": [[1, 1], [2, 1]], "speed": 0.0},
     "speed must be > 0"),
    ({"shape": "cylinder", "radius": 0.2, "path": [[1, 1], [2, 1]], "speed": float("nan")},
     "speed must be finite"),
    ({"shape": "cylinder", "radius": 0.2, "path": [[1, 1], [2, "b"]], "speed": 1.0},
     "must be a number"),
    ({"shape": "cylinder", "x": 1, "y": 1, "radius": 0.2, "path": [[1, 1], [2, 1]],
      "speed": 1.0}, "not x, y"),
    ({"shape": "cylinder", "radius": 0.2, "speed": 1.0}, "path must be a list"),
    ("box at 1 1", "must be a mapping"),
])
def test_a_bad_entry_is_one_line_naming_it_and_the_others_load(entry, reason):
    good = {"shape": "cylinder", "x": 2.0, "y": 3.0, "radius": 0.2}
    obstacles, errors = parse_obstacles({"obstacles": [good, entry, good]})
    assert obstacles == [Obstacle("cylinder", 2.0, 3.0, radius=0.2)] * 2
    assert len(errors) == 1 and "\n" not in errors[0]
    assert errors[0].startswith(f"obstacle 1 {entry!r}: ")  # index and content
    assert reason in errors[0]


def test_empty_and_malformed_documents(tmp_path):
    assert parse_obstacles(None) == ([], [])
    assert parse_obstacles({"obstacles": []}) == ([], [])
    assert parse_obstacles({"obstacles": None}) == ([], [])
    for bad, match in (([1, 2], "mapping"), ({"obstacle": []}, "unknown scenario key"),
                       ({"obstacles": {"shape": "box"}}, "must be a list")):
        with pytest.raises(ScenarioError, match=match):
            parse_obstacles(bad)
    with pytest.raises(ScenarioError, match="cannot read"):
        read_scenario(tmp_path / "missing.yaml")
    (tmp_path / "broken.yaml").write_text("obstacles: [\n")
    with pytest.raises(EcahdError, match="not valid YAML"):
        read_scenario(tmp_path / "broken.yaml")


def test_strict_load_lists_the_bad_entries_lenient_read_keeps_the_good(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text("obstacles:\n  - {shape: cylinder, x: 1, y: 1, radius: 0.2}\n"
                    "  - {shape: cylinder, x: .nan, y: 1, radius: 0.2}\n")
    obstacles, errors = read_scenario(path)
    assert len(obstacles) == 1 and len(errors) == 1 and errors[0].startswith("obstacle 1 ")
    with pytest.raises(ScenarioError, match="1 bad obstacle"):
        load_scenario(path)


def test_moving_obstacle_goes_back_and_forth_along_the_polyline():
    # an L: (0, 0) -> (2, 0) -> (2, 1), length 3 m, at 1 m/s: a round trip takes 6 s
    ob = Obstacle("cylinder", 0.0, 0.0, radius=0.1, path=((0, 0), (2, 0), (2, 1)), speed=1.0)
    assert ob.path_length == pytest.approx(3.0)
    expected = {0.0: (0, 0), 1.0: (1, 0), 2.0: (2, 0), 2.5: (2, 0.5), 3.0: (2, 1),
                3.5: (2, 0.5),  # on the way back
                5.0: (1, 0), 6.0: (0, 0), 7.0: (1, 0),  # one round trip later, again
                6.0 * 100 + 2.5: (2, 0.5)}
    for t, xy in expected.items():
        assert ob.position(t) == pytest.approx(xy, abs=1e-9), t
    static = Obstacle("box", 4.0, 5.0, 0.3, (1.0, 0.5))
    assert static.position(0.0) == static.position(123.4) == (4.0, 5.0)


def test_footprints_cover_the_shape():
    box = Obstacle("box", 1.0, 2.0, math.pi / 2, (0.4, 0.2))  # turned: 0.2 along x, 0.4 along y
    poly = box.footprint()
    assert poly.min(axis=0) == pytest.approx([0.9, 1.8])
    assert poly.max(axis=0) == pytest.approx([1.1, 2.2])
    cyl = Obstacle("cylinder", 0.0, 0.0, radius=0.5, path=((0, 0), (4, 0)), speed=2.0)
    ring = obstacle_footprints([box, cyl], t=1.0)[1]  # cylinder at (2, 0) after 1 s
    d = np.hypot(ring[:, 0] - 2.0, ring[:, 1])
    assert np.all(d >= 0.5)  # circumscribed: the polygon contains the circle ...
    mid = (ring + np.roll(ring, -1, axis=0)) / 2
    # ... tightly: its edges touch the circle at their midpoints
    assert np.hypot(mid[:, 0] - 2.0, mid[:, 1]) == pytest.approx(np.full(len(ring), 0.5))


def test_write_then_load_round_trips(tmp_path):
    path = tmp_path / "scenario.yaml"
    path.write_text(EXAMPLE)
    obstacles = load_scenario(path)
    again = load_scenario(write_scenario(tmp_path / "out" / "copy.yaml", obstacles))
    assert again == obstacles


def test_generated_scenarios_keep_goals_reachable_and_moving_runs_clear_of_the_stops():
    from ecahd_core.astar import AStarPlanner, clearance_for_footprint, plan_from_pose
    from ecahd_core.footprint import make_footprint
    from ecahd_core.maps import load_map
    from ecahd_core.scenario import MARK_GROWTH, generate_scenario, rasterize

    grid, robot = load_map("maze2d-large"), make_footprint("circle")
    stops = np.array([[1.5, 7.5], [10.5, 7.5], [10.5, 1.5]])  # corridor corners of the maze
    a = generate_scenario(grid, robot, stops, static=2, moving=2, seed=3, strict=False)
    b = generate_scenario(grid, robot, stops, static=2, moving=2, seed=3, strict=False)
    assert [o.to_dict() for o in a.obstacles] == [o.to_dict() for o in b.obstacles]  # seeded
    assert len(a.obstacles) == len(a.kinds) >= 1
    # with every static obstacle in place (grown as scan marks grow it) each goal is reachable
    statics = [o for o in a.obstacles if not o.moving]
    planner = AStarPlanner(rasterize(grid, statics, grow=MARK_GROWTH),
                           clearance_for_footprint(robot))
    for s, g in zip(stops[:-1], stops[1:]):
        assert len(plan_from_pose(planner, s, g)) >= 2
    for o in a.obstacles:  # a moving one's whole run keeps keep_clear (1.2 m) from the stops
        if not o.moving:
            continue
        run = np.asarray(o.path)
        for t in np.linspace(0.0, 1.0, 21):
            p = run[0] + t * (run[-1] - run[0])
            assert np.linalg.norm(stops - p, axis=1).min() >= 1.2 - 1e-9
