"""Tests of the cost J of Algorithm 2 (ecahd_core.cost): gradients against finite differences,
the point / line / surface modes, headings, degenerate segments, the loop reference and input
validation."""
import math

import numpy as np
import pytest
import torch

from ecahd_core.cost import (MODES, SWEEP_MATRIX_POINTS, CostConfig, CostTerms, pose_headings,
                             trajectory_cost, trajectory_cost_loops)
from ecahd_core.costmap import CostMap
from ecahd_core.errors import EcahdError, FootprintError, TrajectoryError
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import GridMap, builtin_map, signed_distance

F64 = torch.float64


def occupancy(occ: np.ndarray, resolution: float) -> GridMap:
    return GridMap(data=np.where(occ, 100, 0).astype(np.int8), resolution=resolution,
                   name="hand")


@pytest.fixture(scope="module")
def maze():
    grid = builtin_map("maze2d-large", resolution=0.1)
    return grid, CostMap.from_grid(grid, dtype=F64)


def near_wall_trajectories(grid, B, P, seed, step=0.3, band=(0.1, 0.35)):
    """(B, P, 2) float64 random walks starting in free space ``band`` [m] from a wall."""
    rng = np.random.default_rng(seed)
    sdf = signed_distance(grid)
    rows, cols = np.nonzero((sdf > band[0]) & (sdf < band[1]))
    pick = rng.integers(len(rows), size=B)
    start = grid.cell_to_world(rows[pick], cols[pick]) + rng.uniform(-0.04, 0.04, (B, 2))
    steps = rng.normal(scale=step, size=(B, P - 1, 2))
    traj = np.concatenate([start[:, None], start[:, None] + np.cumsum(steps, axis=1)], axis=1)
    return torch.tensor(traj, dtype=F64)


# ----------------------------------------------------------------------------- gradients
@pytest.mark.parametrize("mode,P", [(m, 4) for m in MODES] + [("surface", SWEEP_MATRIX_POINTS + 2)])
def test_gradient_matches_central_differences(maze, mode, P):
    grid, cm = maze
    traj = near_wall_trajectories(grid, B=3, P=P, seed=1)
    goal = torch.tensor([6.0, 4.5], dtype=F64)
    fp = torch.tensor(make_footprint("quadruped").points, dtype=F64)  # asymmetric: heading matters

    def J(t):
        return trajectory_cost(t, goal, fp, cm, mode=mode, n_interp=6).total.sum()

    x = traj.clone().requires_grad_()
    (grad,) = torch.autograd.grad(J(x), x)
    assert float(trajectory_cost(traj, goal, fp, cm, mode=mode).collision_cost.sum()) > 0
    h = 1e-7
    fd = torch.zeros_like(traj)
    for idx in np.ndindex(*traj.shape):
        plus, minus = traj.clone(), traj.clone()
        plus[idx] += h
        minus[idx] -= h
        fd[idx] = (J(plus) - J(minus)) / (2 * h)
    torch.testing.assert_close(grad, fd, rtol=1e-5, atol=1e-5)


def test_open_space_costs_exactly_zero():
    # 30 m x 30 m with walls only on the border; trajectories around (15, 15) are > 10 m away
    occ = np.zeros((300, 300), dtype=bool)
    occ[[0, -1], :] = True
    occ[:, [0, -1]] = True
    cm = CostMap.from_grid(occupancy(occ, 0.1), dtype=F64)
    rng = np.random.default_rng(3)
    traj = torch.tensor(15 + rng.uniform(-2, 2, (4, 6, 2)), dtype=F64, requires_grad=True)
    fp = make_footprint("circle").points
    for mode in MODES:
        terms = trajectory_cost(traj, (15.0, 15.0), fp, cm, mode=mode)
        assert torch.all(terms.collision_cost == 0)
        (g,) = torch.autograd.grad(terms.collision_cost.sum(), traj)
        assert torch.all(g == 0)


def test_dist_cost_is_mean_squared_distance():
    traj = torch.tensor([[[0.0, 0.0], [3.0, 4.0]], [[1.0, 1.0], [1.0, 1.0]]], dtype=F64)
    cm = CostMap(torch.zeros(4, 4, dtype=F64), origin=(-10, -10), resolution=5.0)
    terms = trajectory_cost(traj, torch.tensor([[0.0, 0.0], [1.0, 2.0]], dtype=F64),
                            np.zeros((1, 2)), cm)
    # (0 + 25) / 2 and (1 + 1) / 2
    torch.testing.assert_close(terms.dist_cost, torch.tensor([12.5, 1.0], dtype=F64))
    torch.testing.assert_close(terms.total, terms.dist_cost + terms.collision_cost)


def test_sigma_ratio_scales_collision_cost(maze):
    grid, cm = maze
    traj = near_wall_trajectories(grid, B=2, P=3, seed=4)
    fp = make_footprint("circle").points
    base = trajectory_cost(traj, (1.0, 1.0), fp, cm)
    scaled = trajectory_cost(traj, (1.0, 1.0), fp, cm, sigma_dist=3.0, sigma_col=2.0)
    torch.testing.assert_close(scaled.collision_cost, 1.5 * base.collision_cost)
    torch.testing.assert_close(scaled.dist_cost, base.dist_cost)


# ------------------------------------------------------------------------------- geometry
def test_surface_sees_a_corner_the_centre_line_misses():
    # 4 m x 4 m at 0.05 m; obstacle block x in [2.0, 3.0), y in [1.0, 2.0): its top-left
    # corner is (2.0, 2.0). The robot drives along y = 2.3 from x = 0.8 to x = 1.9, so its
    # centre stays >= 0.3 m from the block (margin 0.1 m + one cell: cost exactly 0), but the
    # 0.8 m x 1.0 m rectangle reaches x = 2.3 and y = 1.8 at the last pose: it clips the corner.
    occ = np.zeros((80, 80), dtype=bool)
    occ[20:40, 40:60] = True
    cm = CostMap.from_grid(occupancy(occ, 0.05), dtype=F64)
    rect = make_footprint("[[0.4, 0.5], [-0.4, 0.5], [-0.4, -0.5], [0.4, -0.5]]", spacing=0.1)
    x = torch.linspace(0.8, 1.9, 5, dtype=F64)
    traj = torch.stack([x, torch.full_like(x, 2.3)], -1)[None]
    costs = {m: float(trajectory_cost(traj, (1.9, 2.3), rect.points, cm, mode=m).collision_cost)
             for m in MODES}
    assert costs["line"] == 0.0 and costs["point"] == 0.0
    assert costs["surface"] > 0.5


def test_circle_cost_does_not_depend_on_direction(maze):
    # Driving a straight line one way or the other turns every pose by pi. The preset circle's
    # rings have odd point counts (17, 11, 5), so rotating it by pi does not map its points
    # onto themselves; adding the mirrored points -R makes the sample set exactly
    # pi-symmetric, like the ideal circle. Then forward and reverse runs visit the same world
    # points (the DDA points of the reversed segments are the same set) and J must match.
    # The rectangle check shows the comparison is sensitive to heading.
    _, cm = maze
    start, end = np.array([1.3, 1.15]), np.array([3.2, 1.25])  # along the wall y = 1
    traj = torch.tensor(np.linspace(start, end, 5)[None], dtype=F64)
    reverse = traj.flip(1)
    circle = make_footprint("circle").points
    symmetric = np.concatenate([circle, -circle])
    forward_cost = trajectory_cost(traj, end, symmetric, cm).collision_cost
    reverse_cost = trajectory_cost(reverse, end, symmetric, cm).collision_cost
    assert float(forward_cost) > 1.0
    torch.testing.assert_close(forward_cost, reverse_cost, rtol=1e-12, atol=1e-12)
    lopsided = make_footprint("[[0.6, 0.2], [-0.1, 0.2], [-0.1, -0.2], [0.6, -0.2]]").points
    a = trajectory_cost(traj, end, lopsided, cm).collision_cost
    b = trajectory_cost(reverse, end, lopsided, cm).collision_cost
    assert abs(float(a - b)) > 1e-3


def test_cost_rotates_with_the_map():
    # A map with 4-fold symmetry about the centre c of its middle cell, and a bent trajectory
    # starting at c turned by 90 degrees about c: every heading turns by 90 degrees, so every
    # footprint sample point turns with it (Eqs. 4, 7-8) and J is unchanged.
    n, res = 61, 0.05
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    ring = np.maximum(abs(i - 30), abs(j - 30))
    occ = (ring >= 13) & (ring <= 15)
    cm = CostMap.from_grid(occupancy(occ, res), dtype=F64)
    grid = cm.grid.numpy()
    assert np.allclose(grid, np.rot90(grid), atol=1e-12)  # the symmetry the test relies on
    c = np.array([30.5 * res, 30.5 * res])
    u = lambda a: np.array([math.cos(a), math.sin(a)])  # noqa: E731
    pts = np.stack([c, c + 0.35 * u(0.3), c + 0.35 * u(0.3) + 0.3 * u(1.0)])
    turn = np.array([[0.0, -1.0], [1.0, 0.0]])  # +90 degrees
    turned = (pts - c) @ turn.T + c
    fp = make_footprint("quadruped").points
    a = trajectory_cost(torch.tensor(pts[None]), c, fp, cm).collision_cost
    b = trajectory_cost(torch.tensor(turned[None]), c, fp, cm).collision_cost
    assert float(a) > 1.0
    torch.testing.assert_close(a, b, rtol=1e-10, atol=1e-10)


def test_single_point_costs_its_footprint_only(maze):
    _, cm = maze
    p = torch.tensor([[[1.25, 1.3]]], dtype=F64)  # near the corner of the outer wall
    fp = torch.tensor(make_footprint("quadruped").points, dtype=F64)
    terms = trajectory_cost(p, (1.0, 1.0), fp, cm)
    expected = cm.sample(p[0, 0] + fp).sum()  # heading 0: footprint unrotated
    torch.testing.assert_close(terms.collision_cost[0], expected)
    assert float(trajectory_cost(p, (1.0, 1.0), fp, cm, mode="line").collision_cost) == \
        pytest.approx(float(cm.sample(p[0, 0])))


# --------------------------------------------------------------------- degenerate segments
def test_headings_of_repeated_points():
    a, b = [1.0, 1.0], [2.0, 2.0]
    psi = pose_headings(torch.tensor([[a, a, b], [a, b, b], [a, a, a]], dtype=F64))
    q = math.pi / 4
    # no previous heading -> 0; later repeats inherit the last real heading
    torch.testing.assert_close(psi, torch.tensor([[0, q, q], [q, q, q], [0, 0, 0]], dtype=F64))
    assert torch.all(pose_headings(torch.zeros(2, 1, 2)) == 0)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("mode", MODES)
def test_zero_length_segments_are_finite(maze, dtype, mode):
    grid, cm = maze
    a, b = [1.08, 1.2], [1.3, 1.05]  # within the margin of the outer walls x = 1, y = 1
    traj = torch.tensor([[a, a, b, b, b], [a, a, a, a, a], [b, a, a, b, a]], dtype=dtype,
                        requires_grad=True)
    fp = make_footprint("humanoid").points
    terms = trajectory_cost(traj, (3.0, 3.0), fp, cm.to(dtype=dtype), mode=mode)
    assert torch.all(torch.isfinite(terms.total)) and float(terms.collision_cost.sum().detach()) > 0
    (g,) = torch.autograd.grad(terms.total.sum(), traj)
    assert torch.all(torch.isfinite(g))


# -------------------------------------------------------------------------- loop reference
@pytest.mark.parametrize("P", [4, SWEEP_MATRIX_POINTS + 9])  # the sweep matrix; pose by pose
@pytest.mark.parametrize("mode", MODES)
def test_loops_equal_batched(maze, mode, P):
    grid, cm = maze
    traj = near_wall_trajectories(grid, B=2, P=P, seed=7, step=0.1, band=(0.03, 0.1))
    traj[1, 2] = traj[1, 1]  # include a zero-length segment
    goal = traj[:, -1].clone()
    fp = make_footprint("quadruped").points
    kwargs = dict(mode=mode, n_interp=3, sigma_dist=2.0, sigma_col=0.5)
    x1, x2 = traj.clone().requires_grad_(), traj.clone().requires_grad_()
    fast = trajectory_cost(x1, goal, fp, cm, **kwargs)
    slow = trajectory_cost_loops(x2, goal, fp, cm, **kwargs)
    assert isinstance(slow, CostTerms)
    torch.testing.assert_close(fast.dist_cost, slow.dist_cost, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(fast.collision_cost, slow.collision_cost, rtol=1e-10, atol=1e-10)
    assert torch.all(fast.collision_cost > 0)
    (g1,) = torch.autograd.grad(fast.total.sum(), x1)
    (g2,) = torch.autograd.grad(slow.total.sum(), x2)
    torch.testing.assert_close(g1, g2, rtol=1e-9, atol=1e-9)


def test_float32_close_to_float64(maze):
    grid, cm = maze
    traj = near_wall_trajectories(grid, B=4, P=4, seed=5)
    fp = make_footprint("circle").points
    t64 = trajectory_cost(traj, (5.0, 5.0), fp, cm).total
    t32 = trajectory_cost(traj.float(), (5.0, 5.0), fp, cm).total
    assert t32.dtype == torch.float32
    torch.testing.assert_close(t32.double(), t64, rtol=1e-4, atol=1e-3)


# ------------------------------------------------------------------------------ validation
@pytest.mark.parametrize("traj, match", [
    ([[[0.0, 0.0]]], "torch tensor"),
    (torch.zeros(3, 2), r"\(B, P, 2\)"),
    (torch.zeros(1, 3, 3), r"\(B, P, 2\)"),
    (torch.zeros(0, 3, 2), "empty"),
    (torch.zeros(2, 0, 2), "empty"),
    (torch.zeros(1, 3, 2, dtype=torch.int64), "float32 or float64"),
    (torch.tensor([[[0.0, float("nan")]]]), "non-finite"),
    (torch.tensor([[[float("inf"), 0.0]]]), "non-finite"),
])
def test_bad_trajectories_raise(maze, traj, match):
    _, cm = maze
    for fn in (trajectory_cost, trajectory_cost_loops):
        with pytest.raises(TrajectoryError, match=match):
            fn(traj, (0.0, 0.0), make_footprint("circle").points, cm)


def test_bad_goal_footprint_and_settings_raise(maze):
    _, cm = maze
    traj = torch.ones(2, 3, 2)
    fp = make_footprint("circle").points
    with pytest.raises(TrajectoryError, match="goal"):
        trajectory_cost(traj, torch.zeros(3, 2), fp, cm)
    with pytest.raises(TrajectoryError, match="goal"):
        trajectory_cost(traj, (0.0, float("nan")), fp, cm)
    with pytest.raises(FootprintError, match=r"\(R, 2\)"):
        trajectory_cost(traj, (0.0, 0.0), np.zeros((3, 3)), cm)
    with pytest.raises(EcahdError, match=r"\['point', 'line', 'surface'\]"):
        trajectory_cost(traj, (0.0, 0.0), fp, cm, mode="volume")
    with pytest.raises(EcahdError, match="n_interp"):
        trajectory_cost(traj, (0.0, 0.0), fp, cm, n_interp=0)
    with pytest.raises(EcahdError, match="sigma_col"):
        CostConfig(sigma_col=0.0)


def test_config_builds_costmap_and_kwargs():
    cfg = CostConfig(mode="line", n_interp=4, margin=0.2, dilation=0.1)
    assert cfg.cost_kwargs() == dict(mode="line", n_interp=4, sigma_dist=1.0, sigma_col=1.0)
    cm = cfg.make_costmap(builtin_map("maze2d-umaze"), dtype=F64)
    assert (cm.margin, cm.dilation, cm.dtype) == (0.2, 0.1, F64)
    with pytest.raises(TypeError):
        CostConfig("surface")  # keyword-only
    with pytest.raises(AttributeError):
        cfg.mode = "point"  # frozen


def test_sweep_cache_follows_in_place_footprint_changes(maze):
    _, cm = maze
    traj = torch.tensor([[[1.3, 1.2], [1.6, 1.25], [1.9, 1.3]]], dtype=F64)
    fp = torch.tensor(make_footprint("quadruped").points, dtype=F64)
    before = trajectory_cost(traj, (0.0, 0.0), fp, cm).collision_cost
    fp.mul_(1.5)  # same tensor object, new values
    after = trajectory_cost(traj, (0.0, 0.0), fp, cm).collision_cost
    fresh = trajectory_cost(traj, (0.0, 0.0), fp.clone(), cm).collision_cost
    torch.testing.assert_close(after, fresh)
    assert float(after) > float(before)



def test_building_margin_lets_polishing_clear_a_speckle():
    """A single occupied cell (SLAM speckle) on a building's map, 2.4 m legs of a humanoid
    passing over it: with J's 0.1 m margin 30 polishing steps clear few of them (the cost is a
    0.1 m cone the footprint's samples surround, their pushes cancel); with the margin chosen by
    the map (0.5 m) they clear all. maze2d-large keeps 0.1 m."""
    from ecahd_core.collision import check_collision
    from ecahd_core.costmap import BUILDING_MARGIN, DEFAULT_MARGIN, auto_margin
    from ecahd_core.polish import PolishConfig, polish_paths

    n, res = 300, 0.03  # 9 x 9 m, 90 000 cells: a building's size
    occ = np.zeros((n, n), dtype=bool)
    occ[150, 150] = True
    grid = occupancy(occ, res)
    assert auto_margin(grid) == BUILDING_MARGIN
    assert auto_margin(builtin_map("maze2d-large")) == DEFAULT_MARGIN
    assert CostConfig.for_map(grid).margin == BUILDING_MARGIN
    assert CostConfig.for_map(grid, margin=0.2).margin == 0.2
    fp = make_footprint("humanoid")
    c = 150.5 * res  # the speckle's centre [m]
    legs = np.array([[[x0 + k * 0.8, c + dy] for k in range(4)]
                     for dy in np.linspace(-0.3, 0.3, 13) for x0 in (c - 1.5, c - 1.3)])
    legs = legs[[not check_collision(leg, fp, grid).collision_free for leg in legs]]
    assert len(legs) >= 10
    fixed = np.array([True, False, False, True])  # the ends are SD's waypoints

    def cleared(config):
        out, _ = polish_paths(torch.as_tensor(legs, dtype=torch.float32), fixed,
                              config.make_costmap(grid), torch.as_tensor(fp.points), config,
                              PolishConfig(steps=30))
        return np.mean([check_collision(p.numpy().astype(np.float64), fp, grid).collision_free
                        for p in out])

    assert cleared(CostConfig.for_map(grid)) >= 0.95
    assert cleared(CostConfig()) <= 0.5  # why buildings get a wider margin
