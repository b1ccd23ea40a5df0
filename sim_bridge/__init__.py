"""sim_bridge: the PyBullet maze simulator behind its own ROS 2 node.

- ``sim_bridge.sim``: the simulator core without rclpy: walls built from a GridMap, the robot
  footprint as a collision body, unicycle kinematics with real contacts (``MazeSim``), and D4RL
  maze2d episode bookkeeping (``EpisodeTracker``).
- ``sim_bridge.node``: the ``sim_bridge`` executable: ``cmd_vel`` in; ``map``, ``odom``,
  ``clock`` (simulated time), ``collision`` and an optional top-down camera out.
"""
