"""Realistic building maps, generated: what a robotics team's SLAM map of a real building looks like,
so that tests and benchmarks never depend on a map the project cannot generate or ship.

Three kinds (all sizes in metres; the building's long axis follows the map's longer side):

* ``warehouse``: long double-deep shelf rows along the long axis, each shelf a block 1.0-2.4 m deep
  and 6-15 m long whose interior is unknown (the laser only sees the rack outline, which is
  occupied), now and then an empty bay with pallets on the floor; parallel aisles 1.0-2.5 m wide
  (plus one cell) between the rows, cross aisles 1.8-3.0 m wide, side aisles 1.5-3.0 m along the
  walls; an open dock area 3-8 m deep at one short end with pallets, a row of building columns,
  an office room 3-4.5 x 2.5-3.5 m in one corner (door 0.9-1.0 m) and 2-5 dock doors 2.5-3.5 m
  wide onto a short apron outside.
* ``office``: one or two corridors 1.5-2.0 m wide along the long axis (joined by a lobby 3-7 m deep
  at one end on larger floors, else by a cross corridor), rooms 2.8-6 m long and 2.5-6 m deep on
  both sides, each with a door 0.9-1.0 m wide onto a corridor and sometimes a second door
  0.8-1.0 m wide into the next room; cabinets along the walls, desk and chair legs as dots; now
  and then a locked room whose interior is unknown.
* ``depot``: open floor with square pillars 0.4-0.6 m (occupied outline, unknown core) on a
  6-10 m grid, pairs of shelf blocks (1.0-2.0 m x 2-5 m) whose gap is either narrower (0.25-0.7 m)
  or wider (0.95-1.6 m, plus two cells) than a 0.4-0.8 m robot, rows of pallets 0.3 m apart,
  loose boxes 0.4-1.0 m in the open bays, and a rack row along one long wall.

All kinds get what a SLAM map has: walls 0.1-0.3 m thick whose thickness and faces jitter by up to
0.05 m, ragged obstacle faces (single cells grown into free space, only where a cell is <= 0.05 m),
a few wall breaks 0.05-0.25 m wide (narrower than any robot the project knows, the narrowest being
0.30 m wide; breaks in the outer wall let a thin fan of free cells out), sparse speckle
(isolated occupied or unknown cells, about 0.05 per m^2 of open floor, only where the clearance to
any obstacle is >= 1 m), and unknown cells outside the building hull (a 0.4-1.5 m border).

What is guaranteed, for every valid :class:`MapGenConfig` (checked by test/test_mapgen.py):

1. The free cells (value 0) form one 4-connected region: free pockets cut off by walls, furniture
   or speckle are turned unknown.
2. For a circular robot of radius :data:`ROBOT_RADIUS` (0.4 m): the free cells whose clearance
   (``maps.signed_distance``: cell centre to nearest obstacle edge, unknown and the map edge
   counting as obstacle) is >= 0.4 m + CORNER_ERROR (a quarter) cell form one 4-connected
   region; other such regions are turned unknown. All of them lie in the A* expert's
   traversable mask (``AStarPlanner(grid, 0.4).mask``, whose exact clearance is at most a quarter
   cell below the distance transform's), so A* with clearance 0.4 m connects any two of them.
3. By design, the passages meant for the robot stay >= 0.9 m wide: door openings and their
   approaches get no noise and their jambs are redrawn after it, and aisles and wide depot gaps
   are drawn one or two cells wider so that ragged faces (at most one cell each side) leave
   0.9 m. So every room, aisle, dock and bay is reached by the A* expert with clearance 0.4 m:
   ``GeneratedMap.anchors`` holds one point in each (locked rooms are unknown and have none);
   the tests check them over seeds, sizes and resolutions. Should a layout still cut a room off,
   the pass of 2 turns the room's floor unknown: 1 and 2 hold in every case. Depot gaps are drawn
   outside 0.7-0.95 m, away from the 0.8 m threshold where A*'s exact clearance and the distance
   transform can disagree.

Not guaranteed: that A* reaches a cell whose clearance is within a quarter cell above 0.4 m
(such a cell may sit alone in a nook; sample starts and goals with clearance >= 0.4 m +
resolution / 4), that a larger robot reaches every room, or exact door widths at resolutions
coarser than 0.05 m/cell (a door is then widened to the cells the robot needs, see
``_Canvas.passable_cells``).

Same config -> byte-identical map (numpy ``default_rng(seed)`` and cv2 drawing only).
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from enum import Enum

import numpy as np

from ecahd_core.astar import CORNER_ERROR
from ecahd_core.errors import MapError
from ecahd_core.maps import FREE, OCCUPIED, UNKNOWN, GridMap

log = logging.getLogger(__name__)

ROBOT_RADIUS = 0.4  # [m] the circle robot every room must be reachable by
MIN_SIDE = 8.0  # [m] smallest building side a kind can be laid out in
MAX_SIDE = 60.0  # [m]
MIN_RESOLUTION = 0.01  # [m/cell]
MAX_RESOLUTION = 0.2  # [m/cell]
MAX_CELLS_PER_SIDE = 4000  # memory / time bound (60 m at 0.015 m/cell)

SPECKLE_DENSITY = 0.05  # [1/m^2] of open floor
SPECKLE_MIN_CLEARANCE = 1.0  # [m] speckle only where the floor is at least this open
RAGGED_GROW_P = 0.12  # probability that a free cell touching an obstacle becomes occupied
RAGGED_ERODE_P = 0.06  # probability that a wall cell touching free space becomes free
WALL_JITTER = 0.05  # [m] wall thickness / face jitter

# canvas labels while drawing (uint8)
_FREE, _OCC, _UNK = 0, 1, 2


class MapKind(str, Enum):
    """Kinds of building :func:`generate_map` can draw."""

    WAREHOUSE = "warehouse"
    OFFICE = "office"
    DEPOT = "depot"


def _is_number(value) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


@dataclass(frozen=True)
class MapGenConfig:
    """What to generate.

    Attributes:
        kind: ``warehouse`` | ``office`` | ``depot`` (str or :class:`MapKind`).
        width: map size along x [m], in [MIN_SIDE, MAX_SIDE].
        height: map size along y [m], in [MIN_SIDE, MAX_SIDE].
        resolution: cell size [m/cell], in [MIN_RESOLUTION, MAX_RESOLUTION].
        seed: integer >= 0; the same config gives the same map, cell for cell.
    """

    kind: MapKind | str
    width: float
    height: float
    resolution: float = 0.05
    seed: int = 0

    def __post_init__(self) -> None:
        try:
            kind = MapKind(self.kind)
        except ValueError:
            allowed = ", ".join(repr(k.value) for k in MapKind)
            raise MapError(f"unknown map kind {self.kind!r}; allowed: {allowed}") from None
        object.__setattr__(self, "kind", kind)
        for what in ("width", "height"):
            value = getattr(self, what)
            if not (_is_number(value) and math.isfinite(value)):
                raise MapError(f"map {what} must be a finite number [m], got {value!r}")
            if value <= 0 or value > MAX_SIDE:
                raise MapError(f"map {what} must be in (0, {MAX_SIDE:g}] m, got {value!r}")
            if value < MIN_SIDE:
                raise MapError(f"map {what} {value:g} m is too small for a {kind.value}: "
                               f"need at least {MIN_SIDE:g} m")
            object.__setattr__(self, what, float(value))
        res = self.resolution
        if not (_is_number(res) and math.isfinite(res)
                and MIN_RESOLUTION <= res <= MAX_RESOLUTION):
            raise MapError(f"map resolution must be in [{MIN_RESOLUTION}, {MAX_RESOLUTION}] m/cell, "
                           f"got {res!r}")
        object.__setattr__(self, "resolution", float(res))
        rows, cols = self.shape
        if max(rows, cols) > MAX_CELLS_PER_SIDE:
            raise MapError(f"{self.width:g} x {self.height:g} m at {res:g} m/cell is "
                           f"{cols} x {rows} cells; at most {MAX_CELLS_PER_SIDE} per side "
                           f"(use a coarser resolution)")
        if not (isinstance(self.seed, (int, np.integer)) and not isinstance(self.seed, bool)
                and self.seed >= 0):
            raise MapError(f"map seed must be an integer >= 0, got {self.seed!r}")
        object.__setattr__(self, "seed", int(self.seed))

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols) of the grid."""
        return (int(round(self.height / self.resolution)), int(round(self.width / self.resolution)))

    @property
    def name(self) -> str:
        """Map identity, e.g. ``warehouse-30x50-0.05-s0``."""
        return f"{self.kind.value}-{self.width:g}x{self.height:g}-{self.resolution:g}-s{self.seed}"


@dataclass(frozen=True)
class Door:
    """A door opening: centre (x, y) [m], clear width [m], and whether the wall it pierces runs
    along x (``along_x``: the opening spans x, the robot passes along y)."""

    centre: tuple[float, float]
    width: float
    along_x: bool


@dataclass(frozen=True)
class GeneratedMap:
    """A generated map and what the generator knows about it.

    Attributes:
        grid: the occupancy grid (origin (0, 0), name :attr:`MapGenConfig.name`).
        config: what was asked for.
        doors: every door drawn (office rooms; empty for the other kinds).
        anchors: (N, 2) [m] one point in every room, aisle, dock and open bay the robot must be
            able to reach (clearance >= ROBOT_RADIUS, all in one connected region).
        filled_cells: free cells the connectivity pass turned unknown (pockets, unreachable nooks).
    """

    grid: GridMap
    config: MapGenConfig
    doors: tuple[Door, ...]
    anchors: np.ndarray
    filled_cells: int


# ------------------------------------------------------------------------------------ canvas
class _Canvas:
    """A label image in a local frame (x along columns, y along rows, metres) with the drawing
    primitives the kinds share. ``keep`` marks cells no noise or furniture may enter;
    ``openings`` are door cells restored to free after the noise."""

    def __init__(self, width: float, height: float, resolution: float,
                 rng: np.random.Generator) -> None:
        self.res = resolution
        self.rng = rng
        self.cols = int(round(width / resolution))
        self.rows = int(round(height / resolution))
        self.width = self.cols * resolution  # [m]
        self.height = self.rows * resolution  # [m]
        self.labels = np.full((self.rows, self.cols), _UNK, dtype=np.uint8)
        self.wall = np.zeros(self.labels.shape, dtype=bool)  # may be eroded / broken
        self.keep = np.zeros(self.labels.shape, dtype=bool)
        self.openings = np.zeros(self.labels.shape, dtype=bool)
        self.jambs = np.zeros(self.labels.shape, dtype=bool)  # occupied again after the noise
        self.doors: list[Door] = []
        self.anchors: list[tuple[float, float]] = []
        self.jitter = int(round(WALL_JITTER / resolution))  # [cells]

    # -------------------------------------------------------------- metres <-> cells
    def c(self, v: float) -> int:
        """Cell index of a coordinate [m] (boundary between cells)."""
        return int(round(v / self.res))

    def slices(self, x0: float, y0: float, x1: float, y1: float) -> tuple[slice, slice]:
        c0, c1 = sorted((self.c(x0), self.c(x1)))
        r0, r1 = sorted((self.c(y0), self.c(y1)))
        return (slice(max(r0, 0), max(min(r1, self.rows), 0)),
                slice(max(c0, 0), max(min(c1, self.cols), 0)))

    def fill(self, x0: float, y0: float, x1: float, y1: float, label: int) -> None:
        self.labels[self.slices(x0, y0, x1, y1)] = label

    def mark_keep(self, x0: float, y0: float, x1: float, y1: float) -> None:
        self.keep[self.slices(x0, y0, x1, y1)] = True

    def free_rect(self, x0: float, y0: float, x1: float, y1: float) -> bool:
        """Whether the rectangle is all free and outside every keep-out."""
        sl = self.slices(x0, y0, x1, y1)
        return bool(np.all(self.labels[sl] == _FREE) and not np.any(self.keep[sl]))

    def anchor(self, x: float, y: float) -> None:
        """A point the robot must reach; a 0.5 m keep-out around it."""
        self.anchors.append((x, y))
        self.mark_keep(x - 0.5, y - 0.5, x + 0.5, y + 0.5)

    # -------------------------------------------------------------- primitives
    def wall_line(self, xa: float, ya: float, xb: float, yb: float, thickness: float) -> None:
        """An axis-aligned wall from (xa, ya) to (xb, yb) [m] of ``thickness`` [m] centred on the
        line, drawn in pieces 0.3-1.5 m long whose thickness and offset jitter."""
        along_x = abs(yb - ya) < abs(xb - xa)
        t = max(1, int(round(thickness / self.res)))
        if along_x:
            a0, a1 = sorted((self.c(xa), self.c(xb)))
            base = self.c(ya) - t // 2
            limit = self.rows
        else:
            a0, a1 = sorted((self.c(ya), self.c(yb)))
            base = self.c(xa) - t // 2
            limit = self.cols
        a0, a1 = max(a0 - t // 2, 0), min(a1 + (t + 1) // 2, self.cols if along_x else self.rows)
        n = a1 - a0
        if n <= 0:
            return
        # pieces: lengths [cells], each with its own thickness and offset [cells]
        lo, hi = max(1, self.c(0.3)), max(2, self.c(1.5))
        lengths = self.rng.integers(lo, hi, size=n // lo + 1)
        piece = np.repeat(np.arange(len(lengths)), lengths)[:n]
        j = self.jitter
        extra = self.rng.integers(0, j + 1, size=len(lengths))[piece]  # (n,) thicker by
        shift = self.rng.integers(-j, 1, size=len(lengths))[piece]  # (n,) lower face moved by
        along = np.arange(a0, a1)
        for k in range(t + j):
            across = base + shift + k
            ok = (k < t + extra) & (across >= 0) & (across < limit)
            if along_x:
                rr, cc = across[ok], along[ok]
            else:
                rr, cc = along[ok], across[ok]
            self.labels[rr, cc] = _OCC
            self.wall[rr, cc] = True

    def outline(self, x0: float, y0: float, x1: float, y1: float, edge: float = 0.08,
                interior: int = _UNK) -> None:
        """A solid object seen from outside: occupied outline ``edge`` [m] thick, interior
        unknown (racks, pillars) or occupied."""
        self.fill(x0, y0, x1, y1, _OCC)
        e = max(1, int(round(edge / self.res)))
        r, c = self.slices(x0, y0, x1, y1)
        if r.stop - r.start > 2 * e and c.stop - c.start > 2 * e:
            self.labels[r.start + e:r.stop - e, c.start + e:c.stop - e] = interior

    def dot(self, x: float, y: float, size: float = 0.05) -> None:
        """A small occupied square (a leg, a post) of side ``size`` [m], at least one cell."""
        h = max(self.res, size) / 2
        self.fill(x - h, y - h, x + h, y + h, _OCC)

    def passable_cells(self) -> int:
        """Fewest cells across a passage whose best cell keeps the connectivity clearance
        (ROBOT_RADIUS + CORNER_ERROR cells) from both sides: 17 at 0.05 m/cell (0.85 m)."""
        need = ROBOT_RADIUS / self.res + CORNER_ERROR
        n = 1
        while (n - 1 + n % 2) / 2 < need:  # best centre clearance of n cells [cells]
            n += 1
        return n

    def door(self, x: float, y: float, width: float, along_x: bool, thickness: float,
             passable: bool = True) -> None:
        """Open a door of clear ``width`` [m] centred at (x, y) in a wall along x (``along_x``)
        or along y, and keep 1.3 m on both sides of it clear of noise and furniture. A
        ``passable`` door is widened to :meth:`passable_cells` if the resolution rounds it below
        (only at resolutions coarser than 0.05 m/cell)."""
        n = max(1, int(round(width / self.res)))  # clear width [cells]
        if passable:
            n = max(n, self.passable_cells())
        width = n * self.res
        h, d = width / 2, thickness / 2 + 2 * WALL_JITTER + self.res
        a0 = self.c((x if along_x else y) - h)  # first open cell along the wall
        x, y = (a0 * self.res + h, y) if along_x else (x, a0 * self.res + h)
        if along_x:
            box, approach = (x - h, y - d, x + h, y + d), (x - h - 0.2, y - 1.3, x + h + 0.2, y + 1.3)
        else:
            box, approach = (x - d, y - h, x + d, y + h), (x - 1.3, y - h - 0.2, x + 1.3, y + h + 0.2)
        self.mark_keep(*approach)
        rows, cols = self.slices(*box)
        if along_x:
            cols = slice(a0, a0 + n)
        else:
            rows = slice(a0, a0 + n)
        self.labels[rows, cols] = _FREE
        self.openings[rows, cols] = True
        wall_rows, wall_cols = self.slices(x - thickness / 2, y - thickness / 2,
                                           x + thickness / 2, y + thickness / 2)
        for a in (a0 - 1, a0 + n):  # the jambs: one wall cell each side, through the wall
            if along_x and 0 <= a < self.cols:
                self.jambs[wall_rows, a] = True
            elif not along_x and 0 <= a < self.rows:
                self.jambs[a, wall_cols] = True
        self.doors.append(Door(centre=(x, y), width=width, along_x=along_x))

    def breaks(self, xa: float, ya: float, xb: float, yb: float, *, outer_side: int = 0) -> None:
        """A few wall breaks 0.05-0.25 m wide (Poisson, one per 15 m) along a wall line; for an
        outer wall (``outer_side`` = +1 / -1: the outside lies towards larger / smaller
        coordinates) a thin fan of free cells leaks outside."""
        along_x = abs(yb - ya) < abs(xb - xa)
        length = abs(xb - xa) + abs(yb - ya)
        for _ in range(int(self.rng.poisson(length / 15.0))):
            s = self.rng.uniform(0.5, max(0.6, length - 0.5))
            w = max(self.res, self.rng.uniform(0.05, 0.25)) / 2
            if along_x:
                x, y = min(xa, xb) + s, ya
                box = (x - w, y - 0.3, x + w, y + 0.3)
            else:
                x, y = xa, min(ya, yb) + s
                box = (x - 0.3, y - w, x + 0.3, y + w)
            sl = self.slices(*box)
            self.labels[sl] = np.where(self.wall[sl], _FREE, self.labels[sl])
            if outer_side:
                self._fan(x, y, along_x, outer_side)

    def _fan(self, x: float, y: float, along_x: bool, side: int) -> None:
        import cv2

        depth = self.rng.uniform(0.4, 1.2)
        half = self.rng.uniform(0.1, 0.25)
        if along_x:
            pts = [(x, y), (x - half, y + side * depth), (x + half, y + side * depth)]
        else:
            pts = [(x, y), (x + side * depth, y - half), (x + side * depth, y + half)]
        poly = np.array([[self.c(px), self.c(py)] for px, py in pts], dtype=np.int32)
        c0, r0 = np.maximum(poly.min(axis=0), 0)
        c1, r1 = poly.max(axis=0) + 1
        window = self.labels[r0:r1, c0:c1]  # a view: only the fan's bounding box is touched
        fan = np.zeros(window.shape, dtype=np.uint8)
        cv2.fillPoly(fan, [poly - np.array([c0, r0], dtype=np.int32)], 1)
        window[(fan > 0) & (window == _UNK)] = _FREE

    # -------------------------------------------------------------- building shell
    def hull(self, margin_min: float = 0.4, margin_max: float = 1.5,
             margins: tuple[float, float, float, float] | None = None
             ) -> tuple[float, float, float, float, float]:
        """Free building interior with an outer wall, unknown outside. Returns the interior
        (x0, y0, x1, y1) [m] (inner wall faces) and the wall thickness [m]."""
        rng = self.rng
        m = margins if margins is not None else tuple(rng.uniform(margin_min, margin_max, size=4))
        t = rng.uniform(0.15, 0.3)
        x0, y0, x1, y1 = m[0], m[1], self.width - m[2], self.height - m[3]
        self.fill(x0, y0, x1, y1, _FREE)
        h = t / 2
        self.wall_line(x0 + h, y0 + h, x1 - h, y0 + h, t)
        self.wall_line(x0 + h, y1 - h, x1 - h, y1 - h, t)
        self.wall_line(x0 + h, y0 + h, x0 + h, y1 - h, t)
        self.wall_line(x1 - h, y0 + h, x1 - h, y1 - h, t)
        self.breaks(x0 + h, y0 + h, x1 - h, y0 + h, outer_side=-1)
        self.breaks(x0 + h, y1 - h, x1 - h, y1 - h, outer_side=+1)
        self.breaks(x0 + h, y0 + h, x0 + h, y1 - h, outer_side=-1)
        self.breaks(x1 - h, y0 + h, x1 - h, y1 - h, outer_side=+1)
        pad = t + WALL_JITTER + self.res
        return x0 + pad, y0 + pad, x1 - pad, y1 - pad, t

    def transposed(self) -> None:
        """Swap x and y (the kinds lay out their long axis along y)."""
        for name in ("labels", "wall", "keep", "openings", "jambs"):
            setattr(self, name, np.ascontiguousarray(getattr(self, name).T))
        self.rows, self.cols = self.cols, self.rows
        self.width, self.height = self.height, self.width
        self.doors = [Door(centre=d.centre[::-1], width=d.width, along_x=not d.along_x)
                      for d in self.doors]
        self.anchors = [(y, x) for x, y in self.anchors]

    def flipped(self, flip_x: bool, flip_y: bool) -> None:
        """Mirror the drawing (a building's dock or lobby may face either way)."""
        axes = tuple(a for a, f in ((1, flip_x), (0, flip_y)) if f)
        if not axes:
            return
        for name in ("labels", "wall", "keep", "openings", "jambs"):
            setattr(self, name, np.ascontiguousarray(np.flip(getattr(self, name), axis=axes)))

        def fx(x, y):
            return (self.width - x if flip_x else x, self.height - y if flip_y else y)

        self.doors = [Door(centre=fx(*d.centre), width=d.width, along_x=d.along_x)
                      for d in self.doors]
        self.anchors = [fx(x, y) for x, y in self.anchors]


# ------------------------------------------------------------------------------------- kinds
def _long_axis_y(config: MapGenConfig, rng: np.random.Generator) -> tuple[_Canvas, bool]:
    """A canvas whose y is the building's long axis; True if it must be transposed back."""
    transpose = config.width > config.height
    w, h = (config.height, config.width) if transpose else (config.width, config.height)
    return _Canvas(w, h, config.resolution, rng), transpose


def _warehouse(cv: _Canvas) -> None:
    """Dock at the low-y end, shelf rows along y above it (see the module docstring)."""
    rng = cv.rng
    margins = (*rng.uniform(0.4, 1.2, size=2), rng.uniform(0.4, 1.2), rng.uniform(0.4, 1.2))
    margins = (margins[0], rng.uniform(1.0, 1.6), margins[2], margins[3])  # room for an apron
    ix0, iy0, ix1, iy1, t = cv.hull(margins=margins)
    iw, ih = ix1 - ix0, iy1 - iy0

    # 1. dock: open floor along the bottom wall, dock doors with an apron outside
    dock = float(np.clip(rng.uniform(0.15, 0.25) * ih, 3.0, 8.0))
    n_doors = int(np.clip(rng.integers(2, 6), 1, max(1, int(iw // 5))))
    slots = np.linspace(ix0, ix1, n_doors + 2)[1:-1]
    wall_y = margins[1] + t / 2
    for x in slots:
        dw = rng.uniform(2.5, 3.5) if iw >= 10 else rng.uniform(1.2, 2.0)
        cv.fill(x - dw / 2, margins[1] - 0.9 * margins[1], x + dw / 2, wall_y + t, _FREE)
        cv.openings[cv.slices(x - dw / 2, wall_y - t, x + dw / 2, wall_y + t)] = True
        cv.mark_keep(x - dw / 2 - 0.3, margins[1] - 0.9 * margins[1], x + dw / 2 + 0.3, iy0 + 1.5)
    cv.anchor(ix0 + iw / 2, iy0 + dock / 2)

    # 2. shelf zone: side aisles, rows of shelf blocks split by cross aisles
    zx0 = ix0 + rng.uniform(1.5, 3.0)
    zx1 = ix1 - 1.5
    zy0 = iy0 + dock
    zy1 = iy1 - rng.uniform(1.5, 3.0)
    cv.anchor(ix0 + (zx0 - ix0) / 2, (zy0 + zy1) / 2)
    cv.anchor((ix0 + ix1) / 2, (zy1 + iy1) / 2)
    length = zy1 - zy0
    n_blocks = max(1, int(round(length / rng.uniform(10.0, 14.0))))
    cross = [rng.uniform(1.8, 3.0) for _ in range(n_blocks - 1)]
    block = (length - sum(cross)) / n_blocks
    if block < 2.0:
        n_blocks, cross, block = 1, [], length
    ys = []
    y = zy0
    for b in range(n_blocks):
        ys.append((y, y + block))
        y += block + (cross[b] if b < len(cross) else 0.0)
    x = zx0
    single = True  # the first row stands against the side aisle: single-deep
    while True:
        depth = rng.uniform(1.0, 1.3) if single else rng.uniform(1.8, 2.4)
        if x + depth > zx1:
            break
        for b, (ya, yb) in enumerate(ys):
            if rng.random() < 0.08 and not single:  # an empty rack bay: pallets on the floor
                for py in np.arange(ya + 0.3, yb - 1.2, 1.5):
                    if rng.random() < 0.6:
                        cv.outline(x + 0.1, py, x + depth - 0.1, py + 1.0, interior=_OCC)
                continue
            cv.outline(x, ya, x + depth, yb)
            if b < len(ys) - 1:  # anchor in the cross aisle after this block
                cv.anchor(x + depth / 2, (yb + ys[b + 1][0]) / 2)
        single = False
        aisle = rng.uniform(1.0, 2.5) + cv.res  # ragged faces may take a cell each side
        if x + depth + aisle + 1.0 > zx1:
            x += depth
            break
        for ya, yb in ys:
            cv.anchor(x + depth + aisle / 2, (ya + yb) / 2)
        x += depth + aisle
    if zx1 - x >= 0.9:
        cv.anchor((x + ix1) / 2, (zy0 + zy1) / 2)

    # 3. an office room in a dock corner (door onto the dock) and building columns
    if dock >= 4.0 and iw >= 14.0:
        ow, od = rng.uniform(3.0, 4.5), min(dock - 1.5, rng.uniform(2.5, 3.5))
        left = rng.random() < 0.5
        ox0, ox1 = (ix0 - 0.2, ix0 + ow) if left else (ix1 - ow, ix1 + 0.2)
        ti = 0.12
        oy1 = iy0 + od
        cv.wall_line(ox0, oy1, ox1, oy1, ti)
        wx = ox1 if left else ox0
        cv.wall_line(wx, iy0 - 0.2, wx, oy1, ti)
        dwid = rng.uniform(0.9, 1.0)
        cv.door((ox0 + ox1) / 2 + rng.uniform(-0.5, 0.5), oy1, dwid, along_x=True, thickness=ti)
        cv.anchor((ox0 + ox1) / 2, iy0 + od / 2 - 0.1)
    col_sp = rng.uniform(8.0, 12.0)
    for x in np.arange(ix0 + col_sp, ix1 - 2.0, col_sp):
        y = iy0 + dock - 1.0
        if cv.free_rect(x - 0.7, y - 0.7, x + 0.7, y + 0.7):
            cv.outline(x - 0.2, y - 0.2, x + 0.2, y + 0.2, edge=0.1)

    # 4. pallets on the dock floor, clear of doors, anchors and the shelf zone
    for _ in range(int(rng.integers(3, 9))):
        pw, ph = (1.2, 1.0) if rng.random() < 0.5 else (1.0, 1.2)
        px = rng.uniform(ix0 + 0.3, ix1 - 0.3 - pw)
        py = rng.uniform(iy0 + 0.3, iy0 + dock - 1.3 - ph) if dock > 3.0 else iy0 + 0.3
        if cv.free_rect(px - 1.0, py - 1.0, px + pw + 1.0, py + ph + 1.0):
            cv.outline(px, py, px + pw, py + ph, interior=_OCC)


def _office(cv: _Canvas) -> None:
    """Corridors along y, rows of rooms on both sides (see the module docstring)."""
    rng = cv.rng
    ix0, iy0, ix1, iy1, t_out = cv.hull()
    iw, ih = ix1 - ix0, iy1 - iy0
    ti = rng.uniform(0.1, 0.15)  # inner wall thickness [m]

    # 1. a lobby at the low-y end on larger floors; corridors along y
    lobby = float(np.clip(0.12 * ih, 3.0, 7.0)) if ih >= 14 else 0.0
    ry0 = iy0 + lobby  # rooms start here
    if lobby:
        cv.anchor((ix0 + ix1) / 2, iy0 + lobby / 2)
    n_corr = 2 if iw >= 20 else 1
    cw = [rng.uniform(1.5, 2.0) for _ in range(n_corr)]
    # bands of rooms: (x0, x1, door side: +1 door on the high-x face, -1 on the low-x face)
    bands: list[tuple[float, float, int]] = []
    corridors: list[tuple[float, float]] = []
    if n_corr == 1:
        left = rng.uniform(0.4, 0.6) * (iw - cw[0])
        if iw - cw[0] < 2 * 2.5:  # one row of rooms only
            left = iw - cw[0]
        corridors.append((ix0 + left, ix0 + left + cw[0]))
        if left >= 2.5:
            bands.append((ix0, ix0 + left, +1))
        if iw - left - cw[0] >= 2.5:
            bands.append((ix0 + left + cw[0], ix1, -1))
    else:
        outer = [rng.uniform(3.5, 6.0), rng.uniform(3.5, 6.0)]
        c0 = ix0 + outer[0]
        c1 = ix1 - outer[1] - cw[1]
        corridors += [(c0, c0 + cw[0]), (c1, c1 + cw[1])]
        mid = (c0 + cw[0] + c1) / 2
        bands += [(ix0, c0, +1), (c0 + cw[0], mid - ti / 2, -1), (mid + ti / 2, c1, +1),
                  (c1 + cw[1], ix1, -1)]
        cv.wall_line(mid, ry0, mid, iy1, ti)  # between the back-to-back rooms
    # the corridor's far end: rooms across its end when the floor is long
    for ca, cb in corridors:
        cv.anchor((ca + cb) / 2, (ry0 + iy1) / 2)
    cross_y = None
    if n_corr == 2 and not lobby:
        cross_y = (ry0 + iy1) / 2  # join the two corridors

    # 2. rooms along each band
    for bx0, bx1, side in bands:
        face = bx1 if side > 0 else bx0  # the wall on the corridor
        face_x = face - side * ti / 2
        spans = _split(rng, ry0, iy1, 2.8, 6.0, cross_y, 2.0)
        prev_room = None
        for sy0, sy1 in spans:
            if sy0 is None:
                continue
            cv.wall_line(face_x, sy0, face_x, sy1, ti)
            if sy0 > ry0 + 1e-6:
                cv.wall_line(bx0, sy0 + ti / 2, bx1, sy0 + ti / 2, ti)
            if sy1 < iy1 - 1e-6:
                cv.wall_line(bx0, sy1 - ti / 2, bx1, sy1 - ti / 2, ti)
            cv.breaks(face_x, sy0, face_x, sy1)
            room = (bx0 if side > 0 else bx0 + ti, sy0 + ti, bx1 - ti if side > 0 else bx1, sy1 - ti)
            locked = rng.random() < 0.07 and len(spans) > 2
            if locked:
                cv.fill(room[0] + ti, room[1] + ti, room[2] - ti, room[3] - ti, _UNK)
                prev_room = None
                continue
            dw = rng.uniform(0.9, 1.0)
            dy = rng.uniform(room[1] + 0.3 + dw / 2, max(room[1] + 0.31 + dw / 2, room[3] - 0.3 - dw / 2))
            cv.door(face_x, dy, dw, along_x=False, thickness=ti)
            cv.anchor(face_x - side * 1.0, dy)
            if prev_room is not None and rng.random() < 0.3 and bx1 - bx0 > 2.6:
                dw2 = rng.uniform(0.8, 1.0)
                lo, hi = min(bx0, bx1) + 0.4 + dw2 / 2, max(bx0, bx1) - 0.4 - dw2 / 2
                if hi > lo:
                    cv.door(rng.uniform(lo, hi), sy0 + ti / 2, dw2, along_x=True, thickness=ti,
                            passable=False)
            prev_room = room
            _furnish(cv, room, side)
    if cross_y is not None:
        cv.anchor((ix0 + ix1) / 2, cross_y)
    if lobby:  # a reception counter and two columns in the lobby
        cx = rng.uniform(ix0 + 2.0, max(ix0 + 2.1, ix1 - 4.0))
        if cv.free_rect(cx - 0.5, iy0 + 0.8, cx + 2.5, iy0 + 1.9):
            cv.fill(cx, iy0 + 1.0, cx + 2.0, iy0 + 1.6, _OCC)
        for x in (ix0 + iw / 3, ix0 + 2 * iw / 3):
            if cv.free_rect(x - 0.8, ry0 - 1.6, x + 0.8, ry0):
                cv.outline(x - 0.2, ry0 - 1.2, x + 0.2, ry0 - 0.8, edge=0.1)


def _split(rng: np.random.Generator, a: float, b: float, lo: float, hi: float,
           gap_at: float | None, gap: float) -> list[tuple[float, float]]:
    """Split [a, b] into spans of length in [lo, hi] (the last absorbs the rest), leaving out
    ``gap`` metres centred at ``gap_at`` if given."""
    if gap_at is not None:
        return (_split(rng, a, gap_at - gap / 2, lo, hi, None, 0.0)
                + _split(rng, gap_at + gap / 2, b, lo, hi, None, 0.0))
    spans = []
    y = a
    while b - y > 0:
        n = rng.uniform(lo, hi)
        if b - (y + n) < lo:
            n = b - y
        spans.append((y, y + n))
        y += n
    return spans


def _furnish(cv: _Canvas, room: tuple[float, float, float, float], side: int) -> None:
    """Cabinets against the back wall, desks (legs) and chairs (legs) where they fit."""
    rng = cv.rng
    x0, y0, x1, y1 = room
    back = x0 if side > 0 else x1  # wall opposite the door
    for _ in range(int(rng.integers(0, 3))):  # cabinets along the back wall
        d, l = rng.uniform(0.4, 0.6), rng.uniform(0.8, 2.0)
        ya = rng.uniform(y0 + 0.1, max(y0 + 0.11, y1 - l - 0.1))
        xa = back + 0.05 if side > 0 else back - 0.05 - d
        if cv.free_rect(xa, ya, xa + d, ya + l):
            cv.fill(xa, ya, xa + d, ya + l, _OCC)
    for _ in range(int(rng.integers(1, 4))):  # desks: four legs, a chair of five legs nearby
        dw, dd = rng.uniform(1.2, 1.6), rng.uniform(0.6, 0.8)
        xa = rng.uniform(x0 + 0.2, max(x0 + 0.21, x1 - dd - 0.2))
        ya = rng.uniform(y0 + 0.2, max(y0 + 0.21, y1 - dw - 0.2))
        if not cv.free_rect(xa - 0.6, ya - 0.6, xa + dd + 1.0, ya + dw + 0.6):  # chair incl.
            continue
        for lx in (xa, xa + dd):
            for ly in (ya, ya + dw):
                cv.dot(lx, ly)
        cx, cy = xa + dd + 0.4, ya + dw / 2
        for k in range(5):
            a = 2 * math.pi * k / 5
            cv.dot(cx + 0.25 * math.cos(a), cy + 0.25 * math.sin(a), 0.03)


def _depot(cv: _Canvas) -> None:
    """Open floor, pillar grid, shelf-block pairs, pallets, a wall rack row."""
    rng = cv.rng
    ix0, iy0, ix1, iy1, _ = cv.hull()
    ih = iy1 - iy0

    # 1. rack row along the low-x wall (0-0.5 m off it), with an aisle in front
    rack = rng.uniform(0.9, 1.2)
    off = rng.choice([0.0, rng.uniform(0.2, 0.5)])
    fx0 = ix0 + off + rack + rng.uniform(1.5, 2.5)  # floor for the grid starts here
    cv.outline(ix0 + off, iy0 + 1.5, ix0 + off + rack, iy1 - 1.5)
    cv.anchor((ix0 + off + rack + fx0) / 2, (iy0 + iy1) / 2)

    # 2. pillar grid, 6-10 m spacing, at least 2 m off the walls
    sx, sy = rng.uniform(6.0, 10.0, size=2)
    nx, ny = max(1, int((ix1 - fx0 - 4.0) // sx) + 1), max(1, int((ih - 4.0) // sy) + 1)
    px = fx0 + 2.0 + (ix1 - fx0 - 4.0 - (nx - 1) * sx) / 2 + sx * np.arange(nx)
    py = iy0 + 2.0 + (ih - 4.0 - (ny - 1) * sy) / 2 + sy * np.arange(ny)
    ps = rng.uniform(0.4, 0.6)
    for x in px:
        for y in py:
            if x + ps / 2 < ix1 - 1.0:
                cv.outline(x - ps / 2, y - ps / 2, x + ps / 2, y + ps / 2, edge=0.1)
    # 3. bays between pillars (and the walls): shelf pairs, pallet rows or open floor
    ex = np.concatenate([[fx0], px, [ix1]])
    ey = np.concatenate([[iy0], py, [iy1]])
    for i in range(len(ex) - 1):
        for j in range(len(ey) - 1):
            bx0, bx1, by0, by1 = ex[i] + 1.0, ex[i + 1] - 1.0, ey[j] + 1.0, ey[j + 1] - 1.0
            if bx1 - bx0 < 2.0 or by1 - by0 < 2.0:
                continue
            r = rng.random()
            if r < 0.5:
                _shelf_pair(cv, bx0, by0, bx1, by1)
            elif r < 0.7:
                _pallet_row(cv, bx0, by0, bx1, by1)
            else:
                cx, cy = (bx0 + bx1) / 2, (by0 + by1) / 2
                cv.anchor(cx, cy)
                for _ in range(int(rng.integers(0, 4))):  # loose boxes and carts
                    s = rng.uniform(0.4, 1.0)
                    x, y = rng.uniform(bx0, bx1 - s), rng.uniform(by0, by1 - s)
                    if cv.free_rect(x - 0.9, y - 0.9, x + s + 0.9, y + s + 0.9):
                        cv.fill(x, y, x + s, y + s, _OCC)


def _shelf_pair(cv: _Canvas, x0: float, y0: float, x1: float, y1: float) -> None:
    """Two shelf blocks side by side in the bay, their gap narrower (0.25-0.7 m) or wider
    (0.95-1.6 m) than a 0.4-0.8 m robot; the wide gap gets an anchor."""
    rng = cv.rng
    wide = rng.random() < 0.5
    gap = rng.uniform(0.95, 1.6) + 2 * cv.res if wide else rng.uniform(0.25, 0.7)
    bw = min(rng.uniform(1.0, 2.0), (x1 - x0 - gap) / 2)
    bl = min(rng.uniform(2.0, 5.0), y1 - y0)
    if bw < 0.6:
        return
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    cv.outline(cx - gap / 2 - bw, cy - bl / 2, cx - gap / 2, cy + bl / 2)
    cv.outline(cx + gap / 2, cy - bl / 2, cx + gap / 2 + bw, cy + bl / 2)
    if wide:
        cv.anchor(cx, cy)
    else:
        cv.mark_keep(cx - gap / 2, cy - bl / 2, cx + gap / 2, cy + bl / 2)


def _pallet_row(cv: _Canvas, x0: float, y0: float, x1: float, y1: float) -> None:
    """Pallets 1.2 x 1.0 m in a row 0.3 m apart (too narrow for any robot to pass between)."""
    rng = cv.rng
    n = int(rng.integers(2, 5))
    y = rng.uniform(y0, max(y0 + 0.01, y1 - 1.0))
    x = x0
    for _ in range(n):
        if x + 1.2 > x1:
            break
        cv.outline(x, y, x + 1.2, y + 1.0, interior=_OCC)
        x += 1.5


_KINDS = {MapKind.WAREHOUSE: _warehouse, MapKind.OFFICE: _office, MapKind.DEPOT: _depot}


# ------------------------------------------------------------------------------ SLAM artefacts
def _clearance(free: np.ndarray, resolution: float) -> np.ndarray:
    """(H, W) bool free mask -> (H, W) float32 distance [m] from each free cell centre to the
    nearest non-free cell edge, off the map counting as non-free (as maps.signed_distance);
    0 on non-free cells."""
    import cv2

    padded = np.pad(free, 1, constant_values=False).astype(np.uint8)
    d = cv2.distanceTransform(padded, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[1:-1, 1:-1]
    return np.where(free, (d - 0.5) * resolution, 0.0).astype(np.float32)


def _slam_noise(cv: _Canvas) -> None:
    """Ragged obstacle faces, eroded wall faces, speckle; door openings restored."""
    import cv2

    rng = cv.rng
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    free = cv.labels == _FREE
    occ = cv.labels == _OCC
    if cv.res <= WALL_JITTER + 1e-9:  # one grown cell is at most 5 cm
        touches = cv2.dilate(occ.astype(np.uint8), cross) > 0
        grow = free & touches & ~cv.keep & (rng.random(free.shape) < RAGGED_GROW_P)
        cv.labels[grow] = _OCC
    touches_free = cv2.dilate(free.astype(np.uint8), cross) > 0
    erode = cv.wall & touches_free & ~cv.keep & (rng.random(free.shape) < RAGGED_ERODE_P)
    cv.labels[erode] = _FREE
    cv.labels[cv.jambs & ~cv.openings] = _OCC
    cv.labels[cv.openings] = _FREE
    # speckle: isolated occupied / unknown cells where the floor is open
    clear = _clearance(cv.labels == _FREE, cv.res) >= SPECKLE_MIN_CLEARANCE
    candidates = np.flatnonzero(clear & ~cv.keep)
    area = candidates.size * cv.res ** 2  # [m^2]
    n = min(candidates.size, int(rng.poisson(SPECKLE_DENSITY * area)))
    if n:
        picks = rng.choice(candidates, size=n, replace=False)
        kinds = np.where(rng.random(n) < 0.75, _OCC, _UNK).astype(np.uint8)
        cv.labels.flat[picks] = kinds
        pair = (rng.random(n) < 0.3) & ((picks + 1) % cv.cols != 0)  # some are two cells
        cv.labels.flat[picks[pair] + 1] = kinds[pair]


def _connect(labels: np.ndarray, resolution: float) -> int:
    """Guarantees 1 and 2 of the module docstring: turn unknown every free cell outside the
    largest 4-connected free region, and every clearance >= ROBOT_RADIUS cell outside the largest
    4-connected region of such cells; repeat until nothing changes. Returns the cells turned."""
    import cv2

    def drop_minor(mask: np.ndarray) -> int:
        n, lab = cv2.connectedComponents(mask.astype(np.uint8), connectivity=4)
        if n <= 2:
            return 0
        counts = np.bincount(lab.ravel())
        counts[0] = 0
        minor = mask & (lab != int(np.argmax(counts)))
        labels[minor] = _UNK
        return int(minor.sum())

    filled = 0
    for _ in range(8):
        changed = drop_minor(labels == _FREE)
        clear = _clearance(labels == _FREE, resolution)
        changed += drop_minor(clear >= ROBOT_RADIUS + CORNER_ERROR * resolution)
        filled += changed
        if not changed:
            return filled
    raise MapError("map generation did not converge to one connected free region")  # pragma: no cover


# ---------------------------------------------------------------------------------- top level
def generate(config: MapGenConfig) -> GeneratedMap:
    """Draw the building of ``config`` with its SLAM artefacts and the connectivity guarantees
    of the module docstring. Returns the grid and what the generator knows about it."""
    rng = np.random.default_rng([config.seed, list(MapKind).index(config.kind)])
    if config.kind is MapKind.DEPOT:
        cv, transpose = _Canvas(config.width, config.height, config.resolution, rng), False
    else:
        cv, transpose = _long_axis_y(config, rng)
    _KINDS[config.kind](cv)
    _slam_noise(cv)
    if transpose:
        cv.transposed()
    cv.flipped(bool(rng.random() < 0.5), bool(rng.random() < 0.5))
    filled = _connect(cv.labels, config.resolution)
    if filled:
        log.debug("%s: %d free cells turned unknown to keep one connected region",
                  config.name, filled)
    data = np.select([cv.labels == _FREE, cv.labels == _OCC], [FREE, OCCUPIED],
                     UNKNOWN).astype(np.int8)
    grid = GridMap(data=data, resolution=config.resolution, origin=(0.0, 0.0), name=config.name)
    anchors = np.asarray(cv.anchors, dtype=np.float64).reshape(-1, 2)
    return GeneratedMap(grid=grid, config=config, doors=tuple(cv.doors), anchors=anchors,
                        filled_cells=filled)


def generate_map(config: MapGenConfig) -> GridMap:
    """The occupancy grid of :func:`generate` (origin (0, 0) [m], name ``config.name``)."""
    return generate(config).grid
