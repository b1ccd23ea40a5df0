"""The simulator core: a robot footprint driven by unicycle kinematics through a maze of walls,
with real contacts computed by PyBullet (no rclpy here; ``sim_bridge.node`` wraps it for ROS).

World: the map frame of ``ecahd_core.maps`` (x along the grid columns, y up, metres). Every run of
occupied cells becomes a wall box 1 m high (runs with the same columns in consecutive rows are
merged into one box), and four boxes fence the map's bounds, so the robot can never leave the map.
The robot body is the footprint extruded 0.5 m: a cylinder for circles, a box for axis-aligned
rectangles (quadruped, humanoid), the convex hull of the outline for any other polygon (a
non-convex polygon is over-approximated by its hull; Bullet inflates hulls by its 1 mm margin).

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
wall; ``contact_count`` counts such steps since the last reset.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from ecahd_core.errors import EcahdError, SimError
from ecahd_core.footprint import Footprint, make_footprint
from ecahd_core.maps import DEFAULT_RESOLUTION, GridMap, load_map

logger = logging.getLogger(__name__)

WALL_HEIGHT = 1.0  # [m] z extent of the wall boxes, from z = 0
ROBOT_HEIGHT = 0.5  # [m] z extent of the robot body
ROBOT_Z = 0.5  # [m] height of the robot's centre (inside the walls' z range)
FENCE_THICKNESS = 1.0  # [m] walls around the map bounds
BISECTION_STEPS = 6  # advance-to-contact precision: sub-step length / 2**6
D4RL_MAX_EPISODE_STEPS = 800  # maze2d-large's episode length
D4RL_GOAL_RADIUS = 0.5  # [m] sparse reward 1 within this distance of the goal

# drawing colours, RGB
_FREE_RGB = (255, 255, 255)
_WALL_RGB = (64, 64, 64)
_ROBOT_RGB = (40, 90, 220)
_CONTACT_RGB = (220, 40, 40)
_HEADING_RGB = (255, 200, 0)




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
    """

    map: str = "maze2d-large"
    resolution: float = DEFAULT_RESOLUTION
    robot: str = "circle"
    dt: float = 0.02
    max_v: float = 1.0
    max_w: float = 2.0
    start: tuple[float, float, float] = (1.5, 1.5, 0.0)
    contact_tolerance: float = 0.005

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
        in_contact: part of this step's move was rejected, or the shape touches a wall.
        contact_count: steps with ``in_contact`` since the last reset.
    """

    x: float
    y: float
    yaw: float
    v: float
    w: float
    t: float
    in_contact: bool
    contact_count: int


# ------------------------------------------------------------------------------- kinematics
def wrap_angle(a: float) -> float:
    """Angle [rad] wrapped to (-pi, pi]."""
    a = math.fmod(a + math.pi, 2.0 * math.pi)
    if a <= 0.0:
        a += 2.0 * math.pi
    return a - math.pi


def unicycle_step(x: float, y: float, yaw: float, v: float, w: float,
                  dt: float) -> tuple[float, float, float]:
    """Exact unicycle motion for constant v [m/s], w [rad/s] over dt [s] -> (x, y, yaw)."""
    if abs(w) < 1e-9:
        return x + v * dt * math.cos(yaw), y + v * dt * math.sin(yaw), yaw
    yaw1 = yaw + w * dt
    return (x + v / w * (math.sin(yaw1) - math.sin(yaw)),
            y - v / w * (math.cos(yaw1) - math.cos(yaw)),
            yaw1)


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


# ---------------------------------------------------------------------------------- the sim
class MazeSim:
    """A footprint moving through the walls of a GridMap, one PyBullet DIRECT client of its own.

    Usage::

        sim = MazeSim(SimConfig(map="maze2d-large", robot="quadruped", dt=0.02))
        state = sim.step(0.5, 0.0)   # SimState
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
        self._walls, self.n_wall_boxes = self._build_walls(pybullet)
        self._robot = self._build_robot(pybullet)
        # longest sub-step [m] that cannot skip a wall cell or the robot's own width
        self._max_substep = 0.5 * min(self.grid.resolution, self.footprint.inscribed_radius)
        self._reach = self.footprint.circumscribed_radius
        self._backgrounds: dict[int, np.ndarray] = {}
        self._total_steps = 0  # since construction: t = total_steps * dt, without drift
        self._pose = (0.0, 0.0, 0.0)
        self._state: SimState | None = None
        self.reset(*config.start)

    # ------------------------------------------------------------------------ construction
    def _build_walls(self, pybullet) -> tuple[int, int]:
        """One static body whose compound shape holds every wall box and the fence."""
        g, res = self.grid, self.grid.resolution
        ox, oy = g.origin
        half_extents, centres = [], []
        for r0, c0, r1, c1 in wall_rectangles(g.occupied):
            half_extents.append([(c1 - c0) * res / 2, (r1 - r0) * res / 2, WALL_HEIGHT / 2])
            centres.append([ox + (c0 + c1) * res / 2, oy + (r0 + r1) * res / 2, WALL_HEIGHT / 2])
        xmin, ymin, xmax, ymax = g.bounds
        t = FENCE_THICKNESS
        cx, cy = (xmin + xmax) / 2, (ymin + ymax) / 2
        hx, hy = (xmax - xmin) / 2 + t, (ymax - ymin) / 2  # the x fences cover the corners
        for centre, half in (([cx, ymin - t / 2], [hx, t / 2]), ([cx, ymax + t / 2], [hx, t / 2]),
                             ([xmin - t / 2, cy], [t / 2, hy]), ([xmax + t / 2, cy], [t / 2, hy])):
            half_extents.append([*half, WALL_HEIGHT / 2])
            centres.append([*centre, WALL_HEIGHT / 2])
        n = len(half_extents)
        shape = self._client.createCollisionShapeArray(
            shapeTypes=[pybullet.GEOM_BOX] * n, halfExtents=half_extents,
            collisionFramePositions=centres)
        body = self._client.createMultiBody(baseMass=0, baseCollisionShapeIndex=shape)
        return body, n

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
        return self._client.createMultiBody(baseMass=0, baseCollisionShapeIndex=shape,
                                            basePosition=[0.0, 0.0, ROBOT_Z])

    # ---------------------------------------------------------------------------- queries
    def _place(self, x: float, y: float, yaw: float) -> None:
        self._client.resetBasePositionAndOrientation(self._robot, [x, y, ROBOT_Z], _quaternion(yaw))

    def _contact_depth(self, x: float, y: float, yaw: float) -> float | None:
        """Deepest overlap [m] of the robot shape at a pose with the walls (0 when touching),
        None when no wall is touched. Leaves the body at that pose."""
        self._place(x, y, yaw)
        points = self._client.getClosestPoints(self._robot, self._walls, 0.0)
        if not points:
            return None
        return max(0.0, -min(p[8] for p in points))  # p[8]: contactDistance, < 0 inside

    def penetration(self, x: float, y: float, yaw: float = 0.0) -> float:
        """Depth [m] by which the robot shape at (x, y, yaw) would overlap a wall (0 if none).
        Does not move the simulated robot."""
        depth = self._contact_depth(float(x), float(y), float(yaw))
        self._place(*self._pose)
        return 0.0 if depth is None else depth

    def collides(self, x: float, y: float, yaw: float = 0.0) -> bool:
        """Whether the robot shape at (x, y, yaw) overlaps a wall deeper than the tolerance."""
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
        penetrates a wall. Simulated time keeps running (it drives a monotonic clock).
        """
        x, y, yaw = float(x), float(y), float(yaw)
        if not all(math.isfinite(v) for v in (x, y, yaw)):
            raise SimError(f"reset pose ({x}, {y}, {yaw}) is not finite")
        if not self.grid.in_bounds(np.array([x, y])):
            xmin, ymin, xmax, ymax = self.grid.bounds
            raise SimError(f"reset position ({x:.3f}, {y:.3f}) is outside the map "
                           f"[{xmin:.2f}, {xmax:.2f}] x [{ymin:.2f}, {ymax:.2f}] m")
        depth = self.penetration(x, y, yaw)
        if depth > self.config.contact_tolerance:
            raise SimError(f"reset pose ({x:.3f}, {y:.3f}, {yaw:.3f}) puts the "
                           f"{self.footprint.name} footprint {depth:.3f} m into a wall")
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
        # 1. sub-steps: no point of the body moves further than _max_substep in one of them
        travel = abs(v) * cfg.dt + abs(w) * cfg.dt * self._reach
        n_sub = max(1, math.ceil(travel / self._max_substep))
        h = cfg.dt / n_sub
        x0, y0, yaw0 = self._pose
        pose, blocked = self._pose, False
        for _ in range(n_sub):
            # 2. the exact arc for this sub-step, then keep what does not penetrate
            target = unicycle_step(*pose, v, w, h)
            pose, clipped = self._move(pose, target)
            blocked |= clipped
        x1, y1, yaw1 = pose
        self._pose = (x1, y1, wrap_angle(yaw1))
        # 3. contact at the final pose
        touching = self._contact_depth(*self._pose) is not None
        self._total_steps += 1
        in_contact = blocked or touching
        if blocked:  # report the velocity that was realised, not the one commanded
            mid = yaw0 + (yaw1 - yaw0) / 2
            v = ((x1 - x0) * math.cos(mid) + (y1 - y0) * math.sin(mid)) / cfg.dt
            w = (yaw1 - yaw0) / cfg.dt
        count = self.state.contact_count + int(in_contact)
        self._state = SimState(*self._pose, v=v, w=w, t=self._total_steps * cfg.dt,
                               in_contact=in_contact, contact_count=count)
        return self._state

    def _move(self, pose: tuple[float, float, float],
              target: tuple[float, float, float]) -> tuple[tuple[float, float, float], bool]:
        """Move from pose towards target, rejecting the penetrating part -> (new pose, clipped)."""
        depth0 = self._contact_depth(*pose)
        allowed = max(self.config.contact_tolerance, depth0 or 0.0) + 1e-9

        def fits(p: tuple[float, float, float]) -> bool:
            depth = self._contact_depth(*p)
            return depth is None or depth <= allowed

        if fits(target):
            return target, False
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
                    return (sx, sy, yaw), True
            if yaw != pyaw and fits((px, py, yaw)):
                return (px, py, yaw), True
        return (px, py, pyaw), True

    # ------------------------------------------------------------------------------ output
    def render_topdown(self, size: int = 256) -> np.ndarray:
        """A top view drawn with OpenCV: walls dark grey, the robot's footprint blue (red while
        in contact) with a yellow heading line. size: [px] of the longer side
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


# ---------------------------------------------------------------------------------- episodes
@dataclass(frozen=True)
class EpisodeStatus:
    """Bookkeeping after one control step of a D4RL maze2d-style episode.

    Attributes:
        step: control steps taken so far (1 after the first update).
        reward: this step's sparse reward (1.0 within goal_radius of the goal, else 0.0).
        total_reward: sum of rewards so far.
        distance: [m] from the robot to the goal.
        first_reach_step: the step that first earned a reward, None until then.
        contact_steps: steps reported in contact.
        done: the episode has used all its steps.
    """

    step: int
    reward: float
    total_reward: float
    distance: float
    first_reach_step: int | None
    contact_steps: int
    done: bool

    @property
    def reached(self) -> bool:
        return self.first_reach_step is not None


class EpisodeTracker:
    """Counts a D4RL maze2d episode: at most ``max_steps`` control steps, reward 1 per step
    within ``goal_radius`` [m] of the goal (D4RL's sparse reward, no early termination)."""

    def __init__(self, goal_xy, *, max_steps: int = D4RL_MAX_EPISODE_STEPS,
                 goal_radius: float = D4RL_GOAL_RADIUS) -> None:
        goal = np.asarray(goal_xy, dtype=np.float64).reshape(-1)
        if goal.shape != (2,) or not np.all(np.isfinite(goal)):
            raise SimError(f"episode goal must be a finite (x, y), got {goal_xy!r}")
        if not (isinstance(max_steps, (int, np.integer)) and max_steps > 0):
            raise SimError(f"episode max_steps must be a positive integer, got {max_steps!r}")
        if not (math.isfinite(goal_radius) and goal_radius > 0):
            raise SimError(f"episode goal_radius must be > 0 m, got {goal_radius}")
        self.goal = goal
        self.max_steps = int(max_steps)
        self.goal_radius = float(goal_radius)
        self.status = EpisodeStatus(step=0, reward=0.0, total_reward=0.0, distance=math.inf,
                                    first_reach_step=None, contact_steps=0, done=False)

    def update(self, state: SimState) -> EpisodeStatus:
        """Account for one control step that ended in ``state``; raises SimError once done."""
        prev = self.status
        if prev.done:
            raise SimError(f"the episode is over after {self.max_steps} steps")
        step = prev.step + 1
        distance = float(math.hypot(state.x - self.goal[0], state.y - self.goal[1]))
        reward = 1.0 if distance <= self.goal_radius else 0.0
        first = prev.first_reach_step if prev.first_reach_step is not None else (
            step if reward > 0 else None)
        self.status = EpisodeStatus(step=step, reward=reward,
                                    total_reward=prev.total_reward + reward, distance=distance, first_reach_step=first,
                                    contact_steps=prev.contact_steps + int(state.in_contact),
                                    done=step >= self.max_steps)
        return self.status
