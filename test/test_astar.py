"""A* with footprint clearance (ecahd_core.astar) on hand-built grids and the D4RL mazes."""
import heapq
import math

import numpy as np
import pytest

from ecahd_core.astar import (MOTIONS, AStarConfig, AStarPlanner, CoarseAStarPlanner, astar_path,
                              clearance_for_footprint, path_length, plan_from_pose,
                              sample_free_point, sample_free_points)
from ecahd_core.collision import check_collision
from ecahd_core.errors import PlanningError
from ecahd_core.footprint import make_footprint
from ecahd_core.mapgen import MapGenConfig, generate
from ecahd_core.maps import FREE, OCCUPIED, GridMap, builtin_map

SQRT2 = math.sqrt(2.0)


def grid_from_rows(rows, resolution=1.0, name="test"):
    """'#' occupied, '.' free; the first string is the top row (largest y), as in maps.py."""
    occ = np.array([[ch == "#" for ch in line] for line in rows], dtype=bool)[::-1]
    return GridMap(data=np.where(occ, OCCUPIED, FREE).astype(np.int8), resolution=resolution,
                   name=name)


def centre(grid, row, col):
    return grid.cell_to_world(np.array(row), np.array(col))


def distance_to_obstacles(grid, pts):
    """Brute force: distance [m] from points (M, 2) to the nearest occupied square or the map edge.
    Only occupied cells with a free 4-neighbour can be nearest, so only those are tried."""
    res = grid.resolution
    occ = grid.occupied
    free = np.pad(~occ, 1, constant_values=False)
    free_nb = free[:-2, 1:-1] | free[2:, 1:-1] | free[1:-1, :-2] | free[1:-1, 2:]
    rows, cols = np.nonzero(occ & free_nb)
    lo = np.stack([cols, rows], axis=1) * res + np.asarray(grid.origin)  # (K, 2) lower corners
    gap = np.maximum(np.maximum(lo[None] - pts[:, None], pts[:, None] - lo[None] - res), 0.0)
    d = np.linalg.norm(gap, axis=-1).min(axis=1)
    xmin, ymin, xmax, ymax = grid.bounds
    edge = np.minimum.reduce([pts[:, 0] - xmin, xmax - pts[:, 0], pts[:, 1] - ymin, ymax - pts[:, 1]])
    return np.minimum(d, edge)


def densify(path, step):
    out = [path[:1]]
    for a, b in zip(path[:-1], path[1:]):
        n = max(1, int(math.ceil(np.linalg.norm(b - a) / step)))
        out.append(a + (np.arange(1, n + 1)[:, None] / n) * (b - a))
    return np.concatenate(out)


def dijkstra_cost(mask, start, goal):
    """Reference: uniform-cost search [cells] with the same moves and corner rule as astar.py."""
    H, W = mask.shape
    dist = {start: 0.0}
    heap = [(0.0, start)]
    while heap:
        d, (r, c) = heapq.heappop(heap)
        if (r, c) == goal:
            return d
        if d > dist[(r, c)]:
            continue
        for dr, dc, cost in MOTIONS:
            nr, nc = r + dr, c + dc
            if not (0 <= nr < H and 0 <= nc < W and mask[nr, nc]):
                continue
            if dr and dc and not (mask[r + dr, c] and mask[r, c + dc]):
                continue
            if d + cost < dist.get((nr, nc), math.inf):
                dist[(nr, nc)] = d + cost
                heapq.heappush(heap, (d + cost, (nr, nc)))
    return math.inf


# ------------------------------------------------------------------------- optimal length
def test_known_optimal_octile_length():
    # 7 x 5 cells of 1 m, a wall in column 3 with the only opening in the top row (row 4).
    # The path from cell (0, 0) to cell (0, 6) must cross cell (4, 3), which it can only enter
    # from (4, 2) and leave to (4, 4): a diagonal step into it would cut the corner of the wall
    # cell (3, 3). Octile distance (0, 0) -> (4, 2): 2 diagonal + 2 straight = 2*sqrt(2) + 2;
    # (4, 2) -> (4, 4): 2; (4, 4) -> (0, 6): 2*sqrt(2) + 2. Total 4*sqrt(2) + 6 = 11.657 m.
    grid = grid_from_rows([
        ".......",
        "...#...",
        "...#...",
        "...#...",
        "...#...",
    ])
    start, goal = centre(grid, 0, 0), centre(grid, 0, 6)
    path = astar_path(grid, start, goal, clearance=0.0, smooth=False)
    assert path_length(path) == pytest.approx(4 * SQRT2 + 6, abs=1e-9)
    assert any(np.allclose(p, centre(grid, 4, 3)) for p in path)
    smooth = astar_path(grid, start, goal, clearance=0.0, smooth=True)
    assert np.linalg.norm(goal - start) < path_length(smooth) <= 4 * SQRT2 + 6 + 1e-9


def test_diagonal_step_needs_both_side_cells():
    # (0, 1) is a wall. The diagonal (0, 0) -> (1, 1) would clip its corner, so the path goes
    # round through (1, 0): length 2 m instead of sqrt(2) m.
    grid = grid_from_rows([
        "..",
        ".#",
    ])
    path = astar_path(grid, centre(grid, 0, 0), centre(grid, 1, 1), 0.0, smooth=False)
    assert path_length(path) == pytest.approx(2.0)
    np.testing.assert_allclose(path, [[0.5, 0.5], [0.5, 1.5], [1.5, 1.5]])
    # smoothing may not take the diagonal either: it crosses the wall's corner
    smooth = astar_path(grid, centre(grid, 0, 0), centre(grid, 1, 1), 0.0, smooth=True)
    assert path_length(smooth) == pytest.approx(2.0)


def test_no_squeezing_between_two_blocked_cells():
    # The free cells (0, 0) and (1, 1) touch only at a corner between two walls.
    grid = grid_from_rows([
        "#.",
        ".#",
    ])
    with pytest.raises(PlanningError, match="no path"):
        astar_path(grid, centre(grid, 0, 0), centre(grid, 1, 1), 0.0)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_cost_matches_uniform_cost_search(seed):
    rng = np.random.default_rng(seed)
    occ = rng.random((14, 14)) < 0.25
    occ[0, 0] = occ[-1, -1] = False
    grid = GridMap(data=np.where(occ, OCCUPIED, FREE).astype(np.int8), resolution=1.0)
    planner = AStarPlanner(grid, 0.0, smooth=False)
    expected = dijkstra_cost(planner.mask, (0, 0), (13, 13))
    if math.isinf(expected):
        with pytest.raises(PlanningError):
            planner.plan(centre(grid, 0, 0), centre(grid, 13, 13))
    else:
        path = planner.plan(centre(grid, 0, 0), centre(grid, 13, 13))
        assert path_length(path) == pytest.approx(expected, abs=1e-9)


# -------------------------------------------------------------------------------- clearance
def test_path_keeps_clearance():
    grid = builtin_map("maze2d-medium")
    clearance = 0.3
    planner = AStarPlanner(grid, clearance, smooth=False)
    start, goal = np.array([1.5, 1.5]), np.array([6.5, 6.5])
    raw = planner.plan(start, goal)
    rows, cols = grid.world_to_cell(raw[1:-1])
    assert np.all(planner.cell_clearance[rows, cols] >= clearance - 1e-6)
    assert np.all(planner.mask[rows, cols])
    # exact distances of the cell centres, and of the whole path up to the 8-connected steps'
    # dip next to convex corners (< c - sqrt(c^2 - res^2 / 2) = 8.4 mm here)
    assert distance_to_obstacles(grid, raw[1:-1]).min() >= clearance - 1e-6
    assert distance_to_obstacles(grid, densify(raw, 0.01)[1:-1]).min() >= clearance - 0.0085
    smooth = AStarPlanner(grid, clearance).plan(start, goal)
    inner = densify(smooth, 0.01)
    inner = inner[np.linalg.norm(inner - start, axis=1) > 0.1]
    inner = inner[np.linalg.norm(inner - goal, axis=1) > 0.1]
    assert distance_to_obstacles(grid, inner).min() >= clearance - 1e-6


def test_cell_clearance_exact_near_the_threshold():
    # maps.signed_distance overestimates next to convex corners; the planner must not.
    grid = builtin_map("maze2d-large")
    for clearance in (0.28, 0.358, 0.4):
        planner = AStarPlanner(grid, clearance)
        rows, cols = np.nonzero(planner.mask)
        d = distance_to_obstacles(grid, grid.cell_to_world(rows, cols))
        assert d.min() >= clearance - 1e-6


def test_start_and_goal_are_exact():
    grid = builtin_map("maze2d-large")
    start, goal = np.array([1.53, 1.41]), np.array([10.46, 7.58])
    for smooth in (False, True):
        path = astar_path(grid, start, goal, 0.4, smooth=smooth)
        assert path.shape[1] == 2 and len(path) >= 2
        assert np.array_equal(path[0], start) and np.array_equal(path[-1], goal)
        assert np.all(np.any(np.diff(path, axis=0) != 0, axis=1))  # no repeated points


def test_start_equals_goal():
    grid = builtin_map("maze2d-umaze")
    path = astar_path(grid, (1.5, 1.5), (1.5, 1.5), 0.4)
    assert path.shape == (2, 2) and path_length(path) == 0.0


# ------------------------------------------------------------------------------- failures
def test_unreachable_goal_raises():
    grid = grid_from_rows([
        "..#..",
        "..#..",
        "..#..",
    ])
    with pytest.raises(PlanningError, match="no path"):
        astar_path(grid, centre(grid, 1, 0), centre(grid, 1, 4), 0.0)


@pytest.mark.parametrize("bad, message", [
    ((0.5, 0.5), "inside an obstacle"),
    ((-1.0, 1.5), "outside the map"),
    ((1.5, 100.0), "outside the map"),
    ((float("nan"), 1.5), "non-finite"),
    ((1.5,), "must be an \\(x, y\\) pair"),
])
def test_invalid_start_or_goal_raises(bad, message):
    grid = builtin_map("maze2d-large")
    with pytest.raises(PlanningError, match="start.*" + message):
        astar_path(grid, bad, (10.5, 7.5), 0.4)
    with pytest.raises(PlanningError, match="goal.*" + message):
        astar_path(grid, (1.5, 1.5), bad, 0.4)


def test_start_without_clearance_says_by_how_much():
    # x = 1.23 lies in the cell centred at x = 1.25, 0.25 m from the wall at x = 1.0.
    grid = builtin_map("maze2d-large")
    with pytest.raises(PlanningError, match=r"start .*clearance 0\.250 m, 0\.150 m less than "
                                            r"the required 0\.400 m"):
        astar_path(grid, (1.23, 1.5), (10.5, 7.5), 0.4)
    with pytest.raises(PlanningError, match="goal"):
        astar_path(grid, (1.5, 1.5), (10.5, 7.93), 0.4)


def test_config_validation():
    with pytest.raises(PlanningError, match="clearance"):
        AStarConfig(clearance=-0.1)
    with pytest.raises(PlanningError, match="clearance"):
        AStarConfig(clearance=float("nan"))
    fp = make_footprint("quadruped")
    cfg = AStarConfig.for_footprint(fp, padding=0.05)
    assert cfg.clearance == pytest.approx(fp.circumscribed_radius + 0.05)
    assert clearance_for_footprint(make_footprint("circle")) == pytest.approx(0.4)
    planner = AStarPlanner.from_config(builtin_map("maze2d-umaze"), cfg)
    assert planner.clearance == cfg.clearance and planner.smooth


# ------------------------------------------------------------------------------ smoothing
def test_smoothing_is_shorter_than_cells_and_stays_in_mask():
    grid = builtin_map("maze2d-large")
    raw_planner = AStarPlanner(grid, 0.4, smooth=False)
    planner = AStarPlanner(grid, 0.4, smooth=True)
    rng = np.random.default_rng(7)
    for _ in range(15):
        start, goal = sample_free_points(rng, planner.mask, grid, 2)
        raw, smooth = raw_planner.plan(start, goal), planner.plan(start, goal)
        straight = float(np.linalg.norm(goal - start))
        assert straight - 1e-9 <= path_length(smooth) <= path_length(raw) + 1e-9
        # the smoothed vertices are a subsequence of the cell path
        assert all(any(np.array_equal(v, r) for r in raw) for v in smooth)
        assert planner.path_is_clear(smooth)
        rows, cols = grid.world_to_cell(densify(smooth, grid.resolution / 10))
        assert np.all(planner.mask[rows, cols])


# ---------------------------------------------------------------------------------- mazes
def test_maze2d_large_circle_robot():
    grid = builtin_map("maze2d-large")
    clearance = make_footprint("circle").circumscribed_radius  # 0.4 m
    start, goal = np.array([1.5, 1.5]), np.array([10.5, 7.5])
    path = astar_path(grid, start, goal, clearance)
    straight = float(np.linalg.norm(goal - start))  # 10.8 m
    assert straight < path_length(path) < 2 * straight
    assert distance_to_obstacles(grid, densify(path, 0.01)).min() >= clearance - 1e-6


def test_sample_free_points_lie_in_the_mask():
    grid = builtin_map("maze2d-medium")
    planner = AStarPlanner(grid, 0.4)
    rng = np.random.default_rng(0)
    pts = sample_free_points(rng, planner.mask, grid, 500)
    rows, cols = grid.world_to_cell(pts)
    assert pts.shape == (500, 2) and np.all(planner.mask[rows, cols])
    centres = sample_free_points(rng, planner.mask, grid, 5, jitter=False)
    rows, cols = grid.world_to_cell(centres)
    np.testing.assert_allclose(centres, grid.cell_to_world(rows, cols))
    assert sample_free_point(rng, planner.mask, grid).shape == (2,)
    with pytest.raises(PlanningError, match="no cell"):
        sample_free_points(rng, np.zeros_like(planner.mask), grid, 1)


def test_plan_from_a_pose_without_clearance_enters_the_nearest_traversable_cell():
    # 1 m cells, free x in [1, 6], y in [1, 4]. Clearance 0.9 m: a centre needs 0.9 m to every
    # wall edge, which only the middle row's inner centres have (y = 2.5: 1.5 m to y = 1 and
    # y = 4; x = 2.5..4.5: >= 1.5 m to x = 1 and x = 6); the bottom row's lie 0.5 m from y = 1
    grid = grid_from_rows(["#######",
                           "#.....#",
                           "#.....#",
                           "#.....#",
                           "#######"])
    planner = AStarPlanner(grid, 0.9)
    assert np.array_equal(np.argwhere(planner.mask), [[2, 2], [2, 3], [2, 4]])
    pose, goal = np.array([2.6, 1.4]), np.array([4.5, 2.5])  # pose in the bottom row
    path = plan_from_pose(planner, pose, goal)
    np.testing.assert_allclose(path[0], pose)
    np.testing.assert_allclose(path[1], [2.5, 2.5])  # the nearest traversable centre
    np.testing.assert_allclose(path[-1], goal)
    # a pose with clearance: the plain A* plan
    np.testing.assert_allclose(plan_from_pose(planner, [2.5, 2.5], goal),
                               planner.plan([2.5, 2.5], goal))
    with pytest.raises(PlanningError, match="goal"):  # the goal still needs the clearance
        plan_from_pose(planner, [2.5, 2.5], [4.5, 1.5])


# ------------------------------------------------------------------------------ coarse A*
def test_coarse_graph_keeps_a_passage_narrower_than_a_block():
    # 1 m cells, clearance 0: the traversable cells are the free ones. Two rooms, the wall in
    # column 4 open only at row 1. Blocks of 3 x 3 cells: no block is wholly free at the gap, so
    # a mask of wholly free blocks would cut the rooms apart. The block of rows 3-5, columns 3-5
    # holds free cells of both rooms, split by the wall: two pieces, two nodes, so the coarse
    # graph does not cross the wall there and the path goes down to the gap.
    grid = grid_from_rows(["#########",
                           "#...#...#",
                           "#...#...#",
                           "#...#...#",
                           "#...#...#",
                           "#.......#",
                           "#########"])
    fine = AStarPlanner(grid, 0.0)
    coarse = CoarseAStarPlanner(fine, 3)
    labels = coarse.labels
    assert labels[5, 3] >= 0 and labels[5, 5] >= 0 and labels[5, 3] != labels[5, 5]
    assert labels[1, 3] == labels[1, 4] == labels[1, 5]  # the gap's block: one piece
    start, goal = np.array([1.5, 5.5]), np.array([7.5, 5.5])
    path = coarse.plan(start, goal)
    np.testing.assert_array_equal(path[0], start)
    np.testing.assert_array_equal(path[-1], goal)
    assert fine.path_is_clear(path)
    pts = densify(path, 0.01)
    rows, cols = grid.world_to_cell(pts)
    assert np.all(fine.mask[rows, cols]) and np.all(rows[cols == 4] == 1)  # through the gap
    assert path_length(path) <= 1.1 * path_length(fine.plan(start, goal))
    with pytest.raises(PlanningError, match="block"):
        CoarseAStarPlanner(fine, 0)


def test_visible_segments_matches_visible():
    grid = builtin_map("maze2d-medium")
    planner = AStarPlanner(grid, 0.4)
    rng = np.random.default_rng(1)
    a = sample_free_points(rng, planner.mask, grid, 40)
    b = sample_free_points(rng, planner.mask, grid, 40)
    one_by_one = [bool(planner.visible(p, q[None])[0]) for p, q in zip(a, b)]
    assert planner.visible_segments(a, b).tolist() == one_by_one
    assert any(one_by_one) and not all(one_by_one)


@pytest.fixture(scope="module")
def office():
    # 16 x 12 m at 0.05 m/cell: rooms behind 0.9-1.0 m doors, whose traversable band for the
    # 0.4 m clearance is 1-4 cells wide, narrower than the 6-cell (0.3 m) blocks
    return generate(MapGenConfig("office", 16, 12, 0.05, 3))


def test_coarse_paths_are_collision_free_and_near_shortest(office):
    grid = office.grid
    circle = make_footprint("circle")
    fine = AStarPlanner(grid, 0.4)
    coarse = CoarseAStarPlanner.for_resolution(fine, 0.3)
    assert coarse.block == 6
    anchors = office.anchors
    rng = np.random.default_rng(0)
    ratios = []
    for _ in range(12):  # room to room: through doors
        i, j = rng.choice(len(anchors), 2, replace=False)
        path = coarse.plan(anchors[i], anchors[j])
        np.testing.assert_array_equal(path[[0, -1]], anchors[[i, j]])
        assert check_collision(path, circle, grid).collision_free
        assert fine.path_is_clear(path)
        ratios.append(path_length(path) / path_length(fine.plan(anchors[i], anchors[j])))
    print("coarse / exact A* length:", np.round(ratios, 3))
    # measured: mean 1.00x, worst 1.03x; allow some slack for other maps of this kind
    assert max(ratios) < 1.10 and np.mean(ratios) < 1.03


def test_planner_for_picks_the_coarse_search_on_big_maps_and_it_stands_in_everywhere(office):
    from ecahd_core.astar import COARSE_ABOVE_CELLS, plan_from_pose, planner_for

    small = planner_for(builtin_map("maze2d-umaze"), 0.2)
    assert type(small) is AStarPlanner  # 50 x 50 cells: exact
    grid = office.grid
    assert grid.height * grid.width > COARSE_ABOVE_CELLS
    big = planner_for(grid, 0.4)
    assert isinstance(big, CoarseAStarPlanner) and big.clearance == 0.4
    # the fine planner's queries answer through it (SafetyNet, plan_from_pose use them)
    a, b = office.anchors[0], office.anchors[1]
    assert big.point_clearance(a) == big.fine.point_clearance(a)
    assert big.check_endpoint(a, "start")[1] == big.fine.check_endpoint(a, "start")[1]
    path = plan_from_pose(big, a, b)
    np.testing.assert_array_equal(path[[0, -1]], [a, b])
    assert big.fine.path_is_clear(path)
    with pytest.raises(AttributeError):
        big.no_such_query


def _window_clearance(planner, rows, cols):
    """The brute-force reference of AStarPlanner._centre_clearance: hypot of the per-axis gaps
    to every occupied square of the (2w + 1)^2 window, capped at w cells."""
    w = planner._pad
    dr, dc = np.meshgrid(np.arange(-w, w + 1), np.arange(-w, w + 1), indexing="ij")
    dr, dc = dr.ravel(), dc.ravel()
    gap = np.hypot(np.maximum(np.abs(dr) - 0.5, 0.0), np.maximum(np.abs(dc) - 0.5, 0.0))
    occupied = planner._occupied_padded[rows[:, None] + w + dr, cols[:, None] + w + dc]
    return np.where(occupied, gap, np.inf).min(axis=1, initial=float(w)) * planner.grid.resolution


@pytest.mark.parametrize("density", [0.01, 0.05, 0.2])
def test_separable_centre_clearance_equals_the_window_search(density):
    rng = np.random.default_rng(int(density * 100))
    occ = rng.random((70, 90)) < density
    grid = GridMap(np.where(occ, 100, 0).astype(np.int8), 0.05, (0.0, 0.0), name="random")
    planner = AStarPlanner(grid, 0.3)
    rows, cols = np.nonzero(~occ)  # every free cell, near the threshold or not
    np.testing.assert_array_equal(planner._centre_clearance(rows, cols),
                                  _window_clearance(planner, rows, cols))


def test_coarse_graph_equals_its_definition(office):
    """Representatives: each node's cell nearest its centroid, row-major first on ties; edges:
    node pairs adjacent across a block border, each once per direction."""
    fine = AStarPlanner(office.grid, 0.4)
    coarse = CoarseAStarPlanner(fine, 6, landmarks=0)
    labels = coarse.labels
    assert coarse._landmark_dist.shape == (0, coarse.num_nodes)
    for node in np.random.default_rng(0).choice(coarse.num_nodes, 40, replace=False):
        rows, cols = np.nonzero(labels == node)  # row-major
        d2 = (rows - rows.mean()) ** 2 + (cols - cols.mean()) ** 2
        k = int(np.argmin(d2))  # first minimum
        assert tuple(coarse.rep_cells[node]) == (rows[k], cols[k])
    edges = set()
    H, W = labels.shape
    for r in range(H):
        for c in range(W):
            a = labels[r, c]
            if a < 0:
                continue
            if c + 1 < W and (c + 1) % 6 == 0 and labels[r, c + 1] >= 0:
                edges.add((a, labels[r, c + 1]))
            if r + 1 < H and (r + 1) % 6 == 0 and labels[r + 1, c] >= 0:
                edges.add((a, labels[r + 1, c]))
            if (r + 1) % 6 == 0 and (c + 1) % 6 == 0 and r + 1 < H and c + 1 < W and \
                    fine.mask[r:r + 2, c:c + 2].all():
                edges.add((a, labels[r + 1, c + 1]))
                edges.add((labels[r, c + 1], labels[r + 1, c]))
    edges |= {(b, a) for a, b in edges}
    got = {(n, coarse._dst[j]) for n in range(coarse.num_nodes)
           for j in range(coarse._indptr[n], coarse._indptr[n + 1])}
    assert got == edges
    # without landmarks the search still finds a path through the doors
    a, b = office.anchors[0], office.anchors[-1]
    path = coarse.plan(a, b)
    assert fine.path_is_clear(path)
    assert path_length(path) < 1.1 * path_length(fine.plan(a, b))
