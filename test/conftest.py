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
