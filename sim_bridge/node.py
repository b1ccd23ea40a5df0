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

Publishes:
    map (nav_msgs/OccupancyGrid; reliable, transient_local, depth 1): the simulated walls.
    odom (nav_msgs/Odometry; reliable, depth 10): every step. There is no tf here, so the pose is
        given in map coordinates: header.frame_id "map", child_frame_id "base_link", twist in
        base_link.
    clock (rosgraph_msgs/Clock; reliable, depth 10): simulated time, every step.
    collision (std_msgs/Bool; reliable, depth 10): every step, true when the robot's shape hit a
        wall during that step.
    camera/image_raw (sensor_msgs/Image rgb8, 256 px longer side; reliable, depth 1): optional.
Subscribes:
    cmd_vel (geometry_msgs/Twist or TwistStamped; reliable, depth 10): linear.x, angular.z.
    initialpose (geometry_msgs/PoseWithCovarianceStamped; reliable, depth 10): teleport, as
        RViz's "2D Pose Estimate" publishes it (frame "map" or empty).

The loop runs from a steady wall-clock timer (so ``use_sim_time`` cannot stall it) with period
1 / (rate_hz * realtime_factor); each tick advances simulated time by 1 / rate_hz. If a tick
takes longer than its period, simulated time falls behind the wall clock; it never skips.
Bad input (NaN velocities, a pose in a wall, an unknown map) is logged and ignored.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import rclpy
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseWithCovarianceStamped, Twist, TwistStamped
from nav_msgs.msg import OccupancyGrid, Odometry
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import Image
from std_msgs.msg import Bool

from ecahd_core.errors import EcahdError
from ecahd_ros.conversions import grid_to_msg, pose_from_xy_yaw, yaw_from_quaternion
from ecahd_ros.qos import MAP_QOS, STREAM_QOS, VIZ_QOS
from ecahd_ros.params import ParamSpec, declare_parameters, read_parameters
from ecahd_ros.spin import spin_node
from sim_bridge.sim import MazeSim, SimConfig, SimError, SimState

CAMERA_SIZE = 256  # [px] longer side of the top-down image
MAP_FRAME = "map"
BASE_FRAME = "base_link"

# one place for every parameter of the node
PARAMETERS = [
    ParamSpec("map", "maze2d-large", "built-in maze (maze2d-umaze, maze2d-medium, maze2d-large) or Nav2 "
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
]


@dataclass(frozen=True, kw_only=True)
class SimBridgeParams:
    """The node's validated parameters (see the module docstring for units)."""

    map: str
    resolution: float
    robot: str
    footprint: str
    start_x: float
    start_y: float
    start_yaw: float
    rate_hz: float
    control_timeout: float
    max_v: float
    max_w: float
    realtime_factor: float
    publish_camera: bool
    camera_rate_hz: float
    enable_stamped_cmd_vel: bool

    def __post_init__(self) -> None:
        for name in ("resolution", "rate_hz", "control_timeout", "max_v", "max_w",
                     "camera_rate_hz"):
            if not getattr(self, name) > 0:
                raise SimError(f"parameter {name} must be > 0, got {getattr(self, name)}")

    def sim_config(self) -> SimConfig:
        return SimConfig(map=self.map, resolution=self.resolution,
                         robot=self.footprint or self.robot, dt=1.0 / self.rate_hz,
                         max_v=self.max_v, max_w=self.max_w,
                         start=(self.start_x, self.start_y, self.start_yaw))

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


class SimBridge(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("sim_bridge", **kwargs)
        declare_parameters(self, PARAMETERS)
        self.params: SimBridgeParams | None = None
        self.sim: MazeSim | None = None
        self.rejected_commands = 0  # cmd_vel messages ignored as malformed
        self._cmd = (0.0, 0.0)  # (v [m/s], w [rad/s])
        self._cmd_time: float | None = None  # [s of sim time] when _cmd arrived
        self._next_camera_t = 0.0
        try:
            self.params = read_sim_parameters(self)
            self.sim = MazeSim(self.params.sim_config())
        except EcahdError as exc:
            self.get_logger().error(f"sim_bridge cannot start: {exc}")
            return
        p = self.params
        self._map_pub = self.create_publisher(OccupancyGrid, "map", MAP_QOS)
        self._odom_pub = self.create_publisher(Odometry, "odom", STREAM_QOS)
        self._clock_pub = self.create_publisher(ClockMsg, "clock", STREAM_QOS)
        self._collision_pub = self.create_publisher(Bool, "collision", STREAM_QOS)
        self._camera_pub = (self.create_publisher(Image, "camera/image_raw", VIZ_QOS)
                            if p.publish_camera else None)
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
            f"({self.sim.n_wall_boxes} wall boxes) at {p.rate_hz:g} Hz sim time, "
            f"realtime factor {p.realtime_factor:g}"
            f"{' (as fast as possible)' if p.realtime_factor <= 0 else ''}")

    # --------------------------------------------------------------------------- callbacks
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
        odom = Odometry()
        odom.header.stamp, odom.header.frame_id = now, MAP_FRAME
        odom.child_frame_id = BASE_FRAME
        odom.pose.pose = pose_from_xy_yaw(state.x, state.y, state.yaw)
        odom.twist.twist.linear.x, odom.twist.twist.angular.z = state.v, state.w
        self._odom_pub.publish(odom)
        self._collision_pub.publish(Bool(data=state.in_contact))
        if self._camera_pub is not None and state.t >= self._next_camera_t - 1e-9:
            self._next_camera_t = state.t + 1.0 / self.params.camera_rate_hz
            self._camera_pub.publish(self._image(state))

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
    spin_node(SimBridge, args)


if __name__ == "__main__":
    main()
