"""Scenario files: obstacles that are not on the map (issue 11), static or moving back and forth.

A scenario is a YAML file that the simulator reads (``sim_bridge``'s ``obstacles_file``) and a
benchmark writes; the planners never see it (obstacles never appear on ``map``)::

    obstacles:
      - {shape: box, x: 4.5, y: 5.5, yaw: 0.0, size: [0.4, 0.6]}       # static box
      - {shape: cylinder, x: 6.5, y: 5.3, radius: 0.25}                # static cylinder
      - {shape: cylinder, radius: 0.3, path: [[1.5, 3.5], [1.5, 5.5]], speed: 0.4}  # moving

Units: metres, radians, m/s, in the map frame. ``size`` is a box's full extent [x, y] in its own
frame, turned by ``yaw`` about its centre (yaw is optional, 0 by default). A moving obstacle has
a ``path`` of at least 2 points [[x, y], ...] instead of x, y, and a ``speed`` > 0: it starts at
the first point at t = 0 and goes back and forth along the polyline at that speed forever
(ping-pong, no wrap-around), keeping its yaw. Every obstacle is 1 m high (as the walls). A moving
obstacle is kinematic: it passes through walls, other obstacles and the robot (an overlap with the
robot is a contact), so give it a path through free space.

A scenario may also mark **zones** (issue 41): areas of free floor a site's operators never
drive through (a loading bay, a wet floor), each a polygon of at least 3 [x, y] vertices [m] in
the map frame, with an optional name. The simulator ignores them (they are not obstacles);
``ecahd record-demos --habit zone`` drives round them and ``ecahd_core.operator.habit_metrics``
counts the paths that enter one::

    zones:
      - {name: loading_bay, polygon: [[2.0, 1.0], [5.0, 1.0], [5.0, 3.0], [2.0, 3.0]]}

Bad entries do not spoil the others: :func:`parse_obstacles` returns the good obstacles and one
error line per bad entry, naming its index and content (unknown shape or key, a missing field,
a NaN, a non-positive size / radius / speed, a path of fewer than 2 points or zero length).
No pybullet, no rclpy here: ``sim_bridge.sim`` builds the bodies, a benchmark's exact checker can
use :func:`obstacle_footprints`.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ecahd_core.errors import EcahdError
from ecahd_core.footprint import point_segment_distance

SHAPES = ("box", "cylinder")
CYLINDER_POLYGON_SIDES = 32  # footprint polygon of a cylinder (circumscribed, so never smaller)
_KEYS = {"shape", "x", "y", "yaw", "size", "radius", "path", "speed"}
_DOCUMENT_KEYS = ("obstacles", "zones")  # the top-level keys of a scenario file
_ZONE_KEYS = {"name", "polygon"}


class ScenarioError(EcahdError):
    """A scenario file that cannot be read: missing, not YAML, no ``obstacles`` list, or (for the
    strict :func:`load_scenario`) any bad entry."""


@dataclass(frozen=True)
class Obstacle:
    """One obstacle of a scenario.

    Attributes:
        shape: "box" or "cylinder".
        x, y: [m] centre at t = 0 (a moving obstacle's first path point).
        yaw: [rad] heading of a box (cylinders: 0).
        size: (sx, sy) [m] full extent of a box in its own frame; None for cylinders.
        radius: [m] of a cylinder; None for boxes.
        path: ((x, y), ...) [m] polyline a moving obstacle runs back and forth; () when static.
        speed: [m/s] along the path; 0 when static.
    """

    shape: str
    x: float
    y: float
    yaw: float = 0.0
    size: tuple[float, float] | None = None
    radius: float | None = None
    path: tuple[tuple[float, float], ...] = ()
    speed: float = 0.0

    @property
    def moving(self) -> bool:
        return len(self.path) >= 2

    @property
    def path_length(self) -> float:
        """[m] length of the polyline (0 when static)."""
        if not self.moving:
            return 0.0
        return float(np.sum(np.linalg.norm(np.diff(np.asarray(self.path), axis=0), axis=1)))

    @property
    def bounding_radius(self) -> float:
        """[m] radius of the circle about the centre that holds the whole shape."""
        if self.shape == "cylinder":
            return float(self.radius)
        return 0.5 * math.hypot(*self.size)

    def position(self, t: float) -> tuple[float, float]:
        """Centre (x, y) [m] at time t [s]: constant when static; a moving obstacle is at path
        arc length s = speed t folded into [0, L] back and forth (s mod 2L, mirrored past L)."""
        if not self.moving:
            return self.x, self.y
        pts = np.asarray(self.path, dtype=np.float64)  # (K, 2)
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)  # (K-1,)
        length = float(seg.sum())
        s = math.fmod(self.speed * max(float(t), 0.0), 2.0 * length)
        if s > length:
            s = 2.0 * length - s
        cum = np.concatenate([[0.0], np.cumsum(seg)])  # (K,) arc length at each point
        i = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1))
        u = 0.0 if seg[i] == 0 else (s - cum[i]) / seg[i]
        x, y = pts[i] + min(max(u, 0.0), 1.0) * (pts[i + 1] - pts[i])
        return float(x), float(y)

    def footprint(self, t: float = 0.0) -> np.ndarray:
        """(K, 2) counter-clockwise polygon [m] of the shape at time t: a box's 4 corners, or a
        32-gon circumscribing a cylinder (it contains the circle)."""
        cx, cy = self.position(t)
        if self.shape == "box":
            hx, hy = self.size[0] / 2, self.size[1] / 2
            local = np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy]])
            c, s = math.cos(self.yaw), math.sin(self.yaw)
            return local @ np.array([[c, s], [-s, c]]) + [cx, cy]
        n = CYLINDER_POLYGON_SIDES
        a = 2.0 * math.pi * np.arange(n) / n
        r = self.radius / math.cos(math.pi / n)
        return np.stack([cx + r * np.cos(a), cy + r * np.sin(a)], axis=1)

    def to_dict(self) -> dict:
        """The YAML entry of this obstacle (the format :func:`parse_obstacles` reads)."""
        entry: dict = {"shape": self.shape}
        if self.moving:
            entry["path"] = [[float(px), float(py)] for px, py in self.path]
            entry["speed"] = float(self.speed)
        else:
            entry["x"], entry["y"] = float(self.x), float(self.y)
        if self.shape == "box":
            entry["yaw"] = float(self.yaw)
            entry["size"] = [float(v) for v in self.size]
        else:
            entry["radius"] = float(self.radius)
        return entry


def obstacle_footprints(obstacles, t: float = 0.0) -> list[np.ndarray]:
    """The (K, 2) polygon [m] of every obstacle at time t [s] (see :meth:`Obstacle.footprint`)."""
    return [o.footprint(t) for o in obstacles]


# ------------------------------------------------------------------------------- parsing
def _number(entry: dict, key: str, *, positive: bool = False) -> float:
    if key not in entry:
        raise ValueError(f"missing field {key!r}")
    value = entry[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{key} must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{key} must be finite, got {value}")
    if positive and value <= 0:
        raise ValueError(f"{key} must be > 0, got {value:g}")
    return value


def _point(value, what: str) -> tuple[float, float]:
    if not (isinstance(value, (list, tuple)) and len(value) == 2):
        raise ValueError(f"{what} must be [x, y], got {value!r}")
    x, y = (_number({"v": v}, "v") for v in value)
    return x, y


def parse_obstacle(entry) -> Obstacle:
    """One YAML entry -> Obstacle; raises ValueError with the reason (without the entry)."""
    if not isinstance(entry, dict):
        raise ValueError("an obstacle must be a mapping {shape: ..., ...}")
    unknown = sorted(set(map(str, entry)) - _KEYS)
    if unknown:
        raise ValueError(f"unknown field(s) {', '.join(unknown)} "
                         f"(allowed: {', '.join(sorted(_KEYS))})")
    shape = entry.get("shape")
    if shape not in SHAPES:
        raise ValueError(f"shape must be one of {', '.join(SHAPES)}, got {shape!r}"
                         if "shape" in entry else "missing field 'shape'")
    yaw = _number(entry, "yaw") if "yaw" in entry else 0.0
    size, radius = None, None
    if shape == "box":
        if "radius" in entry:
            raise ValueError("a box takes size [sx, sy], not radius")
        if "size" not in entry:
            raise ValueError("missing field 'size'")
        sx, sy = _point(entry["size"], "size")
        if not (sx > 0 and sy > 0):
            raise ValueError(f"size must be > 0 in both directions, got [{sx:g}, {sy:g}]")
        size = (sx, sy)
    else:
        if "size" in entry:
            raise ValueError("a cylinder takes radius, not size")
        radius = _number(entry, "radius", positive=True)
    if "path" in entry or "speed" in entry:
        if "x" in entry or "y" in entry:
            raise ValueError("a moving obstacle starts at path[0]: give path and speed, not x, y")
        raw = entry.get("path")
        if not isinstance(raw, (list, tuple)) or len(raw) < 2:
            raise ValueError(f"path must be a list of at least 2 points [x, y], got {raw!r}")
        path = tuple(_point(p, f"path point {k}") for k, p in enumerate(raw))
        speed = _number(entry, "speed", positive=True)
        obstacle = Obstacle(shape, *path[0], yaw, size, radius, path, speed)
        if obstacle.path_length <= 0:
            raise ValueError("path has zero length (all its points are the same)")
        return obstacle
    return Obstacle(shape, _number(entry, "x"), _number(entry, "y"), yaw, size, radius)


def parse_obstacles(data) -> tuple[list[Obstacle], list[str]]:
    """A loaded scenario ({"obstacles": [...]}, or None / {} for none) -> (obstacles, errors).

    Each bad entry is left out and gives one line "obstacle <i> <entry>: <reason>". Raises
    ScenarioError when the document itself is not a scenario (not a mapping, ``obstacles`` not a
    list, unknown top-level keys)."""
    if data is None:
        return [], []
    if not isinstance(data, dict):
        raise ScenarioError(f"a scenario must be a mapping with an 'obstacles' list, "
                            f"got {type(data).__name__}")
    unknown = sorted(set(map(str, data)) - set(_DOCUMENT_KEYS))
    if unknown:
        raise ScenarioError(f"unknown scenario key(s) {', '.join(unknown)} "
                            f"(allowed: {', '.join(_DOCUMENT_KEYS)})")
    entries = data.get("obstacles") or []
    if not isinstance(entries, list):
        raise ScenarioError(f"scenario 'obstacles' must be a list, got {type(entries).__name__}")
    obstacles, errors = [], []
    for i, entry in enumerate(entries):
        try:
            obstacles.append(parse_obstacle(entry))
        except ValueError as exc:
            errors.append(f"obstacle {i} {entry!r}: {exc}")
    return obstacles, errors


def read_scenario(path: str | os.PathLike) -> tuple[list[Obstacle], list[str]]:
    """Read a scenario YAML -> (good obstacles, one error line per bad entry). Raises
    ScenarioError for a missing or unreadable file or a document that is not a scenario."""
    return _read_with(path, parse_obstacles)


def _read_with(path: str | os.PathLike, parse):
    """``parse`` of a scenario YAML's document; ScenarioError naming the file when it cannot
    be read, is not YAML or ``parse`` refuses it."""
    import yaml

    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise ScenarioError(f"cannot read scenario {path}: {exc.strerror or exc}") from exc
    except yaml.YAMLError as exc:
        raise ScenarioError(f"scenario {path} is not valid YAML: {exc}") from exc
    try:
        return parse(data)
    except ScenarioError as exc:
        raise ScenarioError(f"scenario {path}: {exc}") from exc


def load_scenario(path: str | os.PathLike) -> list[Obstacle]:
    """Read a scenario YAML strictly: every entry must be good, else ScenarioError listing the
    bad ones (the simulator node uses the lenient :func:`read_scenario`)."""
    obstacles, errors = read_scenario(path)
    if errors:
        raise ScenarioError(f"scenario {path} has {len(errors)} bad obstacle(s):\n"
                            + "\n".join(errors))
    return obstacles


@dataclass(frozen=True)
class Zone:
    """An area of free floor the operator never enters: ``polygon`` (V, 2) [m], map frame,
    V >= 3, counter-clockwise; ``name`` for messages and figures."""

    name: str
    polygon: np.ndarray

    def contains(self, xy) -> np.ndarray:
        """(N, 2) [m] -> (N,) bool: the point lies inside the polygon (even-odd rule)."""
        from ecahd_core.footprint import point_in_polygon

        return point_in_polygon(np.asarray(xy, dtype=np.float64).reshape(-1, 2), self.polygon)


def parse_zones(data) -> list[Zone]:
    """The ``zones`` of a loaded scenario document (module docstring) -> [Zone]; [] when it
    has none. Raises ScenarioError naming the first bad zone (index and content): a zone is
    a rule the operator must keep, so none is silently left out."""
    if data is None:
        return []
    if not isinstance(data, dict):
        raise ScenarioError(f"a scenario must be a mapping, got {type(data).__name__}")
    unknown = sorted(set(map(str, data)) - set(_DOCUMENT_KEYS))
    if unknown:
        raise ScenarioError(f"unknown scenario key(s) {', '.join(unknown)} "
                            f"(allowed: {', '.join(_DOCUMENT_KEYS)})")
    entries = data.get("zones") or []
    if not isinstance(entries, list):
        raise ScenarioError(f"scenario 'zones' must be a list, got {type(entries).__name__}")
    zones = []
    for i, entry in enumerate(entries):
        try:
            zones.append(_parse_zone(entry, i))
        except ValueError as exc:
            raise ScenarioError(f"zone {i} {entry!r}: {exc}") from None
    return zones


def _parse_zone(entry, index: int) -> Zone:
    from ecahd_core.footprint import signed_area

    if not isinstance(entry, dict):
        raise ValueError("must be a mapping {name, polygon}")
    unknown = sorted(set(map(str, entry)) - _ZONE_KEYS)
    if unknown:
        raise ValueError(f"unknown key(s) {', '.join(unknown)} (allowed: name, polygon)")
    points = entry.get("polygon")
    if not isinstance(points, list) or len(points) < 3:
        raise ValueError("polygon must be a list of at least 3 [x, y] points")
    poly = np.array([_point(p, "polygon point") for p in points], dtype=np.float64)
    area = signed_area(poly)
    if abs(area) < 1e-9:
        raise ValueError("polygon has zero area")
    if area < 0:
        poly = poly[::-1].copy()
    poly.setflags(write=False)
    return Zone(name=str(entry.get("name", f"zone {index}")), polygon=poly)


def read_zones(path: str | os.PathLike) -> list[Zone]:
    """The zones of a scenario YAML (:func:`parse_zones`); ScenarioError for a file that
    cannot be read, is not YAML or has a bad zone."""
    return _read_with(path, parse_zones)


def write_scenario(path: str | os.PathLike, obstacles, zones=()) -> Path:
    """Write obstacles (and zones) as a scenario YAML that :func:`load_scenario` (and
    :func:`read_zones`) read back equal."""
    import yaml

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    doc: dict = {"obstacles": [o.to_dict() for o in obstacles]}
    if zones:
        doc["zones"] = [{"name": z.name, "polygon": [[float(x), float(y)] for x, y in z.polygon]}
                        for z in zones]
    text = yaml.safe_dump(doc, default_flow_style=None, sort_keys=False)
    path.write_text(text)
    return path


# ----------------------------------------------------------------------------- generation
def rasterize(grid, obstacles, t: float = 0.0, *, grow: int = 0):
    """``grid`` (a GridMap) with the cells that the obstacles' footprints at time t touch made
    occupied (100): the world the robot would have to plan in if it knew them. ``grow``: also
    the cells within that many cells of them (8-neighbourhood), e.g. 1 for what a scan's
    marks on the map's lattice can add to an obstacle (local_costmap)."""
    import cv2

    from ecahd_core.maps import GridMap

    data = grid.data.copy()
    mask = np.zeros(data.shape, dtype=np.uint8)
    for poly in obstacle_footprints(obstacles, t):
        cells = (poly - np.asarray(grid.origin)) / grid.resolution - 0.5  # cell-centre units
        cv2.fillPoly(mask, [np.round(cells * 16).astype(np.int32)], 1, lineType=cv2.LINE_8,
                     shift=4)
    if grow > 0:
        mask = cv2.dilate(mask, np.ones((3, 3), np.uint8), iterations=int(grow))
    data[mask.astype(bool)] = 100
    return GridMap(data, grid.resolution, grid.origin, name=grid.name, frame_id=grid.frame_id,
                   unknown_is_occupied=grid.unknown_is_occupied,
                   occupied_threshold=grid.occupied_threshold)


@dataclass(frozen=True)
class GeneratedScenario:
    """A seeded benchmark scenario (:func:`generate_scenario`).

    Attributes:
        obstacles: the static ones first, then the moving ones.
        kinds: per obstacle "narrowing" (the route keeps its length within 0.5 m: a passage
            remains), "blocking" (only a detour works) or "moving".
        route: (N, 2) [m] the A* route through start and goals the obstacles were placed on.
    """

    obstacles: tuple[Obstacle, ...]
    kinds: tuple[str, ...]
    route: np.ndarray


# "reachable" is judged with every obstacle grown by this many cells: the robot's planner sees
# an obstacle through scan marks on the map's lattice, up to a cell beyond its true outline
# (local_costmap), and a scenario must not count on a gap only the true outline leaves
# (measured 2026-11-29: a goal promised reachable, no way round the scanned boxes found)
MARK_GROWTH = 1


def generate_scenario(grid, footprint, stops, *, static: int, moving: int, seed: int,
                      keep_clear: float = 1.2, spacing: float = 1.0, tries: int = 60,
                      strict: bool = True) -> GeneratedScenario:
    """Obstacles on the route a robot drives: ``stops`` (K, 2) [m] are the start then the goals
    of the episodes in order. Static boxes (0.3-0.5 m sides) are dropped near the A* route
    (clearance of ``footprint``) and kept only if every goal stays reachable for the footprint
    with all of them in place (A* with clearance on the rasterised map, every obstacle grown
    by ``MARK_GROWTH`` cells as the robot's scan marks can grow it); moving cylinders
    (radius 0.15-0.2 m, 0.3-0.5 m/s) cross the route at right angles, from wall to wall (at
    most 1.5 m each side), and only where the robot can get by at one end of their run.
    Nothing within ``keep_clear`` m of a stop (a moving one's whole run), obstacles at least
    ``spacing`` m apart (their paths' midpoints for moving ones). When an obstacle cannot be
    placed in ``tries`` attempts: ScenarioError if ``strict``, else the scenario keeps the
    ones placed so far of that kind (1 m maze corridors rarely take 5 blocking boxes that all
    leave a detour).

    Returns a GeneratedScenario (the same for the same inputs and seed)."""
    from ecahd_core.astar import AStarPlanner, clearance_for_footprint, path_length, \
        plan_from_pose
    from ecahd_core.controller import resample
    from ecahd_core.errors import PlanningError

    rng = np.random.default_rng(seed)
    stops = np.asarray(stops, dtype=np.float64).reshape(-1, 2)
    clearance = clearance_for_footprint(footprint)

    def route_on(g) -> list[np.ndarray] | None:
        planner = AStarPlanner(g, clearance)
        try:
            return [plan_from_pose(planner, a, b) for a, b in zip(stops[:-1], stops[1:])]
        except PlanningError:
            return None

    legs = route_on(grid)
    if legs is None:
        raise ScenarioError("the episodes' goals are not reachable for the footprint even "
                            "without obstacles")
    route = resample(np.concatenate(legs), 0.1)
    base_length = sum(path_length(leg) for leg in legs)
    far = np.min(np.linalg.norm(route[:, None] - stops[None], axis=2), axis=1) > keep_clear
    candidates = route[far]
    if len(candidates) == 0 and static + moving > 0:
        raise ScenarioError(f"no route point lies {keep_clear} m from every start and goal")
    tangent = np.gradient(route, axis=0)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-9)
    tangents = tangent[far]

    obstacles: list[Obstacle] = []
    kinds: list[str] = []

    def spaced(p: np.ndarray) -> bool:
        return all(np.linalg.norm(p - _centre(o)) >= spacing for o in obstacles)

    for _ in range(static):
        for _attempt in range(tries):
            i = int(rng.integers(len(candidates)))
            if not spaced(candidates[i]):
                continue
            normal = np.array([-tangents[i, 1], tangents[i, 0]])
            centre = candidates[i] + rng.uniform(-0.3, 0.3) * normal
            box = Obstacle("box", float(centre[0]), float(centre[1]),
                           yaw=float(rng.uniform(-math.pi, math.pi)),
                           size=(float(rng.uniform(0.3, 0.5)), float(rng.uniform(0.3, 0.5))))
            legs = route_on(rasterize(grid, [*obstacles, box], grow=MARK_GROWTH))
            if legs is not None:
                longer = sum(path_length(leg) for leg in legs) - base_length
                obstacles.append(box)
                kinds.append("blocking" if longer > 0.5 else "narrowing")
                break
        else:
            if strict:
                raise ScenarioError(f"could not place static obstacle {len(obstacles) + 1} of "
                                    f"{static} keeping every goal reachable")
            break
    for _ in range(moving):
        for _attempt in range(tries):
            i = int(rng.integers(len(candidates)))
            if not spaced(candidates[i]):
                continue
            normal = np.array([-tangents[i, 1], tangents[i, 0]])
            radius = float(rng.uniform(0.15, 0.2))
            ends = []
            for sign in (1.0, -1.0):
                d = 0.0
                while d < 1.5:
                    p = candidates[i] + sign * (d + 0.05 + radius) * normal
                    if not (grid.in_bounds(p[None])[0] and grid.is_free(p[None])[0]):
                        break
                    d += 0.05
                ends.append(candidates[i] + sign * d * normal)
            if np.linalg.norm(ends[0] - ends[1]) < 0.6:
                continue
            # its whole run keeps clear of the stops (the robot waits near them: a run through
            # a start would hit a robot that has not moved yet)
            if point_segment_distance(stops, ends[0][None], ends[1][None]).min() < keep_clear:
                continue
            # it must let the robot by at one end of its run at least: a cylinder shuttling
            # across a corridor no wider than the robot plus itself blocks it for good
            statics = [o for o in obstacles if not o.moving]
            if not any(route_on(rasterize(grid, [*statics, Obstacle(
                    "cylinder", float(end[0]), float(end[1]), radius=radius)],
                    grow=MARK_GROWTH)) is not None
                       for end in ends):
                continue
            obstacles.append(Obstacle("cylinder", float(ends[0][0]), float(ends[0][1]),
                                      radius=radius,
                                      path=(tuple(map(float, ends[0])), tuple(map(float, ends[1]))),
                                      speed=float(rng.uniform(0.3, 0.5))))
            kinds.append("moving")
            break
        else:
            if strict:
                raise ScenarioError(f"could not place moving obstacle "
                                    f"{kinds.count('moving') + 1} of {moving} across the route")
            break
    return GeneratedScenario(tuple(obstacles), tuple(kinds), route)


def _centre(o: Obstacle) -> np.ndarray:
    """(2,) [m] a static obstacle's centre, a moving one's path midpoint."""
    if o.moving:
        return np.mean(np.asarray(o.path), axis=0)
    return np.array([o.x, o.y])
