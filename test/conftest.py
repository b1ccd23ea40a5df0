"""Test-wide settings: keep ROS 2 discovery on this machine, plots headless, and one private
rclpy context per test on a DDS domain of this test process (parallel runs do not hear each
other). Core tests never use the ``ros_context`` fixture, so they never import rclpy.

Tests that take seconds each (node processes and process graphs, colcon builds, training runs,
closed-loop demos) are marked ``slow`` (``pytestmark = pytest.mark.slow`` or
``@pytest.mark.slow``; the marker is registered in setup.cfg). While working, run the rest, in
under a minute on two cores::

    python -m pytest -q -m "not slow"

``bash scripts/test.sh`` (what CI runs) still runs everything, the slow tests included."""
import os

import pytest

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.setdefault("MPLBACKEND", "Agg")

ROS_DOMAIN_ID = 60 + os.getpid() % 100  # 60..159, valid for Fast DDS


@pytest.fixture
def one_torch_thread():
    """One torch thread for the test: tiny models' steps take 10x longer with two threads
    contending with other work on a 2-core machine. Use with ``pytestmark =
    pytest.mark.usefixtures("one_torch_thread")``."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


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


def rig_factory(rig_class, context):
    """A fixture's body: yields ``make(**params)`` building ``rig_class(context, **params)``
    (nodes on one executor), and closes every rig made once the test is over::

        @pytest.fixture
        def rig(ros_context):
            yield from rig_factory(Rig, ros_context)
    """
    made = []

    def make(**params):
        made.append(rig_class(context, **params))
        return made[-1]

    yield make
    for rig in made:
        rig.close()


def spin_until(executor, condition, timeout: float = 10.0, what: str = "condition") -> None:
    """Spin ``executor`` in 10 ms slices until ``condition()`` holds; fail the test naming
    ``what`` after ``timeout`` seconds of wall time."""
    import time

    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"not within {timeout:g} s: {what}"
        executor.spin_once(timeout_sec=0.01)


def ray_cast(sensor, angles, circles=(), boxes=()):
    """Ranges (N,) [m] of rays from ``sensor`` (2,) at world ``angles`` (N,) [rad] against
    circles (cx, cy, r) and axis-aligned boxes (xmin, ymin, xmax, ymax), analytically; +inf
    where a ray hits nothing."""
    import numpy as np

    sensor = np.asarray(sensor, dtype=float)
    d = np.stack([np.cos(angles), np.sin(angles)], 1)  # (N, 2)
    r = np.full(len(angles), np.inf)
    for cx, cy, rad in circles:
        oc = sensor - np.array([cx, cy])
        b = d @ oc
        disc = b * b - (oc @ oc - rad * rad)
        t = -b - np.sqrt(np.maximum(disc, 0.0))  # nearest intersection along the ray
        r = np.where((disc >= 0) & (t > 0), np.minimum(r, t), r)
    for x0, y0, x1, y1 in boxes:
        with np.errstate(divide="ignore", invalid="ignore"):
            tx = np.stack([(x0 - sensor[0]) / d[:, 0], (x1 - sensor[0]) / d[:, 0]])
            ty = np.stack([(y0 - sensor[1]) / d[:, 1], (y1 - sensor[1]) / d[:, 1]])
        tmin = np.maximum(tx.min(0), ty.min(0))  # slab method
        tmax = np.minimum(tx.max(0), ty.max(0))
        r = np.where((tmax >= tmin) & (tmin > 0), np.minimum(r, tmin), r)
    return r
