"""tf for the nodes without tf2_ros (tf2_ros is not on PyPI): :class:`TfListener` fills an
:class:`~ecahd_core.frames.TransformBuffer` from ``/tf`` and ``/tf_static`` as
tf2_ros.TransformListener does, and :func:`odometry_pose` places an odometry message's pose in
the global frame through it (REP-105: odometry in ``odom``, ``map -> odom`` from the
localisation). Odometry already in the global frame (a simulator's ground truth) is used as it
is."""
from __future__ import annotations

from geometry_msgs.msg import TransformStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from tf2_msgs.msg import TFMessage

from ecahd_core.bag_io import stamp_seconds
from ecahd_core.errors import EcahdError
from ecahd_core.frames import FrameError, Transform, TransformBuffer
from ecahd_ros.conversions import yaw_from_quaternion
from ecahd_ros.qos import TF_QOS, TF_STATIC_QOS


class TransformUnavailable(EcahdError):
    """Odometry that tf cannot place in the global frame (yet): the nodes say so every few
    seconds instead of once per message (it is expected for the first messages after start-up,
    before the localisation's first transform)."""


WAIT_LOG_PERIOD = 5.0  # [s] between two lines about odometry waiting for its transform


class TfListener:
    """Subscribes ``/tf`` and ``/tf_static`` on ``node`` and keeps their transforms in
    :attr:`buffer`. A malformed transform (non-finite, not a unit rotation, a loop, a second
    parent) is logged in one line and skipped; the others of its message are kept."""

    def __init__(self, node: Node, buffer: TransformBuffer | None = None, *,
                 callback_group=None) -> None:
        self.node = node
        self.buffer = buffer or TransformBuffer()
        self.received = 0  # transforms kept
        self.rejected = 0  # transforms skipped
        self.subscriptions = [  # the node may destroy them (lifecycle cleanup)
            node.create_subscription(TFMessage, "/tf", lambda m: self._on_tf(m, False), TF_QOS,
                                     callback_group=callback_group),
            node.create_subscription(TFMessage, "/tf_static", lambda m: self._on_tf(m, True),
                                     TF_STATIC_QOS, callback_group=callback_group)]

    def _on_tf(self, msg: TFMessage, static: bool) -> None:
        for t in msg.transforms:
            try:
                self.buffer.add_stamped(t, static=static)
                self.received += 1
            except FrameError as exc:
                self.rejected += 1
                self.node.get_logger().error(
                    f"{'/tf_static' if static else '/tf'} transform {t.header.frame_id!r} -> "
                    f"{t.child_frame_id!r} skipped: {exc}", throttle_duration_sec=5.0)


def odometry_pose(msg: Odometry, buffer: TransformBuffer, global_frame: str,
                  tolerance: float) -> tuple[float, float, float]:
    """The robot's (x [m], y [m], yaw [rad]) in ``global_frame`` from an odometry message: as
    it is when its frame is ``global_frame`` (or empty), else through ``buffer``'s transform
    ``global_frame -> frame`` at the message's stamp (``tolerance`` [s]: Nav2's
    transform_tolerance). Raises EcahdError naming the frames and the problem."""
    pose = msg.pose.pose
    xyyaw = (pose.position.x, pose.position.y, yaw_from_quaternion(pose.orientation))
    frame = msg.header.frame_id.lstrip("/")
    if not frame or frame == global_frame:
        return xyyaw
    try:
        return buffer.pose_in(global_frame, frame, stamp_seconds(msg.header.stamp), xyyaw,
                              tolerance=tolerance)
    except FrameError as exc:
        raise TransformUnavailable(f"odometry in frame {frame!r} ignored: no transform "
                                   f"{global_frame} -> {frame} at its stamp ({exc}); is the "
                                   f"localisation (AMCL, SLAM) publishing /tf?") from None


def transform_stamped(parent: str, child: str, stamp, transform: Transform) -> TransformStamped:
    """geometry_msgs/TransformStamped of ``child`` in ``parent`` at ``stamp``
    (builtin_interfaces/Time)."""
    t = TransformStamped()
    t.header.stamp, t.header.frame_id, t.child_frame_id = stamp, parent, child
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = (
        float(v) for v in transform.translation)
    (t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z,
     t.transform.rotation.w) = (float(v) for v in transform.rotation)
    return t


def placed_odometry(node: Node, msg: Odometry, buffer: TransformBuffer, global_frame: str,
                    tolerance: float) -> tuple[float, float, float] | None:
    """:func:`odometry_pose`, or None when tf cannot place it yet: then a warning, at most every
    WAIT_LOG_PERIOD s (after start-up the first odometry often comes before the first
    transform). Other bad odometry raises, as :func:`odometry_pose`."""
    try:
        return odometry_pose(msg, buffer, global_frame, tolerance)
    except TransformUnavailable as exc:
        node.get_logger().warning(str(exc), throttle_duration_sec=WAIT_LOG_PERIOD)
        return None
