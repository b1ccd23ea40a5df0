"""sim_bridge: the PyBullet simulator behind its own ROS 2 node.

- ``sim_bridge.sim``: the simulator core without rclpy: walls built from a GridMap, the robot
  footprint as a collision body, unicycle kinematics with real contacts, a 2D LiDAR and
  obstacles that are not on the map, static or moving (``MazeSim``).
- ``sim_bridge.node``: the ``sim_bridge`` executable: ``cmd_vel`` and ``initialpose`` in;
  ``map``, ``odom``, ``clock`` (simulated time), ``collision``, ``collision_detail``, ``scan``,
  ``sim_obstacles`` and an optional top-down camera out.

Table III's episode bookkeeping (goal radius, episode length) lives in
``ecahd_core.evaluation`` and is computed from recorded bags.
"""
