"""The one home of the QoS profiles every ecahd_ros node and sim_bridge use (STYLE.md habit 12).

    MAP_QOS     map (OccupancyGrid): reliable, transient_local, depth 1, as Nav2's map_server.
    PLAN_QOS    plan (Path): reliable, transient_local, depth 1: a restarted refiner gets the
                latest plan.
    STREAM_QOS  odom, cmd_vel, goal_pose, clock, collision, scan, ecahd/timing: reliable,
                volatile, depth 10.
    VIZ_QOS     RViz-only topics (markers, local_plan, camera): reliable, volatile, depth 1.
    SCAN_QOS    scan subscriptions: rclpy's sensor-data profile (best effort, depth 5), which
                matches reliable and best-effort LiDAR drivers alike.
    TF_QOS      /tf: reliable, volatile, depth 100, as tf2_ros.
    TF_STATIC_QOS  /tf_static: reliable, transient_local, depth 100 (late joiners get them).
"""
from __future__ import annotations

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

MAP_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
PLAN_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)
STREAM_QOS = QoSProfile(depth=10)
VIZ_QOS = QoSProfile(depth=1)
SCAN_QOS = qos_profile_sensor_data
TF_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
TF_STATIC_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)
