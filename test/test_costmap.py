"""Tests of the differentiable cost map (ecahd_core.costmap): Eqs. 10-13 on hand-built grids,
the margin / dilation semantics, the off-map penalty and resolution independence."""
import numpy as np
import pytest
import torch

from ecahd_core.costmap import CostMap
from ecahd_core.errors import MapError, TrajectoryError
from ecahd_core.maps import GridMap, builtin_map

# A 2 x 3 grid, 0.5 m cells, origin (1.0, 2.0); row 0 is the lowest y:
#   row 1 (y centre 2.75):  4  6  8
#   row 0 (y centre 2.25):  0  1  2
#   columns' x centres:  1.25 1.75 2.25
TINY = [[0.0, 1.0, 2.0], [4.0, 6.0, 8.0]]
TINY_ORIGIN = (1.0, 2.0)
TINY_RES = 0.5


def tiny_map(dtype=torch.float64, margin=0.1):
    return CostMap(torch.tensor(TINY, dtype=dtype), origin=TINY_ORIGIN, resolution=TINY_RES,
                   margin=margin, name="tiny")


def occupancy(occ: np.ndarray, resolution: float) -> GridMap:
    return GridMap(data=np.where(occ, 100, 0).astype(np.int8), resolution=resolution,
                   name="hand")


# Hand-computed bilinear values (Eqs. 10-11), t = (p - centre0) / 0.5:
# (1.5, 2.5):    between columns 0-1 and rows 0-1, tx = 0.5, ty = 0.5
#                -> 0.25 (0 + 1 + 4 + 6) = 2.75
# (2.0, 2.375):  columns 1-2, rows 0-1, tx = 0.5, ty = 0.25
#                -> .5*.75*1 + .5*.75*2 + .5*.25*6 + .5*.25*8 = .375 + .75 + .75 + 1 = 2.875
# (1.375, 2.625): columns 0-1, rows 0-1, tx = 0.25, ty = 0.75
#                -> .75*.25*0 + .25*.25*1 + .75*.75*4 + .25*.75*6 = .0625 + 2.25 + 1.125 = 3.4375
HAND_VALUES = [((1.5, 2.5), 2.75), ((2.0, 2.375), 2.875), ((1.375, 2.625), 3.4375)]


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_bilinear_matches_hand_computed_values(dtype):
    cm = tiny_map(dtype)
    pts = torch.tensor([p for p, _ in HAND_VALUES], dtype=dtype)
    expected = torch.tensor([v for _, v in HAND_VALUES], dtype=dtype)
    torch.testing.assert_close(cm.sample(pts), expected)
    for (x, y), v in HAND_VALUES:  # the scalar loop reference agrees
        got = cm.sample_point(torch.tensor(x, dtype=dtype), torch.tensor(y, dtype=dtype))
        assert float(got) == pytest.approx(v)


def test_bilinear_gradient_matches_eqs_12_13():
    # at (2.0, 2.375): tx = 0.5, ty = 0.25, x1 - x0 = y1 - y0 = 0.5 m
    # Eq. 12: [(1-ty)(M10 - M00) + ty (M11 - M01)] / 0.5 = 2 (0.75 * 1 + 0.25 * 2) = 2.5
    # Eq. 13: [(1-tx)(M01 - M00) + tx (M11 - M10)] / 0.5 = 2 (0.5 * 5 + 0.5 * 6) = 11
    cm = tiny_map()
    p = torch.tensor([2.0, 2.375], dtype=torch.float64, requires_grad=True)
    (g,) = torch.autograd.grad(cm.sample(p), p)
    torch.testing.assert_close(g, torch.tensor([2.5, 11.0], dtype=torch.float64))
    x = torch.tensor(2.0, dtype=torch.float64, requires_grad=True)
    y = torch.tensor(2.375, dtype=torch.float64, requires_grad=True)
    gx, gy = torch.autograd.grad(cm.sample_point(x, y), (x, y))  # plain autograd of Eq. 10
    assert (float(gx), float(gy)) == pytest.approx((2.5, 11.0))


def test_equals_grid_at_cell_centres():
    cm = CostMap.from_grid(builtin_map("maze2d-umaze", resolution=0.1), dtype=torch.float64)
    H, W = cm.shape
    rows, cols = np.meshgrid(np.arange(H), np.arange(W), indexing="ij")
    centres = np.stack([(cols + 0.5) * 0.1, (rows + 0.5) * 0.1], axis=-1)  # (H, W, 2)
    torch.testing.assert_close(cm.sample(torch.tensor(centres)), cm.grid, rtol=0, atol=1e-12)
    torch.testing.assert_close(tiny_map().sample(torch.tensor(
        [[[1.25, 2.25], [1.75, 2.25], [2.25, 2.25]], [[1.25, 2.75], [1.75, 2.75], [2.25, 2.75]]],
        dtype=torch.float64)), torch.tensor(TINY, dtype=torch.float64))


def test_planar_layout_equals_pair_layout():
    cm = tiny_map()
    pts = torch.tensor(np.random.default_rng(0).uniform([0.8, 1.8], [2.7, 3.2], (5, 7, 2)))
    torch.testing.assert_close(cm.sample(pts.transpose(1, 2), dim=1), cm.sample(pts))


def block_map():
    """2 m x 2 m at 0.05 m; an obstacle block x, y in [0.75, 1.25) in the middle."""
    occ = np.zeros((40, 40), dtype=bool)
    occ[15:25, 15:25] = True
    return occupancy(occ, 0.05)


def grad_at(cm, x, y):
    p = torch.tensor([x, y], dtype=torch.float64, requires_grad=True)
    value = cm.sample(p)
    return float(value.detach()), torch.autograd.grad(value, p)[0]


def test_cost_levels_and_gradients():
    cm = CostMap.from_grid(block_map(), margin=0.1, dtype=torch.float64)
    # on the block's left edge (x = 0.75), away from corners: cost 1
    value, _ = grad_at(cm, 0.75, 1.0)
    assert value == pytest.approx(1.0)
    # 0.1 m deep inside (x = 0.85, y = 0.95 is off the medial axis): 1 + 0.1 / 0.1 = 2,
    # and the gradient points into the obstacle (descent leads out)
    value, g = grad_at(cm, 0.85, 0.95)
    assert value == pytest.approx(2.0)
    assert g[0] > 1.0 and abs(float(g[1])) < 1e-9
    # inside the margin, 0.05 m left of the block: cost 0.5, non-zero gradient
    value, g = grad_at(cm, 0.70, 1.0)
    assert value == pytest.approx(0.5)
    assert float(g[0]) == pytest.approx(1.0 / 0.1)
    # far away (0.5 m from the block, 0.2 m from the map edge): exactly 0, zero gradient
    value, g = grad_at(cm, 0.25, 1.0)
    assert value == 0.0 and torch.all(g == 0)


def test_dilation_inflates_obstacles():
    plain = CostMap.from_grid(block_map(), dtype=torch.float64)
    dilated = CostMap.from_grid(block_map(), dilation=0.2, dtype=torch.float64)
    p = torch.tensor([0.55, 1.0], dtype=torch.float64)  # 0.2 m left of the block
    assert float(plain.sample(p)) == 0.0
    assert float(dilated.sample(p)) == pytest.approx(1.0)  # on the inflated edge


def test_off_map_penalty_points_back_inside():
    cm = tiny_map(margin=0.1)
    # (1.0, 2.5) is 0.25 m left of the first column of centres: clamped onto (1.25, 2.5),
    # halfway between M(0, 0) = 0 and M(0, 1) = 4 -> 2, plus 0.25 / 0.1 = 2.5. d/dx = -1 / margin
    # points back onto the map; d/dy is still the border's Eq. 13: (4 - 0) / 0.5 = 8
    value, g = grad_at(cm, 1.0, 2.5)
    assert value == pytest.approx(4.5)
    torch.testing.assert_close(g, torch.tensor([-10.0, 8.0], dtype=torch.float64))
    # beyond the top-right corner: both coordinates penalised, L1 distance
    value, g = grad_at(cm, 2.75, 3.25)  # 0.5 m and 0.5 m outside -> 8 + 10
    assert value == pytest.approx(18.0)
    torch.testing.assert_close(g, torch.tensor([10.0, 10.0], dtype=torch.float64))
    # off-map values match the scalar reference
    got = cm.sample_point(torch.tensor(2.75, dtype=torch.float64),
                          torch.tensor(3.25, dtype=torch.float64))
    assert float(got) == pytest.approx(18.0)


def test_resolution_independence():
    # The same world points on maze2d-large at 0.1 m and 0.05 m: identical where the cost is
    # exactly linear between centres, otherwise within a quarter of the edge value (0.025 m of
    # depth at the default margin 0.1 m, half the coarse half-cell).
    coarse = CostMap.from_grid(builtin_map("maze2d-large", resolution=0.1), dtype=torch.float64)
    fine = CostMap.from_grid(builtin_map("maze2d-large", resolution=0.05), dtype=torch.float64)
    exact = torch.tensor([[1.0, 1.5],  # on a wall edge: cost 1
                          [1.05, 1.5],  # 0.05 m from the wall: 0.5
                          [2.5, 1.5],  # open space: 0
                          [0.8, 1.5]],  # 0.2 m inside the outer wall: 3
                         dtype=torch.float64)
    torch.testing.assert_close(coarse.sample(exact), torch.tensor([1.0, 0.5, 0.0, 3.0],
                                                                  dtype=torch.float64))
    torch.testing.assert_close(fine.sample(exact), coarse.sample(exact))
    pts = torch.tensor(np.random.default_rng(0).uniform([0.5, 0.5], [11.5, 8.5], (3000, 2)))
    diff = (coarse.sample(pts) - fine.sample(pts)).abs()
    assert float(diff.max()) <= 0.25 + 1e-9
    assert float(diff.mean()) < 0.03


def test_to_converts_once_and_keeps_values():
    cm = tiny_map(torch.float32)
    assert cm.to() is cm and cm.to("cpu", torch.float32) is cm
    cm64 = cm.to(dtype=torch.float64)
    assert cm64.dtype == torch.float64 and cm.to(dtype=torch.float64) is cm64
    pts = torch.tensor([[1.5, 2.5]], dtype=torch.float64)
    assert float(cm64.sample(pts)) == pytest.approx(2.75)
    assert "tiny" in repr(cm) and cm.bounds == (1.0, 2.0, 2.5, 3.0)


def test_bad_parameters_and_points():
    grid = block_map()
    with pytest.raises(MapError, match="margin"):
        CostMap.from_grid(grid, margin=0.0)
    with pytest.raises(MapError, match="dilation"):
        CostMap.from_grid(grid, dilation=-0.1)
    with pytest.raises(MapError, match="non-finite"):
        CostMap(torch.tensor([[float("nan")]]), origin=(0, 0), resolution=0.1)
    with pytest.raises(TrajectoryError, match="pair"):
        tiny_map().sample(torch.zeros(4, 3, dtype=torch.float64))


def test_a_cost_map_with_added_obstacles_has_the_lookup_of_one_built_whole():
    """add_obstacles patches the base's bilinear lookup table in the regions it changed; it
    must equal the table of a cost map built from the same grid, borders included."""
    from ecahd_core.costmap import add_obstacles

    occ = np.zeros((60, 50), dtype=bool)
    occ[20:40, 0] = True
    base = CostMap.from_grid(GridMap(np.where(occ, 100, 0).astype(np.int8), 0.05, (1.0, -2.0)))
    rows, cols = np.array([0, 1, 59, 30, 45, 59]), np.array([0, 1, 49, 25, 3, 0])
    for tile in (None, 8):
        fused = add_obstacles(base, rows, cols, lambda r, c: occ[r, c], tile=tile)
        whole = CostMap(fused.grid.clone(), origin=fused.origin, resolution=fused.resolution,
                        margin=fused.margin, dilation=fused.dilation)
        assert torch.equal(fused._corners, whole._corners)
        unit = torch.rand(500, 2, generator=torch.Generator().manual_seed(0))
        xy = unit * torch.tensor([2.6, 3.2]) + torch.tensor([0.9, -2.1])  # on and off the map
        assert torch.equal(fused.sample(xy), whole.sample(xy))
    assert torch.equal(base._corners, CostMap(base.grid.clone(), origin=base.origin,
                                              resolution=base.resolution)._corners)  # untouched
