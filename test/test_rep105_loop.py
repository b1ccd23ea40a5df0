"""The closed loop on a robot's frames (REP-105): sim_bridge publishes odometry in `odom` (from
where the robot started) with /tf odom -> base_link and a localisation stand-in's map -> odom;
global_planner and local_refiner place the odometry in `map` through /tf and drive the robot to a
goal given in `map` without touching a wall. One process, a private context, maze2d-large's
corridor y = 5.5, sim time."""
import math
import time

import pytest

rclpy = pytest.importorskip("rclpy")
from geometry_msgs.msg import PoseStamped  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from conftest import spin_until  # noqa: E402
from ecahd_ros.global_planner import GlobalPlanner  # noqa: E402
from ecahd_ros.local_refiner import LocalRefiner  # noqa: E402
from sim_bridge.node import SimBridge  # noqa: E402

pytestmark = pytest.mark.slow  # three nodes driving a robot for seconds of sim time

START, GOAL = (1.5, 5.5, 0.3), (5.5, 5.5)  # the corridor y in [5, 6] is free for x in [1, 7]
WALL_LIMIT = 60.0  # [s]


@pytest.mark.parametrize("drift, jump_at", [(0.0, -1.0), (0.075, 2.0)])
def test_the_robot_reaches_a_map_goal_with_odometry_in_odom(ros_context, drift, jump_at):
    """Also with odometry that drifts 0.075 m per metre driven (0.3 m over the 4 m) and a
    0.2 m localisation correction 2 s in, both corrected by map -> odom as AMCL does."""
    common = [Parameter("map_name", value="maze2d-large"), Parameter("robot", value="circle"),
              Parameter("use_sim_time", value=True)]
    sim = SimBridge(context=ros_context, parameter_overrides=[
        Parameter("map", value="maze2d-large"), Parameter("robot", value="circle"),
        Parameter("start_x", value=START[0]), Parameter("start_y", value=START[1]),
        Parameter("start_yaw", value=START[2]), Parameter("odom_frame", value="odom"),
        Parameter("odom_drift", value=drift), Parameter("odom_jump_at", value=jump_at),
        Parameter("realtime_factor", value=2.0)])
    planner = GlobalPlanner(context=ros_context, parameter_overrides=common)
    refiner = LocalRefiner(context=ros_context, parameter_overrides=common)
    probe = rclpy.create_node("probe", context=ros_context)
    goal_pub = probe.create_publisher(PoseStamped, "goal_pose", 10)
    executor = SingleThreadedExecutor(context=ros_context)
    nodes = (sim, planner, refiner, probe)
    for node in nodes:
        executor.add_node(node)
    deadline = time.monotonic() + WALL_LIMIT
    try:
        # the planner's pose is in map, where the robot is, though odometry starts at (0, 0)
        spin_until(executor, lambda: planner.ready and planner.pose is not None,
                   deadline - time.monotonic(), "map, models and a pose through /tf")
        assert math.dist(planner.pose, START[:2]) < 0.05
        goal = PoseStamped()
        goal.header.frame_id = "map"
        goal.pose.position.x, goal.pose.position.y = GOAL
        goal.pose.orientation.w = 1.0
        spin_until(executor, lambda: goal_pub.get_subscription_count() > 0,
                   deadline - time.monotonic(), "the planner subscribed")
        goal_pub.publish(goal)
        spin_until(executor, lambda: math.dist((sim.sim.state.x, sim.sim.state.y), GOAL) < 0.3,
                   deadline - time.monotonic(), "the robot at the goal")
        state = sim.sim.state
        assert state.contact_count == 0  # no wall touched on the way
        assert refiner.runner.pose[:2] == pytest.approx((state.x, state.y), abs=0.1)
        if drift:  # the odometry itself wandered: only tf kept the poses right
            odom_origin = sim._odom_origin.xy_yaw()
            assert math.dist(odom_origin[:2], START[:2]) > 0.3
    finally:
        executor.shutdown()
        for node in nodes:
            node.destroy_node()


def test_tf_lost_mid_run_stops_the_robot_until_it_returns(ros_context):
    """The localisation's map -> odom stops coming: the odometry can no longer be placed in map,
    the refiner's pose goes stale and the robot is commanded to stop (within stale_timeout);
    a warning names the missing transform; when tf returns the robot drives on to the goal."""
    common = [Parameter("map_name", value="maze2d-large"), Parameter("robot", value="circle"),
              Parameter("use_sim_time", value=True)]
    sim = SimBridge(context=ros_context, parameter_overrides=[
        Parameter("map", value="maze2d-large"), Parameter("robot", value="circle"),
        Parameter("start_x", value=START[0]), Parameter("start_y", value=START[1]),
        Parameter("odom_frame", value="odom"), Parameter("realtime_factor", value=2.0)])
    planner = GlobalPlanner(context=ros_context, parameter_overrides=common)
    refiner = LocalRefiner(context=ros_context, parameter_overrides=common)
    probe = rclpy.create_node("probe", context=ros_context)
    goal_pub = probe.create_publisher(PoseStamped, "goal_pose", 10)
    executor = SingleThreadedExecutor(context=ros_context)
    nodes = (sim, planner, refiner, probe)
    for node in nodes:
        executor.add_node(node)
    deadline = time.monotonic() + WALL_LIMIT
    real_publish = sim._tf_pub.publish
    try:
        spin_until(executor, lambda: planner.ready and planner.pose is not None,
                   deadline - time.monotonic(), "planner ready")
        goal = PoseStamped()
        goal.header.frame_id = "map"
        goal.pose.position.x, goal.pose.position.y = GOAL
        goal.pose.orientation.w = 1.0
        spin_until(executor, lambda: goal_pub.get_subscription_count() > 0,
                   deadline - time.monotonic(), "the planner subscribed")
        goal_pub.publish(goal)
        spin_until(executor, lambda: sim.sim.state.x > START[0] + 0.5,
                   deadline - time.monotonic(), "the robot under way")

        def without_map_odom(msg):  # the localisation died: odom -> base_link only
            msg.transforms = [t for t in msg.transforms if t.child_frame_id != "odom"]
            real_publish(msg)

        sim._tf_pub.publish = without_map_odom
        lost_at = sim.sim.state.t
        stale = refiner.params.stale_timeout
        spin_until(executor, lambda: sim.sim.state.t > lost_at + stale + 1.0,
                   deadline - time.monotonic(), "sim time past the stale timeout")
        x_stopped = sim.sim.state.x
        assert sim.sim.state.v == 0.0  # commanded to stop: no pose it can trust
        t_stopped = sim.sim.state.t
        spin_until(executor, lambda: sim.sim.state.t > t_stopped + 1.0,
                   deadline - time.monotonic(), "a second more without tf")
        assert sim.sim.state.x == pytest.approx(x_stopped, abs=1e-6)  # still standing
        sim._tf_pub.publish = real_publish  # the localisation is back
        spin_until(executor, lambda: math.dist((sim.sim.state.x, sim.sim.state.y), GOAL) < 0.3,
                   deadline - time.monotonic(), "the robot at the goal after tf returned")
        assert sim.sim.state.contact_count == 0
    finally:
        sim._tf_pub.publish = real_publish
        executor.shutdown()
        for node in nodes:
            node.destroy_node()
