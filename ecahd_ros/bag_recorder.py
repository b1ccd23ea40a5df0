"""bag_recorder: records topics into a rosbag2 bag (MCAP storage + metadata.yaml, the layout
Jazzy's ``ros2 bag record`` writes and ``ros2 bag info`` / ``ros2 bag play`` read), without
rosbag2: the ``rosbags`` library writes, rclpy raw subscriptions receive.

Messages are written as received, still CDR-serialised, in the subscription callback, stamped
with the recorder's receive time (its node clock: wall time, or /clock with use_sim_time). A
topic is subscribed once a publisher advertises it (looked up every ``discovery_period``), with
the type that publisher offers, reliable when every publisher is, and transient_local when it is
listed in ``latched_topics`` and every publisher offers transient_local (so a map latched before
the recorder started is still recorded). The publishers' QoS profiles go into the bag's
metadata, as rosbag2 does, so ``ros2 bag play`` re-latches the map. Types are looked up in the
rosbags typestore for ROS 2 Jazzy: a type it does not know is logged and skipped.

Nothing received is dropped: ``received`` and ``written`` count per topic, are logged on close,
and differ only if the storage failed (each failure is logged). The bag is closed (index and
metadata.yaml written) by :meth:`BagRecorder.close`, which ``destroy_node`` calls (and
``main()`` always destroys the node), so Ctrl-C leaves a complete bag.

Parameters (read-only):
    output (str, ""): bag directory to create; it must not exist. Empty: rosbag2_<date>-<time>
        in the working directory, as ``ros2 bag record`` names it.
    topics (str[], map goal_pose odom plan local_plan cmd_vel collision collision_detail
        ecahd/timing ecahd/replan local_costmap scan /tf /tf_static): topics to record, relative
        names resolved in the node's namespace (tf's are absolute, as tf2 publishes them).
    latched_topics (str[], [map, /tf_static]): topics to subscribe transient_local.
    storage (str, "mcap"): rosbag2 storage plugin, mcap or sqlite3.
    discovery_period (double, 0.5): [s, wall time] how often unadvertised topics are looked up.

``read_bag(path)`` (``ecahd_core.bag_io``, re-exported here) reads a bag back as
{topic: [(t_ns, message), ...]} without rclpy.
"""
from __future__ import annotations

import importlib
import math
import time
from functools import partial
from pathlib import Path

import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness, QosReliability,
                                QosTime)
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
from rosbags.typesys import get_typestore

from ecahd_core.bag_io import TYPESTORE, read_bag  # noqa: F401 (read_bag: re-exported here)
from ecahd_core.errors import BagError
from ecahd_ros.params import (ParamSpec, declare_parameters, parameters_dataclass)
from ecahd_ros.spin import spin_node

BAG_VERSION = 9  # rosbag2 metadata version of Jazzy (offered_qos_profiles as a list)
STORAGES = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}
DEFAULT_TOPICS = ["map", "goal_pose", "odom", "plan", "local_plan", "cmd_vel", "collision",
                  "collision_detail", "ecahd/timing", "ecahd/replan", "local_costmap", "scan",
                  "/tf", "/tf_static"]

# one place for every parameter of the node
PARAMETERS = [
    ParamSpec("output", "", "bag directory to create (must not exist); empty: rosbag2_<date>-<time>"),
    ParamSpec("topics", DEFAULT_TOPICS, "topics to record"),
    ParamSpec("latched_topics", ["map", "/tf_static"], "topics subscribed transient_local (latched, like Nav2's map)"),
    ParamSpec("storage", "mcap", f"rosbag2 storage plugin: {' or '.join(STORAGES)}"),
    ParamSpec("discovery_period", 0.5, "[s, wall time] how often unadvertised topics are looked up"),
]


@parameters_dataclass(PARAMETERS)
class BagRecorderParams:
    """The node's validated parameters."""

    def __post_init__(self) -> None:
        if self.storage not in STORAGES:
            raise BagError(f"storage {self.storage!r} is not one of {sorted(STORAGES)}")
        if not self.topics or not all(isinstance(t, str) and t for t in self.topics):
            raise BagError(f"topics must be a non-empty list of topic names, got {self.topics!r}")
        if not (math.isfinite(self.discovery_period) and self.discovery_period > 0):
            raise BagError(f"discovery_period must be > 0 s, got {self.discovery_period}")
        if self.output and Path(self.output).exists():
            raise BagError(f"output {self.output!r} exists already; a bag is never overwritten")


def read_bag_parameters(node: Node) -> BagRecorderParams:
    """Read and validate; raises BagError naming the first bad value."""
    values = {spec.name: node.get_parameter(spec.name).value for spec in PARAMETERS}
    period = values["discovery_period"]
    if isinstance(period, bool) or not isinstance(period, (int, float)):
        raise BagError(f"discovery_period must be a number, got {period!r}")
    return BagRecorderParams(output=values["output"] or default_bag_name(),
                             topics=tuple(dict.fromkeys(values["topics"])),
                             latched_topics=tuple(values["latched_topics"]),
                             storage=values["storage"], discovery_period=float(period))


def default_bag_name() -> str:
    """rosbag2_YYYY_MM_DD-HH_MM_SS, the name ``ros2 bag record`` picks."""
    return time.strftime("rosbag2_%Y_%m_%d-%H_%M_%S")


def message_class(msgtype: str):
    """'pkg/msg/Name' -> the rclpy message class; raises ImportError/AttributeError if absent."""
    package, kind, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), name)


def _qos_time(duration) -> QosTime:
    sec, nsec = divmod(int(duration.nanoseconds), 1_000_000_000)
    return QosTime(sec, nsec)


def to_bag_qos(qos: QoSProfile) -> Qos:
    """rclpy QoSProfile -> rosbags Qos (the same rmw enum values)."""
    return Qos(history=QosHistory(int(qos.history)), depth=int(qos.depth),
               reliability=QosReliability(int(qos.reliability)),
               durability=QosDurability(int(qos.durability)),
               deadline=_qos_time(qos.deadline), lifespan=_qos_time(qos.lifespan),
               liveliness=QosLiveliness(int(qos.liveliness)),
               liveliness_lease_duration=_qos_time(qos.liveliness_lease_duration),
               avoid_ros_namespace_conventions=bool(qos.avoid_ros_namespace_conventions))


class BagRecorder(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("bag_recorder", **kwargs)
        declare_parameters(self, PARAMETERS)
        self.params: BagRecorderParams | None = None
        self.typestore = get_typestore(TYPESTORE)
        self.received: dict[str, int] = {}  # per topic, messages handed to a callback
        self.written: dict[str, int] = {}  # per topic, messages stored in the bag
        self.skipped: dict[str, str] = {}  # topic -> why it is not recorded
        self.bag_path: Path | None = None
        self._writer: Writer | None = None
        self._bag_connections = {}
        self._recording = {}
        self._timer = None
        try:
            self.params = read_bag_parameters(self)
            self.bag_path = Path(self.params.output)
            self._writer = Writer(self.bag_path, version=BAG_VERSION,
                                  storage_plugin=STORAGES[self.params.storage])
            self._writer.open()
        except (BagError, WriterError, OSError) as exc:
            self._writer = None
            self.get_logger().error(f"bag_recorder cannot record: {exc}")
            return
        self._wanted = [self.resolve_topic_name(t) for t in self.params.topics]
        self._latched = {self.resolve_topic_name(t) for t in self.params.latched_topics}
        self.get_logger().info(f"recording {len(self._wanted)} topics into {str(self.bag_path)!r} "
                               f"({self.params.storage})")
        self._discover()
        self._timer = self.create_timer(self.params.discovery_period, self._discover,
                                        clock=Clock(clock_type=ClockType.STEADY_TIME))

    # ---------------------------------------------------------------------------- discovery
    @property
    def pending_topics(self) -> list[str]:
        """Topics still waiting for a publisher."""
        return [t for t in self._wanted if t not in self._recording and t not in self.skipped]

    def _discover(self) -> None:
        if self._writer is None:
            return
        for topic in self.pending_topics:
            publishers = self.get_publishers_info_by_topic(topic)
            if publishers:
                self._subscribe(topic, publishers)
        if not self.pending_topics and self._timer is not None:
            self._timer.cancel()

    def _subscribe(self, topic: str, publishers) -> None:
        msgtype = publishers[0].topic_type
        others = sorted({p.topic_type for p in publishers} - {msgtype})
        if others:
            self.get_logger().warning(f"{topic}: publishers disagree on the type; recording "
                                      f"{msgtype}, not {others}")
        if msgtype not in self.typestore.fielddefs:
            self.skipped[topic] = (f"type {msgtype} unknown to the rosbags {TYPESTORE.value} "
                                   "typestore")
            self.get_logger().error(f"not recording {topic}: {self.skipped[topic]}")
            return
        try:
            cls = message_class(msgtype)
        except (ImportError, AttributeError, ValueError) as exc:
            self.skipped[topic] = f"no Python message class for {msgtype} ({exc})"
            self.get_logger().error(f"not recording {topic}: {self.skipped[topic]}")
            return
        offered = [p.qos_profile for p in publishers]
        bag_hash = self.typestore.hash_rihs01(msgtype)
        if str(publishers[0].topic_type_hash) not in (bag_hash, "", "None"):
            self.get_logger().warning(f"{topic}: the publisher's {msgtype} hash "
                                      f"{publishers[0].topic_type_hash} differs from the "
                                      f"typestore's {bag_hash}; the stored definition may "
                                      "not match")
        reliable = all(q.reliability == ReliabilityPolicy.RELIABLE for q in offered)
        latched = topic in self._latched
        all_latched = all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offered)
        if latched and not all_latched:
            self.get_logger().warning(f"{topic} is in latched_topics but not every publisher "
                                      "offers transient_local: subscribing volatile")
        qos = QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=1000,
                         reliability=(ReliabilityPolicy.RELIABLE if reliable
                                      else ReliabilityPolicy.BEST_EFFORT),
                         durability=(DurabilityPolicy.TRANSIENT_LOCAL if latched and all_latched
                                     else DurabilityPolicy.VOLATILE))
        self._bag_connections[topic] = self._writer.add_connection(
            topic, msgtype, typestore=self.typestore,
            offered_qos_profiles=[to_bag_qos(q) for q in offered])
        self.received[topic] = self.written[topic] = 0
        self._recording[topic] = self.create_subscription(
            cls, topic, partial(self._on_message, topic), qos, raw=True)
        self.get_logger().info(f"recording {topic} [{msgtype}] "
                               f"({qos.reliability.name.lower()}, {qos.durability.name.lower()})")

    # ------------------------------------------------------------------------------ writing
    def _on_message(self, topic: str, data: bytes) -> None:
        self.received[topic] += 1
        if self._writer is None:
            self.get_logger().error(f"{topic}: message received after the bag was closed")
            return
        try:
            self._writer.write(self._bag_connections[topic],
                               self.get_clock().now().nanoseconds, data)
        except (WriterError, OSError) as exc:
            self.get_logger().error(f"{topic}: could not write a message: {exc}")
            return
        self.written[topic] += 1

    @property
    def total_received(self) -> int:
        return sum(self.received.values())

    @property
    def total_written(self) -> int:
        return sum(self.written.values())

    def close(self) -> None:
        """Stop recording, write the storage index and metadata.yaml (idempotent)."""
        writer, self._writer = self._writer, None
        if writer is None:
            return
        if self._timer is not None:
            self._timer.cancel()
        writer.close()
        for sub in self._recording.values():
            self.destroy_subscription(sub)
        summary = ", ".join(f"{t} {self.received[t]}/{self.written[t]}" for t in self.received)
        self.get_logger().info(f"closed {str(self.bag_path)!r}: received {self.total_received}, "
                               f"written {self.total_written} (per topic received/written: "
                               f"{summary or 'none'})")
        if self.pending_topics:
            self.get_logger().warning(f"never advertised, not recorded: {self.pending_topics}")

    @property
    def recording(self) -> bool:
        """The bag is open and being written."""
        return self._writer is not None

    def destroy_node(self) -> None:
        self.close()
        super().destroy_node()


def main(args=None) -> None:
    spin_node(BagRecorder, args, name="bag_recorder")


if __name__ == "__main__":
    main()
