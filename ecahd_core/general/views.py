"""The map as the generalist SD model sees it (issue 40): a planning problem (grid, start S,
goal G) -> fixed-size, metric, frame-independent occupancy images and the affine map between
world metres and the view's normalised coordinates. Pure numpy, batched over problems on one map.

Views of one problem (``make_views``; B problems at once, all on the same grid):

- **global view** (B, C, S, S), S = ``GLOBAL_SIZE`` = 64 px, a square of side L [m]; its
  extent (``ViewConfig.extent``) is one of
  * "problem": centred on the centre of S and G's bounding box, L = max(``MIN_SIDE``,
    l + 2 max(``MARGIN_MIN``, ``MARGIN_FRACTION`` l)), l the box's longer side: S and G at
    least 2 m (and a quarter of their separation) inside. Pixel size 0.125 m (a short trip) to
    1.5 m (``MAX_SIDE`` = 96 m). But an expert path may detour farther than the margin, and on
    office floors it often does (S and G in neighbouring rooms, the path out through both
    doors along the corridor): measured on two generated offices, 25% of the A* expert's
    200 problems each left the view, |u| up to 8 (18-21% with a margin of half the
    separation); such a plan cannot be drawn from what the view shows.
  * "map" (the default): the square on the map's centre whose side is the map's longer side
    plus 2 ``MARGIN_MIN``, at least the "problem" side (then centred on the problem), when it
    is at most ``MAX_SIDE``; the "problem" view on larger maps. Every path on the map is in
    view, at the price of resolution on large maps (0.5 m/px on a 30 m map, 1.0 m/px on
    60 m); the local views keep 0.1 m/px at S and G.
- **local views** (B, 2, C, S_l, S_l), S_l = ``LOCAL_SIZE`` = 32 px at ``LOCAL_RESOLUTION`` =
  0.1 m/px: 3.2 m squares centred on S (index 0) and on G (index 1). The global view is too
  coarse to show whether the robot fits a door at S or G; at 0.1 m/px a 0.9 m door is 9 px
  and a 0.4 m robot radius 4 px, while 3.2 m shows the walls of the corridor or the room
  around the endpoint. The grid's own resolution (0.01-0.2 m/cell) is resampled to it.
- **frame** (:class:`ViewFrame`): centre c (B, 2) and half side h = L / 2 (B,) [m]; world
  p -> view u = (p - c) / h, so the global view spans u in [-1, 1]^2 (x right, y up) and the
  model's waypoints live there. Nothing depends on a building's origin: translating the map
  and the problem together leaves every view and every u unchanged. The scale is not lost: the
  local views are metric and h is given to the model.

Image layout: row r, column c of a view covers y in [y0 + r p, y0 + (r + 1) p), x in
[x0 + c p, x0 + (c + 1) p) (p the pixel size, (x0, y0) the view's lower-left corner): row 0 at
the lowest y as in ``GridMap.data``; pixel centres at u = -1 + (k + 1/2) 2 / S (the
``align_corners=False`` convention of ``torch.nn.functional.grid_sample``).

Channels (C = 2), both resampled by area from the grid's obstacle mask (``GridMap.occupied``;
unknown counts as its ``unknown_is_occupied`` says) with everything off the map occupied:

0. ``any``: 1 where any cell overlapping the pixel is an obstacle (a max-pool): a 0.1 m wall
   survives in a 1.5 m pixel.
1. ``fraction``: the share of the overlapping cells that are obstacles (an area mean),
   quantised to 1/255 so that a dataset stores it exactly as uint8. Max-pooling alone closes
   gaps narrower than two pixels (a 1 m aisle between shelves at 0.8 m/px); the fraction
   keeps them visible as pixels below 1.

Resampling is exact and costs O(S^2) per view whatever the map's size: one summed-area table
of the obstacle mask per map (:class:`OccupancyIntegral`, built once and reused by every problem
on the map; 6 ms for a 1200 x 1200 grid), then four look-ups per pixel.

Sizes, why: S = 64 is the smallest square whose 8 x 8 patch grid (the model's map tokens,
stride 8) gives a patch of 1-12 m, about a room or an aisle segment, and whose CNN runs in a
few ms once per plan (128 px, 0.5 m/px on a 60 m map, is the first thing to try if doors
are lost: 4x the CNN, the same 8 x 8 tokens with one more stride-2 stage); S_l = 32 at
0.1 m/px is the neighbourhood a footprint needs round S and G.

Bad input raises :class:`~ecahd_core.errors.PlanningError` (an ``EcahdError``): points that are
not (B, 2) finite numbers, starts and goals of different counts, a view larger than
``max_side`` (a problem the model cannot see whole).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ecahd_core.errors import PlanningError
from ecahd_core.maps import GridMap

GLOBAL_SIZE = 64  # S [px]
LOCAL_SIZE = 32  # S_l [px]
LOCAL_RESOLUTION = 0.1  # [m/px] of the local views
MIN_SIDE = 8.0  # [m] smallest global view side
MARGIN_MIN = 2.0  # [m] least margin round S and G's bounding box
MARGIN_FRACTION = 0.25  # margin as a share of the box's longer side, where larger
MAX_SIDE = 96.0  # [m] largest global view side
CHANNELS = ("any", "fraction")  # the views' channels, in order
EXTENTS = ("map", "problem")  # what the global view covers (module docstring)
FRACTION_LEVELS = 255  # the fraction channel is a multiple of 1 / FRACTION_LEVELS
_EDGE_EPS = 1e-6  # [cells] a pixel edge this close to a cell edge does not overlap the cell


@dataclass(frozen=True, kw_only=True)
class ViewConfig:
    """Sizes of the views (module docstring); one place defines each default.

    Attributes:
        global_size: S [px], side of the global view.
        local_size: S_l [px], side of each local view.
        local_resolution: [m/px] of the local views.
        min_side: [m] smallest global view side.
        margin_min: [m] least margin round S and G's bounding box.
        margin_fraction: margin as a share of the box's longer side (where larger).
        max_side: [m] a problem whose global view would be larger is refused.
        extent: "map" or "problem", what the global view covers (module docstring).
    """

    global_size: int = GLOBAL_SIZE
    local_size: int = LOCAL_SIZE
    local_resolution: float = LOCAL_RESOLUTION
    min_side: float = MIN_SIDE
    margin_min: float = MARGIN_MIN
    margin_fraction: float = MARGIN_FRACTION
    max_side: float = MAX_SIDE
    extent: str = "map"

    def __post_init__(self) -> None:
        if self.extent not in EXTENTS:
            raise ValueError(f"ViewConfig.extent must be one of "
                             f"{', '.join(repr(e) for e in EXTENTS)}, got {self.extent!r}")
        for name in ("global_size", "local_size"):
            value = getattr(self, name)
            if isinstance(value, bool) or int(value) != value or value < 1:
                raise ValueError(f"ViewConfig.{name} must be a positive integer, got {value!r}")
            object.__setattr__(self, name, int(value))
        for name in ("local_resolution", "min_side", "max_side"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"ViewConfig.{name} must be a finite number > 0, got {value!r}")
        for name in ("margin_min", "margin_fraction"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"ViewConfig.{name} must be a finite number >= 0, "
                                 f"got {value!r}")
        if self.max_side < self.min_side:
            raise ValueError(f"ViewConfig.max_side ({self.max_side}) must be >= min_side "
                             f"({self.min_side})")

    @property
    def channels(self) -> int:
        """C, channels of every view."""
        return len(CHANNELS)


@dataclass(frozen=True)
class ViewFrame:
    """The affine map between world metres and a global view's normalised coordinates:
    u = (p - centre) / half_side, p = centre + half_side u; the view spans u in [-1, 1]^2.

    Attributes:
        centre: (B, 2) float64 [m], the view's centre in the map frame.
        half_side: (B,) float64 [m], half the view's side L.
    """

    centre: np.ndarray
    half_side: np.ndarray

    def __len__(self) -> int:
        return int(self.centre.shape[0])

    @property
    def side(self) -> np.ndarray:
        """(B,) [m] the view's side L."""
        return 2.0 * self.half_side

    def to_view(self, xy) -> np.ndarray:
        """World points -> view coordinates. xy: (B, ..., 2) [m] -> (B, ..., 2) float64."""
        xy, c, h = self._broadcast(xy)
        return (xy - c) / h

    def to_world(self, uv) -> np.ndarray:
        """View coordinates -> world points. uv: (B, ..., 2) -> (B, ..., 2) float64 [m]."""
        uv, c, h = self._broadcast(uv)
        return c + h * uv

    def _broadcast(self, pts) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        pts = np.asarray(pts, dtype=np.float64)
        B = len(self)
        if pts.ndim < 2 or pts.shape[0] != B or pts.shape[-1] != 2:
            raise PlanningError(f"points must have shape ({B}, ..., 2) for a frame of {B} "
                                f"views, got {pts.shape}")
        extra = (1,) * (pts.ndim - 2)
        return (pts, self.centre.reshape(B, *extra, 2),
                self.half_side.reshape(B, *extra, 1))

    def __getitem__(self, index) -> "ViewFrame":
        """The frames of a subset of the problems (an index array, a slice or a mask)."""
        return ViewFrame(np.atleast_2d(self.centre[index]), np.atleast_1d(self.half_side[index]))


@dataclass(frozen=True)
class MapViews:
    """What the model sees of B problems.

    Attributes:
        global_view: (B, C, S, S) float32 in [0, 1], channels ``CHANNELS``.
        local_views: (B, 2, C, S_l, S_l) float32 in [0, 1]; index 0 round the start, 1 round
            the goal.
        frame: the global views' :class:`ViewFrame` (B problems).
    """

    global_view: np.ndarray
    local_views: np.ndarray
    frame: ViewFrame

    def __len__(self) -> int:
        return int(self.global_view.shape[0])


class OccupancyIntegral:
    """The summed-area table of a grid's obstacle mask: area resampling of any window in
    O(pixels), whatever the map's size. Build once per map (:meth:`from_grid`).

    Attributes:
        table: (H + 1, W + 1) int32/int64, table[r, c] = obstacle cells in rows < r, cols < c.
        resolution: [m/cell]; origin: (x, y) [m] of cell (0, 0)'s lower-left corner.
    """

    def __init__(self, occupied: np.ndarray, resolution: float,
                 origin: tuple[float, float] = (0.0, 0.0)) -> None:
        occupied = np.asarray(occupied, dtype=bool)
        if occupied.ndim != 2 or not occupied.size:
            raise PlanningError(f"an obstacle mask must be a non-empty (H, W) array, "
                                f"got shape {occupied.shape}")
        if not (math.isfinite(resolution) and resolution > 0):
            raise PlanningError(f"resolution must be a finite number > 0 m/cell, "
                                f"got {resolution!r}")
        dtype = np.int32 if occupied.size < 2 ** 31 else np.int64
        table = np.zeros((occupied.shape[0] + 1, occupied.shape[1] + 1), dtype=dtype)
        np.cumsum(np.cumsum(occupied, axis=0, dtype=dtype), axis=1, dtype=dtype,
                  out=table[1:, 1:])
        self.table = table
        self.resolution = float(resolution)
        self.origin = (float(origin[0]), float(origin[1]))

    @classmethod
    def from_grid(cls, grid: GridMap) -> "OccupancyIntegral":
        return cls(grid.occupied, grid.resolution, grid.origin)

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the grid."""
        return self.table.shape[0] - 1, self.table.shape[1] - 1

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) [m] of the grid."""
        H, W = self.shape
        ox, oy = self.origin
        return ox, oy, ox + W * self.resolution, oy + H * self.resolution

    def window(self, corner: np.ndarray, pixel: np.ndarray, size: int) -> np.ndarray:
        """Area-resampled square windows (module docstring, "Channels").

        Args:
            corner: (B, 2) [m] lower-left corner (x0, y0) of each window.
            pixel: (B,) [m/px] pixel size of each window.
            size: pixels per side.
        Returns:
            (B, 2, size, size) float32: channel 0 any obstacle, channel 1 obstacle fraction.
        """
        B = corner.shape[0]
        H, W = self.shape
        k = np.arange(size + 1, dtype=np.float64)
        # pixel edges in cell units: (B, size + 1), x along columns, y along rows
        ex = (corner[:, 0:1] + k * pixel[:, None] - self.origin[0]) / self.resolution
        ey = (corner[:, 1:2] + k * pixel[:, None] - self.origin[1]) / self.resolution
        c0, c1 = _cell_ranges(ex)  # (B, size) each: cells [c0, c1) overlap pixel column c
        r0, r1 = _cell_ranges(ey)
        cc0, cc1 = np.clip(c0, 0, W), np.clip(c1, 0, W)  # the part on the map
        rc0, rc1 = np.clip(r0, 0, H), np.clip(r1, 0, H)
        T = self.table
        R0, R1 = rc0[:, :, None], rc1[:, :, None]  # (B, size, 1)
        C0, C1 = cc0[:, None, :], cc1[:, None, :]  # (B, 1, size)
        on_map_occ = (T[R1, C1] - T[R0, C1] - T[R1, C0] + T[R0, C0]).astype(np.int64)
        on_map = (R1 - R0) * (C1 - C0)  # (B, size, size) cells on the map
        total = (r1 - r0)[:, :, None] * (c1 - c0)[:, None, :]  # cells overlapping the pixel
        occupied = on_map_occ + (total - on_map)  # off the map counts as occupied
        out = np.empty((B, 2, size, size), dtype=np.float32)
        out[:, 0] = occupied > 0
        out[:, 1] = np.round(FRACTION_LEVELS * occupied / total) / FRACTION_LEVELS
        return out


def _cell_ranges(edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(B, n + 1) pixel edges in cell units -> (lo, hi) (B, n) int64: the cells a pixel overlaps
    by more than ``_EDGE_EPS`` cells, [lo, hi), at least one."""
    lo = np.floor(edges[:, :-1] + _EDGE_EPS).astype(np.int64)
    hi = np.ceil(edges[:, 1:] - _EDGE_EPS).astype(np.int64)
    return lo, np.maximum(hi, lo + 1)


def _as_points(points, what: str) -> np.ndarray:
    """(B, 2) or (2,) -> (B, 2) float64, finite; PlanningError naming ``what`` otherwise."""
    arr = np.asarray(points, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[None]
    if arr.ndim != 2 or arr.shape[1] != 2 or not len(arr):
        raise PlanningError(f"{what} must have shape (B, 2) or (2,), got {np.shape(points)}")
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise PlanningError(f"{what}[{i}] has non-finite coordinates {arr[i].tolist()}")
    return arr


def view_frames(starts, goals, config: ViewConfig | None = None, *,
                bounds: tuple[float, float, float, float] | None = None) -> ViewFrame:
    """The global views' frames of B problems (module docstring).

    Args:
        starts, goals: (B, 2) or (2,) [m].
        config: the sizes (default :class:`ViewConfig`'s).
        bounds: (xmin, ymin, xmax, ymax) [m] of the map; needed by the "map" extent.
    Raises:
        PlanningError: non-finite points, different counts, or a view side > ``max_side``.
    """
    config = config or ViewConfig()
    starts, goals = _as_points(starts, "starts"), _as_points(goals, "goals")
    side = view_side(starts, goals, config)  # (B,) [m]
    centre = (starts + goals) / 2.0  # (B, 2) [m]
    if config.extent == "map":
        if bounds is None:
            raise PlanningError("the 'map' view extent needs the map's bounds")
        xmin, ymin, xmax, ymax = (float(b) for b in bounds)
        map_side = max(xmax - xmin, ymax - ymin) + 2.0 * config.margin_min
        if map_side <= config.max_side:
            whole = map_side >= side  # (B,) the map's square covers the problem's
            centre = np.where(whole[:, None], [(xmin + xmax) / 2.0, (ymin + ymax) / 2.0],
                              centre)
            side = np.maximum(side, map_side)
    if (side > config.max_side).any():
        i = int(np.argmax(side))
        raise PlanningError(
            f"start {starts[i].round(3).tolist()} and goal {goals[i].round(3).tolist()} are "
            f"{np.abs(goals[i] - starts[i]).max():.2f} m apart along an axis: their view would "
            f"be {side[i]:.1f} m wide, over the {config.max_side:g} m the model's views cover; "
            f"plan to a nearer goal first")
    return ViewFrame(centre=centre, half_side=side / 2.0)


def view_side(starts, goals, config: ViewConfig | None = None) -> np.ndarray:
    """(B,) [m] the global view's side L of B problems (module docstring), ``max_side`` not
    applied. starts, goals: (B, 2) or (2,) [m], finite (PlanningError otherwise)."""
    config = config or ViewConfig()
    starts, goals = _as_points(starts, "starts"), _as_points(goals, "goals")
    if starts.shape != goals.shape:
        raise PlanningError(f"starts {starts.shape} and goals {goals.shape} differ in shape")
    longest = np.abs(goals - starts).max(axis=1)  # (B,) [m] the bounding box's longer side
    margin = np.maximum(config.margin_min, config.margin_fraction * longest)
    return np.maximum(config.min_side, longest + 2.0 * margin)


def make_views(grid: GridMap | OccupancyIntegral, starts, goals,
               config: ViewConfig | None = None) -> MapViews:
    """The global and local views of B problems on one map (module docstring).

    Args:
        grid: the map, or its :class:`OccupancyIntegral` (pass that when making views of many
            problems on one map: the table is built once).
        starts, goals: (B, 2) or (2,) [m] in the map frame.
        config: the sizes (default :class:`ViewConfig`'s).
    Returns:
        :class:`MapViews` with global_view (B, C, S, S), local_views (B, 2, C, S_l, S_l) and
        the frame.
    Raises:
        PlanningError: as :func:`view_frames`.
    """
    config = config or ViewConfig()
    integral = grid if isinstance(grid, OccupancyIntegral) else OccupancyIntegral.from_grid(grid)
    frame = view_frames(starts, goals, config, bounds=integral.bounds)
    starts, goals = _as_points(starts, "starts"), _as_points(goals, "goals")
    B, S, Sl = len(frame), config.global_size, config.local_size
    global_view = integral.window(frame.centre - frame.half_side[:, None],
                                  frame.side / S, S)  # (B, C, S, S)
    half_local = 0.5 * Sl * config.local_resolution  # [m]
    ends = np.concatenate([starts, goals])  # (2B, 2): starts, then goals
    local = integral.window(ends - half_local, np.full(2 * B, config.local_resolution), Sl)
    local_views = local.reshape(2, B, config.channels, Sl, Sl).transpose(1, 0, 2, 3, 4)
    return MapViews(global_view=global_view, local_views=np.ascontiguousarray(local_views),
                    frame=frame)
