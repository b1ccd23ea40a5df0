"""Test-wide settings: keep ROS 2 discovery on this machine, plots headless, and one private
rclpy context per test on a DDS domain of this test process (parallel runs do not hear each
other). Core tests never use the ``ros_context`` fixture, so they never import rclpy."""
import os

import pytest

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.setdefault("MPLBACKEND", "Agg")

ROS_DOMAIN_ID = 60 + os.getpid() % 100  # 60..159, valid for Fast DDS


@pytest.fixture
def ros_domain_id() -> int:
    """The DDS domain of this test process (for child processes that must join it)."""
    return ROS_DOMAIN_ID


@pytest.fixture
def ros_context():
    rclpy = pytest.importorskip("rclpy")
    context = rclpy.context.Context()
    rclpy.init(context=context, domain_id=ROS_DOMAIN_ID)
    yield context
    rclpy.try_shutdown(context=context)


def spin_until(executor, condition, timeout: float = 10.0, what: str = "condition") -> None:
    """Spin ``executor`` in 10 ms slices until ``condition()`` holds; fail the test naming
    ``what`` after ``timeout`` seconds of wall time."""
    import time

    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"not within {timeout:g} s: {what}"
        executor.spin_once(timeout_sec=0.01)
