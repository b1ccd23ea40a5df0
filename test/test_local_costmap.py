"""Tests of the rolling local obstacle window (ecahd_core.local_costmap).

Common setup unless a test says otherwise: 0.1 m cells on a lattice with origin (0, 0), a
3.0 m window = 30 x 30 cells, robot at (5.05, 5.05) facing +x, so the robot sits in lattice cell
(row 50, col 50) and the window's cell (0, 0) is lattice cell (50 - 15, 50 - 15) = (35, 35): the
window covers [3.5, 6.5) x [3.5, 6.5) m and lattice cell (r, c) is window cell (r - 35, c - 35).
"""
import math
import time

import numpy as np
import pytest
import torch

from ecahd_core.cost import CostConfig, trajectory_cost
from ecahd_core.costmap import CostMap
from ecahd_core.errors import EcahdError, MapError
from ecahd_core.local_costmap import LocalCostmap, LocalCostmapConfig
from ecahd_core.maps import GridMap

RES = 0.1
POSE = (5.05, 5.05, 0.0)
SCAN = dict(range_min=0.05, range_max=10.0)


def make(**config) -> LocalCostmap:
    settings = dict(size=3.0, persistence=0.0)
    settings.update(config)
    return LocalCostmap(resolution=RES, config=LocalCostmapConfig(**settings))


def one_beam(lc: LocalCostmap, r: float, *, stamp: float = 0.0, pose=POSE, **scan):
    """A scan of one beam straight ahead (angle 0) of range r [m]."""
    kwargs = {**SCAN, **scan}
    return lc.update(pose, [r], angle_min=0.0, angle_increment=0.01, stamp=stamp, **kwargs)


def marked_cells(lc: LocalCostmap) -> set[tuple[int, int]]:
    return {(int(r), int(c)) for r, c in zip(*np.nonzero(lc.obstacle_mask()))}


def test_window_geometry():
    lc = make()
    assert lc.shape == (30, 30)  # 3.0 m / 0.1 m
    lc.recentre(POSE[:2])
    assert lc.origin == pytest.approx((3.5, 3.5))


def test_wall_scan_marks_the_right_cells():
    # a wall along x = 5.55 (the middle of lattice column 55), 0.5 m ahead of the robot, seen by
    # 101 beams from -0.5 to +0.5 rad: beam theta hits (5.55, 5.05 + 0.5 tan theta), y from
    # 5.05 - 0.273 = 4.777 to 5.323 (beams < 5 mm apart there), so lattice rows 47 .. 53 of
    # column 55 are marked: window rows 12 .. 18, window column 20.
    lc = make()
    theta = np.linspace(-0.5, 0.5, 101)
    stats = lc.update(POSE, 0.5 / np.cos(theta), angle_min=-0.5, angle_increment=0.01, stamp=0.0,
                      **SCAN)
    assert marked_cells(lc) == {(row, 20) for row in range(12, 19)}
    assert stats.marked == 101 and stats.ignored == 0
    xy = lc.points()
    assert xy.shape == (7, 2)
    np.testing.assert_allclose(np.sort(xy[:, 1]), 4.75 + 0.1 * np.arange(7))  # cell centres
    np.testing.assert_allclose(xy[:, 0], 5.55)


def test_sensor_offset_and_heading():
    # robot facing +y (yaw pi/2), sensor 0.2 m ahead of the centre and turned by -pi/2, so the
    # sensor sits at (5.05, 5.25) and its beam 0 points along +x: a 0.5 m return lands at
    # (5.55, 5.25) -> lattice cell (52, 55) -> window cell (17, 20).
    lc = make()
    lc.update((5.05, 5.05, math.pi / 2), [0.5], angle_min=0.0, angle_increment=0.01, stamp=0.0,
              sensor_offset=(0.2, 0.0, -math.pi / 2), **SCAN)
    assert marked_cells(lc) == {(17, 20)}


def test_ray_through_a_marked_cell_clears_it():
    # first a return at 0.5 m marks lattice cell (50, 55) = window (15, 20); then the same beam
    # sees 1.0 m: its ray passes through x = 5.55 and clears that cell, and marks (5.05 + 1.0 =
    # 6.05 -> column 60) window (15, 25).
    lc = make()
    one_beam(lc, 0.5)
    assert marked_cells(lc) == {(15, 20)}
    stats = one_beam(lc, 1.0, stamp=0.1)
    assert marked_cells(lc) == {(15, 25)}
    assert stats.cleared == 1 and stats.marked == 1


def test_a_return_does_not_clear_its_own_cell():
    lc = make()
    for stamp in (0.0, 0.1, 0.2):
        one_beam(lc, 0.5, stamp=stamp)
    assert marked_cells(lc) == {(15, 20)}


def test_inf_ray_clears_but_does_not_mark():
    # +inf = nothing within range_max: clear up to range_max (1.0 m here, past the mark at
    # 0.5 m), never mark. With range_max = 0.3 m the ray stops before the mark, which stays.
    lc = make()
    one_beam(lc, 0.5)
    one_beam(lc, math.inf, stamp=0.1, range_max=0.3)
    assert marked_cells(lc) == {(15, 20)}
    stats = one_beam(lc, math.inf, stamp=0.2, range_max=1.0)
    assert marked_cells(lc) == set()
    assert stats.marked == 0 and stats.cleared == 1


def test_raytrace_range_limits_clearing():
    # the mark is 0.5 m ahead; rays only clear up to raytrace_range = 0.4 m
    lc = make(raytrace_range=0.4)
    one_beam(lc, 0.5)
    one_beam(lc, 1.0, stamp=0.1)
    assert marked_cells(lc) == {(15, 20), (15, 25)}


def test_obstacle_range_limits_marking_but_not_clearing():
    # a return at 1.0 m beyond obstacle_range = 0.8 m does not mark, but its ray still clears
    # the mark at 0.5 m (made while the limit was generous, same lattice)
    lc = make(obstacle_range=0.8)
    one_beam(lc, 0.5)
    stats = one_beam(lc, 1.0, stamp=0.1)
    assert marked_cells(lc) == set()
    assert stats.marked == 0 and stats.cleared == 1


@pytest.mark.parametrize("bad", [math.nan, -math.inf, 0.01, 12.0])
def test_invalid_returns_are_ignored(bad):
    # REP-117: NaN invalid, -inf too close; finite values outside [range_min 0.05, range_max 10]
    # are discarded: no mark, and no clearing of the 0.5 m mark in the beam's way
    lc = make()
    one_beam(lc, 0.5)
    stats = one_beam(lc, bad, stamp=0.1)
    assert marked_cells(lc) == {(15, 20)}
    assert stats == type(stats)(marked=0, cleared=0, expired=0, ignored=1)


def test_clear_on_miss_false_never_clears():
    lc = make(clear_on_miss=False)
    one_beam(lc, 0.5)
    one_beam(lc, math.inf, stamp=0.1, range_max=1.0)
    assert marked_cells(lc) == {(15, 20)}


def test_persistence_expires_old_marks():
    # persistence 2 s: a mark made at t = 0 and not seen again survives t = 1.5, is gone at 2.5
    lc = make(persistence=2.0)
    one_beam(lc, 0.5, stamp=0.0)
    one_beam(lc, math.nan, stamp=1.5)
    assert marked_cells(lc) == {(15, 20)}
    stats = one_beam(lc, math.nan, stamp=2.5)
    assert marked_cells(lc) == set() and stats.expired == 1


def test_window_shift_keeps_marks_in_world_coordinates():
    # mark the cell centred at (5.55, 5.05); move the robot by (+0.5, +0.5) m = 5 cells: the
    # window slides, the mark keeps its world position (and moves by -5 cells in the window)
    lc = make()
    one_beam(lc, 0.5)
    one_beam(lc, math.nan, pose=(5.55, 5.55, 0.0), stamp=0.1)
    assert lc.origin == pytest.approx((4.0, 4.0))
    np.testing.assert_allclose(lc.points(), [[5.55, 5.05]])
    assert marked_cells(lc) == {(10, 15)}
    # drive 10 m away: the cell leaves the window and is forgotten
    one_beam(lc, math.nan, pose=(15.55, 5.55, 0.0), stamp=0.2)
    one_beam(lc, math.nan, pose=(5.55, 5.55, 0.0), stamp=0.3)
    assert lc.points().shape == (0, 2)


def test_to_occupancy_layout():
    # one beam: the ray clears window row 15, columns 15 .. 19 (robot cell to the cell before
    # the return), the return marks column 20; nothing else has been observed
    lc = make()
    one_beam(lc, 0.5)
    layout = lc.to_occupancy(frame_id="odom")
    assert (layout.width, layout.height, layout.resolution) == (30, 30, RES)
    assert layout.origin_xy == pytest.approx((3.5, 3.5)) and layout.frame_id == "odom"
    grid = layout.data.reshape(30, 30)
    assert grid.dtype == np.int8
    assert grid[15, 15:20].tolist() == [0] * 5 and grid[15, 20] == 100
    assert np.count_nonzero(grid == -1) == 30 * 30 - 6


def test_bad_inputs_raise():
    with pytest.raises(EcahdError, match="size"):
        LocalCostmapConfig(size=0.0)
    with pytest.raises(EcahdError, match="persistence"):
        LocalCostmapConfig(persistence=-1.0)
    lc = make()
    with pytest.raises(EcahdError, match="pose"):
        one_beam(lc, 0.5, pose=(math.nan, 0.0, 0.0))
    with pytest.raises(EcahdError, match="range_min"):
        one_beam(lc, 0.5, range_min=2.0, range_max=1.0)


# ----------------------------------------------------------------------------------- fusion
def static_grid(occupied=()) -> GridMap:
    """10 m x 10 m free map of 0.1 m cells, origin (0, 0), with the given (row, col) occupied."""
    data = np.zeros((100, 100), dtype=np.int8)
    for rc in occupied:
        data[rc] = 100
    return GridMap(data=data, resolution=RES)


@pytest.mark.parametrize("dilation", [0.0, 0.2])
def test_fused_costmap_equals_the_map_with_the_obstacle_drawn_in(dilation):
    # a local mark in lattice cell (50, 55) must cost exactly what the static map would cost with
    # that cell occupied, everywhere: the window is recomputed with a ring of
    # ceil((margin + dilation) / res) + 1 cells around it. At the cell itself the signed distance
    # of a lone occupied cell is -(1 - 0.5) 0.1 = -0.05 m, so cost = (0.1 + 0.05 + dilation) / 0.1
    # (1.5 without dilation: "1 on an edge, + 1 per margin of depth").
    cfg = CostConfig(margin=0.1, dilation=dilation)
    grid = static_grid(occupied=[(20, 20)])
    lc = make()
    one_beam(lc, 0.5)
    fused = lc.fused_costmap(grid, cfg)
    assert isinstance(fused, CostMap) and fused.shape == (100, 100)
    reference = cfg.make_costmap(static_grid(occupied=[(20, 20), (50, 55)]))
    torch.testing.assert_close(fused.grid, reference.grid)
    assert (fused.margin, fused.dilation, fused.origin, fused.resolution) == (
        0.1, dilation, (0.0, 0.0), RES)
    at_mark = fused.sample(torch.tensor([5.55, 5.05]))
    assert float(at_mark) == pytest.approx((0.15 + dilation) / 0.1, rel=1e-5)
    assert float(fused.sample(torch.tensor([8.05, 8.05]))) == 0.0  # far from everything
    # the same from the static CostMap (occupancy read back from the cost)
    torch.testing.assert_close(lc.fused_costmap(cfg.make_costmap(grid)).grid, reference.grid)


def test_fused_costmap_without_marks_is_the_static_map():
    grid = static_grid()
    cfg = CostConfig()
    lc = make()
    static = cfg.make_costmap(grid)
    assert lc.fused_costmap(static) is static  # no scan yet
    one_beam(lc, math.inf)  # clears, marks nothing
    assert lc.fused_costmap(static) is static
    assert lc.fused_costmap(grid, cfg) is lc.fused_costmap(grid, cfg)  # built once


def test_fused_costmap_gradient_pushes_away_from_a_local_obstacle():
    # the mark fills [5.5, 5.6] x [5.0, 5.1]; the centre (5.65, 5.05) of the next cell is 0.05 m
    # in front of its +x face, cost (0.1 - 0.05) / 0.1 = 0.5; the gradient of J ("point" mode)
    # points into the obstacle (-x), so a descent step moves the point out and lowers the cost
    lc = make()
    one_beam(lc, 0.5)
    fused = lc.fused_costmap(static_grid(), CostConfig())
    traj = torch.tensor([[[5.65, 5.05]]], requires_grad=True)
    terms = trajectory_cost(traj, traj.detach()[0, -1], None, fused, mode="point")
    before = float(terms.collision_cost.detach())
    assert before == pytest.approx(0.5, abs=1e-4)
    (grad,) = torch.autograd.grad(terms.total.sum(), traj)
    assert float(grad[0, 0, 0]) < 0
    moved = traj.detach() - 0.002 * grad  # gradient ~ -1 / margin = -10 per m: 2 cm out
    assert float(moved[0, 0, 0]) > 5.65
    assert float(fused.sample(moved[0, 0])) < before


def test_fused_costmap_checks_the_lattice_and_config():
    lc = make()
    one_beam(lc, 0.5)
    shifted = GridMap(data=np.zeros((100, 100), dtype=np.int8), resolution=RES,
                      origin=(0.05, 0.0))
    with pytest.raises(MapError, match="lattice"):
        lc.fused_costmap(shifted)
    coarse = GridMap(data=np.zeros((50, 50), dtype=np.int8), resolution=0.2)
    with pytest.raises(MapError, match="resolution"):
        lc.fused_costmap(coarse)
    with pytest.raises(MapError, match="margin"):
        lc.fused_costmap(CostConfig(margin=0.2).make_costmap(static_grid()), CostConfig())


def test_update_speed_is_reported():
    # 360 beams on a 200 x 200 window (6 m at 0.03 m): print the time, assert nothing about it
    lc = LocalCostmap(resolution=0.03, config=LocalCostmapConfig(size=6.0))
    assert lc.shape == (200, 200)
    rng = np.random.default_rng(0)
    ranges = rng.uniform(0.5, 4.0, 360)
    ranges[::7] = math.inf
    times = []
    for k in range(20):
        t0 = time.perf_counter()
        lc.update((30.0, 30.0, 0.01 * k), ranges, angle_min=-math.pi,
                  angle_increment=2 * math.pi / 360, range_min=0.1, range_max=10.0,
                  stamp=0.1 * k)
        times.append(time.perf_counter() - t0)
    print(f"LocalCostmap.update, 360 beams, 200x200 window: median "
          f"{1e3 * float(np.median(times)):.2f} ms")
    assert lc.obstacle_mask().any()
