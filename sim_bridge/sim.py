"""The simulator core: a robot footprint driven by unicycle kinematics through a maze of walls,
with real contacts computed by PyBullet (no rclpy here; ``sim_bridge.node`` wraps it for ROS).

World: the map frame of ``ecahd_core.maps`` (x along the grid columns, y up, metres). Every run of
occupied cells becomes a wall box 1 m high (runs with the same columns in consecutive rows are
merged into one box; unknown cells count as occupied, as ``GridMap.occupied`` says by default),
and four boxes fence the map's bounds, so the robot can never leave the map. PyBullet keeps only
the first 16 children of a compound shape (``createCollisionShapeArray`` drops the rest
silently), so the boxes are grouped, 16 at a time in ~2 m tiles, into static bodies; a label
image (cell -> body) tells a contact query which few bodies are near the robot. A 60 m x 60 m
building at 0.03 m/cell (2000 x 2000 cells, ~35 000 boxes) builds in about a second.
The robot body is the footprint extruded 0.5 m: a cylinder for circles, a box for axis-aligned
rectangles (quadruped, humanoid), the convex hull of the outline for any other polygon (a
non-convex polygon is over-approximated by its hull; Bullet inflates hulls by its 1 mm margin).

Obstacles that are not on the map (``SimConfig.obstacles``, from an ``ecahd_core.scenario``
file) are static boxes / cylinders 1 m high; moving ones are kinematic: before each step's motion
their pose is reset to ``Obstacle.position(t)`` at the step's end time, and they do not push the
robot (an overlap is a contact, and the robot may move out of it). An obstacle that overlaps the
robot's start pose deeper than ``contact_tolerance``, or whose centre (or a path point) is off the
map, is left out with one line in ``MazeSim.rejected_obstacles``.

LiDAR (``MazeSim.scan``): a planar fan of rays cast with ``rayTestBatch`` (at most
:data:`RAY_BATCH` rays per call) at height :data:`SCAN_Z` from the robot's pose composed with a
mounting offset. The robot's own body is in a collision filter group the rays skip. Ranges follow
REP 117: ``inf`` for no return within range_max, ``-inf`` for a return closer than range_min.
A sensor origin inside a wall or obstacle does not see that body (Bullet's rays ignore a shape
they start in).

Motion (D4RL maze2d's point mass, made a unicycle): ``step(v, w)`` clamps the command to
``|v| <= max_v``, ``|w| <= max_w`` and integrates the exact closed form over ``dt``::

    x' = x + v/w (sin(yaw + w dt) - sin(yaw))      (x + v dt cos(yaw) when w = 0)
    y' = y - v/w (cos(yaw + w dt) - cos(yaw))      (y + v dt sin(yaw) when w = 0)
    yaw' = yaw + w dt

in sub-steps short enough (half the smaller of one map cell and the robot's inscribed radius)
that no wall can be jumped over. The body is moved with resetBasePositionAndOrientation and
its contacts with the walls are queried with getClosestPoints(distance=0): no dynamics, no
planner cost map, the real shapes.

Contacts: a pose counts as penetrating when the robot shape overlaps a wall deeper than
``contact_tolerance`` (or deeper than it already did, so a robot placed in contact can still
move out). The penetrating part of a move is rejected, the rest is kept: the robot advances along
the commanded arc as far as it can (bisection), then slides along x or y with the remaining
displacement (maze walls are axis-aligned), keeping the new heading if that fits, else the old
one. A step is ``in_contact`` when part of its move was rejected or the final shape touches a
wall or obstacle; ``contact_count`` counts such steps since the last reset, and
``collision_kind`` says what was hit ("moving_obstacle" before "static_obstacle" before "wall"
when a step hit several), so a benchmark can count obstacle contacts apart from wall contacts.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from ecahd_core.controller import unicycle_step  # the kinematics (shared with record-demos)
from ecahd_core.errors import SimError
from ecahd_core.footprint import Footprint, make_footprint
from ecahd_core.maps import DEFAULT_MAP, DEFAULT_RESOLUTION, GridMap, load_map
from ecahd_core.scenario import Obstacle

logger = logging.getLogger(__name__)

WALL_HEIGHT = 1.0  # [m] z extent of the wall boxes, from z = 0
ROBOT_HEIGHT = 0.5  # [m] z extent of the robot body
ROBOT_Z = 0.5  # [m] height of the robot's centre (inside the walls' z range)
FENCE_THICKNESS = 1.0  # [m] walls around the map bounds
BISECTION_STEPS = 6  # advance-to-contact precision: sub-step length / 2**6
MAX_COMPOUND_SHAPES = 16  # children PyBullet keeps in one createCollisionShapeArray
WALL_TILE = 2.0  # [m] wall boxes are grouped into bodies per tile of this size
RAY_BATCH = 8192  # rays per rayTestBatch call (PyBullet refuses more than 16384)
SCAN_Z = 0.3  # [m] height of the LiDAR plane: inside the walls, obstacles and robot body
ROBOT_FILTER_GROUP = 0x40  # collision filter group of the robot body, which rays skip
RAY_FILTER_MASK = 0x3F  # Bullet's default, static, kinematic, debris, sensor, character groups

# what a contact was with (SimState.collision_kind), most informative first
MOVING_OBSTACLE, STATIC_OBSTACLE, WALL = "moving_obstacle", "static_obstacle", "wall"
COLLISION_KINDS = (MOVING_OBSTACLE, STATIC_OBSTACLE, WALL)

# drawing colours, RGB
_FREE_RGB = (255, 255, 255)
_WALL_RGB = (64, 64, 64)
_ROBOT_RGB = (40, 90, 220)
_CONTACT_RGB = (220, 40, 40)
_HEADING_RGB = (255, 200, 0)
_OBSTACLE_RGB = (150, 100, 40)


# ------------------------------------------------------------------------------ configuration
@dataclass(frozen=True, kw_only=True)
class SimConfig:
    """Simulator settings.

    Attributes:
        map: a built-in maze (maze2d-umaze, maze2d-medium, maze2d-large) or a Nav2 map YAML path.
        resolution: [m/cell] rasterisation of built-in mazes (ignored for YAML files).
        robot: footprint preset (circle, quadruped, humanoid) or a Nav2 polygon string.
        dt: [s] simulated time per step.
        max_v: [m/s] limit on |linear velocity|.
        max_w: [rad/s] limit on |angular velocity|.
        start: (x [m], y [m], yaw [rad]) pose after construction.
        contact_tolerance: [m] penetration depth still accepted as a legal pose.
        obstacles: obstacles that are not on the map (``ecahd_core.scenario``).
        seed: seed of the simulator's random generator (scan noise).
    """

    map: str = DEFAULT_MAP
    resolution: float = DEFAULT_RESOLUTION
    robot: str = "circle"
    dt: float = 0.02
    max_v: float = 1.0
    max_w: float = 2.0
    start: tuple[float, float, float] = (1.5, 1.5, 0.0)
    contact_tolerance: float = 0.005
    obstacles: tuple[Obstacle, ...] = ()
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("dt", "max_v", "max_w"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise SimError(f"sim {name} must be a positive finite number, got {value!r}")
        if not (math.isfinite(self.contact_tolerance) and self.contact_tolerance >= 0):
            raise SimError(f"sim contact_tolerance must be >= 0 m, got {self.contact_tolerance}")
        if len(self.start) != 3:
            raise SimError(f"sim start must be (x, y, yaw), got {self.start!r}")


@dataclass(frozen=True)
class SimState:
    """The robot after a step.

    Attributes:
        x, y: [m] position in the map frame.
        yaw: [rad] heading in (-pi, pi].
        v: [m/s] linear velocity of the step (the clamped command; the realised one when the
            move was blocked).
        w: [rad/s] angular velocity of the step (same rule).
        t: [s] simulated time since the simulator was built (a reset does not rewind it).
        in_contact: part of this step's move was rejected, or the shape touches a wall or an
            obstacle.
        contact_count: steps with ``in_contact`` since the last reset.
        collision_kind: what this step's contact was with: "moving_obstacle",
            "static_obstacle" or "wall" (the first of these when several), None without contact.
        collision_obstacle: index in ``SimConfig.obstacles`` of the obstacle hit, else None.
    """

    x: float
    y: float
    yaw: float
    v: float
    w: float
    t: float
    in_contact: bool
    contact_count: int
    collision_kind: str | None = None
    collision_obstacle: int | None = None


# ------------------------------------------------------------------------------- kinematics
def wrap_angle(a: float) -> float:
    """Angle [rad] wrapped to (-pi, pi]."""
    a = math.fmod(a + math.pi, 2.0 * math.pi)
    if a <= 0.0:
        a += 2.0 * math.pi
    return a - math.pi


# ------------------------------------------------------------------------------ wall boxes
def wall_rectangles(occupied: np.ndarray) -> list[tuple[int, int, int, int]]:
    """Cover the occupied cells with axis-aligned rectangles of cells.

    occupied: (H, W) bool -> [(row0, col0, row1, col1)], end indices exclusive. Each row's runs
    of occupied cells are merged with the identical run of the row below, so a maze wall of any
    length is one rectangle.
    """
    occ = np.asarray(occupied, dtype=bool)
    H, W = occ.shape
    rects: list[tuple[int, int, int, int]] = []
    open_runs: dict[tuple[int, int], int] = {}  # (col0, col1) -> first row
    for r in range(H + 1):
        runs: set[tuple[int, int]] = set()
        if r < H:
            edges = np.flatnonzero(np.diff(np.concatenate([[0], occ[r].astype(np.int8), [0]])))
            runs = {(int(a), int(b)) for a, b in zip(edges[0::2], edges[1::2])}
        for span in [s for s in open_runs if s not in runs]:
            rects.append((open_runs.pop(span), span[0], r, span[1]))
        for span in runs:
            open_runs.setdefault(span, r)
    return sorted(rects)


def _is_axis_aligned_rectangle(poly: np.ndarray) -> bool:
    if len(poly) != 4:
        return False
    xs, ys = np.unique(np.round(poly[:, 0], 9)), np.unique(np.round(poly[:, 1], 9))
    corners = {(float(a), float(b)) for a in xs for b in ys}
    return len(xs) == 2 and len(ys) == 2 and corners == {(float(a), float(b))
                                                           for a, b in np.round(poly, 9)}


def _is_convex(poly: np.ndarray) -> bool:
    d = np.roll(poly, -1, axis=0) - poly
    cross = d[:, 0] * np.roll(d[:, 1], -1) - d[:, 1] * np.roll(d[:, 0], -1)
    return bool(np.all(cross >= -1e-12) or np.all(cross <= 1e-12))


def _quaternion(yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by yaw about z (PyBullet's order)."""
    return 0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0)


@dataclass(frozen=True)
class Contact:
    """One body the robot shape touches: depth [m] of the overlap (0 when touching), what it is
    (WALL, STATIC_OBSTACLE, MOVING_OBSTACLE) and the obstacle's index (None for walls)."""

    depth: float
    kind: str
    obstacle: int | None = None


def scan_angles(beams: int, angle_min: float = -math.pi,
                angle_max: float | None = None) -> tuple[np.ndarray, float]:
    """Beam angles [rad] of a scan -> ((beams,) angles, increment), as LaserScan lays them out:
    angle_min + i * increment. angle_max None: a full turn, angle_max = angle_min + 2 pi -
    increment."""
    if not (isinstance(beams, (int, np.integer)) and beams >= 1):
        raise SimError(f"scan beams must be an integer >= 1, got {beams!r}")
    if angle_max is None:
        increment = 2.0 * math.pi / beams
    elif beams == 1:
        increment = 0.0
    else:
        increment = (angle_max - angle_min) / (beams - 1)
    if not (math.isfinite(angle_min) and math.isfinite(increment) and increment >= 0):
        raise SimError(f"scan angles must be finite with angle_max >= angle_min, got "
                       f"[{angle_min}, {angle_max}]")
    return angle_min + increment * np.arange(beams), float(increment)


def _collision_kind(contacts) -> tuple[str | None, int | None]:
    """(kind, obstacle index) of the most informative contact (COLLISION_KINDS order)."""
    best = None
    for c in contacts:
        if best is None or COLLISION_KINDS.index(c.kind) < COLLISION_KINDS.index(best.kind):
            best = c
    return (None, None) if best is None else (best.kind, best.obstacle)


# ---------------------------------------------------------------------------------- the sim
class MazeSim:
    """A footprint moving through the walls of a GridMap (and obstacles that are not on it), one
    PyBullet DIRECT client of its own.

    Usage::

        sim = MazeSim(SimConfig(map=DEFAULT_MAP, robot="quadruped", dt=0.02))
        state = sim.step(0.5, 0.0)   # SimState
        ranges = sim.scan(beams=360, range_max=8.0)   # (360,) [m]
        image = sim.render_topdown(256)
        sim.close()
    """

    def __init__(self, config: SimConfig) -> None:
        import pybullet
        from pybullet_utils.bullet_client import BulletClient

        self.config = config
        self.grid: GridMap = load_map(config.map, config.resolution)
        self.grid.require_free_space()
        self.footprint: Footprint = make_footprint(config.robot)
        self._client = BulletClient(connection_mode=pybullet.DIRECT)
        self._rng = np.random.default_rng(config.seed)
        self._build_walls(pybullet)
        self._robot = self._build_robot(pybullet)
        # longest sub-step [m] that cannot skip a wall cell or the robot's own width
        self._max_substep = 0.5 * min(self.grid.resolution, self.footprint.inscribed_radius)
        self._reach = self.footprint.circumscribed_radius
        self._backgrounds: dict[int, np.ndarray] = {}
        self._total_steps = 0  # since construction: t = total_steps * dt, without drift
        self._pose = (float(config.start[0]), float(config.start[1]), float(config.start[2]))
        self._state: SimState | None = None
        self.rejected_obstacles: list[str] = []
        self._obstacles: list[tuple[int, Obstacle, int]] = []  # (scenario index, obstacle, body)
        self._obstacle_xy = np.zeros((0, 2))  # (M, 2) current centres [m]
        self._obstacle_reach = np.zeros(0)
        self._obstacle_t0 = 0.0  # [s] sim time at which the moving obstacles set off
        self._build_obstacles(pybullet, config.obstacles)
        self.reset(*config.start)

    # ------------------------------------------------------------------------ construction
    def _compound_body(self, pybullet, half_extents, centres) -> int:
        shape = self._client.createCollisionShapeArray(
            shapeTypes=[pybullet.GEOM_BOX] * len(half_extents), halfExtents=half_extents,
            collisionFramePositions=centres)
        return self._client.createMultiBody(baseMass=0, baseCollisionShapeIndex=shape)

    def _build_walls(self, pybullet) -> None:
        """Static bodies of at most MAX_COMPOUND_SHAPES wall boxes each (boxes of one ~2 m tile
        together), the fence as one more body, and the (H, W) cell -> wall body label image."""
        g, res = self.grid, self.grid.resolution
        ox, oy = g.origin
        rects = np.asarray(wall_rectangles(g.occupied), dtype=np.int64).reshape(-1, 4)
        tile = max(1, int(round(WALL_TILE / res)))  # [cells]
        order = np.lexsort((rects[:, 1] // tile, rects[:, 0] // tile))
        rects = rects[order]  # (N, 4) row0, col0, row1, col1, tile by tile
        r0, c0, r1, c1 = rects.T
        half = np.stack([(c1 - c0) * res / 2, (r1 - r0) * res / 2,
                         np.full(len(rects), WALL_HEIGHT / 2)], axis=1)  # (N, 3)
        centre = np.stack([ox + (c0 + c1) * res / 2, oy + (r0 + r1) * res / 2,
                           np.full(len(rects), WALL_HEIGHT / 2)], axis=1)  # (N, 3)
        self._wall_bodies: list[int] = []
        self._cell_body = np.full(g.occupied.shape, -1, dtype=np.int32)  # index in _wall_bodies
        n = MAX_COMPOUND_SHAPES
        for k, i in enumerate(range(0, len(rects), n)):
            self._wall_bodies.append(self._compound_body(pybullet, half[i:i + n].tolist(),
                                                         centre[i:i + n].tolist()))
            for a, b, c, d in rects[i:i + n]:
                self._cell_body[a:c, b:d] = k
        xmin, ymin, xmax, ymax = g.bounds
        t = FENCE_THICKNESS
        cx, cy = (xmin + xmax) / 2, (ymin + ymax) / 2
        hx, hy = (xmax - xmin) / 2 + t, (ymax - ymin) / 2  # the x fences cover the corners
        fence = (([cx, ymin - t / 2], [hx, t / 2]), ([cx, ymax + t / 2], [hx, t / 2]),
                 ([xmin - t / 2, cy], [t / 2, hy]), ([xmax + t / 2, cy], [t / 2, hy]))
        self._fence = self._compound_body(pybullet, [[*h, WALL_HEIGHT / 2] for _, h in fence],
                                          [[*c, WALL_HEIGHT / 2] for c, _ in fence])
        self.n_wall_boxes = len(rects) + len(fence)
        self.n_wall_bodies = len(self._wall_bodies) + 1

    def _build_robot(self, pybullet) -> int:
        fp, h = self.footprint, ROBOT_HEIGHT / 2
        if fp.is_circle:
            shape = self._client.createCollisionShape(pybullet.GEOM_CYLINDER, radius=fp.radius,
                                                      height=ROBOT_HEIGHT)
        elif _is_axis_aligned_rectangle(fp.polygon):
            lo, hi = fp.polygon.min(axis=0), fp.polygon.max(axis=0)
            shape = self._client.createCollisionShape(
                pybullet.GEOM_BOX, halfExtents=[*((hi - lo) / 2).tolist(), h],
                collisionFramePosition=[*((hi + lo) / 2).tolist(), 0.0])
        else:
            if not _is_convex(fp.polygon):
                logger.warning("footprint %s is not convex: the simulated body is its convex hull",
                               fp.name)
            vertices = [[float(px), float(py), z] for px, py in fp.polygon for z in (-h, h)]
            shape = self._client.createCollisionShape(pybullet.GEOM_MESH, vertices=vertices)
        body = self._client.createMultiBody(baseMass=0, baseCollisionShapeIndex=shape,
                                            basePosition=[0.0, 0.0, ROBOT_Z])
        # the LiDAR's rays (mask RAY_FILTER_MASK) skip the robot's own body
        self._client.setCollisionFilterGroupMask(body, -1, ROBOT_FILTER_GROUP, -1)
        return body

    def set_obstacles(self, obstacles) -> list[str]:
        """Replace the obstacles (a new scenario, e.g. per benchmark episode): the old bodies
        go, the new ones appear; moving ones set off from their path's start now. Returns the
        lines of the obstacles left out (off the map, overlapping the robot)."""
        import pybullet

        for _, _, body in self._obstacles:
            self._client.removeBody(body)
        self._obstacles = []
        self.rejected_obstacles = []
        self._obstacle_t0 = self._total_steps * self.config.dt
        self._build_obstacles(pybullet, tuple(obstacles))
        return list(self.rejected_obstacles)

    def _build_obstacles(self, pybullet, obstacles) -> None:
        """A static body per obstacle; those off the map or on the robot's pose are rejected."""
        t = self._total_steps * self.config.dt - self._obstacle_t0
        for i, ob in enumerate(obstacles):
            points = np.asarray(ob.path if ob.moving else [(ob.x, ob.y)], dtype=np.float64)
            if not np.all(self.grid.in_bounds(points)):
                self._reject(i, ob, "it is (or its path goes) outside the map")
                continue
            if ob.shape == "box":
                shape = self._client.createCollisionShape(
                    pybullet.GEOM_BOX, halfExtents=[ob.size[0] / 2, ob.size[1] / 2,
                                                    WALL_HEIGHT / 2])
            else:
                shape = self._client.createCollisionShape(pybullet.GEOM_CYLINDER,
                                                          radius=ob.radius, height=WALL_HEIGHT)
            x, y = ob.position(t)
            body = self._client.createMultiBody(baseMass=0, baseCollisionShapeIndex=shape,
                                                basePosition=[x, y, WALL_HEIGHT / 2],
                                                baseOrientation=_quaternion(ob.yaw))
            self._place(*self._pose)
            points = self._client.getClosestPoints(self._robot, body, 0.0)
            depth = max(0.0, -min(p[8] for p in points)) if points else None
            if depth is not None and depth > self.config.contact_tolerance:
                self._client.removeBody(body)
                self._reject(i, ob, f"it overlaps the robot's start pose "
                                    f"({self._pose[0]:.3f}, {self._pose[1]:.3f}, "
                                    f"{self._pose[2]:.3f}) by {depth:.3f} m")
                continue
            self._obstacles.append((i, ob, body))
        self._obstacle_xy = np.array([ob.position(t) for _, ob, _ in self._obstacles],
                                     dtype=np.float64).reshape(-1, 2)
        self._obstacle_reach = np.array([ob.bounding_radius for _, ob, _ in self._obstacles])

    def _reject(self, index: int, obstacle: Obstacle, why: str) -> None:
        line = f"obstacle {index} {obstacle.to_dict()!r} left out: {why}"
        self.rejected_obstacles.append(line)
        logger.warning(line)

    def _move_obstacles(self, t: float) -> None:
        """Kinematic obstacles to their pose at time t [s]."""
        for k, (_, ob, body) in enumerate(self._obstacles):
            if ob.moving:
                x, y = ob.position(t - self._obstacle_t0)
                self._obstacle_xy[k] = (x, y)
                self._client.resetBasePositionAndOrientation(body, [x, y, WALL_HEIGHT / 2],
                                                             _quaternion(ob.yaw))

    @property
    def obstacles(self) -> list[tuple[int, Obstacle, tuple[float, float]]]:
        """The obstacles in the world: (index in SimConfig.obstacles, obstacle, current centre)."""
        return [(i, ob, (float(x), float(y)))
                for (i, ob, _), (x, y) in zip(self._obstacles, self._obstacle_xy)]

    # ---------------------------------------------------------------------------- queries
    def _place(self, x: float, y: float, yaw: float) -> None:
        self._client.resetBasePositionAndOrientation(self._robot, [x, y, ROBOT_Z], _quaternion(yaw))

    def _nearby_bodies(self, x: float, y: float) -> list[tuple[int, str, int | None]]:
        """(body, kind, obstacle index) of the bodies that may touch the robot centred at (x, y):
        the fence, wall bodies with a cell within reach, obstacles within reach."""
        g, res = self.grid, self.grid.resolution
        near = [(self._fence, WALL, None)]
        k = int(math.ceil(self._reach / res)) + 1  # [cells]
        col = int(math.floor((x - g.origin[0]) / res))
        row = int(math.floor((y - g.origin[1]) / res))
        H, W = self._cell_body.shape
        window = self._cell_body[max(0, row - k):min(H, row + k + 1),
                                 max(0, col - k):min(W, col + k + 1)]
        for b in np.unique(window[window >= 0]):
            near.append((self._wall_bodies[b], WALL, None))
        if len(self._obstacles):
            d = np.hypot(self._obstacle_xy[:, 0] - x, self._obstacle_xy[:, 1] - y)
            for m in np.flatnonzero(d <= self._obstacle_reach + self._reach + 1e-6):
                i, ob, body = self._obstacles[m]
                near.append((body, MOVING_OBSTACLE if ob.moving else STATIC_OBSTACLE, i))
        return near

    def _contacts(self, x: float, y: float, yaw: float) -> list[Contact]:
        """Every body the robot shape at a pose touches or overlaps. Leaves the body there."""
        self._place(x, y, yaw)
        found = []
        for body, kind, index in self._nearby_bodies(x, y):
            points = self._client.getClosestPoints(self._robot, body, 0.0)
            if points:  # p[8]: contactDistance, < 0 inside
                found.append(Contact(max(0.0, -min(p[8] for p in points)), kind, index))
        return found

    def penetration(self, x: float, y: float, yaw: float = 0.0) -> float:
        """Depth [m] by which the robot shape at (x, y, yaw) would overlap a wall or obstacle
        (0 if none). Does not move the simulated robot."""
        contacts = self._contacts(float(x), float(y), float(yaw))
        self._place(*self._pose)
        return max((c.depth for c in contacts), default=0.0)

    def collides(self, x: float, y: float, yaw: float = 0.0) -> bool:
        """Whether the robot shape at (x, y, yaw) overlaps a wall or obstacle deeper than the
        tolerance."""
        return self.penetration(x, y, yaw) > self.config.contact_tolerance

    @property
    def state(self) -> SimState:
        """The state after the last reset or step."""
        assert self._state is not None
        return self._state

    # ----------------------------------------------------------------------------- control
    def reset(self, x: float, y: float, yaw: float = 0.0) -> SimState:
        """Teleport the robot to a free pose, zero its velocity and contact count.

        Raises SimError for a non-finite pose, a position off the map, or a pose whose shape
        penetrates a wall or obstacle. Simulated time keeps running (it drives a monotonic clock).
        """
        x, y, yaw = float(x), float(y), float(yaw)
        if not all(math.isfinite(v) for v in (x, y, yaw)):
            raise SimError(f"reset pose ({x}, {y}, {yaw}) is not finite")
        if not self.grid.in_bounds(np.array([x, y])):
            xmin, ymin, xmax, ymax = self.grid.bounds
            raise SimError(f"reset position ({x:.3f}, {y:.3f}) is outside the map "
                           f"[{xmin:.2f}, {xmax:.2f}] x [{ymin:.2f}, {ymax:.2f}] m")
        contacts = self._contacts(x, y, yaw)
        self._place(*self._pose)
        deepest = max(contacts, key=lambda c: c.depth, default=None)
        if deepest is not None and deepest.depth > self.config.contact_tolerance:
            what = "a wall" if deepest.kind == WALL else f"obstacle {deepest.obstacle}"
            raise SimError(f"reset pose ({x:.3f}, {y:.3f}, {yaw:.3f}) puts the "
                           f"{self.footprint.name} footprint {deepest.depth:.3f} m into {what}")
        self._pose = (x, y, wrap_angle(yaw))
        self._place(*self._pose)
        self._state = SimState(*self._pose, v=0.0, w=0.0, t=self._total_steps * self.config.dt,
                               in_contact=False, contact_count=0)
        return self._state

    def step(self, v: float, w: float) -> SimState:
        """Advance dt seconds with linear velocity v [m/s] and angular velocity w [rad/s]
        (clamped to the limits). Raises SimError for non-finite input."""
        v, w = float(v), float(w)
        if not (math.isfinite(v) and math.isfinite(w)):
            raise SimError(f"velocity command (v={v}, w={w}) is not finite")
        cfg = self.config
        v = min(max(v, -cfg.max_v), cfg.max_v)
        w = min(max(w, -cfg.max_w), cfg.max_w)
        # 0. moving obstacles to where they are at the end of this step
        self._move_obstacles((self._total_steps + 1) * cfg.dt)
        # 1. sub-steps: no point of the body moves further than _max_substep in one of them
        travel = abs(v) * cfg.dt + abs(w) * cfg.dt * self._reach
        n_sub = max(1, math.ceil(travel / self._max_substep))
        h = cfg.dt / n_sub
        x0, y0, yaw0 = self._pose
        pose, blockers = self._pose, []
        for _ in range(n_sub):
            # 2. the exact arc for this sub-step, then keep what does not penetrate
            target = unicycle_step(*pose, v, w, h)
            pose, blocker = self._move(pose, target)
            blockers += blocker
        x1, y1, yaw1 = pose
        self._pose = (x1, y1, wrap_angle(yaw1))
        # 3. contact at the final pose
        touching = self._contacts(*self._pose)
        self._total_steps += 1
        in_contact = bool(blockers or touching)
        if blockers:  # report the velocity that was realised, not the one commanded
            mid = yaw0 + (yaw1 - yaw0) / 2
            v = ((x1 - x0) * math.cos(mid) + (y1 - y0) * math.sin(mid)) / cfg.dt
            w = (yaw1 - yaw0) / cfg.dt
        count = self.state.contact_count + int(in_contact)
        kind, obstacle = _collision_kind(blockers + touching)
        self._state = SimState(*self._pose, v=v, w=w, t=self._total_steps * cfg.dt,
                               in_contact=in_contact, contact_count=count,
                               collision_kind=kind, collision_obstacle=obstacle)
        return self._state

    def _move(self, pose: tuple[float, float, float], target: tuple[float, float, float]
              ) -> tuple[tuple[float, float, float], list[Contact]]:
        """Move from pose towards target, rejecting the penetrating part -> (new pose, the
        contacts that blocked the move; empty when it was not clipped)."""
        depth0 = max((c.depth for c in self._contacts(*pose)), default=0.0)
        allowed = max(self.config.contact_tolerance, depth0) + 1e-9
        blockers: list[Contact] = []

        def fits(p: tuple[float, float, float]) -> bool:
            deep = [c for c in self._contacts(*p) if c.depth > allowed]
            if deep and not blockers:
                blockers.extend(deep)
            return not deep

        if fits(target):
            return target, []
        # advance along the move as far as it fits (bisection on the fraction of the move)
        lo, hi = 0.0, 1.0
        for _ in range(BISECTION_STEPS):
            mid = (lo + hi) / 2
            if fits(tuple(a + mid * (b - a) for a, b in zip(pose, target))):
                lo = mid
            else:
                hi = mid
        px, py, pyaw = (a + lo * (b - a) for a, b in zip(pose, target))
        # slide: the remaining displacement along x or along y, larger component first
        rx, ry = target[0] - px, target[1] - py
        slides = [(px + rx, py), (px, py + ry)]
        if abs(ry) > abs(rx):
            slides.reverse()
        for yaw in (target[2], pyaw):
            for sx, sy in slides:
                if fits((sx, sy, yaw)):
                    return (sx, sy, yaw), blockers
            if yaw != pyaw and fits((px, py, yaw)):
                return (px, py, yaw), blockers
        return (px, py, pyaw), blockers

    # ------------------------------------------------------------------------------ sensing
    def sensor_pose(self, offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
                    ) -> tuple[float, float, float]:
        """(x [m], y [m], yaw [rad]) in the map frame of a sensor mounted at ``offset``
        (x, y, yaw in base_link) on the robot at its current pose."""
        x, y, yaw = self._pose
        ox, oy, oyaw = (float(v) for v in offset)
        c, s = math.cos(yaw), math.sin(yaw)
        return x + c * ox - s * oy, y + s * ox + c * oy, wrap_angle(yaw + oyaw)

    def scan(self, offset: tuple[float, float, float] = (0.0, 0.0, 0.0), beams: int = 360,
             range_min: float = 0.1, range_max: float = 8.0, angle_min: float = -math.pi,
             angle_max: float | None = None, *, noise_std: float = 0.0,
             rng: np.random.Generator | None = None) -> np.ndarray:
        """A 2D LiDAR scan from the current pose -> (beams,) ranges [m], REP 117 style.

        offset: (x [m], y [m], yaw [rad]) of the sensor in base_link. Beam i points at
        angle_min + i * increment in the sensor frame (see :func:`scan_angles`; angle_max None
        = a full turn). A beam that hits nothing within range_max reads ``inf``; a hit closer
        than range_min reads ``-inf``. noise_std [m]: Gaussian noise added to the hits (from
        ``rng``, by default the simulator's generator seeded with ``SimConfig.seed``) before
        that classification. Walls and obstacles are seen; the robot's own body is not.
        """
        if not (math.isfinite(range_min) and math.isfinite(range_max)
                and 0 <= range_min < range_max):
            raise SimError(f"scan range must satisfy 0 <= range_min < range_max, got "
                           f"[{range_min}, {range_max}]")
        if not (math.isfinite(noise_std) and noise_std >= 0):
            raise SimError(f"scan noise_std must be >= 0 m, got {noise_std}")
        angles, _ = scan_angles(beams, angle_min, angle_max)  # (N,) in the sensor frame
        sx, sy, syaw = self.sensor_pose(offset)
        a = syaw + angles
        n = len(a)
        starts = np.tile([sx, sy, SCAN_Z], (n, 1))  # (N, 3)
        ends = np.stack([sx + range_max * np.cos(a), sy + range_max * np.sin(a),
                         np.full(n, SCAN_Z)], axis=1)  # (N, 3)
        fraction = np.ones(n)
        for i in range(0, n, RAY_BATCH):
            hits = self._client.rayTestBatch(starts[i:i + RAY_BATCH].tolist(),
                                             ends[i:i + RAY_BATCH].tolist(),
                                             collisionFilterMask=RAY_FILTER_MASK)
            fraction[i:i + len(hits)] = [h[2] if h[0] >= 0 else 1.0 for h in hits]
        hit = fraction < 1.0
        ranges = np.where(hit, fraction * range_max, np.inf)
        if noise_std > 0:
            rng = self._rng if rng is None else rng
            ranges[hit] += rng.normal(0.0, noise_std, int(hit.sum()))
            ranges[hit & (ranges > range_max)] = np.inf
        ranges[hit & (ranges < range_min)] = -np.inf
        return ranges

    # ------------------------------------------------------------------------------ output
    def render_topdown(self, size: int = 256) -> np.ndarray:
        """A top view drawn with OpenCV: walls dark grey, obstacles brown, the robot's footprint
        blue (red while in contact) with a yellow heading line. size: [px] of the longer side
        -> (H, W, 3) uint8 RGB, north (+y) up."""
        import cv2

        if not (isinstance(size, (int, np.integer)) and size >= 8):
            raise SimError(f"render size must be an integer >= 8 px, got {size!r}")
        xmin, ymin, xmax, ymax = self.grid.bounds
        scale = size / max(xmax - xmin, ymax - ymin)  # [px/m]
        if size not in self._backgrounds:
            W = max(1, int(round((xmax - xmin) * scale)))
            H = max(1, int(round((ymax - ymin) * scale)))
            occ = cv2.resize(self.grid.occupied[::-1].astype(np.uint8), (W, H),
                             interpolation=cv2.INTER_NEAREST).astype(bool)
            bg = np.empty((H, W, 3), dtype=np.uint8)
            bg[:] = _FREE_RGB
            bg[occ] = _WALL_RGB
            self._backgrounds[size] = bg
        img = self._backgrounds[size].copy()
        s = self.state

        def to_px(xy: np.ndarray) -> np.ndarray:
            return np.stack([(xy[..., 0] - xmin) * scale, (ymax - xy[..., 1]) * scale],
                            axis=-1).round().astype(np.int32)

        for _, ob, _ in self._obstacles:
            cv2.fillPoly(img, [to_px(ob.footprint(s.t))], _OBSTACLE_RGB)
        outline = self.footprint.transformed(np.array([s.x, s.y]), np.array(s.yaw), "polygon")
        cv2.fillPoly(img, [to_px(outline)], _CONTACT_RGB if s.in_contact else _ROBOT_RGB)
        nose = np.array([s.x, s.y]) + self._reach * np.array([math.cos(s.yaw), math.sin(s.yaw)])
        c, tip = to_px(np.array([s.x, s.y])), to_px(nose)
        cv2.line(img, tuple(int(v) for v in c), tuple(int(v) for v in tip), _HEADING_RGB,
                 max(1, size // 128))
        return img

    def close(self) -> None:
        """Disconnect the PyBullet client (idempotent)."""
        client, self._client = self._client, None
        if client is not None:
            client.disconnect()

    def __enter__(self) -> MazeSim:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
