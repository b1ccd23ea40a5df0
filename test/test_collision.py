"""Exact swept-footprint collision checker: hand-built grids whose outcomes are derived in the
comments, the maze2d-large layout, bad input, and a brute-force cross-check."""
import math

import numpy as np
import pytest

from ecahd_core.collision import (CollisionReport, check_collision, collision_free_rate,
                                  convex_pieces, densify)
from ecahd_core.errors import TrajectoryError
from ecahd_core.footprint import make_footprint, point_in_polygon, polygon_footprint
from ecahd_core.maps import OCCUPIED, GridMap, builtin_map

SQRT2 = math.sqrt(2.0)


def grid_from_mask(occ: np.ndarray, resolution: float) -> GridMap:
    """(H, W) bool, row 0 at the lowest y, origin (0, 0)."""
    return GridMap(data=np.where(occ, OCCUPIED, 0).astype(np.int8), resolution=resolution)


def corridor(width_cells: int, *, wall_cells: int = 2, length_cells: int = 40,
             resolution: float = 0.1) -> GridMap:
    """A corridor along x: ``wall_cells`` wall rows, ``width_cells`` free rows, wall rows."""
    occ = np.zeros((2 * wall_cells + width_cells, length_cells), dtype=bool)
    occ[:wall_cells] = True
    occ[wall_cells + width_cells:] = True
    return grid_from_mask(occ, resolution)


def line(a, b, n: int = 20) -> np.ndarray:
    """(n, 2) evenly spaced points from a to b."""
    return np.linspace(np.asarray(a, float), np.asarray(b, float), n)


def square(side: float) -> np.ndarray:
    h = side / 2
    return np.array([[h, h], [-h, h], [-h, -h], [h, -h]])


def block_map() -> GridMap:
    """4 m x 4 m at 0.1 m with one solid block x in [1, 3), y in [1, 3): its lower-left corner
    is the wall corner at (1, 1)."""
    occ = np.zeros((40, 40), dtype=bool)
    occ[10:30, 10:30] = True
    return grid_from_mask(occ, 0.1)


# ---------------------------------------------------------------------------- circle robot
def test_circle_exactly_as_wide_as_the_corridor_fits():
    # Free rows 2..9 -> y in [0.2, 1.0]: a 0.8 m corridor. A 0.4 m circle on y = 0.6 is exactly
    # 0.4 m from both walls: touching, not colliding. The corridor is 4 m long and the map edge
    # (off-map = wall) is 0.5 m from the path ends at x = 0.5 and 3.5.
    grid = corridor(8)
    fp = make_footprint("circle", radius=0.4)
    rep = check_collision(line((0.5, 0.6), (3.5, 0.6)), fp, grid)
    assert isinstance(rep, CollisionReport)
    assert rep.collision_free
    assert rep.penetration_fraction == 0.0 and rep.max_depth == 0.0
    assert rep.first_collision_index is None
    assert not rep.colliding.any() and np.all(rep.depths == 0.0)


def test_circle_shifted_sideways_collides():
    # On y = 0.65 the upper wall (y = 1.0) is 0.35 m away: every pose overlaps it by 0.05 m.
    grid = corridor(8)
    fp = make_footprint("circle", radius=0.4)
    rep = check_collision(line((0.5, 0.65), (3.5, 0.65)), fp, grid)
    assert not rep.collision_free
    assert rep.penetration_fraction == 1.0
    assert rep.first_collision_index == 0
    assert rep.max_depth == pytest.approx(0.05, abs=1e-9)


def test_tolerance_decides_touching():
    # Moving 1e-4 m off the centre line overlaps the wall by 1e-4 m: a collision at the 1e-6 m
    # default tolerance, mere touching at a 1e-3 m tolerance.
    grid = corridor(8)
    fp = make_footprint("circle", radius=0.4)
    traj = line((0.5, 0.6001), (3.5, 0.6001))
    assert not check_collision(traj, fp, grid).collision_free
    assert check_collision(traj, fp, grid, tolerance=1e-3).collision_free


# ---------------------------------------------------------------------------- square robot
def test_square_along_a_corridor_as_wide_as_it_is_fits():
    # Free rows 2..5 -> y in [0.2, 0.6]. The 0.4 x 0.4 square on y = 0.4 heading along x
    # (the segment direction) spans y in [0.2, 0.6]: its sides lie on the walls (depth 0).
    grid = corridor(4)
    fp = polygon_footprint(square(0.4))
    rep = check_collision(line((0.5, 0.4), (3.5, 0.4)), fp, grid)
    assert rep.collision_free
    assert np.allclose(rep.dense_poses[:, 2], 0.0)


def test_square_rotated_45_degrees_collides():
    # Rotated by 45 deg, its half-diagonal 0.2 * sqrt(2) = 0.283 m reaches past the walls at
    # +-0.2 m: the vertex pokes 0.2 * sqrt(2) - 0.2 = 0.0828 m into the wall cell below it, and
    # pushing the square up by that much is the cheapest way out (along the diagonal axes the
    # cell's corner needs 0.094 m).
    grid = corridor(4)
    fp = polygon_footprint(square(0.4))
    traj = line((0.5, 0.4), (3.5, 0.4))
    rep = check_collision(traj, fp, grid, headings=np.full(len(traj), math.pi / 4))
    assert not rep.collision_free and rep.penetration_fraction == 1.0
    assert rep.max_depth == pytest.approx(0.2 * SQRT2 - 0.2, abs=1e-9)


def test_square_turning_on_the_spot_is_sampled():
    # Two identical waypoints turning 0 -> 90 deg: the corners sweep a circle of radius 0.283 m,
    # so the poses in between (about 45 deg) hit the walls of the 0.4 m corridor although both
    # end poses fit. The turn is sampled every step of corner travel: ceil(pi/2 * 0.283 / 0.025)
    # = 18 poses plus the last one.
    grid = corridor(4)
    fp = polygon_footprint(square(0.4))
    rep = check_collision([[2.0, 0.4], [2.0, 0.4]], fp, grid, headings=[0.0, math.pi / 2])
    assert len(rep.dense_poses) == math.ceil(math.pi / 2 * 0.2 * SQRT2 / 0.025) + 1
    assert not rep.colliding[0] and not rep.colliding[-1]
    assert not rep.collision_free


# --------------------------------------------------------------------------- wall corners
def test_diagonal_through_a_wall_corner_collides():
    # x + y = 2.5 passes (1.25, 1.25), 0.25 m inside the block: the centre itself is in an
    # occupied cell there, so the depth is the full radius.
    fp = make_footprint("circle", radius=0.2)
    rep = check_collision(line((0.5, 2.0), (2.0, 0.5)), fp, block_map())
    assert not rep.collision_free
    assert rep.max_depth == pytest.approx(0.2)
    # It first collides once the centre passes x = 0.8 (y = 1.7), 0.2 m from the block's left
    # edge x = 1; dense poses advance 0.025 m along the diagonal, i.e. 0.018 m in x.
    x = rep.dense_poses[rep.first_collision_index, 0]
    assert 0.8 < x < 0.8 + 0.018


def test_path_around_the_wall_corner_is_free():
    # Down x = 0.5 then along y = 0.5: 0.5 m from the block and from the map edge, radius 0.2.
    fp = make_footprint("circle", radius=0.2)
    traj = np.array([[0.5, 2.0], [0.5, 0.5], [2.0, 0.5]])
    assert check_collision(traj, fp, block_map()).collision_free


def test_path_inside_a_wall_collides_everywhere():
    fp = make_footprint("quadruped")
    rep = check_collision(line((1.5, 1.5), (2.5, 2.5)), fp, block_map())
    assert rep.penetration_fraction == 1.0
    assert rep.first_collision_index == 0 and rep.colliding.all()


def test_leaving_the_map_collides():
    # Off-map is wall. Heading -x on y = 0.5 at radius 0.2, the map edge x = 0 is touched at
    # x = 0.2: dense poses are x = 0.5 - 0.025 k, so the first colliding one is k = 13 (x = 0.175).
    fp = make_footprint("circle", radius=0.2)
    rep = check_collision([[0.5, 0.5], [-1.0, 0.5]], fp, block_map())
    assert not rep.collision_free
    assert rep.first_collision_index == 13
    assert rep.dense_poses[13, 0] == pytest.approx(0.175)
    assert rep.colliding[13:].all()  # including the poses 1 m beyond the edge
    assert rep.max_depth == pytest.approx(0.2)


# ------------------------------------------------------------------------- oriented robots
def gap_map() -> GridMap:
    """2.5 m x 2.5 m at 0.05 m: a wall band y in [1.0, 1.5) with a gap x in [1.0, 1.35)
    (7 cells = 0.35 m)."""
    occ = np.zeros((50, 50), dtype=bool)
    occ[20:30] = True
    occ[20:30, 20:27] = False
    return grid_from_mask(occ, 0.05)


def test_quadruped_fits_a_gap_lengthwise_not_sideways():
    # The Go1 is 0.65 m long x 0.30 m wide. Driving up x = 1.175 (heading +y) it spans
    # x in [1.025, 1.325]: 0.025 m from each side of the 0.35 m gap. Its ends stay on the map
    # (y from 0.4 - 0.325 > 0 to 2.1 + 0.325 < 2.5).
    fp = make_footprint("quadruped")
    traj = line((1.175, 0.4), (1.175, 2.1), 35)
    along = check_collision(traj, fp, gap_map())
    assert along.collision_free
    assert np.allclose(along.dense_poses[:, 2], math.pi / 2)
    # Facing +x on the same path (headings given), it spans x in [0.85, 1.5]: 0.15 m into both
    # gap sides while its 0.30 m-deep body (y +-0.15) overlaps the band y in [1.0, 1.5), i.e.
    # for centres y in (0.85, 1.65) (touching at the ends). Dense poses are y = 0.4 + 0.0125 k,
    # k = 0..136 (step = 0.05 / 4): k = 37..99 collide, 63 of 137.
    across = check_collision(traj, fp, gap_map(), headings=np.zeros(len(traj)))
    assert not across.collision_free
    assert across.max_depth == pytest.approx(0.15)
    assert len(across.dense_poses) == 137
    assert np.array_equal(np.flatnonzero(across.colliding), np.arange(37, 100))
    assert across.penetration_fraction == pytest.approx(63 / 137)


def test_humanoid_does_not_fit_the_gap():
    # The G1 is 0.50 m wide across its heading, wider than the 0.35 m gap.
    traj = line((1.175, 0.4), (1.175, 2.1), 35)
    assert not check_collision(traj, make_footprint("humanoid"), gap_map()).collision_free


def test_non_convex_footprint_straddles_a_peg():
    # A 0.6 m square robot with a notch cut from its front: x in [0.05, 0.3], y in [-0.1, 0.1].
    # A 0.2 m x 0.1 m peg (x in [1.2, 1.4), y in [1.0, 1.1)) sits in the notch of the robot at
    # (1.1, 1.05) heading +x: the notch spans x in [1.15, 1.4], y in [0.95, 1.15], 0.05 m clear of
    # the peg on three sides. Its convex hull, or the robot turned around, covers the peg.
    u_shape = np.array([[-0.3, -0.3], [0.3, -0.3], [0.3, -0.1], [0.05, -0.1],
                        [0.05, 0.1], [0.3, 0.1], [0.3, 0.3], [-0.3, 0.3]])
    occ = np.zeros((30, 30), dtype=bool)
    occ[10, 12:14] = True
    grid = grid_from_mask(occ, 0.1)
    fp = polygon_footprint(u_shape)
    assert len(convex_pieces(fp.polygon)) == len(u_shape) - 2  # triangles by ear clipping
    pose = [[1.1, 1.05]]
    assert check_collision(pose, fp, grid, headings=[0.0]).collision_free
    assert not check_collision(pose, fp, grid, headings=[math.pi]).collision_free
    hull = polygon_footprint(square(0.6))
    assert not check_collision(pose, hull, grid, headings=[0.0]).collision_free


# -------------------------------------------------------------------------- degenerate input
def test_single_point_and_zero_length_trajectories():
    grid = block_map()
    fp = make_footprint("quadruped")
    rep = check_collision([[0.5, 0.5]], fp, grid)
    assert rep.collision_free and rep.dense_poses.shape == (1, 3)
    assert rep.dense_poses[0, 2] == 0.0  # no segment: heading 0
    rep = check_collision([[0.5, 0.5], [0.5, 0.5]], fp, grid)
    assert rep.collision_free and rep.colliding.shape == (len(rep.dense_poses),)
    assert check_collision([[2.0, 2.0]], fp, grid).penetration_fraction == 1.0


def test_zero_length_segments_keep_the_heading():
    # Segments: zero, +y (1 m), zero, +x (1 m); at step 0.5 each gives max(1, ceil(L / 0.5))
    # poses, and the last waypoint closes: 1 + 2 + 1 + 2 + 1 = 7 poses. The repeated first
    # waypoint faces where the robot goes next (+y); the repeated corner keeps the heading of the
    # segment before it (+y).
    poses = densify([[0, 0], [0, 0], [0, 1], [0, 1], [1, 1]], step=0.5)
    assert np.allclose(poses[:, :2], [[0, 0], [0, 0], [0, 0.5], [0, 1], [0, 1], [0.5, 1], [1, 1]])
    assert np.allclose(poses[:, 2], [math.pi / 2] * 4 + [0.0] * 3)


def test_dense_spacing_and_waypoints():
    traj = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.37]])
    poses = densify(traj, step=0.1)
    steps = np.linalg.norm(np.diff(poses[:, :2], axis=0), axis=1)
    assert steps.max() <= 0.1 + 1e-12
    # every waypoint is a dense pose: 10 poses on the first segment, ceil(3.7) = 4 on the second
    assert len(poses) == 10 + 4 + 1
    assert np.allclose(poses[[0, 10, 14], :2], traj)


def test_given_headings_turn_the_short_way():
    # 3.0 rad -> -3.0 rad is a 0.283 rad turn through pi, not a 6 rad turn through 0.
    poses = densify([[0, 0], [1, 0]], step=0.1, headings=[3.0, -3.0])
    assert np.all(np.abs(poses[:, 2]) >= 3.0 - 1e-12)


@pytest.mark.parametrize("bad", [
    np.zeros((5, 3)),  # wrong width
    np.zeros(2),  # one point without the P axis
    np.zeros((0, 2)),  # no points
    np.zeros((2, 5, 2)),  # a batch
    [[0.5, 0.5], [np.nan, 1.0]],
    [[0.5, 0.5], [np.inf, 1.0]],
    [["a", "b"]],
])
def test_bad_trajectories_raise(bad):
    with pytest.raises(TrajectoryError):
        check_collision(bad, make_footprint("circle"), block_map())


def test_bad_options_raise():
    fp, grid = make_footprint("circle"), block_map()
    traj = [[0.5, 0.5], [0.6, 0.5]]
    for kwargs in ({"step": 0.0}, {"step": float("nan")}, {"tolerance": -1.0},
                   {"headings": [0.0]}, {"headings": [0.0, np.nan]}):
        with pytest.raises(TrajectoryError):
            check_collision(traj, fp, grid, **kwargs)
    with pytest.raises(TrajectoryError):
        collision_free_rate([], fp, grid)


# ---------------------------------------------------------------------------- maze2d-large
# Corridor centres of maze2d-large, read off maps.MAZE_LAYOUTS (the top line is y in [8, 9]):
# "#OOOO#OOOOO#" is y in [7, 8] (open x in [1, 5)), column x in [4, 5) is open for y in [5, 8),
# "#OOOOOO#OOO#" is y in [5, 6] (open x in [1, 7)), column x in [6, 7) is open for y in [1, 6).
# Every centre line is 0.5 m from the walls; a turn's diagonal wall corner is 0.71 m away.
MAZE_PATH = np.array([[1.5, 7.5], [4.5, 7.5], [4.5, 5.5], [6.5, 5.5], [6.5, 1.5]])


def resample(waypoints: np.ndarray, n: int) -> np.ndarray:
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(waypoints, axis=0), axis=1))])
    t = np.linspace(0.0, s[-1], n)
    return np.stack([np.interp(t, s, waypoints[:, 0]), np.interp(t, s, waypoints[:, 1])], axis=1)


@pytest.mark.parametrize("robot", ["circle", "quadruped", "humanoid"])
def test_maze2d_large_corridor_centres_are_free(robot):
    grid = builtin_map("maze2d-large", resolution=0.1)
    rep = check_collision(resample(MAZE_PATH, 100), make_footprint(robot), grid)
    assert rep.collision_free


def test_maze2d_large_wall_between_open_cells():
    # The bottom open line "#OO#OOO#OGO#" is y in [1, 2]: x in [3, 4) is wall, so y = 1.5 from
    # x = 1.5 to 4.5 runs through it (x in [4, 7) is open again, and the walls of the next line
    # up, y in [2, 3), stay 0.5 m away).
    grid = builtin_map("maze2d-large", resolution=0.1)
    rep = check_collision(line((1.5, 1.5), (4.5, 1.5)), make_footprint("circle"), grid)
    assert not rep.collision_free
    # the 0.4 m circle touches the wall at x = 3 - 0.4 = 2.6 and clears it at x = 4 + 0.4 = 4.4
    assert rep.dense_poses[rep.colliding, 0].min() == pytest.approx(2.6, abs=0.03)
    assert rep.dense_poses[rep.colliding, 0].max() == pytest.approx(4.4, abs=0.03)


def test_collision_free_rate():
    grid = builtin_map("maze2d-large", resolution=0.1)
    fp = make_footprint("circle")
    free = resample(MAZE_PATH, 50)
    blocked = line((1.5, 1.5), (4.5, 1.5))
    rate, mean_pf = collision_free_rate([free, blocked, free, blocked], fp, grid)
    assert rate == 0.5
    assert mean_pf == pytest.approx(check_collision(blocked, fp, grid).penetration_fraction / 2)


# ------------------------------------------------------------------- brute-force cross-check
@pytest.mark.parametrize("robot", ["quadruped", "humanoid", "notched", "circle"])
def test_agrees_with_point_sampling(robot):
    # Fill the footprint with points every 3 mm and look them up in the grid: if any point is in
    # an occupied cell the footprint overlaps it (so the checker must not say free), and an
    # overlap deeper than 1 cm must contain a sample point.
    if robot == "notched":
        fp = polygon_footprint([[0.3, 0.2], [-0.2, 0.2], [0.0, 0.05], [-0.25, -0.2], [0.3, -0.2]])
    else:
        fp = make_footprint(robot, **({"radius": 0.23} if robot == "circle" else {}))
    r = fp.circumscribed_radius
    g = np.arange(-r, r, 0.003) + 0.0015
    local = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    if fp.is_circle:
        local = local[np.hypot(local[:, 0], local[:, 1]) < fp.radius]
    else:
        local = local[point_in_polygon(local, fp.polygon)]
    grid = builtin_map("maze2d-large", resolution=0.1)
    rng = np.random.default_rng(7)
    n = 150
    poses = np.column_stack([rng.uniform(-0.3, 12.3, n), rng.uniform(-0.3, 9.3, n),
                             rng.uniform(-math.pi, math.pi, n)])
    for x, y, th in poses:
        rep = check_collision([[x, y]], fp, grid, headings=[th])
        c, s = math.cos(th), math.sin(th)
        world = local @ np.array([[c, s], [-s, c]]) + (x, y)
        hit = bool((~grid.is_free(world)).any())
        if rep.collision_free:
            assert not hit, (x, y, th)
        if rep.max_depth > 0.01:
            assert hit, (x, y, th)


@pytest.mark.parametrize("robot", ["circle", "quadruped"])
def test_far_poses_passed_by_the_distance_transform_give_the_same_verdicts(robot):
    # a grid that holds its free_distance lets check_collision skip poses far from every wall;
    # verdicts, depths and first collisions are those of the full test
    from ecahd_core.mapgen import MapGenConfig, generate_map

    fp = make_footprint(robot)
    plain = generate_map(MapGenConfig("office", 12, 10, 0.05, 3))
    fast = generate_map(MapGenConfig("office", 12, 10, 0.05, 3))
    d = fast.free_distance
    assert d.shape == (fast.height, fast.width) and float(d[fast.occupied].max()) == 0.0
    assert "free_distance" not in plain.__dict__
    rng = np.random.default_rng(0)
    verdicts = []
    for _ in range(40):
        traj = rng.uniform([1.0, 1.0], [11.0, 9.0]) + np.cumsum(rng.normal(0, 0.4, (4, 2)), 0)
        a, b = check_collision(traj, fp, plain), check_collision(traj, fp, fast)
        assert a.collision_free == b.collision_free
        assert a.first_collision_index == b.first_collision_index
        np.testing.assert_array_equal(a.colliding, b.colliding)
        np.testing.assert_allclose(a.depths, b.depths)
        verdicts.append(a.collision_free)
    assert 0 < sum(verdicts) < len(verdicts)  # both kinds were checked
    # off the map counts as occupied there too
    off = np.array([[-1.0, 5.0], [0.2, 5.0]])
    assert not check_collision(off, fp, fast).collision_free
