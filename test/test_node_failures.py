"""Failures that show, and failures that do not kill: a node that cannot configure exits non-zero
within 10 s with one line; an exception while spinning (a hostile /clock) is logged and the node
keeps working."""
import os
import subprocess
import sys
import threading
import time

import pytest

rclpy = pytest.importorskip("rclpy")
from builtin_interfaces.msg import Time  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402

from ecahd_ros.spin import CONFIGURE_EXIT_CODE, spin_forever  # noqa: E402


@pytest.mark.slow
@pytest.mark.parametrize("module,params,reason", [
    ("ecahd_ros.global_planner", ["method:=rrt"], "parameter method must be one of"),
    ("ecahd_ros.global_planner", ["robot:=spaceship"], "spaceship"),
    ("ecahd_ros.local_refiner", ["dd_model:=/nonexistent/dd.pt"], "does not exist"),
    ("ecahd_ros.local_refiner", ["control_rate:=-1.0"], "control_rate"),
    ("ecahd_ros.global_planner", ["lanes:=/nonexistent/lanes.npz"],
     "lane field /nonexistent/lanes.npz: no such file"),
])
def test_a_node_that_cannot_configure_exits_with_one_line(module, params, reason,
                                                          ros_domain_id):
    args = [sys.executable, "-m", module, "--ros-args"]
    for p in params:
        args += ["-p", p]
    env = {**os.environ, "ROS_DOMAIN_ID": str(ros_domain_id)}
    t0 = time.monotonic()
    proc = subprocess.run(args, capture_output=True, text=True, timeout=30, env=env)
    assert time.monotonic() - t0 < 10.0
    assert proc.returncode == CONFIGURE_EXIT_CODE
    lines = [line for line in proc.stderr.splitlines() if "cannot configure" in line]
    assert len(lines) == 1 and reason in lines[0], proc.stderr


def test_a_negative_clock_does_not_end_the_node(ros_context, capfd):
    from ecahd_ros.local_refiner import LocalRefiner

    node = LocalRefiner(context=ros_context, parameter_overrides=[
        Parameter("use_sim_time", value=True), Parameter("dd_enabled", value=False)])
    probe = rclpy.create_node("hostile", context=ros_context)
    clock_pub = probe.create_publisher(Clock, "/clock", 10)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    thread = threading.Thread(target=spin_forever, args=(executor, node.get_logger()),
                              daemon=True)
    thread.start()
    try:
        deadline = time.monotonic() + 5.0
        while clock_pub.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.01)
        clock_pub.publish(Clock(clock=Time(sec=-5, nanosec=0)))  # rclpy's time source raises
        time.sleep(0.3)
        clock_pub.publish(Clock(clock=Time(sec=12, nanosec=0)))  # valid again
        deadline = time.monotonic() + 5.0
        while node.get_clock().now().nanoseconds < 12e9 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert thread.is_alive()  # still spinning
        assert node.get_clock().now().nanoseconds == 12_000_000_000  # and still listening
        assert "exception while spinning" in capfd.readouterr().err  # it did raise, once
    finally:
        rclpy.try_shutdown(context=ros_context)
        thread.join(timeout=5.0)
        executor.shutdown()
        node.destroy_node()
        probe.destroy_node()
