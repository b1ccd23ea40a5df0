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
        cells = []
        node = goal
        while True:
            row, col = divmod(node, stride)
            cells.append((row - 1, col - 1))
            if node == start:
                break
            node = parent[node]
        return cells[::-1]

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
        res = self.grid.resolution
        origin = np.asarray(self.grid.origin)
        p = (np.asarray(a, dtype=np.float64) - origin) / res  # (2,) [cells]
        q = (np.asarray(bs, dtype=np.float64) - origin) / res  # (M, 2) [cells]
        d = q - p  # (M, 2)
        # 1. parameters t in [0, 1] of the end points and of the crossings of the grid lines
        #    x = k and y = k; NaN pads segments that cross fewer lines than others
        ts = [np.zeros((len(q), 1)), np.ones((len(q), 1))]
        for axis in (0, 1):
            lo = np.floor(np.minimum(p[axis], q[:, axis]))
            hi = np.floor(np.maximum(p[axis], q[:, axis]))
            n = int(np.max(hi - lo, initial=0))
            if n == 0:
                continue
            lines = lo[:, None] + np.arange(1, n + 1)  # (M, n) grid lines between the end cells
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.clip((lines - p[axis]) / d[:, axis:axis + 1], 0.0, 1.0)
            ts.append(np.where(lines <= hi[:, None], t, np.nan))
        t = np.sort(np.concatenate(ts, axis=1), axis=1)  # (M, K), NaN last
        # 2. one probe point per crossed cell (interval midpoint); a zero-length interval is a
        #    pass through a grid corner and probes the four cells around it
        t_lo, t_hi = t[:, :-1], t[:, 1:]  # (M, K-1)
        real = np.isfinite(t_hi)
        corner = real & (t_hi - t_lo < 1e-9)
        mid = np.where(real, 0.5 * (t_lo + t_hi), 0.0)
        pts = p + mid[..., None] * d[:, None, :]  # (M, K-1, 2) [cells]
        spread = np.array([[-0.5, -0.5], [-0.5, 0.5], [0.5, -0.5], [0.5, 0.5]])  # (4, 2)
        probes = pts[..., None, :] + corner[..., None, None] * spread  # (M, K-1, 4, 2)
        # 3. every probe must lie in a traversable cell on the map
        col = np.floor(probes[..., 0]).astype(np.int64)
        row = np.floor(probes[..., 1]).astype(np.int64)
        inside = (row >= 0) & (row < self.grid.height) & (col >= 0) & (col < self.grid.width)
        ok = inside & self.mask[np.clip(row, 0, self.grid.height - 1),
                                np.clip(col, 0, self.grid.width - 1)]
        return np.all(ok | ~real[..., None], axis=(1, 2))

    # ---------------------------------------------------------------------- exact clearance
    def _centre_clearance(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Exact distance [m] from the centres of cells (rows, cols) (K,) to the nearest obstacle
        square, searched within the padding window (capped at its radius) -> (K,)."""
        w = self._pad
        dr, dc = np.meshgrid(np.arange(-w, w + 1), np.arange(-w, w + 1), indexing="ij")
        dr, dc = dr.ravel(), dc.ravel()  # (Q,) window offsets [cells]
        # centre-to-square distance, per axis the gap beyond the square's half width
        gap = np.hypot(np.maximum(np.abs(dr) - 0.5, 0.0), np.maximum(np.abs(dc) - 0.5, 0.0))
        occupied = self._occupied_padded[rows[:, None] + w + dr, cols[:, None] + w + dc]  # (K, Q)
        dist = np.where(occupied, gap, np.inf).min(axis=1, initial=float(w))
        return dist * self.grid.resolution

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


# ------------------------------------------------------------------------------- helpers
def astar_path(grid: GridMap, start_xy, goal_xy, clearance: float, *, smooth: bool = True) -> np.ndarray:
    """One A* query: (N, 2) world path [m] from exactly ``start_xy`` to exactly ``goal_xy``.

    Builds the traversable mask each call; for many queries on one map use :class:`AStarPlanner`.
    Raises PlanningError (see :meth:`AStarPlanner.plan`).
    """
    return AStarPlanner(grid, clearance, smooth=smooth).plan(start_xy, goal_xy)


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
