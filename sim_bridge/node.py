"""sim_bridge: the PyBullet maze simulator (``sim_bridge.sim``) behind ROS 2 topics, with its own
simulated clock so a run can go faster than real time.

Parameters (read-only: they configure the simulator at start-up):
    map (str, "maze2d-large"): built-in maze or Nav2 map YAML path.
    resolution (double, 0.1): [m/cell] rasterisation of built-in mazes.
    robot (str, "circle"): footprint preset (circle, quadruped, humanoid).
    footprint (str, ""): Nav2 polygon "[[x, y], ...]" [m]; overrides ``robot`` when set.
    start_x, start_y, start_yaw (double, 1.5, 1.5, 0.0): [m, m, rad] initial pose.
    rate_hz (double, 50.0): simulation steps per second of simulated time (dt = 1 / rate_hz).
    control_timeout (double, 0.5): [s of sim time] a cmd_vel older than this stops the robot.
    max_v (double, 1.0): [m/s] limit on |linear velocity|.
    max_w (double, 2.0): [rad/s] limit on |angular velocity|.
    realtime_factor (double, 1.0): sim seconds per wall second; 0 or less = as fast as possible.
    publish_camera (bool, false): publish a top-down image on ``camera/image_raw``.
    camera_rate_hz (double, 1.0): [Hz of sim time] image rate.
    enable_stamped_cmd_vel (bool, false): cmd_vel is geometry_msgs/TwistStamped instead of Twist
        (Nav2 Jazzy's parameter name and default).
    publish_scan (bool, true): publish a 2D LiDAR scan on ``scan``.
    scan_rate_hz (double, 10.0): [Hz of sim time] scan rate (also the ``sim_obstacles`` rate).
    scan_beams (int, 360): beams per scan, a full turn: angle_min = -pi, increment = 2 pi / beams.
    scan_range_min, scan_range_max (double, 0.1, 8.0): [m] REP 117: a return closer than
        range_min reads -inf, no return within range_max reads +inf.
    scan_noise_std (double, 0.0): [m] Gaussian noise on every return.
    scan_offset_x, scan_offset_y, scan_offset_yaw (double, 0.0, 0.0, 0.0): [m, m, rad] the fixed
        base_link -> base_scan transform (where the LiDAR is mounted).
    scan_frame_id (str, "base_scan"): header.frame_id of the scans.
    seed (int, 0): seed of the simulator's random generator (scan noise).
    obstacles_file (str, ""): scenario YAML of obstacles that are not on the map
        (``ecahd_core.scenario``; '' = none). A bad entry, or an obstacle off the map or on the
        start pose, is logged (one line naming it) and left out; the others load.

Publishes:
    map (nav_msgs/OccupancyGrid; reliable, transient_local, depth 1): the simulated walls.
    odom (nav_msgs/Odometry; reliable, depth 10): every step, in ``odom_frame``: "odom" (the
        default, REP-105) gives it from where the robot started; "map" gives the true pose in
        map coordinates. header.frame_id ``odom_frame``, child_frame_id "base_link", twist in
        base_link.
    /tf (tf2_msgs/TFMessage; reliable, depth 100): every step, ``odom_frame`` -> base_link
        and, with an odometry frame, map -> ``odom_frame`` (the start pose: a localisation
        stand-in without drift).
    /tf_static (tf2_msgs/TFMessage; reliable, transient_local): base_link -> scan_frame_id from
        the scan_offset_* parameters.
    clock (rosgraph_msgs/Clock; reliable, depth 10): simulated time, every step.
    collision (std_msgs/Bool; reliable, depth 10): every step, true when the robot's shape hit a
        wall or an obstacle during that step.
    collision_detail (std_msgs/String; reliable, depth 10): only on steps with a contact, JSON
        ``{"t": sim time [s], "kind": "wall" | "static_obstacle" | "moving_obstacle",
        "obstacle": index in obstacles_file's list or null, "x": [m], "y": [m],
        "contact_count": n}`` ("kind" is the first of moving, static, wall when a step hit
        several), so a bag tells obstacle contacts from wall contacts.
    scan (sensor_msgs/LaserScan; reliable, depth 10): at scan_rate_hz of sim time. A scan's
        pose is the robot's pose at its stamp (the sim time of the step) composed with the
        scan_offset_* transform (base_link -> scan_frame_id on /tf_static); frame scan_frame_id. It sees walls and
        obstacles, not the robot itself.
    sim_obstacles (visualization_msgs/MarkerArray; reliable, depth 1): the true obstacles as
        CUBE / CYLINDER markers (id = index in the scenario) in frame "map", 1 m high, at
        scan_rate_hz; only when there are obstacles. Obstacles never appear on ``map``.
    camera/image_raw (sensor_msgs/Image rgb8, 256 px longer side; reliable, depth 1): optional.
Subscribes:
    cmd_vel (geometry_msgs/Twist or TwistStamped; reliable, depth 10): linear.x, angular.z.
    initialpose (geometry_msgs/PoseWithCovarianceStamped; reliable, depth 10): teleport, as
        RViz's "2D Pose Estimate" publishes it (frame "map" or empty).

The loop runs from a steady wall-clock timer (so ``use_sim_time`` cannot stall it) with period
1 / (rate_hz * realtime_factor); each tick advances simulated time by 1 / rate_hz. If a tick
takes longer than its period, simulated time falls behind the wall clock; it never skips.
Bad input while running (NaN velocities, a pose in a wall) is logged and ignored. A configuration
that cannot work (a parameter out of range, an unknown map, an unreadable obstacles_file) raises
EcahdError from the constructor, so ``ros2 run`` exits non-zero naming the reason.
"""
from __future__ import annotations

import json
import math

import numpy as np
import rclpy
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseWithCovarianceStamped, Twist, TwistStamped
from nav_msgs.msg import OccupancyGrid, Odometry
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import Image, LaserScan
from std_msgs.msg import Bool, String
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import Marker, MarkerArray

from ecahd_core.errors import EcahdError
from ecahd_core.frames import Transform
from ecahd_core.scenario import Obstacle, read_scenario
from ecahd_ros.conversions import grid_to_msg, pose_from_xy_yaw, yaw_from_quaternion
from ecahd_ros.qos import MAP_QOS, STREAM_QOS, TF_QOS, TF_STATIC_QOS, VIZ_QOS
from ecahd_ros.params import (declare_parameters, parameters_dataclass, read_parameters, require,
                              require_non_negative, require_positive)
from ecahd_ros.sim_bridge_params import DYNAMIC, PARAMETERS  # every parameter, declared once
from ecahd_ros.spin import spin_node
from ecahd_ros.tf_listener import transform_stamped
from sim_bridge.sim import WALL_HEIGHT, MazeSim, SimConfig, SimError, SimState, scan_angles

CAMERA_SIZE = 256  # [px] longer side of the top-down image
MAP_FRAME = "map"
BASE_FRAME = "base_link"


@parameters_dataclass(PARAMETERS)
class SimBridgeParams:
    """The node's validated parameters (see the module docstring for units)."""

    def __post_init__(self) -> None:
        for name in ("resolution", "rate_hz", "control_timeout", "max_v", "max_w",
                     "camera_rate_hz"):
            if not getattr(self, name) > 0:
                raise SimError(f"parameter {name} must be > 0, got {getattr(self, name)}")
        require_positive(self, "scan_rate_hz", "scan_beams")
        require_non_negative(self, "scan_range_min", "scan_noise_std")
        require(self.scan_range_max > self.scan_range_min, "scan_range_max",
                self.scan_range_max, f"> scan_range_min ({self.scan_range_min})")
        require(bool(self.scan_frame_id.strip()), "scan_frame_id", self.scan_frame_id,
                "a frame name")
        require(bool(self.odom_frame.strip()) and self.odom_frame not in (BASE_FRAME,
                                                                       self.scan_frame_id),
                "odom_frame", self.odom_frame, "'map' or an odometry frame such as 'odom'")

    @property
    def scan_offset(self) -> tuple[float, float, float]:
        """(x [m], y [m], yaw [rad]) of the LiDAR in base_link."""
        return self.scan_offset_x, self.scan_offset_y, self.scan_offset_yaw

    def sim_config(self, obstacles: tuple[Obstacle, ...] = ()) -> SimConfig:
        return SimConfig(map=self.map, resolution=self.resolution,
                         robot=self.footprint or self.robot, dt=1.0 / self.rate_hz,
                         max_v=self.max_v, max_w=self.max_w,
                         start=(self.start_x, self.start_y, self.start_yaw),
                         obstacles=tuple(obstacles), seed=self.seed)

    @property
    def timer_period(self) -> float:
        """[s] wall time between steps; 0 runs a step on every executor iteration."""
        if self.realtime_factor <= 0:
            return 0.0
        return 1.0 / (self.rate_hz * self.realtime_factor)


def read_sim_parameters(node: Node) -> SimBridgeParams:
    """Read and validate; raises EcahdError (SimError for ranges) naming the first bad value."""
    return read_parameters(node, PARAMETERS, SimBridgeParams)


def stamp(t: float) -> Time:
    """Simulated time [s] -> builtin_interfaces/Time (rounded to the nanosecond)."""
    ns = int(round(t * 1e9))
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def obstacle_markers(sim: MazeSim, stamp_msg: Time) -> MarkerArray:
    """The obstacles in the world now -> MarkerArray of CUBE / CYLINDER markers (frame map,
    id = index in the scenario, 1 m high, standing on z = 0)."""
    out = MarkerArray()
    for index, ob, (x, y) in sim.obstacles:
        m = Marker()
        m.header.stamp, m.header.frame_id = stamp_msg, MAP_FRAME
        m.ns, m.id, m.action = "sim_obstacles", index, Marker.ADD
        m.pose = pose_from_xy_yaw(x, y, ob.yaw)
        m.pose.position.z = WALL_HEIGHT / 2
        if ob.shape == "box":
            m.type = Marker.CUBE
            m.scale.x, m.scale.y = ob.size
        else:
            m.type = Marker.CYLINDER
            m.scale.x = m.scale.y = 2.0 * ob.radius
        m.scale.z = WALL_HEIGHT
        m.color.r, m.color.g, m.color.b, m.color.a = ((0.9, 0.5, 0.1, 0.8) if ob.moving
                                                      else (0.6, 0.4, 0.2, 0.8))
        out.markers.append(m)
    return out


class SimBridge(Node):
    """Raises EcahdError (after releasing what it built) when the configuration cannot work."""

    def __init__(self, **kwargs) -> None:
        super().__init__("sim_bridge", **kwargs)
        self.params: SimBridgeParams | None = None
        self.sim: MazeSim | None = None
        try:
            self._configure()
        except EcahdError:
            self.destroy_node()
            raise

    def _configure(self) -> None:
        declare_parameters(self, PARAMETERS, dynamic=DYNAMIC)
        self.rejected_commands = 0  # cmd_vel messages ignored as malformed
        self._cmd = (0.0, 0.0)  # (v [m/s], w [rad/s])
        self._cmd_time: float | None = None  # [s of sim time] when _cmd arrived
        self._next_camera_t = 0.0
        self._next_scan_t = 0.0
        self.params = p = read_sim_parameters(self)
        obstacles: list[Obstacle] = []
        if p.obstacles_file.strip():
            obstacles, errors = read_scenario(p.obstacles_file)  # unreadable file: raises
            for line in errors:
                self.get_logger().error(f"{p.obstacles_file}: {line}; left out")
        self.sim = MazeSim(p.sim_config(tuple(obstacles)))
        for line in self.sim.rejected_obstacles:
            self.get_logger().error(f"{p.obstacles_file}: {line}")
        self._scan_angles, self._scan_increment = scan_angles(p.scan_beams)
        self._map_pub = self.create_publisher(OccupancyGrid, "map", MAP_QOS)
        self._odom_pub = self.create_publisher(Odometry, "odom", STREAM_QOS)
        self._clock_pub = self.create_publisher(ClockMsg, "clock", STREAM_QOS)
        self._collision_pub = self.create_publisher(Bool, "collision", STREAM_QOS)
        self._detail_pub = self.create_publisher(String, "collision_detail", STREAM_QOS)
        self._camera_pub = (self.create_publisher(Image, "camera/image_raw", VIZ_QOS)
                            if p.publish_camera else None)
        self._scan_pub = (self.create_publisher(LaserScan, "scan", STREAM_QOS)
                          if p.publish_scan else None)
        self._obstacles_pub = self.create_publisher(MarkerArray, "sim_obstacles", VIZ_QOS)
        self._tf_pub = self.create_publisher(TFMessage, "/tf", TF_QOS)
        self._tf_static_pub = self.create_publisher(TFMessage, "/tf_static", TF_STATIC_QOS)
        # REP-105: odometry starts where the robot starts; the stand-in localisation publishes
        # map -> odom there (no drift)
        self._odom_origin = (Transform.identity() if p.odom_frame == MAP_FRAME
                             else Transform.from_xy_yaw(p.start_x, p.start_y, p.start_yaw))
        self._driven = 0.0  # [m] path length, for odom_drift
        self._last_xy = (p.start_x, p.start_y)
        self._jumped = False
        self._tf_static_pub.publish(TFMessage(transforms=[transform_stamped(
            BASE_FRAME, p.scan_frame_id, stamp(self.sim.state.t),
            Transform.from_xy_yaw(*p.scan_offset))]))
        self.add_on_set_parameters_callback(self._on_set_parameters)
        cmd_type = TwistStamped if p.enable_stamped_cmd_vel else Twist
        self.create_subscription(cmd_type, "cmd_vel", self._on_cmd_vel, STREAM_QOS)
        self.create_subscription(PoseWithCovarianceStamped, "initialpose", self._on_initialpose,
                                 STREAM_QOS)
        self._map_pub.publish(grid_to_msg(self.sim.grid, stamp(self.sim.state.t)))
        self._publish(self.sim.state)
        self._timer = self.create_timer(p.timer_period, self._on_tick,
                                        clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(
            f"simulating {self.sim.footprint.name} on {self.sim.grid.name!r} "
            f"({self.sim.n_wall_boxes} wall boxes, {len(self.sim.obstacles)} obstacles) at "
            f"{p.rate_hz:g} Hz sim time, "
            f"realtime factor {p.realtime_factor:g}"
            f"{' (as fast as possible)' if p.realtime_factor <= 0 else ''}")

    # --------------------------------------------------------------------------- callbacks
    def _on_set_parameters(self, changes):
        """``obstacles_file`` may change at run time: the new scenario replaces the obstacles
        (an unreadable file is rejected with its reason; bad entries are left out, logged)."""
        from rcl_interfaces.msg import SetParametersResult

        for change in changes:
            if change.name != "obstacles_file":
                continue
            path = str(change.value).strip()
            try:
                obstacles, errors = read_scenario(path) if path else ([], [])
            except EcahdError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
            for line in errors:
                self.get_logger().error(f"{path}: {line}; left out")
            for line in self.sim.set_obstacles(obstacles):
                self.get_logger().error(f"{path}: {line}")
            if not self.sim.obstacles:  # RViz: clear the old markers
                clear = Marker()
                clear.action = Marker.DELETEALL
                self._obstacles_pub.publish(MarkerArray(markers=[clear]))
            self.get_logger().info(f"obstacles from {path or 'nothing'}: "
                                   f"{len(self.sim.obstacles)} in the world")
        return SetParametersResult(successful=True)

    def _on_cmd_vel(self, msg: Twist | TwistStamped) -> None:
        twist = msg.twist if isinstance(msg, TwistStamped) else msg
        v, w = twist.linear.x, twist.angular.z
        if not (math.isfinite(v) and math.isfinite(w)):
            self.rejected_commands += 1
            self.get_logger().error(f"ignoring cmd_vel with non-finite values "
                                    f"(linear.x={v}, angular.z={w})")
            return
        self._cmd = (v, w)
        self._cmd_time = self.sim.state.t

    def _on_initialpose(self, msg: PoseWithCovarianceStamped) -> None:
        if msg.header.frame_id not in ("", MAP_FRAME):
            self.get_logger().error(f"ignoring initialpose in frame {msg.header.frame_id!r}: "
                                    f"expected {MAP_FRAME!r} (there is no tf here)")
            return
        pose = msg.pose.pose
        try:
            state = self.sim.reset(pose.position.x, pose.position.y,
                                   yaw_from_quaternion(pose.orientation))
        except SimError as exc:
            self.get_logger().error(f"ignoring initialpose: {exc}")
            return
        self._cmd, self._cmd_time = (0.0, 0.0), None  # a teleported robot stands still
        self.get_logger().info(f"teleported to ({state.x:.3f}, {state.y:.3f}, {state.yaw:.3f})")

    def _on_tick(self) -> None:
        t = self.sim.state.t
        fresh = self._cmd_time is not None and t - self._cmd_time <= self.params.control_timeout
        v, w = self._cmd if fresh else (0.0, 0.0)
        self._publish(self.sim.step(v, w))

    # ------------------------------------------------------------------------------ output
    def _publish(self, state: SimState) -> None:
        now = stamp(state.t)
        self._clock_pub.publish(ClockMsg(clock=now))
        frame = self.params.odom_frame
        if frame != MAP_FRAME:
            self._drift(state)
        base = self._odom_origin.inverse() * Transform.from_xy_yaw(state.x, state.y, state.yaw)
        odom = Odometry()
        odom.header.stamp, odom.header.frame_id = now, frame
        odom.child_frame_id = BASE_FRAME
        odom.pose.pose = pose_from_xy_yaw(*base.xy_yaw())
        odom.twist.twist.linear.x, odom.twist.twist.angular.z = state.v, state.w
        self._odom_pub.publish(odom)
        transforms = [transform_stamped(frame, BASE_FRAME, now, base)]
        if frame != MAP_FRAME:
            transforms.append(transform_stamped(MAP_FRAME, frame, now, self._odom_origin))
        self._tf_pub.publish(TFMessage(transforms=transforms))
        self._collision_pub.publish(Bool(data=state.in_contact))
        if state.in_contact:
            self._detail_pub.publish(String(data=json.dumps({
                "t": state.t, "kind": state.collision_kind, "obstacle": state.collision_obstacle,
                "x": state.x, "y": state.y, "contact_count": state.contact_count})))
        if state.t >= self._next_scan_t - 1e-9:
            self._next_scan_t = state.t + 1.0 / self.params.scan_rate_hz
            if self._scan_pub is not None:
                self._scan_pub.publish(self._scan(state))
            if self.sim.obstacles:
                self._obstacles_pub.publish(obstacle_markers(self.sim, now))
        if self._camera_pub is not None and state.t >= self._next_camera_t - 1e-9:
            self._next_camera_t = state.t + 1.0 / self.params.camera_rate_hz
            self._camera_pub.publish(self._image(state))

    def _drift(self, state: SimState) -> None:
        """The odometry's error (odom_drift, odom_jump at odom_jump_at) as a moving odom origin:
        map -> odom changes by it, so map -> base_link through tf stays the true pose while the
        odometry itself wanders, as a real robot's does under a localisation."""
        p = self.params
        step = math.dist((state.x, state.y), self._last_xy)
        self._last_xy = (state.x, state.y)
        self._driven += step
        shift = [0.0, 0.0]
        if p.odom_drift:  # sideways, in the odom frame's y
            shift[1] += p.odom_drift * step
        if p.odom_jump_at >= 0 and not self._jumped and state.t >= p.odom_jump_at:
            self._jumped = True
            shift[0] += p.odom_jump
        if shift != [0.0, 0.0]:
            self._odom_origin = Transform.from_xy_yaw(shift[0], shift[1], 0.0) * self._odom_origin

    def _scan(self, state: SimState) -> LaserScan:
        p = self.params
        ranges = self.sim.scan(p.scan_offset, p.scan_beams, p.scan_range_min, p.scan_range_max,
                               noise_std=p.scan_noise_std)
        msg = LaserScan()
        msg.header.stamp, msg.header.frame_id = stamp(state.t), p.scan_frame_id
        msg.angle_min = float(self._scan_angles[0])
        msg.angle_max = float(self._scan_angles[-1])
        msg.angle_increment = self._scan_increment
        msg.time_increment = 0.0  # every beam at the stamp
        msg.scan_time = 1.0 / p.scan_rate_hz
        msg.range_min, msg.range_max = p.scan_range_min, p.scan_range_max
        msg.ranges = ranges.astype(np.float32).tolist()
        return msg

    def _image(self, state: SimState) -> Image:
        rgb = self.sim.render_topdown(CAMERA_SIZE)
        msg = Image()
        msg.header.stamp, msg.header.frame_id = stamp(state.t), MAP_FRAME
        msg.height, msg.width = rgb.shape[:2]
        msg.encoding, msg.is_bigendian, msg.step = "rgb8", 0, rgb.shape[1] * 3
        msg.data = rgb.tobytes()
        return msg

    def destroy_node(self) -> None:
        super().destroy_node()
        if self.sim is not None:
            self.sim.close()


def main(args=None) -> None:
    spin_node(SimBridge, args, name="sim_bridge")


if __name__ == "__main__":
    main()
