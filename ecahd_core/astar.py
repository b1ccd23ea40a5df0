"""A* with footprint clearance on the fine occupancy grid: the expert that generates the training
data (paper Sec. IV-A, "A* trajectories between random point pairs") and the classical baseline
(Hart, Nilsson, Raphael 1968; paper ref. [12]).

The robot is reduced to a point with a clearance:

    clearance = footprint circumscribed radius + padding  [m]

which is heading-independent and conservative for any footprint shape. A cell is *traversable*
iff the distance from its centre to the nearest obstacle edge (``maps.signed_distance``, made
exact near the threshold) is >= clearance. The search is 8-connected with an octile heuristic
(motion table ``MOTIONS``); a diagonal step needs both side cells traversable, so a path never
cuts the corner of a blocked cell (and in particular never squeezes between two blocked cells).
With that rule, two cells are connected iff they are 4-connected in the traversable mask, which
the planner uses to reject unreachable goals at once.

The world path starts exactly at the start point, runs through the centres of the cells of the
search, and ends exactly at the goal point. Optional smoothing (string pulling) replaces runs of
cells by straight segments that cross traversable cells only (found exactly, cell by cell) and
whose exact distance to the obstacle squares is >= clearance.

What is guaranteed: every cell centre on the path has clearance (exact distance to the nearest
obstacle square) >= clearance, and so has every shortcut segment. The short 8-connected steps
between neighbouring centres are not checked between their ends: next to a convex obstacle
corner one can come closer by at most c - sqrt(c^2 - res^2 / 2) (6 mm for c = 0.4 m, res = 0.1 m).
The start and goal themselves only need a traversable cell.

Frames and units: map frame, metres; a cell (row, col) is the square
[ox + col*res, ox + (col+1)*res] x [oy + row*res, oy + (row+1)*res], row 0 at the lowest y
(see ``maps.py``). Search costs are counted in cells.
"""
from __future__ import annotations

import array
import heapq
import math
from dataclasses import dataclass

import numpy as np

from ecahd_core.errors import PlanningError
from ecahd_core.footprint import Footprint
from ecahd_core.maps import GridMap, signed_distance

SQRT2 = math.sqrt(2.0)
# drow, dcol, cost [cells]
MOTIONS: tuple[tuple[int, int, float], ...] = (
    (0, 1, 1.0),
    (1, 0, 1.0),
    (0, -1, 1.0),
    (-1, 0, 1.0),
    (1, 1, SQRT2),
    (1, -1, SQRT2),
    (-1, 1, SQRT2),
    (-1, -1, SQRT2),
)
SDF_TOLERANCE = 1e-6  # [m] a clearance that falls short by less than this still counts
CORNER_ERROR = 0.25  # [cells] bound on the overestimate of maps.signed_distance ((sqrt 2 - 1) / 2)
_LOS_CHUNK = 32  # path vertices tested for line of sight per vectorised block when smoothing
COARSE_LANDMARKS = 8  # landmarks of the coarse A*'s ALT heuristic
COARSE_WEIGHT = 1.0  # weighted A* on the coarse graph (1.0: the shortest chain)


@dataclass(frozen=True)
class AStarConfig:
    """A* settings.

    Attributes:
        clearance: required distance [m] from a path cell centre to the nearest obstacle edge;
            usually the footprint's circumscribed radius plus a padding (``for_footprint``).
        smooth: shortcut the cell path by line of sight (string pulling).
    """

    clearance: float
    smooth: bool = True

    def __post_init__(self) -> None:
        if not (isinstance(self.clearance, (int, float)) and math.isfinite(self.clearance)
                and self.clearance >= 0):
            raise PlanningError(f"A* clearance must be a finite number >= 0 m, got {self.clearance!r}")

    @classmethod
    def for_footprint(cls, footprint: Footprint, *, padding: float = 0.0,
                      smooth: bool = True) -> "AStarConfig":
        """Clearance = ``footprint.circumscribed_radius`` + ``padding`` [m]."""
        return cls(clearance=clearance_for_footprint(footprint, padding=padding), smooth=smooth)


def clearance_for_footprint(footprint: Footprint, *, padding: float = 0.0) -> float:
    """Heading-independent clearance [m] of a footprint: circumscribed radius + padding."""
    if not (math.isfinite(padding) and padding >= 0):
        raise PlanningError(f"clearance padding must be a finite number >= 0 m, got {padding!r}")
    return float(footprint.circumscribed_radius + padding)


class AStarPlanner:
    """A* on one map for one clearance; the traversable mask is computed once and reused.

    Attributes:
        grid: the map.
        clearance: required clearance [m].
        smooth: whether :meth:`plan` shortcuts the cell path.
        cell_clearance: (H, W) distance [m] from each cell centre to the nearest obstacle edge
            (``maps.signed_distance``, made exact where it decides traversability).
        mask: (H, W) bool, the cell is traversable (cell_clearance >= clearance).
        components: (H, W) int32 label of each traversable cell's 4-connected region, 0 elsewhere.
    """

    def __init__(self, grid: GridMap, clearance: float, *, smooth: bool = True) -> None:
        import cv2

        config = AStarConfig(clearance=float(clearance), smooth=smooth)  # validates
        self.grid = grid
        self.clearance = config.clearance
        self.smooth = config.smooth
        # Obstacle squares that can be nearest to a free point: occupied cells (everything off
        # the map included) with a free 4-neighbour, on the map padded by `_pad` cells.
        res = grid.resolution
        self._pad = int(math.ceil(self.clearance / res)) + 2
        occ = np.pad(grid.occupied, self._pad, constant_values=True)
        free = ~occ
        free_nb = np.zeros_like(free)
        free_nb[1:] |= free[:-1]
        free_nb[:-1] |= free[1:]
        free_nb[:, 1:] |= free[:, :-1]
        free_nb[:, :-1] |= free[:, 1:]
        self._occupied_padded = occ
        self._boundary_padded = occ & free_nb
        # The signed distance measures from the nearest obstacle *centre* minus half a cell, which
        # overestimates the distance to a square's corner by up to (sqrt(2) - 1) / 2 cells. Cells
        # that close to the threshold get the exact distance to the obstacle squares instead.
        sdf = signed_distance(grid)
        near = (sdf >= self.clearance - SDF_TOLERANCE) & (sdf < self.clearance + CORNER_ERROR * res)
        rows, cols = np.nonzero(near)
        sdf[rows, cols] = self._centre_clearance(rows, cols)
        sdf.setflags(write=False)
        self.cell_clearance = sdf
        mask = sdf >= self.clearance - SDF_TOLERANCE
        mask.setflags(write=False)
        self.mask = mask
        _, labels = cv2.connectedComponents(mask.astype(np.uint8), connectivity=4)
        self.components = labels.astype(np.int32)
        # The search runs on flat indices of the mask padded with one blocked cell all around,
        # so a neighbour index never leaves the array and needs no bounds check.
        self._stride = grid.width + 2
        padded = np.pad(mask, 1, constant_values=False)
        self._traversable: list[bool] = padded.reshape(-1).tolist()
        # (flat offset, cost [cells], flat offsets of the two side cells or None for straight steps)
        self._moves = []
        for drow, dcol, cost in MOTIONS:
            offset = drow * self._stride + dcol
            sides = (drow * self._stride, dcol) if drow and dcol else None
            self._moves.append((offset, cost, sides))

    @classmethod
    def from_config(cls, grid: GridMap, config: AStarConfig) -> "AStarPlanner":
        return cls(grid, config.clearance, smooth=config.smooth)

    # ------------------------------------------------------------------------------ queries
    def check_endpoint(self, xy, what: str = "point") -> tuple[np.ndarray, tuple[int, int]]:
        """Validate a start or goal: on the map, not in an obstacle, in a cell with clearance.

        Returns the point as a float (2,) array [m] and its cell (row, col); raises PlanningError
        naming the problem (for a cell without clearance: by how much it falls short).
        """
        point = self.grid.validate_point(xy, what)
        row, col = (int(v) for v in self.grid.world_to_cell(point))
        have = float(self.cell_clearance[row, col])
        if not self.mask[row, col]:
            raise PlanningError(
                f"{what} ({point[0]:.3f}, {point[1]:.3f}) is too close to an obstacle of map "
                f"{self.grid.name!r}: its cell has clearance {have:.3f} m, "
                f"{self.clearance - have:.3f} m less than the required {self.clearance:.3f} m")
        return point, (row, col)

    def connected(self, a_cell: tuple[int, int], b_cell: tuple[int, int]) -> bool:
        """Whether a path exists between two traversable cells."""
        label = self.components[a_cell]
        return bool(label != 0 and label == self.components[b_cell])

    def plan(self, start_xy, goal_xy) -> np.ndarray:
        """Plan from ``start_xy`` to ``goal_xy`` [m].

        Returns:
            (N, 2) world path [m], N >= 2: exactly ``start_xy``, then cell centres, then exactly
            ``goal_xy`` (consecutive duplicates removed; shortcut if ``smooth``).

        Raises:
            PlanningError: start or goal NaN / off the map / in an obstacle / without clearance,
                or no path between them.
        """
        start, start_cell = self.check_endpoint(start_xy, "start")
        goal, goal_cell = self.check_endpoint(goal_xy, "goal")
        if not self.connected(start_cell, goal_cell):
            raise PlanningError(
                f"no path from start ({start[0]:.3f}, {start[1]:.3f}) to goal "
                f"({goal[0]:.3f}, {goal[1]:.3f}) on map {self.grid.name!r} with clearance "
                f"{self.clearance:.3f} m: they lie in separate regions of the clearance-free space")
        cells = self.search(start_cell, goal_cell)
        rows, cols = np.asarray(cells, dtype=np.int64).T
        path = np.concatenate([start[None], self.grid.cell_to_world(rows, cols), goal[None]])
        keep = np.concatenate([[True], np.any(np.diff(path, axis=0) != 0, axis=1)])
        path = path[keep]
        if len(path) == 1:  # start == goal
            path = np.stack([start, goal])
        if self.smooth:
            path = self.shortcut(path)
        return path

    # ------------------------------------------------------------------------------- search
    def search(self, start_cell: tuple[int, int], goal_cell: tuple[int, int]) -> list[tuple[int, int]]:
        """A* over traversable cells. Returns the cells (row, col) from start to goal inclusive;
        raises PlanningError if the goal cannot be reached."""
        stride = self._stride
        traversable = self._traversable
        start = (start_cell[0] + 1) * stride + start_cell[1] + 1
        goal = (goal_cell[0] + 1) * stride + goal_cell[1] + 1
        goal_row, goal_col = divmod(goal, stride)

        def octile(node: int) -> float:  # [cells], admissible and consistent
            row, col = divmod(node, stride)
            dr, dc = abs(row - goal_row), abs(col - goal_col)
            return (dr + dc) + (SQRT2 - 2.0) * min(dr, dc)

        g = {start: 0.0}  # cost from the start [cells]
        parent = {start: start}
        closed = set()
        heap = [(octile(start), 0.0, start)]  # (f = g + h, h, node): ties go to the node nearer the goal
        while heap:
            _, _, node = heapq.heappop(heap)
            if node in closed:
                continue
            if node == goal:
                break
            closed.add(node)
            g_node = g[node]
            for offset, cost, sides in self._moves:
                nb = node + offset
                if not traversable[nb] or nb in closed:
                    continue
                if sides is not None and not (traversable[node + sides[0]]
                                              and traversable[node + sides[1]]):
                    continue  # diagonal step would cut the corner of a blocked cell
                g_nb = g_node + cost
                if g_nb < g.get(nb, math.inf):
                    g[nb] = g_nb
                    parent[nb] = node
                    h = octile(nb)
                    heapq.heappush(heap, (g_nb + h, h, nb))
        else:
            raise PlanningError(f"A* found no path between cells {start_cell} and {goal_cell} "
                                f"on map {self.grid.name!r} with clearance {self.clearance:.3f} m")
        return _unwind(parent, start, goal, stride)

    # ---------------------------------------------------------------------------- smoothing
    def shortcut(self, path: np.ndarray) -> np.ndarray:
        """String pulling: from each kept vertex jump to the furthest following vertex that is in
        line of sight, extending while consecutive vertices stay visible.

        path: (N, 2) [m] whose consecutive vertices see each other -> (M, 2), M <= N, a subset of
        the vertices with the same first and last point.
        """
        N = len(path)
        kept = [0]
        anchor = 0
        while anchor < N - 1:
            furthest = anchor + 1  # the next vertex is always visible
            while furthest < N - 1:
                candidates = path[furthest + 1:min(N, furthest + 1 + _LOS_CHUNK)]
                visible = self.visible(path[anchor], candidates)
                blocked = np.flatnonzero(~visible)
                if len(blocked):
                    furthest += int(blocked[0])
                    break
                furthest += len(candidates)
            # Crossing traversable cells does not bound the clearance between cell centres: keep
            # only a shortcut whose exact clearance holds, else fall back towards the cell path.
            while (furthest > anchor + 1 and self.segment_clearance(path[anchor], path[furthest])
                   < self.clearance - SDF_TOLERANCE):
                furthest -= 1
            kept.append(furthest)
            anchor = furthest
        return path[kept]

    def visible(self, a: np.ndarray, bs: np.ndarray) -> np.ndarray:
        """Line of sight: whether each segment a -> b touches traversable cells only.

        a: (2,) [m], bs: (M, 2) [m] -> (M,) bool. Exact: the cells a segment crosses are those
        that contain the midpoints between its consecutive grid-line crossings; where it passes
        through a grid corner, all four cells around the corner count as touched (the rule that
        keeps A*'s diagonal steps off blocked corners).
        """
        return self.visible_segments(a, bs)

    def visible_segments(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """:meth:`visible` for M segments a[i] -> b[i]: a (2,) or (M, 2) [m], b (M, 2) [m] ->
        (M,) bool."""
        res = self.grid.resolution
        origin = np.asarray(self.grid.origin)
        p = (np.asarray(a, dtype=np.float64) - origin) / res  # (2,) or (M, 2) [cells]
        q = (np.asarray(b, dtype=np.float64) - origin) / res  # (M, 2) [cells]
        p_col = p[..., None, :]  # (1, 2) or (M, 1, 2): one start per segment
        d = q - p  # (M, 2)
        # 1. parameters t in [0, 1] of the end points and of the crossings of the grid lines
        #    x = k and y = k; NaN pads segments that cross fewer lines than others
        ts = [np.zeros((len(q), 1)), np.ones((len(q), 1))]
        for axis in (0, 1):
            lo = np.floor(np.minimum(p[..., axis], q[:, axis]))
            hi = np.floor(np.maximum(p[..., axis], q[:, axis]))
            n = int(np.max(hi - lo, initial=0))
            if n == 0:
                continue
            lines = lo[:, None] + np.arange(1, n + 1)  # (M, n) grid lines between the end cells
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.clip((lines - p_col[..., axis]) / d[:, axis:axis + 1], 0.0, 1.0)
            ts.append(np.where(lines <= hi[:, None], t, np.nan))
        t = np.sort(np.concatenate(ts, axis=1), axis=1)  # (M, K), NaN last
        # 2. one probe point per crossed cell (interval midpoint); a zero-length interval is a
        #    pass through a grid corner and probes the four cells around it
        t_lo, t_hi = t[:, :-1], t[:, 1:]  # (M, K-1)
        real = np.isfinite(t_hi)
        corner = real & (t_hi - t_lo < 1e-9)
        mid = np.where(real, 0.5 * (t_lo + t_hi), 0.0)
        pts = p_col + mid[..., None] * d[:, None, :]  # (M, K-1, 2) [cells]
        # 3. every probe must lie in a traversable cell on the map
        ok = self._in_mask(pts) | ~real  # (M, K-1)
        if corner.any():
            spread = np.array([[-0.5, -0.5], [-0.5, 0.5], [0.5, -0.5], [0.5, 0.5]])  # (4, 2)
            ok[corner] &= np.all(self._in_mask(pts[corner][:, None, :] + spread), axis=1)
        return np.all(ok, axis=1)

    def _in_mask(self, pts: np.ndarray) -> np.ndarray:
        """Whether points (..., 2) [cells, x then y] lie in traversable cells on the map -> (...)."""
        col = np.floor(pts[..., 0]).astype(np.int64)
        row = np.floor(pts[..., 1]).astype(np.int64)
        inside = (row >= 0) & (row < self.grid.height) & (col >= 0) & (col < self.grid.width)
        return inside & self.mask[np.clip(row, 0, self.grid.height - 1),
                                  np.clip(col, 0, self.grid.width - 1)]

    # ---------------------------------------------------------------------- exact clearance
    def _centre_clearance(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Exact distance [m] from the centres of cells (rows, cols) (K,) to the nearest obstacle
        square, capped at the padding width w [cells] -> (K,).

        The centre-to-square distance of a square (dr, dc) cells away is hypot(g(dr), g(dc))
        with g(0) = 0, g(k) = |k| - 0.5, increasing in each gap. A row pass gives every cell the
        gap to the nearest obstacle square of its own row (:func:`_row_gap`); the column pass
        takes the minimum of hypot(g(dr), that) over the 2w + 1 rows round each queried cell
        only: O(H W + K w) instead of a (K, (2w + 1)^2) window (the whole build 1.25 -> 0.24 s
        on a 2000 x 2000 map, ``scripts/compare_astar_build.py``), and the same numbers bit
        for bit (a test compares with the window)."""
        w = self._pad
        if len(rows) == 0:
            return np.zeros(0)
        row_gap = _row_gap(self._occupied_padded, w)
        best = np.full(len(rows), float(w))
        c = cols + w
        for dr in range(-w, w + 1):
            np.minimum(best, np.hypot(max(abs(dr) - 0.5, 0.0), row_gap[rows + w + dr, c]),
                       out=best)
        return best * self.grid.resolution

    def segment_clearance(self, a, b) -> float:
        """Exact distance [m] from the segment a -> b (points [m]) to the nearest obstacle square
        (everything off the map counts as obstacle), searched within clearance + 2 cells of the
        segment; a segment that enters an obstacle square may get a positive value, so test
        :meth:`visible` first. Use a == b for a point."""
        res = self.grid.resolution
        origin = np.asarray(self.grid.origin)
        a = (np.asarray(a, dtype=np.float64) - origin) / res  # [cells]
        b = (np.asarray(b, dtype=np.float64) - origin) / res
        # Boundary squares in the segment's bounding box grown by w - 1 cells: any square further
        # out is more than w - 1 > clearance / res cells away. Padded index = cell index + w.
        w = self._pad
        col_lo, row_lo = np.floor(np.minimum(a, b)).astype(np.int64) + 1  # -(w - 1) + w
        col_hi, row_hi = np.floor(np.maximum(a, b)).astype(np.int64) + 2 * w  # +(w - 1) + w + 1
        col_lo, row_lo = max(col_lo, 0), max(row_lo, 0)
        rows, cols = np.nonzero(self._boundary_padded[row_lo:row_hi, col_lo:col_hi])
        if len(rows) == 0:
            return (w - 1) * res
        lower = np.stack([cols + col_lo - w, rows + row_lo - w], axis=1).astype(np.float64)  # (K, 2)
        # 1. segment end points to the squares [lower, lower + 1]
        ends = np.stack([a, b])  # (2, 2)
        gap = np.maximum(np.maximum(lower[None] - ends[:, None], ends[:, None] - lower[None] - 1.0), 0.0)
        d_ends = np.linalg.norm(gap, axis=-1).min()  # (2, K) -> scalar
        # 2. square corners to the segment
        corners = (lower[:, None] + np.array([[0, 0], [1, 0], [0, 1], [1, 1]])).reshape(-1, 2)
        ab = b - a
        t = np.clip((corners - a) @ ab / max(float(ab @ ab), 1e-18), 0.0, 1.0)
        d_corners = np.linalg.norm(corners - (a + t[:, None] * ab), axis=1).min()
        return float(min(d_ends, d_corners)) * res

    def point_clearance(self, xy) -> float:
        """Exact distance [m] from a point to the nearest obstacle square (see
        :meth:`segment_clearance`)."""
        return self.segment_clearance(xy, xy)

    def path_is_clear(self, path: np.ndarray) -> bool:
        """Whether every segment of a (N, 2) path [m] crosses traversable cells only."""
        path = np.asarray(path, dtype=np.float64)
        return all(bool(self.visible(path[i], path[i + 1:i + 2])[0]) for i in range(len(path) - 1))


class CoarseAStarPlanner:
    """A* for large maps: a search on blocks of fine cells, then the path made exact on the fine
    grid. Same contract and guarantees as :meth:`AStarPlanner.plan` (whose traversable mask,
    checks and string pulling it reuses); the paths are near-shortest instead of shortest.

    1. Coarse graph (built once): the fine traversable mask is cut into square blocks of
       ``block`` x ``block`` cells, and each 4-connected piece of traversable cells inside a
       block is one node, represented by its cell nearest to the piece's centroid. Two nodes are
       joined if a fine cell of one is 4-adjacent to a fine cell of the other (or, across a block
       corner, diagonal with both side cells traversable); the edge cost is the distance between
       the representatives. A node's cells are connected inside the node, so two fine cells are
       connected iff their nodes are: a narrow door (a band of traversable cells narrower than a
       block) is never lost, as it would be by a mask of "wholly traversable" blocks.
    2. Coarse A* (Euclidean heuristic, consistent) gives a chain of nodes from the start's to the
       goal's.
    3. Fine path: start, the representatives of the chain's inner nodes, goal. Each consecutive
       pair is joined directly if the segment crosses traversable cells only and keeps the exact
       clearance (:meth:`AStarPlanner.segment_clearance`), else by fine A* restricted to the cells
       of the two nodes (connected by construction). Representative-to-representative joins are
       cached.
    4. String pulling (:meth:`AStarPlanner.shortcut`).

    Every vertex is thus the start, the goal or a traversable cell centre, and every segment is a
    fine 8-connected step or a segment with the exact clearance: what :class:`AStarPlanner`
    guarantees. What is lost is optimality: the chain is shortest for the representatives, not
    for the fine grid. Measured against :class:`AStarPlanner` with 0.3 m blocks and clearance
    0.4 m on generated maps (``ecahd map generate``, seed 1; pairs seeded (99, i)): a 30 x 15 m
    depot at 0.05 m/cell, 50 pairs: 1.000x the length on average, at worst 1.02x; a 30 x 50 m
    warehouse at 0.03 m/cell, 30 pairs: 1.004x, at worst 1.06x (another way round a shelf
    block); a 60 x 60 m office at 0.03 m/cell, 12 pairs of 78 m on average: 1.000x, at worst
    1.01x; every path collision-free by ``collision.check_collision``. CPU time per pair:
    3 / 10 / 29 ms on that depot / warehouse / a 60 x 60 m office at 0.03 m/cell, against
    40 / 420 / 6000 ms for :class:`AStarPlanner`.

    Attributes:
        fine: the :class:`AStarPlanner` whose mask, clearance and checks are used.
        block: block side [cells].
        labels: (H, W) int32 node of each traversable fine cell, -1 elsewhere.
        num_nodes: number of coarse nodes.
    """

    def __init__(self, fine: AStarPlanner, block: int, *,
                 landmarks: int = COARSE_LANDMARKS) -> None:
        import cv2

        if isinstance(block, bool) or not isinstance(block, (int, np.integer)) or block < 1:
            raise PlanningError(f"coarse A* block must be an integer >= 1 cell, got {block!r}")
        self.fine = fine
        self.grid = fine.grid
        self.clearance = fine.clearance
        self.block = B = int(block)
        mask = fine.mask
        H, W = mask.shape
        nbr, nbc = -(-H // B), -(-W // B)
        # 1. the pieces of every block at once: blocks laid out with one blocked row and column
        #    between them, so that one labelling never joins cells of different blocks
        padded = np.zeros((nbr * B, nbc * B), dtype=bool)
        padded[:H, :W] = mask
        spaced = np.zeros((nbr, B + 1, nbc, B + 1), dtype=np.uint8)
        spaced[:, :B, :, :B] = padded.reshape(nbr, B, nbc, B)
        n, lab = cv2.connectedComponents(spaced.reshape(nbr * (B + 1), nbc * (B + 1)),
                                         connectivity=4)
        labels = lab.reshape(nbr, B + 1, nbc, B + 1)[:, :B, :, :B].reshape(nbr * B, nbc * B)
        labels = np.ascontiguousarray(labels[:H, :W], dtype=np.int32) - 1  # (H, W), -1: none
        labels.setflags(write=False)
        self.labels = labels
        N = self.num_nodes = n - 1
        # 2. representatives: each node's cell nearest to its centroid (row-major on ties)
        rows, cols = np.nonzero(labels >= 0)
        ids = labels[rows, cols]
        count = np.bincount(ids, minlength=N)
        c_row = np.bincount(ids, rows, minlength=N) / count
        c_col = np.bincount(ids, cols, minlength=N) / count
        d2 = (rows - c_row[ids]) ** 2 + (cols - c_col[ids]) ** 2
        nearest = np.full(N, np.inf)
        np.minimum.at(nearest, ids, d2)
        at = np.flatnonzero(d2 == nearest[ids])  # cells at their node's least d2, row-major
        first = np.full(N, len(ids), dtype=np.int64)
        np.minimum.at(first, ids[at], at)  # the first of them (what a stable sort would take)
        self.rep_cells = np.stack([rows[first], cols[first]], axis=1)  # (N, 2) row, col
        self.rep_xy = self.grid.cell_to_world(rows[first], cols[first])  # (N, 2) [m]
        # 3. edges across block borders
        pairs = []  # (K, 2) node pairs, in runs along each border
        cs = np.arange(B - 1, W - 1, B)  # last column of a block with a block to its right
        rs = np.arange(B - 1, H - 1, B)
        for a, b in ((labels[:, cs].T, labels[:, cs + 1].T), (labels[rs, :], labels[rs + 1, :])):
            ok = (a >= 0) & (b >= 0)
            pairs.append(np.stack([a[ok], b[ok]], axis=1))
        r, c = np.meshgrid(rs, cs, indexing="ij")
        corner = mask[r, c] & mask[r + 1, c + 1] & mask[r, c + 1] & mask[r + 1, c]
        r, c = r[corner], c[corner]
        pairs.append(np.stack([labels[r, c], labels[r + 1, c + 1]], axis=1))
        pairs.append(np.stack([labels[r, c + 1], labels[r + 1, c]], axis=1))
        e = np.concatenate(pairs).astype(np.int64)
        run = np.concatenate([[True], np.any(e[1:] != e[:-1], axis=1)]) if len(e) else []
        e = e[run]  # a border's cells repeat the same pair: drop the runs before sorting
        e = np.unique(np.concatenate([e[:, 0] * N + e[:, 1], e[:, 1] * N + e[:, 0]]))
        src, dst = e // N, e % N  # sorted by source
        cost = np.hypot(*(self.rep_cells[src] - self.rep_cells[dst]).T)  # [cells]
        self._indptr: list[int] = np.searchsorted(src, np.arange(N + 1)).tolist()
        self._dst: list[int] = dst.tolist()
        self._cost: list[float] = cost.tolist()
        # node of each cell of the fine planner's padded flat layout (-1 off the mask)
        self._label_flat = array.array("i", np.pad(labels, 1, constant_values=-1).tobytes())
        self._joins: dict[tuple[int, int], list] = {}  # (node, node) -> inner points [m]
        self._landmark_dist = self._landmarks(landmarks)  # (K, N) [cells]

    def _dijkstra(self, source: int) -> np.ndarray:
        """(N,) cost [cells] from ``source`` to every node over the coarse graph, inf if none."""
        indptr, dst, cost = self._indptr, self._dst, self._cost
        dist = [math.inf] * self.num_nodes
        dist[source] = 0.0
        heap = [(0.0, source)]
        while heap:
            d, node = heapq.heappop(heap)
            if d > dist[node]:
                continue
            for j in range(indptr[node], indptr[node + 1]):
                nb = dst[j]
                d_nb = d + cost[j]
                if d_nb < dist[nb]:
                    dist[nb] = d_nb
                    heapq.heappush(heap, (d_nb, nb))
        return np.asarray(dist)

    def _landmarks(self, k: int) -> np.ndarray:
        """Costs from ``k`` landmarks (farthest-point picks in the largest connected region of
        the coarse graph, from its lowest node on) to every node: (K, N) [cells]. Used by the ALT
        heuristic max_L |d(L, goal) - d(L, n)| (Goldberg & Harrekson 2005), which is consistent."""
        if self.num_nodes == 0 or k == 0:
            return np.zeros((0, self.num_nodes))
        comp = self.fine.components[tuple(self.rep_cells.T)]  # (N,) region of each node
        largest = np.bincount(comp).argmax()
        far = np.full(self.num_nodes, -1.0)
        far[comp == largest] = math.inf
        dists = []
        node = int(np.flatnonzero(comp == largest)[0])
        for _ in range(k):
            d = self._dijkstra(node)
            dists.append(d)
            far = np.minimum(far, np.where(np.isfinite(d), d, -1.0))
            node = int(np.argmax(far))
            if far[node] <= 0:
                break
        return np.stack(dists)

    @classmethod
    def for_resolution(cls, fine: AStarPlanner, block_size: float, *,
                       landmarks: int = COARSE_LANDMARKS) -> "CoarseAStarPlanner":
        """Blocks of about ``block_size`` [m] (at least one cell)."""
        return cls(fine, max(1, int(round(block_size / fine.grid.resolution))),
                   landmarks=landmarks)

    @property
    def mask(self) -> np.ndarray:
        return self.fine.mask

    @property
    def components(self) -> np.ndarray:
        return self.fine.components

    def __getattr__(self, name: str):
        """Every other query (``check_endpoint``, ``point_clearance``, ``cell_clearance``, ...)
        is the fine planner's: a coarse planner stands in wherever an AStarPlanner is used."""
        if name.startswith("__") or name == "fine":
            raise AttributeError(name)
        return getattr(self.fine, name)

    def plan(self, start_xy, goal_xy) -> np.ndarray:
        """Plan from ``start_xy`` to ``goal_xy`` [m]: (N, 2) world path [m], N >= 2, exactly the
        start first and the goal last (see the class docstring). Raises PlanningError as
        :meth:`AStarPlanner.plan`."""
        fine = self.fine
        start, start_cell = fine.check_endpoint(start_xy, "start")
        goal, goal_cell = fine.check_endpoint(goal_xy, "goal")
        if not fine.connected(start_cell, goal_cell):
            raise PlanningError(
                f"no path from start ({start[0]:.3f}, {start[1]:.3f}) to goal "
                f"({goal[0]:.3f}, {goal[1]:.3f}) on map {self.grid.name!r} with clearance "
                f"{self.clearance:.3f} m: they lie in separate regions of the clearance-free space")
        chain = self.search(int(self.labels[start_cell]), int(self.labels[goal_cell]))
        pts = [start, *self.rep_xy[chain[1:-1]], goal]
        nodes = chain if len(chain) > 1 else chain * 2  # nodes[k]: the node of pts[k]
        last = len(pts) - 2
        # 1. which consecutive points see each other with the clearance (cached for reps)
        direct = [None] * (last + 1)
        todo = []
        for k in range(last + 1):
            if 0 < k < last and (nodes[k], nodes[k + 1]) in self._joins:
                direct[k] = False  # use the cached join
            else:
                todo.append(k)
        if todo:
            a = np.array([pts[k] for k in todo])
            b = np.array([pts[k + 1] for k in todo])
            seen = self.fine.visible_segments(a, b)
            for k, ok in zip(todo, seen):
                direct[k] = bool(ok) and (fine.segment_clearance(pts[k], pts[k + 1])
                                          >= self.clearance - SDF_TOLERANCE)
        # 2. the fine path: direct segments, cached or new restricted searches
        out = [start]
        for k in range(last + 1):
            key = (nodes[k], nodes[k + 1])
            if direct[k]:
                inner = []
            elif 0 < k < last and key in self._joins:
                inner = self._joins[key]
            else:
                a_cell = tuple(int(v) for v in self.grid.world_to_cell(pts[k]))
                b_cell = tuple(int(v) for v in self.grid.world_to_cell(pts[k + 1]))
                cells = self.search_within(a_cell, b_cell, set(key))
                rows, cols = np.asarray(cells, dtype=np.int64).T
                inner = list(self.grid.cell_to_world(rows, cols))
            if 0 < k < last:
                self._joins[key] = inner
            out.extend(inner)
            out.append(pts[k + 1])
        path = np.asarray(out, dtype=np.float64)
        keep = np.concatenate([[True], np.any(np.diff(path, axis=0) != 0, axis=1)])
        path = path[keep]
        if len(path) == 1:  # start == goal
            path = np.stack([start, goal])
        if fine.smooth:
            path = fine.shortcut(path)
        return path

    def search(self, start: int, goal: int) -> list[int]:
        """A* over coarse nodes; returns the nodes from ``start`` to ``goal`` inclusive."""
        indptr, dst, cost = self._indptr, self._dst, self._cost
        # heuristic of every node [cells]: Euclidean between representatives, or ALT if larger
        heuristic = np.hypot(*(self.rep_cells - self.rep_cells[goal]).T)
        L = self._landmark_dist
        if len(L) and np.isfinite(L[0, goal]):
            with np.errstate(invalid="ignore"):
                alt = np.abs(L[:, goal:goal + 1] - L).max(axis=0)
            heuristic = np.fmax(heuristic, alt)  # NaN (other regions) -> Euclidean
        h_of: list[float] = (COARSE_WEIGHT * heuristic).tolist()
        g = {start: 0.0}
        parent = {start: start}
        closed = set()
        heap = [(h_of[start], h_of[start], start)]
        while heap:
            _, _, node = heapq.heappop(heap)
            if node in closed:
                continue
            if node == goal:
                break
            closed.add(node)
            g_node = g[node]
            for j in range(indptr[node], indptr[node + 1]):
                nb = dst[j]
                if nb in closed:
                    continue
                g_nb = g_node + cost[j]
                if g_nb < g.get(nb, math.inf):
                    g[nb] = g_nb
                    parent[nb] = node
                    h = h_of[nb]
                    heapq.heappush(heap, (g_nb + h, h, nb))
        else:
            raise PlanningError(f"coarse A* found no path between nodes {start} and {goal} on map "
                                f"{self.grid.name!r} with clearance {self.clearance:.3f} m")
        chain = [goal]
        while chain[-1] != start:
            chain.append(parent[chain[-1]])
        return chain[::-1]

    def search_within(self, start_cell: tuple[int, int], goal_cell: tuple[int, int],
                      nodes: set[int]) -> list[tuple[int, int]]:
        """Fine A* (the moves and corner rule of :meth:`AStarPlanner.search`) through the cells of
        ``nodes`` only; returns the cells (row, col) from start to goal inclusive."""
        fine = self.fine
        stride = fine._stride
        traversable = fine._traversable
        label = self._label_flat
        start = (start_cell[0] + 1) * stride + start_cell[1] + 1
        goal = (goal_cell[0] + 1) * stride + goal_cell[1] + 1
        goal_row, goal_col = divmod(goal, stride)
        g = {start: 0.0}
        parent = {start: start}
        closed = set()
        heap = [(0.0, 0.0, start)]
        while heap:
            _, _, node = heapq.heappop(heap)
            if node in closed:
                continue
            if node == goal:
                break
            closed.add(node)
            g_node = g[node]
            for offset, cost, sides in fine._moves:
                nb = node + offset
                if label[nb] not in nodes or nb in closed:
                    continue
                if sides is not None and not (traversable[node + sides[0]]
                                              and traversable[node + sides[1]]):
                    continue
                g_nb = g_node + cost
                if g_nb < g.get(nb, math.inf):
                    g[nb] = g_nb
                    parent[nb] = node
                    row, col = divmod(nb, stride)
                    dr, dc = abs(row - goal_row), abs(col - goal_col)
                    h = (dr + dc) + (SQRT2 - 2.0) * min(dr, dc)
                    heapq.heappush(heap, (g_nb + h, h, nb))
        else:
            raise PlanningError(f"A* found no path between cells {start_cell} and {goal_cell} "
                                f"within coarse nodes {sorted(nodes)} on map {self.grid.name!r}")
        return _unwind(parent, start, goal, stride)


# ------------------------------------------------------------------------------- helpers
def _row_gap(occupied: np.ndarray, cap: int) -> np.ndarray:
    """(H, W) bool -> (H, W) float64: for each cell, g(k) with k [cells] the distance along its
    row to the nearest occupied cell (g(0) = 0, g(k) = k - 0.5), at most ``cap``."""
    H, W = occupied.shape
    dt = np.int16 if W + 2 * cap + 4 < np.iinfo(np.int16).max else np.int32
    col = np.arange(W, dtype=dt)
    far = W + cap + 1
    left = np.where(occupied, col, dt(-far))  # the last occupied column at or left of each cell
    np.maximum.accumulate(left, axis=1, out=left)
    right = np.where(occupied[:, ::-1], col[::-1], dt(W + far))  # ... at or right, reversed
    np.minimum.accumulate(right, axis=1, out=right)
    np.subtract(col, left, out=left)
    np.subtract(right[:, ::-1], col, out=right[:, ::-1])
    np.minimum(left, right[:, ::-1], out=left)
    np.minimum(left, cap + 1, out=left)
    k = left.astype(np.float64)
    k -= 0.5
    np.maximum(k, 0.0, out=k)
    return np.minimum(k, float(cap), out=k)


def _unwind(parent: dict, start: int, goal: int, stride: int) -> list[tuple[int, int]]:
    """The (row, col) cells from ``start`` to ``goal`` along ``parent`` links of flat indices
    into a grid padded by one cell (``stride`` = its width)."""
    cells = []
    node = goal
    while True:
        row, col = divmod(node, stride)
        cells.append((row - 1, col - 1))
        if node == start:
            break
        node = parent[node]
    return cells[::-1]


def astar_path(grid: GridMap, start_xy, goal_xy, clearance: float, *, smooth: bool = True) -> np.ndarray:
    """One A* query: (N, 2) world path [m] from exactly ``start_xy`` to exactly ``goal_xy``.

    Builds the traversable mask each call; for many queries on one map use :class:`AStarPlanner`.
    Raises PlanningError (see :meth:`AStarPlanner.plan`).
    """
    return AStarPlanner(grid, clearance, smooth=smooth).plan(start_xy, goal_xy)


# maps above this many cells get the coarse search (CoarseAStarPlanner, blocks of
# COARSE_BLOCK_SIZE): on a 60 x 60 m office at 0.03 m/cell exact A* takes seconds per path
COARSE_ABOVE_CELLS = 50_000
COARSE_BLOCK_SIZE = 0.3  # [m]


def planner_for(grid: GridMap, clearance: float, *, smooth: bool = True,
                landmarks: int = COARSE_LANDMARKS):
    """The A* a caller should plan with on ``grid``: :class:`AStarPlanner` on maps of at most
    ``COARSE_ABOVE_CELLS`` cells, else a :class:`CoarseAStarPlanner` over it (same contract and
    checks, paths within about 1% of the shortest; its graph takes about a second to build on a
    4 M-cell map, once: ``scripts/compare_astar_build.py``). ``landmarks``: of the coarse
    search's ALT heuristic; each costs a Dijkstra over the coarse graph at build time, so a
    planner for one query (a detour on a grid that changes) wants 0."""
    fine = AStarPlanner(grid, clearance, smooth=smooth)
    if grid.height * grid.width <= COARSE_ABOVE_CELLS:
        return fine
    return CoarseAStarPlanner.for_resolution(fine, COARSE_BLOCK_SIZE, landmarks=landmarks)


def plan_from_pose(planner: AStarPlanner, pose_xy, goal_xy) -> np.ndarray:
    """A* from a robot's pose, which (unlike a benchmark start) may lie in a cell without the
    clearance, e.g. after the robot brushed a wall: the search then starts from the nearest
    traversable cell centre of the goal's region and the path is prefixed with the pose.

    Returns (N, 2) [m], exactly ``pose_xy`` first and ``goal_xy`` last. Raises PlanningError for
    a goal without clearance or unreachable, and a pose off the map or in an obstacle.
    """
    pose = planner.grid.validate_point(pose_xy, "robot pose")
    goal, goal_cell = planner.check_endpoint(goal_xy, "goal")
    row, col = (int(v) for v in planner.grid.world_to_cell(pose))
    if planner.mask[row, col]:
        return planner.plan(pose, goal)
    rows, cols = np.nonzero(planner.components == planner.components[goal_cell])
    centres = planner.grid.cell_to_world(rows, cols)  # (K, 2) traversable, the goal's region
    entry = centres[int(np.argmin(np.linalg.norm(centres - pose, axis=1)))]
    return np.concatenate([pose[None], planner.plan(entry, goal)])


def path_length(path) -> float:
    """Sum of segment lengths [m] of a (N, 2) path; 0.0 for fewer than two points."""
    pts = np.asarray(path, dtype=np.float64)
    if len(pts) < 2:
        return 0.0
    return float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))


def sample_free_points(rng: np.random.Generator, mask: np.ndarray, grid: GridMap, n: int, *,
                       jitter: bool = True) -> np.ndarray:
    """Uniformly random points in the cells where ``mask`` (H, W) is True -> (n, 2) [m].

    Each point lies in a uniformly chosen mask cell: at its centre, or with ``jitter`` uniformly
    inside it (kept 1 % away from the cell edges so the point maps back to the same cell).
    Raises PlanningError if the mask has no True cell.
    """
    rows, cols = np.nonzero(mask)
    if len(rows) == 0:
        raise PlanningError(f"map {grid.name!r} has no cell to sample from (the clearance-free "
                            "space is empty)")
    pick = rng.integers(0, len(rows), size=n)
    centres = grid.cell_to_world(rows[pick], cols[pick])  # (n, 2)
    if not jitter:
        return centres
    return centres + 0.98 * (rng.random((n, 2)) - 0.5) * grid.resolution


def sample_free_point(rng: np.random.Generator, mask: np.ndarray, grid: GridMap, *,
                      jitter: bool = True) -> np.ndarray:
    """One point of :func:`sample_free_points` -> (2,) [m]."""
    return sample_free_points(rng, mask, grid, 1, jitter=jitter)[0]
