"""Coordinate frames over time, as tf2's buffer keeps them (REP-105: ``map`` -> ``odom`` ->
``base_link`` -> ``base_scan``), for a pip-only install where tf2 is not available: the nodes feed
it the transforms of ``/tf`` and ``/tf_static`` and look up the robot's pose in ``map`` or a
scan's mounting at its own stamp.

Semantics follow tf2's ``BufferCore``:

- every frame has at most one parent; a transform ``parent -> child`` stamped ``t`` says where
  ``child``'s origin and axes lie in ``parent`` at ``t``; a static one holds at every time;
- :meth:`TransformBuffer.lookup` (``target``, ``source``, ``time``) returns T_target_source, the
  transform that maps points given in ``source`` into ``target``, composed along the tree
  through the frames' common ancestor, each link interpolated at ``time`` (translation linearly,
  rotation by slerp); ``time`` None is the latest time at which every link of the chain is known
  (tf2's time 0);
- a time before a link's oldest kept stamp, or after its newest, is an extrapolation and raises
  :class:`ExtrapolationError` naming the link and the gap, unless the time is at most
  ``tolerance`` seconds after the newest stamp (Nav2's ``transform_tolerance``): the newest is
  then used; dynamic transforms are kept for ``cache_time`` seconds;
- unknown frames, frames not connected, a transform that would close a loop or give a frame a
  second parent raise :class:`FrameError` naming the frames.

Poses: ``translation`` (3,) [m], ``rotation`` (4,) quaternion (x, y, z, w), as in
geometry_msgs/Transform.
"""
from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np

from ecahd_core.errors import EcahdError

CACHE_TIME = 10.0  # [s] tf2's default buffer length
# [s] the nodes' transform_tolerance by default (and eval-bag's, the demo's): a transform at most
# this much older than the odometry it places is used
TRANSFORM_TOLERANCE = 0.3


class FrameError(EcahdError):
    """An unknown frame, frames not connected, a loop, a second parent."""


class ExtrapolationError(FrameError):
    """A lookup at a time outside what a link of the chain has."""


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz])


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors ``v`` (..., 3) by the unit quaternion ``q`` (x, y, z, w)."""
    u, w = q[:3], q[3]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def _slerp(a: np.ndarray, b: np.ndarray, s: float) -> np.ndarray:
    dot = float(np.dot(a, b))
    if dot < 0.0:  # the shorter way round
        b, dot = -b, -dot
    if dot > 0.9995:
        q = a + s * (b - a)
    else:
        theta = math.acos(dot)
        q = (math.sin((1 - s) * theta) * a + math.sin(s * theta) * b) / math.sin(theta)
    return q / np.linalg.norm(q)


@dataclass(frozen=True)
class Transform:
    """A rigid transform: ``translation`` (3,) [m] and unit ``rotation`` (4,) (x, y, z, w)."""

    translation: np.ndarray
    rotation: np.ndarray

    @classmethod
    def identity(cls) -> "Transform":
        return cls(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]))

    @classmethod
    def from_xy_yaw(cls, x: float, y: float, yaw: float, z: float = 0.0) -> "Transform":
        """A planar transform: (x, y) [m], heading ``yaw`` [rad] about z."""
        return cls(np.array([x, y, z], dtype=np.float64),
                   np.array([0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)]))

    @classmethod
    def checked(cls, translation, rotation) -> "Transform":
        """From raw values, or FrameError: finite, and a rotation of unit length (within 1e-3,
        then normalised)."""
        t = np.asarray(translation, dtype=np.float64).reshape(3)
        q = np.asarray(rotation, dtype=np.float64).reshape(4)
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(q))):
            raise FrameError(f"transform is not finite: translation {t.tolist()}, rotation "
                             f"{q.tolist()}")
        n = float(np.linalg.norm(q))
        if abs(n - 1.0) > 1e-3:
            raise FrameError(f"transform rotation {q.tolist()} is not a unit quaternion "
                             f"(norm {n:.4g})")
        return cls(t, q / n)

    def __mul__(self, other: "Transform") -> "Transform":
        """Composition: (A * B) maps points of B's source frame through B, then A."""
        return Transform(self.translation + _rotate(self.rotation, other.translation),
                         _quat_mul(self.rotation, other.rotation))

    def inverse(self) -> "Transform":
        conj = self.rotation * np.array([-1.0, -1.0, -1.0, 1.0])
        return Transform(-_rotate(conj, self.translation), conj)

    def apply(self, points) -> np.ndarray:
        """Points (N, 2) or (N, 3) [m] of the source frame in the target frame (same shape; 2D
        points lie at z = 0)."""
        p = np.asarray(points, dtype=np.float64)
        flat = p.shape[-1] == 2
        p3 = np.concatenate([p, np.zeros(p.shape[:-1] + (1,))], axis=-1) if flat else p
        out = _rotate(self.rotation, p3) + self.translation
        return out[..., :2] if flat else out

    def yaw(self) -> float:
        """[rad] the heading of the rotation about z."""
        x, y, z, w = self.rotation
        return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))

    def xy_yaw(self) -> tuple[float, float, float]:
        """(x [m], y [m], yaw [rad]): the planar pose of the source frame's origin."""
        return float(self.translation[0]), float(self.translation[1]), self.yaw()


def interpolate(a: Transform, b: Transform, s: float) -> Transform:
    """The transform ``s`` (0..1) of the way from ``a`` to ``b``."""
    return Transform(a.translation + s * (b.translation - a.translation),
                     _slerp(a.rotation, b.rotation, s))


class _Link:
    """One frame's transforms from its parent: static, or stamped and time-sorted."""

    def __init__(self, parent: str, static: bool) -> None:
        self.parent, self.static = parent, static
        self.stamps: list[float] = []
        self.transforms: list[Transform] = []

    def add(self, stamp: float, transform: Transform, cache_time: float) -> None:
        if self.static:
            self.stamps, self.transforms = [0.0], [transform]
            return
        i = bisect.bisect_left(self.stamps, stamp)
        if i < len(self.stamps) and self.stamps[i] == stamp:
            self.transforms[i] = transform  # the same stamp again: the newer message wins
        else:
            self.stamps.insert(i, stamp)
            self.transforms.insert(i, transform)
        cut = bisect.bisect_left(self.stamps, self.stamps[-1] - cache_time)
        del self.stamps[:cut], self.transforms[:cut]

    @property
    def newest(self) -> float:
        return math.inf if self.static else self.stamps[-1]

    def at(self, time: float, child: str, tolerance: float) -> Transform:
        if self.static:
            return self.transforms[0]
        first, last = self.stamps[0], self.stamps[-1]
        if time > last:
            if time - last <= tolerance:
                return self.transforms[-1]
            raise ExtrapolationError(
                f"{self.parent} -> {child} is known up to {last:.3f} s; {time:.3f} s is "
                f"{time - last:.3f} s into the future (tolerance {tolerance:g} s)")
        if time < first:
            raise ExtrapolationError(
                f"{self.parent} -> {child} is known from {first:.3f} s; {time:.3f} s is "
                f"{first - time:.3f} s before it (the buffer keeps the last seconds only)")
        i = bisect.bisect_left(self.stamps, time)
        if self.stamps[i] == time:
            return self.transforms[i]
        t0, t1 = self.stamps[i - 1], self.stamps[i]
        return interpolate(self.transforms[i - 1], self.transforms[i], (time - t0) / (t1 - t0))


class TransformBuffer:
    """Transforms over time between named frames (see the module docstring).

    Args:
        cache_time: [s] how long dynamic transforms are kept, counted back from each link's
            newest stamp.
    """

    def __init__(self, cache_time: float = CACHE_TIME) -> None:
        if not cache_time > 0:
            raise FrameError(f"cache_time must be > 0 s, got {cache_time}")
        self.cache_time = float(cache_time)
        self._links: dict[str, _Link] = {}  # child frame -> its link to its parent

    def set_transform(self, parent: str, child: str, stamp: float, transform: Transform, *,
                      static: bool = False) -> None:
        """``child``'s pose in ``parent`` at ``stamp`` [s] (any time when ``static``)."""
        for name in (parent, child):
            if not name or name.startswith("/") or any(c.isspace() for c in name):
                raise FrameError(f"frame id {name!r} is not valid (non-empty, no leading '/', "
                                 f"no spaces)")
        if parent == child:
            raise FrameError(f"transform from {parent!r} to itself")
        if not math.isfinite(stamp):
            raise FrameError(f"transform {parent} -> {child} has a non-finite stamp {stamp}")
        link = self._links.get(child)
        if link is not None and link.parent != parent:
            raise FrameError(f"frame {child!r} already has the parent {link.parent!r}; a "
                             f"transform from {parent!r} would give it two")
        if link is None:
            if child in self._ancestors(parent):
                raise FrameError(f"transform {parent} -> {child} would close a loop: "
                                 f"{child!r} is already an ancestor of {parent!r}")
            link = self._links[child] = _Link(parent, static)
        elif link.static != static:
            raise FrameError(f"{parent} -> {child} is {'static' if link.static else 'dynamic'}; "
                             f"it cannot become {'static' if static else 'dynamic'}")
        link.add(float(stamp), transform, self.cache_time)

    def add_stamped(self, t, *, static: bool = False) -> tuple[str, str]:
        """Keep a geometry_msgs/TransformStamped ``t`` (an rclpy message or a rosbags record:
        anything with its fields) -> (parent, child). Frame ids lose a leading '/' (ROS 1's
        convention, which tf2 strips too); FrameError names a malformed transform."""
        parent, child = t.header.frame_id.lstrip("/"), t.child_frame_id.lstrip("/")
        tr, q = t.transform.translation, t.transform.rotation
        stamp = t.header.stamp.sec + t.header.stamp.nanosec * 1e-9
        self.set_transform(parent, child, stamp,
                           Transform.checked((tr.x, tr.y, tr.z), (q.x, q.y, q.z, q.w)),
                           static=static)
        return parent, child

    def frames(self) -> set[str]:
        """Every frame named so far."""
        return set(self._links) | {link.parent for link in self._links.values()}

    def _ancestors(self, frame: str) -> list[str]:
        """``frame`` and its parents up to the root, in order."""
        chain = [frame]
        while chain[-1] in self._links:
            chain.append(self._links[chain[-1]].parent)
        return chain

    def _chain(self, target: str, source: str) -> tuple[list[str], list[str]]:
        """The frames from ``source`` up to the common ancestor (exclusive) and from ``target``
        up to it, or FrameError."""
        known = self.frames()
        for name, role in ((target, "target"), (source, "source")):
            if name not in known:
                raise FrameError(f"{role} frame {name!r} is unknown (known: "
                                 f"{sorted(known) or 'none'})")
        up_s, up_t = self._ancestors(source), self._ancestors(target)
        common = next((f for f in up_s if f in set(up_t)), None)
        if common is None:
            raise FrameError(f"frames {target!r} and {source!r} are not connected: their roots "
                             f"are {up_t[-1]!r} and {up_s[-1]!r}")
        return up_s[:up_s.index(common)], up_t[:up_t.index(common)]

    def latest_common_time(self, target: str, source: str) -> float:
        """[s] the latest time at which every link between the frames is known (inf when all
        are static)."""
        from_source, from_target = self._chain(target, source)
        return min((self._links[f].newest for f in from_source + from_target), default=math.inf)

    def lookup(self, target: str, source: str, time: float | None = None, *,
               tolerance: float = 0.0) -> Transform:
        """T_target_source at ``time`` [s] (None: :meth:`latest_common_time`), each link
        interpolated; ``tolerance`` [s]: a time at most this far after a link's newest stamp
        uses the newest. Raises FrameError / ExtrapolationError naming the problem."""
        from_source, from_target = self._chain(target, source)
        if time is None:
            time = self.latest_common_time(target, source)
            if math.isinf(time):
                time = 0.0  # every link static
        up = Transform.identity()  # T_common_source
        for frame in from_source:
            up = self._links[frame].at(time, frame, tolerance) * up
        down = Transform.identity()  # T_common_target
        for frame in from_target:
            down = self._links[frame].at(time, frame, tolerance) * down
        return down.inverse() * up

    def pose_in(self, target: str, source: str, time: float | None, pose, *,
                tolerance: float = 0.0) -> tuple[float, float, float]:
        """A planar ``pose`` (x [m], y [m], yaw [rad]) given in ``source`` at ``time`` [s], in
        ``target``: (x, y, yaw). Raises as :meth:`lookup`."""
        x, y, yaw = (float(v) for v in pose)
        return (self.lookup(target, source, time, tolerance=tolerance)
                * Transform.from_xy_yaw(x, y, yaw)).xy_yaw()
