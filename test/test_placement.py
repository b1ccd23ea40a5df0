"""Waypoints in free space: placement.WaypointPlacer (issue 10)."""
import numpy as np
import pytest

from ecahd_core.collision import check_collision
from ecahd_core.errors import EcahdError
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import GridMap
from ecahd_core.placement import WaypointPlacer, placer_for


def block_map(resolution: float = 0.1):
    """A 6 x 4 m room with a wall block x in [1, 5], y in [1.5, 2.5] between a bottom corridor
    (y < 1.5) and a top one (y > 2.5)."""
    k = int(round(0.1 / resolution))
    data = np.zeros((40 * k, 60 * k), dtype=np.int8)
    data[15 * k:25 * k, 10 * k:50 * k] = 100
    return GridMap(data, resolution, (0.0, 0.0), name="block")


def test_a_waypoint_just_inside_a_wall_moves_to_the_nearest_free_pose():
    grid, robot = block_map(), make_footprint("circle")
    # (3, 1.2) is 0.3 m below the block: the 0.4 m circle overlaps it by 0.1 m; the nearest
    # free positions are 0.1 m lower, and a little lower still the legs keep clear of the block
    plan = np.array([[0.5, 0.75], [3.0, 1.2], [5.5, 0.75]])
    placer = WaypointPlacer(grid, robot, leg_rounds=0)
    assert placer.blocked(plan).tolist() == [False, True, False]
    placed, moved = placer.place(plan)
    assert moved == 1 and 0.9 <= placed[1, 1] <= 1.1 + 1e-9 and abs(placed[1, 0] - 3.0) < 0.1
    np.testing.assert_array_equal(placed[[0, 2]], plan[[0, 2]])
    assert check_collision(placed, robot, grid).collision_free


def test_a_deep_waypoint_goes_to_the_side_its_legs_reach_not_the_nearest():
    grid, robot = block_map(), make_footprint("circle")
    # (3, 2.3): the top corridor is nearer (free from y = 2.9, 0.6 m away) than the bottom one
    # (free up to y = 1.1, 1.2 m away), but the legs from and to the bottom corridor would cross
    # the block from there
    plan = np.array([[0.5, 0.75], [3.0, 2.3], [5.5, 0.75]])
    placed, moved = WaypointPlacer(grid, robot, reach=1.5, leg_rounds=0).place(plan)
    assert moved == 1 and placed[1, 1] <= 1.1 + 1e-9
    assert check_collision(placed, robot, grid).collision_free
    # out of reach: the waypoint stays where it was
    stuck, moved = WaypointPlacer(grid, robot, reach=0.3, leg_rounds=0).place(plan)
    assert moved == 0 and np.array_equal(stuck, plan)


def test_the_goal_moves_only_within_its_own_reach():
    grid, robot = block_map(), make_footprint("circle")
    plan = np.array([[0.5, 0.75], [3.0, 1.2]])
    placer = WaypointPlacer(grid, robot, leg_rounds=0)
    assert placer.place(plan)[1] == 0  # last_reach 0: a goal the caller checked stays
    placed, moved = placer.place(plan, last_reach=0.2)
    assert moved == 1 and np.linalg.norm(placed[1] - plan[1]) <= 0.2 + 1e-9


def test_leg_repair_bends_a_leg_that_crosses_a_wall_round_it():
    grid, robot = block_map(0.05), make_footprint("circle")
    plan = np.array([[0.5, 0.75], [5.5, 3.25]])  # both ends free, the straight leg crosses
    assert not check_collision(plan, robot, grid).collision_free
    placer = WaypointPlacer(grid, robot, reach=1.5, leg_rounds=4)
    repaired, added = placer.repair(plan)
    assert added >= 1 and len(repaired) == len(plan) + added
    np.testing.assert_array_equal(repaired[[0, -1]], plan[[0, -1]])
    assert check_collision(repaired, robot, grid).collision_free
    assert placer.leg_walls(repaired).max() == 0
    # a free leg is left alone
    free = np.array([[0.5, 0.75], [5.5, 0.75]])
    assert placer.repair(free)[1] == 0


def test_leg_repair_searches_a_leg_no_waypoint_improves_once_not_every_round(monkeypatch):
    """A leg through a wall thicker than the repair's reach (no free waypoint within it)
    stays as it is, and the later rounds do not search it again (the same leg, the same
    answer)."""
    data = np.zeros((200, 120), dtype=np.int8)  # 6 x 10 m at 0.05 m
    data[20:180, :] = 100  # a wall across the room from y = 1 m to y = 9 m
    grid = GridMap(data, 0.05, (0.0, 0.0), name="wall")
    robot = make_footprint("circle")
    plan = np.array([[0.5, 0.5], [2.5, 0.5], [2.5, 9.5]])  # the second leg crosses it
    placer = WaypointPlacer(grid, robot, reach=1.0, leg_rounds=3)
    calls = {"best": 0, "two_bends": 0}
    for name in calls:
        original = getattr(WaypointPlacer, f"_{name}")

        def spy(self, *args, _original=original, _name=name, **kwargs):
            calls[_name] += 1
            return _original(self, *args, **kwargs)

        monkeypatch.setattr(WaypointPlacer, f"_{name}", spy)
    repaired, added = placer.repair(plan)
    assert added == 0
    np.testing.assert_array_equal(repaired, plan)
    assert calls == {"best": 1, "two_bends": 1}


def test_placer_for_chooses_by_map_size_and_rejects_bad_reach():
    robot = make_footprint("circle")
    small = block_map()  # 2400 cells: off unless asked for
    assert placer_for(small, robot) is None and placer_for(small, robot, 0.0) is None
    assert placer_for(small, robot, 0.5).reach == 0.5
    big = GridMap(np.zeros((300, 300), dtype=np.int8), 0.05, (0.0, 0.0), name="big")
    assert isinstance(placer_for(big, robot), WaypointPlacer)
    with pytest.raises(EcahdError, match="reach"):
        placer_for(small, robot, -1.0)
    with pytest.raises(EcahdError, match="reach"):
        WaypointPlacer(small, robot, reach=float("nan"))


@pytest.mark.parametrize("robot", ["circle", "quadruped"])
def test_best_judges_candidates_in_score_order_and_finds_the_argmin_over_free_ones(robot):
    """_best scores every candidate on the distance transform and asks the exact checker only
    in score order: its answer must be the argmin over all free candidates (ties: the nearest),
    the answer of judging every candidate first."""
    from ecahd_core.collision import DEFAULT_TOLERANCE
    from ecahd_core.mapgen import MapGenConfig, generate
    from ecahd_core.placement import LEG_WEIGHT

    grid = generate(MapGenConfig("office", 16, 12, 0.05, 3)).grid
    fp = make_footprint(robot)
    placer = WaypointPlacer(grid, fp)
    rng = np.random.default_rng(0)
    lo, hi = np.array(grid.origin) + 0.5, np.array(grid.origin) + [15.5, 11.5]
    found = 0
    for _ in range(40):
        prev, at, nxt = rng.uniform(lo, hi, size=(3, 2))
        off = placer._within(placer.reach)
        got = placer._best(at, off, prev, nxt)
        cand = at + off
        cand = cand[grid.in_bounds(cand)]  # the reference: every candidate judged
        d = cand - prev
        depth = placer.clearance.depths(np.column_stack([cand, np.arctan2(d[:, 1], d[:, 0])]),
                                        fp)
        cand = cand[depth <= DEFAULT_TOLERANCE]
        if len(cand) == 0:
            assert got is None
            continue
        score = (LEG_WEIGHT * (placer.wall_length(prev, cand) + placer.wall_length(nxt, cand))
                 + np.linalg.norm(cand - at, axis=1))
        np.testing.assert_allclose(got, cand[int(np.argmin(score))])
        found += 1
    assert found >= 20


def test_a_wider_repair_reach_finds_a_door_away_from_the_leg():
    """A leg across a wall whose door is 2.7 m from where it crosses: leg repair within the
    placement's 1 m reach cannot bend it through the door; within 3 m (the default) it can."""
    res = 0.05
    data = np.zeros((int(6 / res), int(10 / res)), dtype=np.int8)
    data[int(2.9 / res):int(3.1 / res), :] = 100  # a wall along y = 3 m
    data[int(2.9 / res):int(3.1 / res), int(7.2 / res):int(8.2 / res)] = 0  # a 1 m door
    grid, robot = GridMap(data, res, (0.0, 0.0), name="door"), make_footprint("circle")
    leg = np.array([[3.0, 1.0], [7.0, 5.0]])  # crosses the wall at x = 5 m
    near, _ = WaypointPlacer(grid, robot, leg_rounds=3, repair_reach=1.0).repair(leg)
    assert not check_collision(near, robot, grid).collision_free
    placer = WaypointPlacer(grid, robot, leg_rounds=3)
    assert placer.repair_reach == 3.0
    far, added = placer.repair(leg)
    assert added >= 1 and check_collision(far, robot, grid).collision_free
    assert any(7.2 < x < 8.2 and 2.5 < y < 3.5 for x, y in far[1:-1])  # through the door
    with pytest.raises(EcahdError, match="leg repair's reach"):
        WaypointPlacer(grid, robot, repair_reach=0.0)


def test_two_bends_take_a_leg_round_the_end_of_a_wall_that_no_single_bend_clears():
    """a and b 0.6 m either side of a wall that ends 1 m above the map's edge: every single new
    waypoint leaves a leg clipping the wall's end; two (one below each side) clear it."""
    res = 0.05
    data = np.zeros((int(6 / res), int(6 / res)), dtype=np.int8)
    data[int(1.0 / res):, int(2.9 / res):int(3.1 / res)] = 100  # a wall x = 3 m, from y = 1 m up
    grid, robot = GridMap(data, res, (0.0, 0.0), name="wall_end"), make_footprint("circle")
    leg = np.array([[2.3, 3.0], [3.7, 3.0]])
    one, _ = WaypointPlacer(grid, robot, leg_rounds=3, two_bends=False).repair(leg)
    assert not check_collision(one, robot, grid).collision_free
    placer = WaypointPlacer(grid, robot, leg_rounds=3)
    two, added = placer.repair(leg)
    assert added >= 2 and check_collision(two, robot, grid).collision_free
    np.testing.assert_array_equal(two[[0, -1]], leg)
    assert placer.leg_walls(two).max() == 0
    # round the wall's end: a waypoint below it on each side
    assert any(x < 2.9 and y < 1.0 for x, y in two) and any(x > 3.1 and y < 1.0 for x, y in two)


def test_repairing_only_the_first_legs_gives_those_legs_as_a_full_repair_does():
    """``legs=1``: the first leg is bent exactly as when every leg is repaired; the others stay."""
    grid, robot = block_map(0.05), make_footprint("circle")
    # both legs cross the block: bottom corridor -> top corridor -> bottom corridor
    plan = np.array([[0.5, 0.75], [3.0, 3.25], [5.5, 0.75]])
    placer = WaypointPlacer(grid, robot, reach=1.5, leg_rounds=4)
    full, n_full = placer.repair(plan)
    first, n_first = placer.repair(plan, legs=1)
    assert 0 < n_first < n_full
    k = int(np.flatnonzero((first == plan[1]).all(axis=1))[0])  # where the first leg ends
    np.testing.assert_array_equal(first[:k + 1], full[:k + 1])
    np.testing.assert_array_equal(first[k:], plan[1:])  # the second leg as it was
    none, n_none = placer.repair(plan, legs=0)
    assert n_none == 0 and np.array_equal(none, plan)


def test_wall_length_samples_each_leg_and_counts_off_map_as_wall():
    """wall_length's samples (ceil(length / resolution) + 1 per leg) are judged as
    StaticClearance.wall_distance < the inscribed radius + half a cell diagonal, off the map
    included, each in the cell floor((xy - origin) / resolution + EDGE_SHIFT); its float32 cell
    coordinates may read a sample within ~1e-4 cell of that edge in the neighbouring cell (at
    most one sample of a leg, on few legs); each leg's value does not depend on the others in
    its batch (a batch longer than WALL_CHUNK is judged in chunks of similar legs)."""
    from ecahd_core.placement import EDGE_SHIFT, WALL_CHUNK

    rng = np.random.default_rng(3)
    # scattered posts: the near region's edge lies everywhere
    data = np.where(rng.random((80, 120)) < 0.004, 100, 0).astype(np.int8)
    grid = GridMap(data, 0.05, (0.0, 0.0), name="posts")
    placer = WaypointPlacer(grid, make_footprint("circle"))
    lo, hi = np.array(grid.bounds[:2]) - 1.0, np.array(grid.bounds[2:]) + 1.0
    a = rng.uniform(lo, hi, (3 * WALL_CHUNK, 2))
    b = a + rng.uniform(-3, 3, a.shape)
    b[:5] = a[:5]  # zero-length legs
    # legs along cell edges (waypoints on a lattice of the resolution): read in the cells above
    a[5:300] = np.round(a[5:300] / grid.resolution) * grid.resolution
    b[5:300] = a[5:300] + np.round(b[5:300] - a[5:300]) * [[1.0, 0.0]]
    near_map = np.pad(grid.free_distance < placer._near, 1, constant_values=True)
    got = placer.wall_length(a, b)
    off_by = []
    for k in range(len(a)):
        length = float(np.linalg.norm(b[k] - a[k]))
        count = max(int(np.ceil(length / grid.resolution)) + 1, 2)
        pts = a[k] + np.linspace(0.0, 1.0, count)[:, None] * (b[k] - a[k])
        cell = np.floor((pts - grid.origin[:2]) / grid.resolution + EDGE_SHIFT).astype(int)
        cell = np.clip(cell, -1, [grid.width, grid.height])
        near = near_map[cell[:, 1] + 1, cell[:, 0] + 1]
        off_by.append(abs(got[k] - near.mean() * length) / (length / count + 1e-12))
    off_by = np.array(off_by)
    assert np.all(off_by[:300] < 1e-6), off_by[:300].max()
    assert np.all(off_by < 1 + 1e-6) and np.mean(off_by > 1e-6) < 0.01, off_by.max()
    np.testing.assert_array_equal(placer.wall_length(a[7], b[7:8]), got[7:8])
    np.testing.assert_array_equal(placer.wall_length(a[::-1], b[::-1]), got[::-1])
    off = np.array([[lo[0] - 0.5, lo[1]]])  # a leg wholly off the map is wall all along
    assert placer.wall_length(off[0], off + [1.0, 0.0])[0] == pytest.approx(1.0)
    assert placer.wall_length(a[0], np.empty((0, 2))).shape == (0,)


def test_a_robot_wider_than_long_is_judged_by_its_half_width_along_a_leg_but_not_past_its_ends():
    """The humanoid (0.25 m long, 0.5 m wide) walking past the end of a wall 0.18 m to its
    side overlaps it (half-width 0.25 m), though its inscribed circle (0.125 m) clears it: the
    leg counts as wall, and the exact checker agrees. A leg that stops 0.2 m before a wall
    straight ahead keeps the front (0.125 m) clear: the band's circle is trimmed at the ends,
    so that leg counts no wall. The quadruped (longer than wide) keeps the inscribed test."""
    from ecahd_core.placement import leg_band

    grid = block_map(0.05)  # the block's left end at x = 1.0, y in [1.5, 2.5]
    human, quad = make_footprint("humanoid"), make_footprint("quadruped")
    assert leg_band(human) == (0.25, 0.125)
    assert leg_band(quad) == (None, 0.0) and leg_band(make_footprint("circle")) == (None, 0.0)
    past = np.array([[0.82, 0.5], [0.82, 3.5]])  # x 0.82: 0.18 m left of the block's end
    for robot, walls in ((human, True), (quad, False)):
        placer = WaypointPlacer(grid, robot)
        assert bool(placer.leg_walls(past)[0] > 0) == walls, robot.name
        assert bool(check_collision(past, robot, grid).collision_free) != walls, robot.name
    placer = WaypointPlacer(grid, human)
    ahead = np.array([[3.0, 0.4], [3.0, 1.3]])  # stops 0.2 m below the block, facing it
    assert check_collision(ahead, human, grid).collision_free
    assert placer.leg_walls(ahead)[0] == 0
    # the same leg judged by a circle of the half-width all along would have counted wall
    square = make_footprint("[[0.25, 0.25], [-0.25, 0.25], [-0.25, -0.25], [0.25, -0.25]]")
    assert WaypointPlacer(grid, square).leg_walls(ahead)[0] > 0


def test_read_cells_reads_the_nearest_pixel_in_pieces_on_images_wider_than_remap_takes(
        monkeypatch):
    """read_cells (cv2.remap, nearest) reads the same pixels as rounding the coordinates
    ((K, n) float32, off the image or NaN: 1), also where the image or the output is wider than
    REMAP_SIDE: in column pieces and in windows round the samples, halving the legs (and a
    single leg's samples) until a window fits."""
    import ecahd_core.placement as placement

    rng = np.random.default_rng(5)
    image = (rng.random((90, 140)) < 0.5).astype(np.uint8)
    u = rng.uniform(-5, 145, (40, 70)).astype(np.float32)
    v = rng.uniform(-5, 95, (40, 70)).astype(np.float32)
    u[:, :10] = np.linspace(0, 139, 10)[None]  # a few legs across the whole width
    v[3, 5], u[4, 6] = np.nan, np.nan
    col, row = np.rint(u), np.rint(v)
    inside = (col >= 0) & (col < 140) & (row >= 0) & (row < 90)
    want = np.ones(u.shape, dtype=np.uint8)
    want[inside] = image[row[inside].astype(int), col[inside].astype(int)]
    np.testing.assert_array_equal(placement.read_cells(image, u, v), want)
    calls = []
    import cv2

    real = cv2.remap

    def spy(img, *args, **kwargs):
        calls.append(img.shape)
        return real(img, *args, **kwargs)

    monkeypatch.setattr(cv2, "remap", spy)
    monkeypatch.setattr(placement, "REMAP_SIDE", 32)
    np.testing.assert_array_equal(placement.read_cells(image, u, v), want)
    assert len(calls) > 4 and all(max(s) <= 32 for s in calls)
    np.testing.assert_array_equal(placement.read_cells(image, u[:0], v[:0]), want[:0])
