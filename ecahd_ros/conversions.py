"""Message conversion between ROS 2 messages and ecahd_core types (the only place that knows both)."""
from __future__ import annotations

import json

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Pose, PoseStamped
from nav_msgs.msg import OccupancyGrid, Path
from std_msgs.msg import String
from visualization_msgs.msg import Marker, MarkerArray

from ecahd_core.errors import EcahdError
from ecahd_core.maps import GridMap, grid_from_occupancy_message, to_occupancy_grid


def grid_to_msg(grid: GridMap, stamp: Time | None = None) -> OccupancyGrid:
    """GridMap -> nav_msgs/OccupancyGrid (row-major from the origin, -1 unknown, 0..100)."""
    return layout_to_msg(to_occupancy_grid(grid), stamp)


def layout_to_msg(layout, stamp: Time | None = None) -> OccupancyGrid:
    """An OccupancyGridLayout (``ecahd_core.maps``) -> nav_msgs/OccupancyGrid."""
    msg = OccupancyGrid()
    msg.header.frame_id = layout.frame_id
    if stamp is not None:
        msg.header.stamp = stamp
        msg.info.map_load_time = stamp
    msg.info.resolution = float(layout.resolution)
    msg.info.width = layout.width
    msg.info.height = layout.height
    msg.info.origin.position.x = float(layout.origin_xy[0])
    msg.info.origin.position.y = float(layout.origin_xy[1])
    msg.info.origin.orientation.w = 1.0
    msg.data = layout.data.astype(np.int8).tolist()
    return msg


def msg_to_grid(msg: OccupancyGrid, *, unknown_is_occupied: bool = True,
                name: str = "occupancy_grid") -> GridMap:
    """nav_msgs/OccupancyGrid -> GridMap; raises MapError for a malformed or rotated grid.
    The float32 resolution is restored (0.1 stays 0.1): the rule lives in
    :func:`ecahd_core.maps.grid_from_occupancy_message`, which ``ecahd eval-bag`` uses too."""
    return grid_from_occupancy_message(msg, unknown_is_occupied=unknown_is_occupied, name=name)


def xy_to_path(xy: np.ndarray, frame_id: str, stamp: Time | None = None) -> Path:
    """(N, 2) positions [m] -> nav_msgs/Path, each pose facing the next point."""
    xy = np.asarray(xy, dtype=np.float64)
    path = Path()
    path.header.frame_id = frame_id
    if stamp is not None:
        path.header.stamp = stamp
    d = np.diff(xy, axis=0, append=xy[-1:] if len(xy) < 2 else xy[-1:] + (xy[-1:] - xy[-2:-1]))
    yaw = np.arctan2(d[:, 1], d[:, 0])
    for (x, y), a in zip(xy, yaw):
        ps = PoseStamped()
        ps.header = path.header
        ps.pose = pose_from_xy_yaw(float(x), float(y), float(a))
        path.poses.append(ps)
    return path


def path_to_xy(path: Path) -> np.ndarray:
    """nav_msgs/Path -> (N, 2) positions [m]."""
    return np.array([[p.pose.position.x, p.pose.position.y] for p in path.poses],
                    dtype=np.float64).reshape(-1, 2)


def pose_from_xy_yaw(x: float, y: float, yaw: float) -> Pose:
    pose = Pose()
    pose.position.x, pose.position.y = x, y
    pose.orientation.z, pose.orientation.w = float(np.sin(yaw / 2)), float(np.cos(yaw / 2))
    return pose


def no_heading(pose: Pose) -> None:
    """Set ``pose``'s orientation to all zeros: "any heading" (see :func:`heading_of`)."""
    o = pose.orientation
    o.x = o.y = o.z = o.w = 0.0


def yaw_from_quaternion(q) -> float:
    """Heading [rad] of a geometry_msgs/Quaternion (rotation about z)."""
    return float(np.arctan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z)))


def heading_of(orientation) -> float | None:
    """The yaw [rad] of a geometry_msgs/Quaternion; None for all zeros (no heading asked: a
    goal_pose from a script that sets only the position); EcahdError if not finite."""
    q = np.array([orientation.x, orientation.y, orientation.z, orientation.w], dtype=np.float64)
    if not np.all(np.isfinite(q)):
        raise EcahdError(f"orientation has non-finite values {q.tolist()}")
    norm = float(np.linalg.norm(q))
    if norm < 1e-9:
        return None
    x, y, z, w = q / norm
    return float(np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))


def timing_message(stage: str, ms: float, stamp_s: float, **extra) -> String:
    """The ``ecahd/timing`` message: std_msgs/String with JSON {"stage", "ms", "stamp", ...}."""
    return String(data=json.dumps({"stage": stage, "ms": round(float(ms), 3), **extra,
                                   "stamp": stamp_s}))


def candidate_markers(plan, frame_id: str, stamp) -> MarkerArray:
    """SparsePlan (its candidates (N, P, 2) [m] and ``best``) -> MarkerArray: DELETEALL, then one LINE_STRIP per candidate (id = its index),
    the chosen one purple and wider, the others translucent grey."""
    out = MarkerArray()
    clear = Marker()
    clear.action = Marker.DELETEALL
    out.markers.append(clear)
    for i, cand in enumerate(plan.candidates):
        m = Marker()
        m.header.frame_id, m.header.stamp = frame_id, stamp
        m.ns, m.id, m.type, m.action = "candidates", i, Marker.LINE_STRIP, Marker.ADD
        m.pose.orientation.w = 1.0
        chosen = i == plan.best
        m.scale.x = 0.08 if chosen else 0.03
        m.color.r, m.color.g, m.color.b, m.color.a = ((0.55, 0.2, 0.8, 1.0) if chosen
                                                      else (0.5, 0.5, 0.5, 0.6))
        for x, y in cand:
            m.points.append(Point(x=float(x), y=float(y), z=0.0))
        out.markers.append(m)
    return out


def footprint_markers(footprint, local: np.ndarray, frame_id: str, stamp,
                      colliding: bool) -> MarkerArray:
    """The footprint outline at each point of ``local`` (P, 2), facing along the path."""
    out = MarkerArray()
    clear = Marker()
    clear.action = Marker.DELETEALL
    out.markers.append(clear)
    d = np.diff(local, axis=0)
    heading = np.arctan2(d[:, 1], d[:, 0])
    heading = np.append(heading, heading[-1])
    outlines = footprint.transformed(local, heading, which="polygon")  # (P, V, 2)
    for i, poly in enumerate(outlines):
        m = Marker()
        m.header.frame_id, m.header.stamp = frame_id, stamp
        m.ns, m.id, m.type, m.action = "local_plan_footprints", i, Marker.LINE_STRIP, Marker.ADD
        m.pose.orientation.w = 1.0
        m.scale.x = 0.02
        m.color.r, m.color.g, m.color.b, m.color.a = ((0.9, 0.1, 0.1, 1.0) if colliding
                                                      else (0.1, 0.3, 0.9, 0.8))
        for px, py in np.concatenate([poly, poly[:1]]):
            m.points.append(Point(x=float(px), y=float(py), z=0.0))
        out.markers.append(m)
    return out
