"""Reading rosbag2 bags (MCAP or SQLite3) with the ``rosbags`` library alone: no rclpy, no ROS
message packages, so ``ecahd eval-bag`` runs on any machine with numpy and rosbags.

Messages come back as rosbags dataclasses with the ROS field names (``msg.pose.position.x``),
deserialised with the definitions stored in the bag, or with the ROS 2 Jazzy typestore for a
bag that stores none. The helpers below read the few fields the evaluation needs from them (or
from rclpy messages, which have the same names).
"""
from __future__ import annotations

import math
from pathlib import Path

from rosbags.typesys import Stores, get_typestore

from ecahd_core.errors import BagError

TYPESTORE = Stores.ROS2_JAZZY  # the message definitions bags are written and read with


def _bag_folder(path) -> Path:
    path = Path(path)
    if not (path / "metadata.yaml").is_file():
        raise BagError(f"{str(path)!r} is not a rosbag2 directory (no metadata.yaml)")
    return path


def bag_topics(path) -> dict[str, int]:
    """The topics of a rosbag2 bag -> {topic: message count}, from its index alone (no message
    is read), so a caller can pick what to read from a large bag. Raises as :func:`read_bag`."""
    from rosbags.highlevel import AnyReader, AnyReaderError

    path = _bag_folder(path)
    try:
        with AnyReader([path], default_typestore=get_typestore(TYPESTORE)) as reader:
            return {topic: int(info.msgcount) for topic, info in reader.topics.items()}
    except AnyReaderError as exc:
        raise BagError(f"cannot read bag {str(path)!r}: {exc}") from exc


def read_bag(path, topics=None) -> dict[str, list[tuple[int, object]]]:
    """Read a rosbag2 bag (MCAP or SQLite3) -> {topic: [(receive time [ns], message), ...]} in
    time order, every recorded topic present (maybe with an empty list: a topic that was
    advertised but never published). topics: names to keep (default all). Raises BagError for
    a folder without metadata.yaml or a bag rosbags cannot read."""
    from rosbags.highlevel import AnyReader, AnyReaderError

    path = _bag_folder(path)
    try:
        with AnyReader([path], default_typestore=get_typestore(TYPESTORE)) as reader:
            connections = [c for c in reader.connections if topics is None or c.topic in topics]
            out: dict[str, list[tuple[int, object]]] = {c.topic: [] for c in connections}
            if not connections:  # rosbags reads every connection when given none
                return out
            for conn, t_ns, raw in reader.messages(connections=connections):
                out[conn.topic].append((int(t_ns), reader.deserialize(raw, conn.msgtype)))
    except AnyReaderError as exc:
        raise BagError(f"cannot read bag {str(path)!r}: {exc}") from exc
    return out


def stamp_seconds(stamp) -> float:
    """builtin_interfaces/Time -> [s]."""
    return stamp.sec + stamp.nanosec * 1e-9


def quaternion_yaw(q) -> float:
    """Heading [rad] of a geometry_msgs/Quaternion (rotation about z)."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
