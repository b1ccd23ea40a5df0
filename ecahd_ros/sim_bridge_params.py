"""The parameters of the ``sim_bridge`` node (``sim_bridge.node``), declared once here, on the
ROS side, so that what reads them without running the simulator (``ecahd config``, the
navigation benchmark's control limits) does not import ``sim_bridge``: the simulator depends on
``ecahd_ros``, never the reverse. ``sim_bridge.node`` declares, reads and validates them
(``SimBridgeParams``); its docstring gives each one's meaning and units."""
from __future__ import annotations

from ecahd_core.maps import DEFAULT_MAP
from ecahd_ros.params import ParamSpec, shared

PARAMETERS = [
    ParamSpec("map", DEFAULT_MAP, "built-in maze (maze2d-umaze, maze2d-medium, maze2d-large) or Nav2 "
                            "map YAML path"),
    ParamSpec("resolution", 0.1, "[m/cell] rasterisation of built-in mazes"),
    ParamSpec("robot", "circle", "footprint preset: circle, quadruped, humanoid"),
    ParamSpec("footprint", "", "Nav2 footprint polygon '[[x, y], ...]' [m]; overrides robot when set"),
    ParamSpec("start_x", 1.5, "[m] initial x in the map frame"),
    ParamSpec("start_y", 1.5, "[m] initial y in the map frame"),
    ParamSpec("start_yaw", 0.0, "[rad] initial heading"),
    ParamSpec("rate_hz", 50.0, "simulation steps per second of simulated time"),
    ParamSpec("control_timeout", 0.5, "[s of sim time] a cmd_vel older than this stops the robot"),
    ParamSpec("max_v", 1.0, "[m/s] limit on |linear velocity|"),
    ParamSpec("max_w", 2.0, "[rad/s] limit on |angular velocity|"),
    ParamSpec("realtime_factor", 1.0, "simulated seconds per wall second; 0 or less = as fast as possible"),
    ParamSpec("publish_camera", False, "publish a top-down rgb8 image on camera/image_raw"),
    ParamSpec("camera_rate_hz", 1.0, "[Hz of sim time] top-down image rate"),
    ParamSpec("enable_stamped_cmd_vel", False, "cmd_vel is geometry_msgs/TwistStamped instead of Twist"),
    ParamSpec("publish_scan", True, "publish a 2D LiDAR sensor_msgs/LaserScan on scan"),
    ParamSpec("scan_rate_hz", 10.0, "[Hz of sim time] scan rate (and sim_obstacles marker rate)"),
    ParamSpec("scan_beams", 360, "beams per scan over a full turn (angle_min -pi, "
                                 "increment 2 pi / beams)"),
    ParamSpec("scan_range_min", 0.1, "[m] closer returns read -inf (REP 117)"),
    ParamSpec("scan_range_max", 8.0, "[m] no return within it reads +inf (REP 117)"),
    ParamSpec("scan_noise_std", 0.0, "[m] standard deviation of Gaussian range noise"),
    *shared("scan_offset_x", "scan_offset_y", "scan_offset_yaw"),
    ParamSpec("scan_frame_id", "base_scan", "header.frame_id of the scans"),
    ParamSpec("odom_frame", "odom", "frame of odom: a robot's odometry frame such as 'odom' "
                                    "(REP-105: odom from where the robot started, /tf odom -> "
                                    "base_link, and a localisation stand-in's map -> odom), or "
                                    "'map' (the true pose, /tf map -> base_link); /tf_static "
                                    "always holds base_link -> scan_frame_id"),
    ParamSpec("odom_drift", 0.0, "[m per m driven] with an odometry frame: the odometry drifts "
                                 "(along map y) by this much per metre driven, and the "
                                 "stand-in localisation's map -> odom corrects it (as AMCL "
                                 "does); 0 = none"),
    ParamSpec("odom_jump_at", -1.0, "[s of sim time] with an odometry frame: the localisation "
                                    "corrects the odometry by odom_jump at once at this time "
                                    "(an AMCL correction); -1 = never"),
    ParamSpec("odom_jump", 0.2, "[m] the size of that correction (along map x)"),
    ParamSpec("seed", 0, "seed of the simulator's random generator (scan noise)"),
    ParamSpec("obstacles_file", "", "scenario YAML of obstacles that are not on the map "
                                    "('' = none); dynamic: setting it replaces the obstacles "
                                    "(moving ones set off again)"),
]

# parameters that can be set at run time (the others are read-only)
DYNAMIC = ("obstacles_file",)
