"""Occupancy grid maps: built-in D4RL maze2d layouts, Nav2 map_server YAML files, and the
nav_msgs/OccupancyGrid data layout, as plain numpy.

Map frame (REP-103 style, as Nav2): x along the grid columns, y up, metres. ``origin`` is the world
position of the lower-left corner of cell (row 0, col 0); row 0 is the lowest row in y, exactly as
the row-major ``OccupancyGrid.data`` array starts "from the origin". Image files store the top row
first, so loading/saving flips rows.

Occupancy values follow OccupancyGrid: -1 unknown, 0 free ... 100 occupied.
"""
from __future__ import annotations

import hashlib
import math
import os
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from ecahd_core.errors import MapError, PlanningError

# the map the shipped models learnt: every command's and node's default
DEFAULT_MAP = "maze2d-large"

UNKNOWN = -1
FREE = 0
OCCUPIED = 100

# D4RL maze2d layouts (d4rl/pointmaze/maze_model.py): '#' wall, 'O' open, 'G' goal (open).
# Top line is the largest y. Each character is one 1.0 m x 1.0 m cell.
MAZE_LAYOUTS: dict[str, tuple[str, ...]] = {
    "maze2d-umaze": (
        "#####",
        "#GOO#",
        "###O#",
        "#OOO#",
        "#####",
    ),
    "maze2d-medium": (
        "########",
        "#OO##OO#",
        "#OO#OOO#",
        "##OOO###",
        "#OO#OOO#",
        "#O#OO#O#",
        "#OOO#OG#",
        "########",
    ),
    "maze2d-large": (
        "############",
        "#OOOO#OOOOO#",
        "#O##O#O#O#O#",
        "#OOOOOO#OOO#",
        "#O####O###O#",
        "#OO#O#OOOOO#",
        "##O#O#O#O###",
        "#OO#OOO#OGO#",
        "############",
    ),
}
MAZE_CELL_SIZE = 1.0  # [m] size of one maze character
DEFAULT_RESOLUTION = 0.1  # [m/cell] fine grid used for A*, cost maps and collision checks
# the largest grid the package plans on: 4000 x 4000 cells (60 x 60 m at 0.015 m/cell, 200 x 200 m
# at 0.05); its float64 cost map alone takes 128 MB. Larger maps: coarser resolution or a crop.
MAX_MAP_CELLS = 16_000_000


@dataclass(frozen=True)
class GridMap:
    """An occupancy grid in the map frame.

    Attributes:
        data: (H, W) int8 occupancy values (-1 unknown, 0..100), row 0 at the origin (lowest y).
        resolution: cell size [m/cell].
        origin: world (x, y) [m] of the lower-left corner of cell (0, 0).
        name: a human-readable identity ("maze2d-large", a YAML file name, ...).
        frame_id: the TF frame the map lives in.
        unknown_is_occupied: whether unknown cells (-1) count as obstacles.
        occupied_threshold: occupancy value at or above which a known cell is an obstacle.
    """

    data: np.ndarray
    resolution: float
    origin: tuple[float, float] = (0.0, 0.0)
    name: str = "custom"
    frame_id: str = "map"
    unknown_is_occupied: bool = True
    occupied_threshold: int = 65

    def __post_init__(self) -> None:
        data = np.asarray(self.data)
        if data.ndim != 2 or data.shape[0] < 1 or data.shape[1] < 1:
            raise MapError(f"map {self.name!r}: occupancy data must be a non-empty 2-D array, "
                           f"got shape {data.shape}")
        if data.size > MAX_MAP_CELLS:
            raise MapError(f"map {self.name!r}: {data.shape[1]} x {data.shape[0]} cells is over "
                           f"the size limit of {MAX_MAP_CELLS:,} cells; save it at a coarser "
                           f"resolution or crop it")
        if not np.issubdtype(data.dtype, np.integer):
            raise MapError(f"map {self.name!r}: occupancy data must be integers, got {data.dtype}")
        if data.min() < -1 or data.max() > 100:
            raise MapError(f"map {self.name!r}: occupancy values must lie in -1..100, "
                           f"got {data.min()}..{data.max()}")
        if not (math.isfinite(self.resolution) and self.resolution > 0):
            raise MapError(f"map {self.name!r}: resolution must be a positive number [m/cell], "
                           f"got {self.resolution}")
        ox, oy = (float(v) for v in self.origin)
        if not (math.isfinite(ox) and math.isfinite(oy)):
            raise MapError(f"map {self.name!r}: origin must be finite, got {self.origin}")
        if not 0 < self.occupied_threshold <= 100:
            raise MapError(f"map {self.name!r}: occupied_threshold must be in 1..100")
        data = np.ascontiguousarray(data, dtype=np.int8)
        data.setflags(write=False)
        object.__setattr__(self, "data", data)
        object.__setattr__(self, "origin", (ox, oy))
        object.__setattr__(self, "resolution", float(self.resolution))

    # ----------------------------------------------------------------------------- geometry
    @property
    def height(self) -> int:
        """Number of rows (cells along y)."""
        return int(self.data.shape[0])

    @property
    def width(self) -> int:
        """Number of columns (cells along x)."""
        return int(self.data.shape[1])

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) [m] of the mapped area."""
        ox, oy = self.origin
        return ox, oy, ox + self.width * self.resolution, oy + self.height * self.resolution

    @cached_property
    def occupied(self) -> np.ndarray:
        """(H, W) bool obstacle mask (unknown cells follow ``unknown_is_occupied``)."""
        occ = self.data >= self.occupied_threshold
        if self.unknown_is_occupied:
            occ = occ | (self.data < 0)
        occ.setflags(write=False)
        return occ

    @cached_property
    def free_distance(self) -> np.ndarray:
        """(H, W) float32 [m]: from each cell's centre to the nearest occupied cell's centre
        (off the map counts as occupied; an occupied cell has 0). Exact Euclidean distance
        transform, computed on first use and kept. The exact collision checker uses it, where a
        grid has it, to pass poses far from every obstacle without testing cells
        (``collision.check_collision``)."""
        import cv2

        free = np.pad(~self.occupied, 1, constant_values=False).astype(np.uint8)
        dist = cv2.distanceTransform(free, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[1:-1, 1:-1]
        dist = (dist * self.resolution).astype(np.float32)
        dist.setflags(write=False)
        return dist

    def world_to_cell(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Cell indices of world points. xy: (..., 2) [m] -> (row, col) int arrays of shape (...).

        Points off the map get indices outside [0, H) x [0, W); use :meth:`in_bounds`.
        """
        xy = np.asarray(xy, dtype=np.float64)
        col = np.floor((xy[..., 0] - self.origin[0]) / self.resolution).astype(np.int64)
        row = np.floor((xy[..., 1] - self.origin[1]) / self.resolution).astype(np.int64)
        return row, col

    def cell_to_world(self, row: np.ndarray, col: np.ndarray) -> np.ndarray:
        """World (x, y) [m] of cell centres. row, col: int arrays (...) -> (..., 2)."""
        x = self.origin[0] + (np.asarray(col, dtype=np.float64) + 0.5) * self.resolution
        y = self.origin[1] + (np.asarray(row, dtype=np.float64) + 0.5) * self.resolution
        return np.stack([x, y], axis=-1)

    def crop(self, xmin: float, ymin: float, xmax: float, ymax: float) -> "GridMap":
        """The cells that overlap the box [xmin, xmax] x [ymin, ymax] [m] (clipped to the map),
        on the same cell lattice; everything outside it then counts as off the map (occupied
        when ``unknown_is_occupied``). The map itself if the box covers it."""
        r0, c0 = (int(v) for v in self.world_to_cell(np.array([xmin, ymin])))
        r1, c1 = (int(v) for v in self.world_to_cell(np.array([xmax, ymax])))
        r0, c0 = max(r0, 0), max(c0, 0)
        r1, c1 = min(r1 + 1, self.height), min(c1 + 1, self.width)
        if r0 >= r1 or c0 >= c1:
            raise MapError(f"map {self.name!r}: the box ({xmin:.2f}, {ymin:.2f}) - ({xmax:.2f}, "
                           f"{ymax:.2f}) lies off the map")
        if (r0, c0, r1, c1) == (0, 0, self.height, self.width):
            return self
        ox, oy = self.origin
        return GridMap(self.data[r0:r1, c0:c1], self.resolution,
                       (ox + c0 * self.resolution, oy + r0 * self.resolution), name=self.name,
                       frame_id=self.frame_id, unknown_is_occupied=self.unknown_is_occupied,
                       occupied_threshold=self.occupied_threshold)

    def in_bounds(self, xy: np.ndarray) -> np.ndarray:
        """(..., 2) -> (...) bool: the point lies on the map (NaN is never on the map)."""
        xy = np.asarray(xy, dtype=np.float64)
        xmin, ymin, xmax, ymax = self.bounds
        with np.errstate(invalid="ignore"):
            return ((xy[..., 0] >= xmin) & (xy[..., 0] < xmax)
                    & (xy[..., 1] >= ymin) & (xy[..., 1] < ymax))

    def is_free(self, xy: np.ndarray) -> np.ndarray:
        """(..., 2) -> (...) bool: the point is on the map in a free cell."""
        xy = np.asarray(xy, dtype=np.float64)
        inside = self.in_bounds(xy)
        safe = np.where(inside[..., None], xy, np.asarray(self.origin))
        row, col = self.world_to_cell(safe)
        return inside & ~self.occupied[row, col]

    def free_cell_centres(self) -> np.ndarray:
        """(N, 2) world coordinates [m] of the centres of all free cells."""
        rows, cols = np.nonzero(~self.occupied)
        return self.cell_to_world(rows, cols)

    def validate_point(self, xy, what: str = "point") -> np.ndarray:
        """Return ``xy`` as a float (2,) array, or raise PlanningError naming the problem
        (wrong shape, NaN/inf, off the map, inside an obstacle)."""
        arr = np.asarray(xy, dtype=np.float64).reshape(-1)
        if arr.shape != (2,):
            raise PlanningError(f"{what} must be an (x, y) pair, got {np.asarray(xy).shape}")
        if not np.all(np.isfinite(arr)):
            raise PlanningError(f"{what} has non-finite coordinates {arr.tolist()}")
        if not self.in_bounds(arr):
            xmin, ymin, xmax, ymax = self.bounds
            raise PlanningError(f"{what} ({arr[0]:.3f}, {arr[1]:.3f}) is outside the map "
                                f"{self.name!r} [{xmin:.2f}, {xmax:.2f}] x [{ymin:.2f}, {ymax:.2f}] m")
        if not self.is_free(arr):
            raise PlanningError(f"{what} ({arr[0]:.3f}, {arr[1]:.3f}) is inside an obstacle of "
                                f"map {self.name!r}")
        return arr

    def require_free_space(self) -> None:
        """Raise MapError if the map has no free cell at all."""
        if not np.any(~self.occupied):
            raise MapError(f"map {self.name!r} has no free cell")

    def changed_share(self, other: "GridMap") -> float:
        """The share of cells whose obstacle state differs in ``other``, an updated map of the
        same site (a SLAM update, an edited map: the same cells, resolution and origin);
        MapError naming the difference when ``other`` covers another extent."""
        same = (self.occupied.shape == other.occupied.shape
                and abs(self.resolution - other.resolution) < 1e-9
                and np.allclose(self.origin, other.origin, atol=1e-6))
        if not same:
            raise MapError(
                f"map {other.name!r} is not an update of {self.name!r}: "
                f"{other.width} x {other.height} cells of {other.resolution:g} m at "
                f"{tuple(round(v, 3) for v in other.origin)} against {self.width} x "
                f"{self.height} of {self.resolution:g} m at "
                f"{tuple(round(v, 3) for v in self.origin)}")
        return float(np.mean(self.occupied != other.occupied))

    def fingerprint(self) -> str:
        """A short stable hash of the obstacle layout, resolution and origin (the map's identity
        recorded in datasets and checkpoints)."""
        h = hashlib.sha256()
        h.update(np.packbits(self.occupied).tobytes())
        h.update(np.asarray([self.height, self.width], dtype=np.int64).tobytes())
        h.update(np.asarray([self.resolution, *self.origin], dtype=np.float64).round(9).tobytes())
        return h.hexdigest()[:16]


# --------------------------------------------------------------------------------- built-in
def builtin_map_names() -> list[str]:
    """Names accepted by :func:`builtin_map`."""
    return sorted(MAZE_LAYOUTS)


def builtin_map(name: str, resolution: float = DEFAULT_RESOLUTION) -> GridMap:
    """A D4RL maze2d layout rasterised at ``resolution`` [m/cell] (1.0 m per maze cell).

    The origin is the lower-left corner of the maze, so the maze covers
    [0, n_cols] x [0, n_rows] metres.
    """
    if name not in MAZE_LAYOUTS:
        raise MapError(f"unknown built-in map {name!r}; choose one of {builtin_map_names()}")
    per_cell = MAZE_CELL_SIZE / resolution
    k = int(round(per_cell))
    if k < 1 or abs(per_cell - k) > 1e-6:
        raise MapError(f"resolution {resolution} m must divide the maze cell size "
                       f"{MAZE_CELL_SIZE} m into a whole number of cells")
    layout = MAZE_LAYOUTS[name]
    coarse = np.array([[ch == "#" for ch in line] for line in layout], dtype=bool)[::-1]
    fine = np.kron(coarse, np.ones((k, k), dtype=bool))
    data = np.where(fine, OCCUPIED, FREE).astype(np.int8)
    return GridMap(data=data, resolution=resolution, origin=(0.0, 0.0), name=name)


def load_map(spec: str, resolution: float = DEFAULT_RESOLUTION) -> GridMap:
    """A built-in maze name or a path to a Nav2 map YAML file."""
    if spec in MAZE_LAYOUTS:
        return builtin_map(spec, resolution)
    if spec.endswith((".yaml", ".yml")) or os.path.exists(spec):
        return load_nav2_yaml(spec)
    raise MapError(f"map {spec!r} is neither a built-in map {builtin_map_names()} "
                   f"nor an existing Nav2 map YAML file")


# ------------------------------------------------------------------------- Nav2 map_server
_NAV2_MODES = ("trinary", "scale", "raw")


def load_nav2_yaml(path: str | os.PathLike, *, unknown_is_occupied: bool = True) -> GridMap:
    """Load a Nav2 map_server map (YAML + PGM/PNG image) as map_server interprets it.

    Keys: image, resolution, origin [x, y, yaw], negate, occupied_thresh, free_thresh,
    mode (trinary | scale | raw; default trinary).
    """
    import cv2
    import yaml

    path = Path(path)
    try:
        meta = yaml.safe_load(path.read_text())
    except FileNotFoundError as exc:
        raise MapError(f"map YAML {str(path)!r} does not exist") from exc
    except yaml.YAMLError as exc:
        raise MapError(f"map YAML {str(path)!r} is not valid YAML: {exc}") from exc
    if not isinstance(meta, dict):
        raise MapError(f"map YAML {str(path)!r} must be a mapping of keys, got {type(meta).__name__}")
    for key in ("image", "resolution", "origin"):
        if key not in meta:
            raise MapError(f"map YAML {str(path)!r} lacks the required key {key!r}")
    try:
        resolution = float(meta["resolution"])
        origin = [float(v) for v in meta["origin"]]
        negate = int(meta.get("negate", 0))
        occ_th = float(meta.get("occupied_thresh", 0.65))
        free_th = float(meta.get("free_thresh", 0.25))
    except (TypeError, ValueError) as exc:
        raise MapError(f"map YAML {str(path)!r} has a malformed value: {exc}") from exc
    mode = str(meta.get("mode", "trinary"))
    if mode not in _NAV2_MODES:
        raise MapError(f"map YAML {str(path)!r}: mode {mode!r} is not one of {list(_NAV2_MODES)}")
    if len(origin) not in (2, 3):
        raise MapError(f"map YAML {str(path)!r}: origin must be [x, y, yaw], got {meta['origin']}")
    if len(origin) == 3 and abs(origin[2]) > 1e-9:
        raise MapError(f"map YAML {str(path)!r}: a rotated map origin (yaw {origin[2]}) "
                       "is not supported")
    if not 0.0 <= free_th < occ_th <= 1.0:
        raise MapError(f"map YAML {str(path)!r}: need 0 <= free_thresh < occupied_thresh <= 1, "
                       f"got {free_th}, {occ_th}")
    image_path = Path(meta["image"])
    if not image_path.is_absolute():
        image_path = path.parent / image_path
    img = cv2.imread(str(image_path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise MapError(f"map image {str(image_path)!r} (from {str(path)!r}) is missing or unreadable")
    if img.ndim == 3:  # colour: map_server averages the colour channels, ignores alpha
        img = img[..., :3].mean(axis=2)
    img = np.asarray(img, dtype=np.float64)
    if img.max(initial=0) > 255:
        raise MapError(f"map image {str(image_path)!r} must be 8-bit")
    img = img[::-1]  # image top row is the largest y
    if mode == "raw":
        data = np.clip(img, -1, 100)
        data = np.where(img > 100, UNKNOWN, data).astype(np.int8)
    else:
        occ = img / 255.0 if negate else (255.0 - img) / 255.0
        data = np.full(img.shape, UNKNOWN, dtype=np.int8)
        if mode == "trinary":
            data[occ > occ_th] = OCCUPIED
            data[occ < free_th] = FREE
        else:  # scale
            data[occ > occ_th] = OCCUPIED
            data[occ < free_th] = FREE
            mid = (occ >= free_th) & (occ <= occ_th)
            data[mid] = np.rint(99 * (occ[mid] - free_th) / (occ_th - free_th)).astype(np.int8)
    return GridMap(data=data, resolution=resolution, origin=(origin[0], origin[1]),
                   name=path.stem, unknown_is_occupied=unknown_is_occupied,
                   occupied_threshold=max(1, int(math.ceil(occ_th * 100))) if mode != "trinary" else 65)


def save_nav2_yaml(grid: GridMap, path: str | os.PathLike, image_format: str = "pgm") -> Path:
    """Save as map_saver does in trinary mode: free 254, occupied 0, unknown 205, with the fixed
    thresholds occupied 0.65 / free 0.196 that ROS 1 and Nav2 (since navigation2 PR 5278) write,
    so that the grey 205 pixel ((255-205)/255 = 0.1961) reloads as unknown, not free.

    Returns the YAML path; the image is written beside it with the same stem.
    """
    import cv2
    import yaml

    if image_format not in ("pgm", "png"):
        raise MapError(f"image_format must be 'pgm' or 'png', got {image_format!r}")
    path = Path(path)
    image_name = path.with_suffix("." + image_format).name
    img = np.full(grid.data.shape, 205, dtype=np.uint8)
    known = grid.data >= 0
    img[known & (grid.data >= grid.occupied_threshold)] = 0
    img[known & (grid.data < grid.occupied_threshold)] = 254
    if not cv2.imwrite(str(path.parent / image_name), img[::-1]):
        raise MapError(f"could not write map image next to {str(path)!r}")
    meta = {
        "image": image_name,
        "mode": "trinary",
        "resolution": grid.resolution,
        "origin": [grid.origin[0], grid.origin[1], 0.0],
        "negate": 0,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
    }
    path.write_text(yaml.safe_dump(meta, sort_keys=False))
    return path


# ----------------------------------------------------------------- nav_msgs/OccupancyGrid
@dataclass(frozen=True)
class OccupancyGridLayout:
    """The fields of nav_msgs/OccupancyGrid as plain Python (no rclpy): ``data`` row-major from
    the origin, -1 unknown, 0..100."""

    data: np.ndarray  # (H*W,) int8
    width: int
    height: int
    resolution: float  # [m/cell]
    origin_xy: tuple[float, float]  # [m]
    frame_id: str = "map"


def to_occupancy_grid(grid: GridMap) -> OccupancyGridLayout:
    """GridMap -> OccupancyGrid fields."""
    return OccupancyGridLayout(data=grid.data.reshape(-1).copy(), width=grid.width,
                               height=grid.height, resolution=grid.resolution,
                               origin_xy=grid.origin, frame_id=grid.frame_id)


def from_occupancy_grid(data, width: int, height: int, resolution: float,
                        origin_xy: tuple[float, float], *, frame_id: str = "map",
                        name: str = "occupancy_grid", unknown_is_occupied: bool = True,
                        occupied_threshold: int = 65) -> GridMap:
    """OccupancyGrid fields -> GridMap; raises MapError when the sizes or values do not match."""
    arr = np.asarray(data)
    if width <= 0 or height <= 0:
        raise MapError(f"OccupancyGrid {name!r}: width and height must be positive, "
                       f"got {width} x {height}")
    if arr.size != width * height:
        raise MapError(f"OccupancyGrid {name!r}: data has {arr.size} cells, "
                       f"width x height = {width} x {height} = {width * height}")
    if arr.size and (arr.min() < -1 or arr.max() > 100):
        raise MapError(f"OccupancyGrid {name!r}: values must lie in -1..100")
    return GridMap(data=arr.astype(np.int8).reshape(height, width), resolution=resolution,
                   origin=tuple(origin_xy), name=name, frame_id=frame_id,
                   unknown_is_occupied=unknown_is_occupied,
                   occupied_threshold=occupied_threshold)


def grid_from_occupancy_message(msg, *, unknown_is_occupied: bool = True,
                                name: str = "occupancy_grid") -> GridMap:
    """A nav_msgs/OccupancyGrid read by its field names (an rclpy message or the rosbags
    dataclass a bag deserialises to; no ROS import here) -> GridMap; raises MapError for a
    malformed or rotated grid (a non-finite or zero origin quaternion included).

    The message carries the resolution as float32 (0.1 arrives as 0.10000000149); it is restored
    to the shortest decimal that float32 value stands for, so a map keeps its fingerprint (and
    the models trained for it still load) after a trip through a message or a bag."""
    q = msg.info.origin.orientation
    quaternion = (q.x, q.y, q.z, q.w)
    if not all(math.isfinite(v) for v in quaternion):
        raise MapError(f"OccupancyGrid origin orientation is not finite: {quaternion}")
    if abs(q.w) < 1e-6 and max(abs(q.x), abs(q.y), abs(q.z)) < 1e-6:
        raise MapError("OccupancyGrid origin orientation is the zero quaternion")
    if max(abs(q.x), abs(q.y), abs(q.z)) > 1e-6 * max(1.0, abs(q.w)):
        raise MapError("OccupancyGrid with a rotated origin is not supported")
    resolution = float(str(np.float32(msg.info.resolution)))  # float32 -> shortest decimal
    return from_occupancy_grid(np.asarray(msg.data, dtype=np.int16), msg.info.width,
                               msg.info.height, resolution,
                               (msg.info.origin.position.x, msg.info.origin.position.y),
                               frame_id=msg.header.frame_id or "map", name=name,
                               unknown_is_occupied=unknown_is_occupied)


# ------------------------------------------------------------------------ distance fields
def signed_distance(grid: GridMap) -> np.ndarray:
    """Signed distance [m] from each cell centre to the nearest obstacle boundary.

    Returns (H, W) float64: positive in free space (distance to the closest obstacle edge),
    negative inside obstacles (depth below the closest free edge). Everything off the map counts
    as obstacle, so free cells at the map edge see the edge as a wall. Exact up to the
    half-cell discretisation of cv2.distanceTransform (DIST_L2, precise mask).
    """
    import cv2

    occ = np.pad(grid.occupied, 1, constant_values=True)
    free_u8 = (~occ).astype(np.uint8)
    d_out = cv2.distanceTransform(free_u8, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)  # to nearest obstacle centre
    d_in = cv2.distanceTransform(1 - free_u8, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)  # to nearest free centre
    half = 0.5
    sdf = np.where(occ, -(d_in - half), d_out - half)[1:-1, 1:-1]
    return sdf.astype(np.float64) * grid.resolution
