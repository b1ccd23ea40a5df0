"""The path-tracking controller the local_refiner node drives with (pure numpy, no rclpy).

Pure pursuit: the lookahead point is the first point of the path at least ``lookahead`` m from
the robot, beyond the path point nearest to it. With alpha the heading error to it and L its
distance, the command is the arc v = max_v, w = v * 2 sin(alpha) / L, slowed so |w| <= max_w and
so the robot can stop at the goal (v <= sqrt(2 max_accel d_goal)); when |alpha| > pi/4 the robot
first turns on the spot (v = 0, w = clip(2 alpha)). |dv| <= max_accel * dt per tick.

Poses are (x [m], y [m], yaw [rad]); paths are (N, 2) [m] in the same frame.
"""
from __future__ import annotations

import math

import numpy as np

ROTATE_THRESHOLD = math.pi / 4  # [rad] heading error above which the robot turns on the spot
ROTATE_GAIN = 2.0  # [1/s] w = gain * alpha when turning on the spot
RESAMPLE_STEP = 0.05  # [m] spacing of the path points the lookahead search walks


def unicycle_step(x: float, y: float, yaw: float, v: float, w: float,
                  dt: float) -> tuple[float, float, float]:
    """Exact unicycle motion for constant v [m/s], w [rad/s] over dt [s] -> (x, y, yaw) (the
    simulator's kinematics, ``sim_bridge.sim``; the operator's, ``ecahd_core.operator``)."""
    if abs(w) < 1e-9:
        return x + v * dt * math.cos(yaw), y + v * dt * math.sin(yaw), yaw
    yaw1 = yaw + w * dt
    return (x + v / w * (math.sin(yaw1) - math.sin(yaw)),
            y - v / w * (math.cos(yaw1) - math.cos(yaw)),
            yaw1)


def straight_local_plan(a: np.ndarray, b: np.ndarray, points: int) -> np.ndarray:
    """LocalPlan(a, b): (points, 2) [m] evenly spaced from a to b, both included."""
    frac = np.linspace(0.0, 1.0, points)[:, None]
    return a[None] + frac * (b - a)[None]


def resample(path: np.ndarray, step: float = RESAMPLE_STEP) -> np.ndarray:
    """(N, 2) polyline -> (M, 2) points at most ``step`` m apart, the vertices included."""
    out = [path[:1]]
    for a, b in zip(path[:-1], path[1:]):
        n = max(1, int(math.ceil(np.linalg.norm(b - a) / step)))
        out.append(a + np.linspace(0.0, 1.0, n + 1)[1:, None] * (b - a))
    return np.concatenate(out)


def lookahead_point(path: np.ndarray, xy: np.ndarray, lookahead: float) -> np.ndarray:
    """The first point of ``path`` (N, 2) beyond the one nearest ``xy`` that is at least
    ``lookahead`` m from ``xy``; the path's end if none is."""
    pts = resample(path)
    d = np.linalg.norm(pts - xy[None], axis=1)
    ahead = np.flatnonzero(d[int(np.argmin(d)):] >= lookahead)
    return pts[int(np.argmin(d)) + ahead[0]] if len(ahead) else pts[-1]


def pure_pursuit(pose: tuple[float, float, float], target: np.ndarray, goal_distance: float,
                 v_prev: float, dt: float, p) -> tuple[float, float]:
    """(v [m/s], w [rad/s]) towards ``target`` from ``pose`` (x, y, yaw) within the limits of
    ``p`` (any object with max_v [m/s], max_w [rad/s], max_accel [m/s^2]); dt [s]."""
    x, y, yaw = pose
    dx, dy = float(target[0] - x), float(target[1] - y)
    L = math.hypot(dx, dy)
    if L < 1e-6:
        return 0.0, 0.0
    alpha = math.atan2(math.sin(math.atan2(dy, dx) - yaw), math.cos(math.atan2(dy, dx) - yaw))
    if abs(alpha) > ROTATE_THRESHOLD:  # turn on the spot first
        return (max(0.0, v_prev - p.max_accel * dt),  # slowing down within max_accel
                float(np.clip(ROTATE_GAIN * alpha, -p.max_w, p.max_w)))
    kappa = 2.0 * math.sin(alpha) / L  # [1/m] the arc through the lookahead point
    v_target = min(p.max_v, math.sqrt(2.0 * p.max_accel * max(goal_distance, 0.0)))
    if abs(kappa) > 1e-9:
        v_target = min(v_target, p.max_w / abs(kappa))
    v = float(np.clip(v_target, v_prev - p.max_accel * dt, v_prev + p.max_accel * dt))
    v = max(0.0, v)
    return v, float(np.clip(v * kappa, -p.max_w, p.max_w))


class PathTracker:
    """Pure pursuit's memory of one path: resampled once (RESAMPLE_STEP apart), with the index
    of the point nearest the robot kept between ticks, so a tick searches only a window of
    ``window`` m of arc length ahead of it: the work per tick does not grow with the path.

    path: (N, 2) [m]."""

    def __init__(self, path: np.ndarray, *, window: float = 2.0) -> None:
        self.points = resample(np.asarray(path, dtype=np.float64).reshape(-1, 2))  # (M, 2)
        seg = np.linalg.norm(np.diff(self.points, axis=0), axis=1)
        self._arc = np.concatenate([[0.0], np.cumsum(seg)])  # (M,) [m] arc length
        self._window = max(2, int(math.ceil(window / RESAMPLE_STEP)))
        self.index = 0  # the point nearest the robot at the last tick

    @property
    def end(self) -> np.ndarray:
        return self.points[-1]

    def lookahead(self, xy: np.ndarray, lookahead: float) -> tuple[np.ndarray, float]:
        """(the first point beyond the nearest one at least ``lookahead`` m from ``xy``, or the
        window's last point / the path's end; the arc length [m] left from the nearest point
        to the path's end)."""
        lo, hi = self.index, min(len(self.points), self.index + self._window)
        pts = self.points[lo:hi]
        d = np.linalg.norm(pts - np.asarray(xy)[None], axis=1)
        near = int(np.argmin(d))
        self.index = lo + near
        ahead = np.flatnonzero(d[near:] >= lookahead)
        target = pts[near + ahead[0]] if len(ahead) else pts[-1]
        return target, float(self._arc[-1] - self._arc[self.index])
