"""The differentiable collision cost map read by bilinear interpolation (paper Sec. III-B/C,
Eqs. 10-13).

The occupancy grid is turned into a dimensionless cost defined in world units, so the same world
point gets (almost) the same cost whatever the grid resolution:

    cost(p) = relu(margin - (sdf(p) - dilation)) / margin

- 0 in open space farther than ``margin`` [m] from every obstacle,
- 1 on an obstacle edge,
- growing linearly with depth inside an obstacle (1 more per ``margin`` metres), so the gradient
  that pushes a trajectory out of a wall never vanishes inside it (except on the wall's medial
  axis, where the signed distance itself has a ridge).

``sdf`` is :func:`ecahd_core.maps.signed_distance` (positive in free space, negative inside
obstacles, everything off the map counts as obstacle). ``dilation`` [m] inflates the obstacles,
e.g. by the robot radius: the "dilation" variant of Table II.

The cost is stored at cell centres and read with hand-written bilinear interpolation between the
four surrounding cell centres (Eqs. 10-11), differentiable w.r.t. the query point: the batched
:meth:`CostMap.sample` computes the partial derivatives of Eqs. 12-13 alongside the value (one
autograd node instead of a dozen), the scalar :meth:`CostMap.sample_point` is plain autograd
through Eq. 10 and serves as its reference.

Points outside the lattice of cell centres (the outer half cell of the map and everything off the
map) are clamped onto it and get a penalty that grows linearly with the distance outside, at the
same slope as the cost inside an obstacle (1 per ``margin`` metres): the linear continuation of
"off the map is obstacle", whose gradient points back onto the map.
"""
from __future__ import annotations

import copy
import math

import numpy as np
import torch

from ecahd_core.errors import MapError, TrajectoryError
from ecahd_core.maps import FREE, OCCUPIED, GridMap, signed_distance

DEFAULT_MARGIN = 0.1  # [m] distance from an obstacle at which the cost reaches 0
DEFAULT_DILATION = 0.0  # [m] obstacle inflation (Table II "dilation"); 0 = the paper's Surface
# [m] the margin on a building's map (auto_margin): J reads the cost map at sample points
# (footprint points 0.15 m apart, N_interp per segment along the sweep), so with 0.1 m a single
# occupied cell (SLAM speckle, a shelf corner) between samples is invisible to J, DD and
# polishing, yet the exact checker finds the plan in collision (docs/RESULTS.md, 2026-12-03)
BUILDING_MARGIN = 0.5


def auto_margin(grid) -> float:
    """[m] the cost-map margin chosen by the map: BUILDING_MARGIN on maps over
    ``astar.COARSE_ABOVE_CELLS`` cells (buildings), DEFAULT_MARGIN (the setting of the paper's
    tables) on smaller ones such as maze2d-large."""
    from ecahd_core.astar import COARSE_ABOVE_CELLS

    return BUILDING_MARGIN if grid.width * grid.height > COARSE_ABOVE_CELLS else DEFAULT_MARGIN


class CostMap:
    """A collision cost grid in world units, sampled by bilinear interpolation.

    Attributes:
        grid: (H, W) tensor, the dimensionless cost at the cell centres; row 0 is the lowest y,
            as in :class:`~ecahd_core.maps.GridMap`.
        origin: world (x, y) [m] of the lower-left corner of cell (0, 0).
        resolution: cell size [m/cell].
        margin: [m] distance from an obstacle edge at which the cost falls to 0.
        dilation: [m] how much the obstacles were inflated before computing the cost.
        name: identity of the source map.

    The tensors live on one device with one dtype; :meth:`to` gives a converted copy.
    """

    def __init__(self, grid: torch.Tensor, *, origin: tuple[float, float], resolution: float,
                 margin: float = DEFAULT_MARGIN, dilation: float = DEFAULT_DILATION,
                 name: str = "custom") -> None:
        if not isinstance(grid, torch.Tensor) or grid.ndim != 2 or grid.numel() == 0:
            raise MapError(f"cost map {name!r}: grid must be a non-empty 2-D tensor, got "
                           f"{getattr(grid, 'shape', type(grid).__name__)}")
        if not grid.is_floating_point():
            raise MapError(f"cost map {name!r}: grid must be floating point, got {grid.dtype}")
        if not bool(torch.isfinite(grid).all()):
            raise MapError(f"cost map {name!r}: grid has non-finite values")
        if not (math.isfinite(resolution) and resolution > 0):
            raise MapError(f"cost map {name!r}: resolution must be > 0 [m/cell], got {resolution}")
        if not (math.isfinite(margin) and margin > 0):
            raise MapError(f"cost map {name!r}: margin must be > 0 m, got {margin}")
        if not (math.isfinite(dilation) and dilation >= 0):
            raise MapError(f"cost map {name!r}: dilation must be >= 0 m, got {dilation}")
        ox, oy = (float(v) for v in origin)
        if not (math.isfinite(ox) and math.isfinite(oy)):
            raise MapError(f"cost map {name!r}: origin must be finite, got {origin}")
        self.grid = grid
        self.origin = (ox, oy)
        self.resolution = float(resolution)
        self.margin = float(margin)
        self.dilation = float(dilation)
        self.name = name
        self._converted: dict[tuple[torch.device, torch.dtype], CostMap] = {}
        self._build_lookup()

    # ----------------------------------------------------------------------------- building
    @classmethod
    def from_grid(cls, grid: GridMap, *, margin: float = DEFAULT_MARGIN,
                  dilation: float = DEFAULT_DILATION, dtype: torch.dtype = torch.float32,
                  device: torch.device | str = "cpu") -> CostMap:
        """Cost map of an occupancy grid: relu(margin - (sdf - dilation)) / margin at each cell
        centre (see the module docstring). margin, dilation [m]."""
        if not (math.isfinite(margin) and margin > 0):
            raise MapError(f"cost map {grid.name!r}: margin must be > 0 m, got {margin}")
        if not (math.isfinite(dilation) and dilation >= 0):
            raise MapError(f"cost map {grid.name!r}: dilation must be >= 0 m, got {dilation}")
        sdf = signed_distance(grid) - dilation  # (H, W) [m]
        cost = np.maximum(margin - sdf, 0.0) / margin  # (H, W) dimensionless
        return cls(torch.as_tensor(cost, dtype=dtype, device=device), origin=grid.origin,
                   resolution=grid.resolution, margin=margin, dilation=dilation, name=grid.name)

    def _build_lookup(self) -> None:
        """Precompute what :meth:`sample` needs, on the grid's device and dtype."""
        H, W = self.grid.shape
        # Eq. 10 neighbours of every cell centre (row i, col j), one table row per cell:
        # M(x0, y0), M(x1, y0), M(x0, y1), M(x1, y1) with x1 = col j + 1, y1 = row i + 1.
        # The last row / column is repeated, so a point clamped onto the upper border still finds
        # four neighbours (its weight on the repeated ones is 0).
        g = self.grid
        padded = torch.cat([g, g[:, -1:]], dim=1)
        padded = torch.cat([padded, padded[-1:]], dim=0)  # (H + 1, W + 1)
        corners = torch.stack([padded[:-1, :-1], padded[:-1, 1:], padded[1:, :-1], padded[1:, 1:]])
        self._corners = corners.reshape(4, H * W).contiguous()  # (4, H*W), column = cell
        # world position [m] of the centre of cell (0, 0): continuous index = (xy - centre0) / res
        self._centre0 = (self.origin[0] + 0.5 * self.resolution,
                         self.origin[1] + 0.5 * self.resolution)

    @staticmethod
    def _corner_block(g: torch.Tensor, r0: int, r1: int, c0: int, c1: int) -> torch.Tensor:
        """The lookup table's four corner values of cells rows r0..r1-1, cols c0..c1-1 of the
        cost grid g (H, W) -> (4, r1 - r0, c1 - c0), the last row / column repeated (what
        :meth:`_build_lookup` computes for the whole grid)."""
        H, W = g.shape
        rows = torch.arange(r0, r1 + 1, device=g.device).clamp_(max=H - 1)
        cols = torch.arange(c0, c1 + 1, device=g.device).clamp_(max=W - 1)
        padded = g[rows][:, cols]  # (r1 - r0 + 1, c1 - c0 + 1)
        return torch.stack([padded[:-1, :-1], padded[:-1, 1:], padded[1:, :-1], padded[1:, 1:]])

    def _patched(self, grid: torch.Tensor, boxes: list[tuple[int, int, int, int]],
                 name: str) -> CostMap:
        """A CostMap of ``grid`` (H, W), which equals this one's but in the (r0, r1, c0, c1)
        ``boxes`` (finite there): this one's lookup table copied and recomputed in the boxes
        only, instead of built over the whole map (on 2000 x 2000 cells, the table is 4 x 4 M
        values)."""
        H, W = self.shape
        for r0, r1, c0, c1 in boxes:
            if not bool(torch.isfinite(grid[r0:r1, c0:c1]).all()):
                raise MapError(f"cost map {name!r}: grid has non-finite values")
        out = copy.copy(self)  # origin, resolution, margin, dilation and the lookup's origin
        out.grid, out.name, out._converted = grid, name, {}
        corners = self._corners.clone().view(4, H, W)
        for r0, r1, c0, c1 in boxes:  # a cell's corners read its row and column + 1
            r0, c0 = max(r0 - 1, 0), max(c0 - 1, 0)
            corners[:, r0:r1, c0:c1] = self._corner_block(grid, r0, r1, c0, c1)
        out._corners = corners.view(4, H * W)
        return out

    # ------------------------------------------------------------------------------ access
    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) cells."""
        return int(self.grid.shape[0]), int(self.grid.shape[1])

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) [m] of the mapped area."""
        H, W = self.shape
        ox, oy = self.origin
        return ox, oy, ox + W * self.resolution, oy + H * self.resolution

    @property
    def device(self) -> torch.device:
        return self.grid.device

    @property
    def dtype(self) -> torch.dtype:
        return self.grid.dtype

    def to(self, device: torch.device | str | None = None,
           dtype: torch.dtype | None = None) -> CostMap:
        """This cost map on another device and/or dtype (``self`` when nothing changes).
        Converted copies are remembered, so calling this in a sampling loop copies once."""
        device = self.grid.device if device is None else torch.device(device)
        dtype = self.grid.dtype if dtype is None else dtype
        if device == self.grid.device and dtype == self.grid.dtype:
            return self
        key = (device, dtype)
        if key not in self._converted:
            self._converted[key] = CostMap(self.grid.to(device=device, dtype=dtype),
                                           origin=self.origin, resolution=self.resolution,
                                           margin=self.margin, dilation=self.dilation,
                                           name=self.name)
        return self._converted[key]

    def __repr__(self) -> str:
        H, W = self.shape
        return (f"CostMap({self.name!r}, {H}x{W} cells of {self.resolution} m, "
                f"margin={self.margin} m, dilation={self.dilation} m, "
                f"{self.grid.dtype}, {self.grid.device})")

    # ---------------------------------------------------------------------------- sampling
    def sample(self, xy: torch.Tensor, *, dim: int = -1) -> torch.Tensor:
        """Cost at world points by bilinear interpolation between cell centres (Eqs. 10-11).

        Args:
            xy: world coordinates [m] with the (x, y) pair along ``dim``, e.g. (..., 2) for the
                default dim=-1; the lookup runs on its device and dtype.
            dim: the dimension of size 2 holding (x, y). The batched cost J passes (B, M, 2, R)
                with dim=-2: x and y as two planes avoid slow operations over a trailing
                dimension of size 2.

        Returns:
            ``xy``'s shape without ``dim``: the dimensionless cost. Differentiable w.r.t. ``xy``;
            the gradient is the analytic one of Eqs. 12-13, computed alongside the value, which
            is much cheaper than recording a dozen autograd steps. Off the lattice of cell
            centres the point is clamped onto it and the L1 distance outside [m] / margin is
            added.
        """
        if not (-xy.ndim <= dim < xy.ndim) or xy.shape[dim] != 2:
            raise TrajectoryError(f"cost map points need the (x, y) pair along dimension {dim}, "
                                  f"got shape {tuple(xy.shape)}")
        dim = dim % xy.ndim
        cmap = self.to(xy.device, xy.dtype)
        if xy.requires_grad and torch.is_grad_enabled():
            return _BilinearLookup.apply(xy, cmap, dim)
        return cmap._interpolate(xy, dim, with_grad=False)[0]

    def _interpolate(self, xy: torch.Tensor, dim: int, *, with_grad: bool):
        """Value (Eq. 10 plus the off-lattice penalty) and, if ``with_grad``, its gradient
        (Eqs. 12-13) [1/m] stacked along ``dim`` like ``xy``. -> (value, grad or None)."""
        H, W = self.grid.shape
        inv_res = 1.0 / self.resolution
        with torch.no_grad():
            x, y = xy.unbind(dim)  # (...) [m]
            u = (x - self._centre0[0]) * inv_res  # (...) continuous column index of x
            v = (y - self._centre0[1]) * inv_res  # (...) continuous row index of y
            u_in = u.clamp(0.0, W - 1.0)  # clamped onto the lattice of cell centres
            v_in = v.clamp(0.0, H - 1.0)
            du, dv = u - u_in, v - v_in  # (...) cells off the lattice, 0 on it
            col0 = u_in.floor()  # (...) column of the neighbours x0
            row0 = v_in.floor()  # (...) row of the neighbours y0
            flat = torch.add(col0, row0, alpha=W).long().reshape(-1)  # table column of the cell
            m = self._corners.index_select(1, flat).view(4, *u.shape)  # (4, ...) neighbours
            m00, m10, m01, m11 = m.unbind(0)  # M(x0,y0), M(x1,y0), M(x0,y1), M(x1,y1)
            tx = u_in - col0  # Eq. 11 (x1 - x0 = one cell)
            ty = v_in - row0
            # Eq. 10 grouped as two interpolations along x, then one along y:
            # (1-ty) [(1-tx) M00 + tx M10] + ty [(1-tx) M01 + tx M11]
            value = torch.lerp(torch.lerp(m00, m10, tx), torch.lerp(m01, m11, tx), ty)
            # off the lattice: + L1 distance [m] / margin = (|du| + |dv|) resolution / margin
            value += (du.abs() + dv.abs()) * (self.resolution / self.margin)
            if not with_grad:
                return value, None
            # Eq. 12: dInterp/dx = [(1-ty)(M10 - M00) + ty (M11 - M01)] / (x1 - x0)
            d_dx = torch.lerp(m10 - m00, m11 - m01, ty) * inv_res
            # Eq. 13: dInterp/dy = [(1-tx)(M01 - M00) + tx (M11 - M10)] / (y1 - y0)
            d_dy = torch.lerp(m01 - m00, m11 - m10, tx) * inv_res
            # off the lattice the lookup is pinned to the border and only the penalty moves:
            # d/dx = on * Eq. 12 + sign(du) / margin with on = 1 on the lattice, 0 off it
            su, sv = du.sign(), dv.sign()
            d_dx = torch.addcmul(su / self.margin, d_dx, 1.0 - su.abs())
            d_dy = torch.addcmul(sv / self.margin, d_dy, 1.0 - sv.abs())
        return value, torch.stack([d_dx, d_dy], dim)

    def sample_point(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """The cost at one point, Eq. 10 written for scalars (the loop reference of
        :func:`ecahd_core.cost.trajectory_cost_loops`). x, y: 0-d tensors [m] on the grid's
        device and dtype -> 0-d tensor.

        Same value and gradient as :meth:`sample` (here by plain autograd); slow, for tests and
        benchmarks only.
        """
        H, W = self.shape
        u = (x - self._centre0[0]) / self.resolution  # continuous column index
        v = (y - self._centre0[1]) / self.resolution  # continuous row index
        u_in = torch.clamp(u, 0.0, W - 1.0)
        v_in = torch.clamp(v, 0.0, H - 1.0)
        outside = ((u - u_in).abs() + (v - v_in).abs()) * (self.resolution / self.margin)
        col0, row0 = math.floor(u_in.item()), math.floor(v_in.item())
        col1, row1 = min(col0 + 1, W - 1), min(row0 + 1, H - 1)
        tx = u_in - col0  # Eq. 11
        ty = v_in - row0
        M = self.grid
        value = ((1 - tx) * (1 - ty) * M[row0, col0]  # Eq. 10
                 + tx * (1 - ty) * M[row0, col1]
                 + (1 - tx) * ty * M[row1, col0]
                 + tx * ty * M[row1, col1])
        return value + outside


class _BilinearLookup(torch.autograd.Function):
    """Autograd wrapper of :meth:`CostMap._interpolate`: the forward pass also computes the
    gradient (Eqs. 12-13), the backward pass only scales it."""

    @staticmethod
    def forward(ctx, xy: torch.Tensor, costmap: CostMap, dim: int) -> torch.Tensor:
        value, grad_xy = costmap._interpolate(xy, dim, with_grad=True)
        ctx.save_for_backward(grad_xy)
        ctx.dim = dim
        return value

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, grad_value: torch.Tensor):
        (grad_xy,) = ctx.saved_tensors
        return grad_value.unsqueeze(ctx.dim) * grad_xy, None, None


def add_obstacles(base: CostMap, rows: np.ndarray, cols: np.ndarray, occupied_of, *,
                  tile: int | None = None, name: str = "marks") -> CostMap:
    """``base``'s cost with the cells (rows, cols) of its grid occupied as well: what
    :meth:`CostMap.from_grid` would give for the occupancy ``base`` was built from plus those
    cells, computed on the regions round them only.

    The cost is a decreasing function of the distance to the nearest obstacle, so in free space
    the cost of a union of obstacles is the larger of their costs: each region (the marks' cells
    grown by the reach of an obstacle's cost, ``margin + dilation``) gets the cost of what is
    occupied in it, with a free ring round it so its border is no wall, and the result is the
    cell-wise maximum with ``base``. In free space this is the whole map's cost exactly (a test
    compares); inside an obstacle the depth term is at least ``base``'s but can be lower than
    the whole map's where a mark fills a gap of a wall that reaches past the region.

    Args:
        base: the cost map to add to (H, W).
        rows, cols: (K,) int cells of ``base``'s grid to mark occupied; those off it are ignored.
        occupied_of: (row slice, col slice) -> (h, w) bool, the occupancy ``base`` was built
            from on that region of its grid.
        tile: marks are grouped into square tiles of this many cells, each tile's region
            computed on its own (marks spread over a big map: a few small regions instead of
            one that spans the map); None: one region round all marks.

    Returns:
        A new CostMap (same extent, resolution, origin, margin, dilation, dtype and device;
        named ``base.name + "+" + name``), or ``base`` itself when no mark lies on it.
    """
    rows, cols = np.asarray(rows, dtype=np.int64), np.asarray(cols, dtype=np.int64)
    H, W = base.shape
    on = (rows >= 0) & (rows < H) & (cols >= 0) & (cols < W)
    rows, cols = rows[on], cols[on]
    if not len(rows):
        return base
    pad = math.ceil((base.margin + base.dilation) / base.resolution) + 1  # [cells]
    if tile is None:
        groups = [np.arange(len(rows))]
    else:
        key = (rows // tile) * (-(-W // tile)) + cols // tile
        order = np.argsort(key, kind="stable")
        groups = np.split(order, np.flatnonzero(np.diff(key[order])) + 1)
    fused = base.grid.clone()  # (H, W)
    boxes = []
    for g in groups:
        r, c = rows[g], cols[g]
        r_lo, r_hi = max(int(r.min()) - pad, 0), min(int(r.max()) + 1 + pad, H)
        c_lo, c_hi = max(int(c.min()) - pad, 0), min(int(c.max()) + 1 + pad, W)
        occ = np.array(occupied_of(slice(r_lo, r_hi), slice(c_lo, c_hi)), dtype=bool)
        occ[r - r_lo, c - c_lo] = True
        ring = np.pad(occ, pad, constant_values=False)
        region = GridMap(data=np.where(ring, OCCUPIED, FREE).astype(np.int8),
                         resolution=base.resolution, name="marks")
        window = CostMap.from_grid(region, margin=base.margin, dilation=base.dilation,
                                   dtype=base.dtype, device=base.device).grid[pad:-pad, pad:-pad]
        patch = fused[r_lo:r_hi, c_lo:c_hi]  # a view: writing it writes ``fused``
        patch.copy_(torch.maximum(patch, window))
        boxes.append((r_lo, r_hi, c_lo, c_hi))
    return base._patched(fused, boxes, f"{base.name}+{name}")
