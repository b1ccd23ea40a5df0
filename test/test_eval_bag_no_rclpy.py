"""``ecahd eval-bag`` where ROS is not installed: a bag written here with ``rosbags`` alone is
scored by the command in a subprocess in which rclpy and every ROS message package fail to
import; the new records (collision_detail, the control ticks' monitor / reason / wall) come out
as hand-counted metrics, and a bag recorded before them still evaluates."""
import json
import subprocess
import sys

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from ecahd_ros.eval_bag import evaluate_bag

TS = get_typestore(Stores.ROS2_JAZZY)
T = TS.types
BLOCKED = ("rclpy", "builtin_interfaces", "std_msgs", "geometry_msgs", "nav_msgs",
           "sensor_msgs", "rosgraph_msgs", "visualization_msgs")


def _time(s: float):
    sec = int(np.floor(s))
    return T["builtin_interfaces/msg/Time"](sec=sec, nanosec=int(round((s - sec) * 1e9)))


def _header(s: float, frame: str = "map"):
    return T["std_msgs/msg/Header"](stamp=_time(s), frame_id=frame)


def _pose(x: float, y: float, yaw: float = 0.0):
    return T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
        orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=float(np.sin(yaw / 2)),
                                                      w=float(np.cos(yaw / 2))))


# a robot's bag (REP-105): odometry in odom, whose origin a localisation puts at map (0.5, 2.0)
# turned -90 deg (map -> odom on /tf)
ODOM_IN_MAP = (0.5, 2.0, -np.pi / 2)


def _tf(t: float, parent: str = "map", child: str = "odom", pose=ODOM_IN_MAP):
    """A TFMessage with one transform: ``child``'s pose (x, y, yaw) in ``parent`` at t [s]."""
    x, y, yaw = pose
    vec, quat = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    transform = T["geometry_msgs/msg/Transform"](
        translation=vec(x=x, y=y, z=0.0),
        rotation=quat(x=0.0, y=0.0, z=float(np.sin(yaw / 2)), w=float(np.cos(yaw / 2))))
    return T["tf2_msgs/msg/TFMessage"](transforms=[T["geometry_msgs/msg/TransformStamped"](
        header=_header(t, parent), child_frame_id=child, transform=transform)])


def _in_odom(pose):
    """A map pose (x, y, yaw) seen from odom's origin (ODOM_IN_MAP)."""
    from ecahd_core.frames import Transform

    return (Transform.from_xy_yaw(*ODOM_IN_MAP).inverse()
            * Transform.from_xy_yaw(*pose)).xy_yaw()


def _map_msg(wall_x: float | None = None):
    # 4 m x 2 m at 0.1 m (stored as float32) with a one-cell wall frame; wall_x: one more
    # wall, the cell column [wall_x, wall_x + 0.1] across the map
    data = np.zeros((20, 40), dtype=np.int8)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    if wall_x is not None:
        data[:, int(round(wall_x / 0.1))] = 100
    info = T["nav_msgs/msg/MapMetaData"](map_load_time=_time(0.0), resolution=0.1, width=40,
                                         height=20, origin=_pose(0.0, 0.0))
    return T["nav_msgs/msg/OccupancyGrid"](header=_header(0.0), info=info,
                                           data=data.reshape(-1))


def _odom(t: float, x: float, frame: str = "map"):
    vec = T["geometry_msgs/msg/Vector3"]
    twist = T["geometry_msgs/msg/Twist"](linear=vec(x=0.0, y=0.0, z=0.0),
                                         angular=vec(x=0.0, y=0.0, z=0.0))
    pose = (x, 1.0, 0.0)
    if frame == "odom":  # the map pose seen from odom's origin
        pose = _in_odom(pose)
    return T["nav_msgs/msg/Odometry"](
        header=_header(t, frame), child_frame_id="base_link",
        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=_pose(*pose),
                                                       covariance=np.zeros(36)),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist,
                                                         covariance=np.zeros(36)))


def _string(text: str):
    return T["std_msgs/msg/String"](data=text)


def _plan(t: float, points):
    return T["nav_msgs/msg/Path"](header=_header(t), poses=[
        T["geometry_msgs/msg/PoseStamped"](header=_header(t), pose=_pose(x, y))
        for x, y in points])


def write_bag(path, *, new_records: bool = True, odom_frame: str = "map", namespace="",
              global_tf: bool = False, poses: str = "odom", goals: str = "goal_pose",
              contacts: bool = True, wall_x: float | None = None) -> None:
    """Two episodes on the one clock (receive time = sim time [s]):
    0: goal (3.0, 1.0) at 0 s; the robot drives along y = 1 from x = 0.55 at 1 m/s, reaching
       x = 3.0 at 2.45 s; one SD plan; five control ticks; two static-obstacle contacts.
    1: goal (1.0, 1.0) at 3.5 s; the robot stays at x = 3.0 (never within 0.5 m); a
       fallback_astar and an astar plan; three control ticks; a moving-obstacle and a wall
       contact.
    new_records False: a bag from before collision_detail and the monitor / wall keys.
    odom_frame "odom": the odometry in odom and map -> odom (ODOM_IN_MAP) on /tf every 0.5 s.
    A real robot's recording of the same run (Nav2-style):
    namespace: "/robot1" (or a tuple of them: the run under each) in front of every topic, tf's
    too unless global_tf.
    poses "tf": no odometry; map -> odom (ODOM_IN_MAP) on /tf every 0.5 s, odom ->
       base_footprint at 50 Hz, base_footprint -> base_link (identity) and base_link ->
       base_scan (0.1 m ahead) on /tf_static.
    goals "plan": no goal_pose (navigate_to_pose); /plan at 0 s ending at (3.0, 1.0), a replan
       at 1 s ending 0.03 m from it, an empty plan at 2 s, at 3.5 s a plan ending at (1.0, 1.0).
    contacts False: no collision nor collision_detail (no simulator).
    wall_x: a one-cell wall across the map at x = wall_x [m] (see _map_msg)."""
    msgs = []  # (t [s], topic, msgtype, message)
    msgs.append((0.0, "/map", "nav_msgs/msg/OccupancyGrid", _map_msg(wall_x)))
    for t, (x, y) in ((0.0, (3.0, 1.0)), (3.5, (1.0, 1.0))):
        if goals == "goal_pose":
            msgs.append((t, "/goal_pose", "geometry_msgs/msg/PoseStamped",
                         T["geometry_msgs/msg/PoseStamped"](header=_header(t),
                                                            pose=_pose(x, y))))
        else:  # the planner's plans from the robot's start
            msgs.append((t, "/plan", "nav_msgs/msg/Path", _plan(t, [(0.55, 1.0), (x, y)])))
    if goals == "plan":
        msgs.append((1.0, "/plan", "nav_msgs/msg/Path", _plan(1.0, [(1.55, 1.0), (3.03, 1.0)])))
        msgs.append((2.0, "/plan", "nav_msgs/msg/Path", _plan(2.0, [])))
    if poses == "tf":
        for child, parent, pose in (("base_link", "base_footprint", (0.0, 0.0, 0.0)),
                                    ("base_scan", "base_link", (0.1, 0.0, 0.0))):
            msgs.append((0.0, "/tf_static", "tf2_msgs/msg/TFMessage",
                         _tf(0.0, parent, child, pose)))
    hits = {1.0: "static_obstacle", 1.02: "static_obstacle", 4.0: "moving_obstacle",
            4.5: "wall"}
    for i in range(251):  # 50 Hz for 5 s
        t = i / 50
        x = min(0.55 + t, 3.0)
        if poses == "odom":
            msgs.append((t, "/odom", "nav_msgs/msg/Odometry", _odom(t, x, odom_frame)))
        else:
            msgs.append((t, "/tf", "tf2_msgs/msg/TFMessage",
                         _tf(t, "odom", "base_footprint", _in_odom((x, 1.0, 0.0)))))
        if (odom_frame != "map" or poses == "tf") and i % 25 == 0:
            msgs.append((t, "/tf", "tf2_msgs/msg/TFMessage", _tf(t)))
        hit = next((kind for tc, kind in hits.items() if abs(tc - t) < 1e-9), None)
        if contacts:
            msgs.append((t, "/collision", "std_msgs/msg/Bool",
                         T["std_msgs/msg/Bool"](data=bool(hit))))
        if hit and new_records and contacts:
            msgs.append((t + 1e-4, "/collision_detail", "std_msgs/msg/String", _string(
                json.dumps({"t": t, "kind": hit, "obstacle": 0, "x": x, "y": 1.0,
                            "contact_count": 1}))))
    timing = [(0.01, {"stage": "sd", "ms": 300.0}),
              (3.6, {"stage": "fallback_astar", "ms": 40.0}),
              (3.7, {"stage": "astar", "ms": 20.0})]
    ticks = [  # receive time, wall [s], monitor, reason
        (0.05, 1000.00, "none", "follow"), (0.10, 1000.05, "stop", "follow"),
        (0.15, 1000.10, "stop", "blocked"), (0.20, 1000.20, "slowdown", "follow"),
        (0.25, 1000.25, "none", "goal_reached"),
        (3.55, 2000.00, "none", "follow"), (3.60, 2000.05, "none", "follow"),
        (3.65, 2000.10, "none", "follow")]
    for t, wall, monitor, reason in ticks:
        record = {"stage": "control", "ms": 1.0, "reason": reason}
        if new_records:
            record.update(monitor=monitor, wall=wall, map_ready=True)
        timing.append((t, record))
    for t, record in timing:
        msgs.append((t, "/ecahd/timing", "std_msgs/msg/String", _string(json.dumps(record))))
    msgs.append((0.3, "/ecahd/timing", "std_msgs/msg/String", _string("not json")))  # skipped
    if new_records and contacts:
        msgs.append((0.4, "/collision_detail", "std_msgs/msg/String", _string("{}")))  # no kind
    prefixes = (namespace,) if isinstance(namespace, str) else tuple(namespace)

    def recorded_as(topic: str) -> list[str]:  # under each namespace; global tf's once
        if global_tf and topic in ("/tf", "/tf_static"):
            return [topic]
        return [prefix + topic for prefix in prefixes]

    msgs = [(t, name, msgtype, msg) for t, topic, msgtype, msg in msgs
            for name in recorded_as(topic)]
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {}
        for t, topic, msgtype, msg in sorted(msgs, key=lambda m: m[0]):
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=TS)
            writer.write(conns[topic], int(round(t * 1e9)) + 1,
                         TS.serialize_cdr(msg, msgtype))


def copy_bag(src, dst, *, drop=()) -> None:
    """Write bag ``src``'s messages to a new bag ``dst``, leaving out the topics in ``drop``."""
    from rosbags.rosbag2 import Reader

    with Reader(src) as reader:
        keep = [c for c in reader.connections if c.topic not in drop]
        rows = [(c, t, raw) for c, t, raw in reader.messages(connections=keep)]
    with Writer(dst, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {}
        for c, t, raw in rows:
            if c.topic not in conns:
                conns[c.topic] = writer.add_connection(c.topic, c.msgtype, typestore=TS)
            writer.write(conns[c.topic], t, raw)


@pytest.mark.slow
def test_eval_bag_scores_a_bag_with_rclpy_and_ros_messages_blocked(tmp_path):
    bag, out, md = tmp_path / "bag", tmp_path / "m.json", tmp_path / "m.md"
    write_bag(bag)
    code = (f"import sys\n"
            f"for name in {BLOCKED!r}:\n"
            f"    sys.modules[name] = None  # any import of it raises ImportError\n"
            f"from ecahd_ros.cli import main\n"
            f"sys.exit(main(['eval-bag', {str(bag)!r}, '--json', {str(out)!r}, "
            f"'--md', {str(md)!r}]))\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "malformed ecahd/timing" in proc.stderr and "malformed collision_detail" in proc.stderr
    result = json.loads(out.read_text())
    assert result["map"]["resolution"] == 0.1  # the float32 0.1 restored
    ep0, ep1 = result["episodes"]
    # episode 0: x = 0.55 + 0.1 k > 2.5 from step k = 20 -> 2.0 s of sim time
    assert ep0["first_reach"] == 20 and ep0["time_to_goal_s"] == pytest.approx(2.0)
    assert ep1["reached"] is False and ep1["time_to_goal_s"] is None
    assert (ep0["contact_steps_wall"], ep0["contact_steps_static"],
            ep0["contact_steps_moving"]) == (0, 2, 0)
    assert (ep1["contact_steps_wall"], ep1["contact_steps_static"],
            ep1["contact_steps_moving"]) == (1, 0, 1)
    assert ep0["contact_steps"] == 2 and ep1["contact_steps"] == 2  # the Bool flags agree
    assert (ep0["monitor_stops"], ep0["monitor_slowdowns"], ep0["blocked_ticks"]) == (2, 1, 1)
    assert (ep0["global_plans"], ep0["fallbacks"]) == (1, 0)
    assert (ep1["global_plans"], ep1["fallbacks"]) == (2, 1)
    assert ep0["control_ticks"] == 5 and ep0["inference_time_s"] == pytest.approx(0.3)
    # episode 0's intervals 50, 50, 100, 50 ms (sorted 50 50 50 100, rank 0.99 * 3 = 2.97):
    # p50 50, p99 50 + 0.97 * 50 = 98.5; |d - 50| sorted 0 0 0 50: jitter p99 0.97 * 50 = 48.5
    assert ep0["cmd_interval_ms_p50"] == pytest.approx(50.0, abs=1e-6)
    assert ep0["cmd_interval_ms_p99"] == pytest.approx(98.5, abs=1e-6)
    assert ep0["cmd_jitter_ms_p99"] == pytest.approx(48.5, abs=1e-6)
    mean = result["mean"]
    assert (mean["wall_contact_episodes"], mean["static_contact_episodes"],
            mean["moving_contact_episodes"]) == (1, 1, 1)
    assert mean["monitor_stops"] == 1.0 and mean["global_plans"] == 1.5
    assert mean["fallbacks"] == 0.5 and mean["time_to_goal_s"] == pytest.approx(2.0)
    # pooled 50 50 100 50 | 50 50 (rank 0.99 * 5 = 4.95): p99 50 + 0.95 * 50 = 97.5,
    # jitter p99 0.95 * 50 = 47.5
    assert mean["cmd_interval_ms_p99"] == pytest.approx(97.5, abs=1e-6)
    assert mean["cmd_jitter_ms_p99"] == pytest.approx(47.5, abs=1e-6)
    assert "moving-obstacle contact: 1 / 1 / 1 of 2" in md.read_text()


def test_a_bag_from_before_the_new_records_still_evaluates(tmp_path):
    write_bag(tmp_path / "old", new_records=False)
    result = evaluate_bag(tmp_path / "old", map_name="old")
    ep0, ep1 = result.metrics
    assert ep0.contact_steps == 2 and ep0.contact_steps_static is None  # flags only
    assert (ep0.monitor_stops, ep0.blocked_ticks, ep0.global_plans) == (0, 1, 1)
    assert ep0.cmd_jitter_ms_p99 is None and ep0.first_reach == 20
    s = result.summary
    assert s.static_contact_episodes is None and s.cmd_interval_ms_p50 is None
    assert s.global_plans == 1.5 and s.monitor_stops == 0.0


def test_eval_bag_draws_the_episodes_obstacles(tmp_path, capsys):
    from ecahd_core.scenario import Obstacle, write_scenario
    from ecahd_ros.cli import main

    bag, png = tmp_path / "bag", tmp_path / "t.png"
    write_bag(bag)
    folder = tmp_path / "scenarios"
    write_scenario(folder / "episode_0.yaml", [
        Obstacle("box", 1.5, 0.5, size=(0.3, 0.3)),
        Obstacle("cylinder", 1.0, 0.2, radius=0.1, path=((1.0, 0.2), (1.0, 0.8)), speed=0.3)])
    # episode 1 has no file: drawn without obstacles
    assert main(["eval-bag", str(bag), "--png", str(png), "--scenarios", str(folder)]) == 0
    assert png.stat().st_size > 1000
    assert main(["eval-bag", str(bag), "--png", str(png), "--scenarios",
                 str(tmp_path / "missing")]) == 2
    assert "not a folder" in capsys.readouterr().err


def test_a_robots_bag_with_odometry_in_odom_is_scored_through_its_tf(tmp_path):
    """The same run recorded as a robot records it (odometry in odom, map -> odom on /tf)
    scores as its map-frame recording; without the tf it is refused, naming what to record."""
    from ecahd_core.errors import BagError

    write_bag(tmp_path / "map")
    write_bag(tmp_path / "odom", odom_frame="odom")
    want, got = evaluate_bag(tmp_path / "map"), evaluate_bag(tmp_path / "odom")
    for a, b in zip(want.episodes, got.episodes):
        np.testing.assert_allclose(b.odom, a.odom, atol=1e-9)  # stamps and map poses
    for a, b in zip(want.metrics, got.metrics):
        assert (b.first_reach, b.reached, b.time_to_goal_s, b.contact_steps) == \
            (a.first_reach, a.reached, a.time_to_goal_s, a.contact_steps)
    # the same odometry without its tf cannot be placed in map
    copy_bag(tmp_path / "odom", tmp_path / "no_tf", drop={"/tf"})
    with pytest.raises(BagError, match="record /tf and /tf_static"):
        evaluate_bag(tmp_path / "no_tf")
