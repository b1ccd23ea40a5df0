"""What every ecahd_ros node does round its callbacks, in one home: a guard so that no message
can kill a node (bad input is logged in one line and dropped, a bug with its traceback), the
node clock in seconds, and the check that a message is in the frame the node works in."""
from __future__ import annotations

import traceback
from collections.abc import Callable

from rclpy.node import Node

from ecahd_core.errors import EcahdError


def guard(node: Node, callback: Callable) -> Callable:
    """``callback`` wrapped so no exception escapes: EcahdError is logged as one error line,
    anything else with its traceback; the message is dropped and the node keeps running."""
    def wrapped(*args) -> None:
        try:
            callback(*args)
        except EcahdError as exc:
            node.get_logger().error(str(exc))
        except Exception:  # noqa: BLE001 (a node must survive a bug in one message)
            node.get_logger().error(f"{callback.__name__} failed:\n{traceback.format_exc()}")
    return wrapped


def now_seconds(node: Node) -> float:
    """The node's clock (sim time with ``use_sim_time``) [s]."""
    return node.get_clock().now().nanoseconds * 1e-9


def check_frame(frame: str, expected: str, what: str) -> None:
    """Raise EcahdError('<what> in frame <frame> ignored: expected <expected>') unless the
    message's ``frame`` is ``expected``."""
    if frame != expected:
        raise EcahdError(f"{what} in frame {frame!r} ignored: expected {expected!r}")
