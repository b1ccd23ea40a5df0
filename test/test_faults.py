"""Faults (issue 9): what the navigation graph does when a part of it fails.

1. **A node dies mid-episode and is restarted** (``TestProcessGraph``): sim_bridge,
   global_planner and local_refiner each in its own process (``ecahd_ros.demo.NodeProcess``,
   as ``ecahd demo`` runs them) on maze2d-large, the circle robot in the corridor y = 5.5
   (free for x in [1, 7]), sim time at ``REALTIME_FACTOR``. This process publishes the goals
   and watches odom, cmd_vel, plan and the refiner's timing records. Each node in turn is
   killed (SIGKILL, as a crash) while the robot drives: the other processes keep running; with
   the refiner gone the robot stops within sim_bridge's ``control_timeout`` of its last
   cmd_vel; after the restart the robot drives towards the goal again. A burst of 40 goals in
   0.4 s is coalesced (the last one is planned) while cmd_vel stays at rate.
2. **A stalled local stage** (``test_a_stalled_local_stage_never_stops_cmd_vel``): an in-process
   local_refiner whose local stage takes STALL seconds keeps publishing cmd_vel at its rate,
   zero until the refined plan is ready.
3. **Malformed messages on every subscribed topic** (``test_malformed_*``): no node dies, no
   published number is non-finite, each bad message is logged in one line, valid input
   afterwards works. (map_publisher subscribes to nothing; bag_recorder stores raw bytes and
   records the bad messages like any other.)

Wall time: about 50 s on two cores, most of it process start-up and driving.
"""
import json
import math
import threading
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
from builtin_interfaces.msg import Time  # noqa: E402
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped, Twist  # noqa: E402
from nav_msgs.msg import OccupancyGrid, Odometry, Path  # noqa: E402
from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import QoSProfile  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from conftest import ROS_DOMAIN_ID, spin_until  # noqa: E402
from ecahd_core.maps import builtin_map  # noqa: E402
from ecahd_ros.conversions import grid_to_msg, pose_from_xy_yaw, xy_to_path, yaw_from_quaternion  # noqa: E402,E501
from ecahd_ros.qos import MAP_QOS, PLAN_QOS, STREAM_QOS  # noqa: E402

pytestmark = pytest.mark.slow  # node processes, killed and restarted while the robot drives

MAP = "maze2d-large"
Y = 5.5  # the corridor y in [5, 6] is free for x in [1, 7]
WEST, EAST = (1.5, Y), (6.5, Y)
REALTIME_FACTOR = 2.0
CONTROL_TIMEOUT = 0.5  # [s sim] sim_bridge's
CONTROL_RATE = 20.0  # [Hz] the process graph's refiner (its default)
# [s sim] slack on "stopped within control_timeout": sim steps (0.02 s) and the refiner's /clock,
# which lags the simulator's by a message
STOP_MARGIN = 0.2
# the probe's queues: deep enough that a probe busy for seconds (killing a process, a loaded CI
# machine) still gets every odom and timing record, so it judges by their stamps, not by when it
# happened to read them (a depth of 10 once made a robot that had stopped in time look 1.8 s late)
PROBE_QOS = QoSProfile(depth=2000)


def finite(*values) -> bool:
    return all(math.isfinite(float(v)) for v in values)


def pose_values(pose) -> tuple:
    p, q = pose.position, pose.orientation
    return p.x, p.y, p.z, q.x, q.y, q.z, q.w


def goal_msg(x: float, y: float, frame: str = "map") -> PoseStamped:
    msg = PoseStamped()
    msg.header.frame_id = frame
    msg.pose.position.x, msg.pose.position.y = x, y
    msg.pose.orientation.w = 1.0
    return msg


# ------------------------------------------------------------------------ 1. node processes
class ProcessGraph:
    """sim_bridge, global_planner, local_refiner as processes; a probe node in this process."""

    def __init__(self, out) -> None:
        from ecahd_ros.demo import NodeProcess

        self.NodeProcess = NodeProcess
        self.out = out
        common = {"map_name": MAP, "robot": "circle", "use_sim_time": True}
        self.params = {
            # odometry in map (the true pose): a restarted simulator is put where the robot was
            "sim_bridge": {"map": MAP, "robot": "circle", "start_x": WEST[0], "start_y": Y,
                           "realtime_factor": REALTIME_FACTOR, "odom_frame": "map",
                           "control_timeout": CONTROL_TIMEOUT, "publish_scan": False},
            "global_planner": dict(common),
            # the sim runs at twice real time: control at 20 Hz of sim time, as ecahd demo does
            "local_refiner": {**common, "control_rate": CONTROL_RATE, "control_clock": "ros"},
        }
        self.procs = {}
        self.starts = 0
        self.context = rclpy.context.Context()
        rclpy.init(context=self.context, domain_id=ROS_DOMAIN_ID)
        self.probe = rclpy.create_node("fault_probe", context=self.context)
        self.odom = None  # (x, y, yaw, v, w, t [s sim])
        self.odom_log = []  # every odom, in order
        self.cmds = 0
        self.plans = []  # (monotonic time, (N, 2))
        self.control_stamps = []  # [s sim] the refiner's control ticks
        self.refiner_ready = False
        self.bad = []  # non-finite numbers seen
        self.probe.create_subscription(Odometry, "odom", self._on_odom, PROBE_QOS)
        self.probe.create_subscription(Twist, "cmd_vel", self._on_cmd, PROBE_QOS)
        self.probe.create_subscription(Path, "plan", self._on_plan, PLAN_QOS)
        self.probe.create_subscription(String, "ecahd/timing", self._on_timing, PROBE_QOS)
        self.goal_pub = self.probe.create_publisher(PoseStamped, "goal_pose", STREAM_QOS)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.probe)
        for name in self.params:
            self.start(name)
        self.spin_until(lambda: self.refiner_ready and self.odom is not None
                        and self.goal_pub.get_subscription_count() > 0, "graph up", 60.0)

    # callbacks
    def _on_odom(self, msg) -> None:
        pose, twist = msg.pose.pose, msg.twist.twist
        t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        self.odom = (pose.position.x, pose.position.y, yaw_from_quaternion(pose.orientation),
                     twist.linear.x, twist.angular.z, t)
        self.odom_log.append(self.odom)
        if not finite(*pose_values(pose), twist.linear.x, twist.angular.z):
            self.bad.append(("odom", self.odom))

    def _on_cmd(self, msg) -> None:
        self.cmds += 1
        if not finite(msg.linear.x, msg.angular.z):
            self.bad.append(("cmd_vel", (msg.linear.x, msg.angular.z)))

    def _on_plan(self, msg) -> None:
        xy = np.array([[p.pose.position.x, p.pose.position.y] for p in msg.poses])
        self.plans.append((time.monotonic(), xy))
        if not np.all(np.isfinite(xy)):
            self.bad.append(("plan", xy))

    def _on_timing(self, msg) -> None:
        record = json.loads(msg.data)
        if record.get("stage") == "control":
            self.control_stamps.append(record["stamp"])
            self.refiner_ready = self.refiner_ready or bool(record.get("map_ready"))

    # processes
    def ensure_up(self) -> None:
        """Start again any node that an earlier test left killed or dead, so that one failing
        test does not fail the ones after it."""
        for name, proc in list(self.procs.items()):
            if proc.proc.poll() is not None:
                self.procs.pop(name).stop()
        missing = [name for name in self.params if name not in self.procs]
        if not missing:
            return
        for name in missing:
            at = {}
            if name == "sim_bridge" and self.odom is not None:
                at = {"start_x": self.odom[0], "start_y": self.odom[1], "start_yaw": self.odom[2]}
            self.start(name, **at)
        self.refiner_ready, self.odom = False, None
        self.spin_until(lambda: self.refiner_ready and self.odom is not None
                        and self.goal_pub.get_subscription_count() > 0, "graph up", 60.0)

    def start(self, name: str, **overrides) -> None:
        self.starts += 1
        self.procs[name] = self.NodeProcess(name, {**self.params[name], **overrides},
                                            domain=ROS_DOMAIN_ID,
                                            out=self.out / f"{self.starts:02d}-{name}")

    def kill(self, name: str) -> None:
        """SIGKILL: a crash, nothing cleaned up."""
        proc = self.procs.pop(name)
        proc.proc.kill()
        proc.proc.wait()
        proc.stop()  # closes its log

    def spin_until(self, condition, what: str, timeout: float = 20.0) -> None:
        deadline = time.monotonic() + timeout
        while not condition():
            self.check_alive()
            if time.monotonic() >= deadline:
                pytest.fail(f"not within {timeout:g} s: {what}\n{self.log_tails()}")
            self.executor.spin_once(timeout_sec=0.01)
        assert not self.bad, f"non-finite numbers published: {self.bad[:3]}"

    def spin_for(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        self.spin_until(lambda: time.monotonic() >= deadline, "never")

    def check_alive(self) -> None:
        from ecahd_core.errors import EcahdError

        for proc in self.procs.values():
            try:
                proc.check()
            except EcahdError as exc:
                pytest.fail(f"a node died: {exc}")

    # the robot
    def distance(self, goal) -> float:
        return math.hypot(self.odom[0] - goal[0], self.odom[1] - goal[1])

    def far_end(self):
        return EAST if self.distance(EAST) > self.distance(WEST) else WEST

    def drive(self, goal) -> None:
        """Publish ``goal`` and spin until the robot drives towards it."""
        self.goal_pub.publish(goal_msg(*goal))
        d0 = self.distance(goal)
        self.spin_until(lambda: self.odom[3] > 0.2 and self.distance(goal) < d0 - 0.3,
                        f"the robot drives towards {goal}")

    def advances(self, goal, metres: float, what: str, timeout: float = 20.0, *,
                 since=None) -> None:
        """Spin until the robot is ``metres`` closer to ``goal`` than now (or than the point
        ``since`` (x, y) [m])."""
        d0 = self.distance(goal) if since is None else math.hypot(since[0] - goal[0],
                                                                   since[1] - goal[1])
        self.spin_until(lambda: self.distance(goal) < d0 - metres, what, timeout)

    def plan_to(self, goal, since: float):
        """The first plan received after ``since`` (monotonic) that ends at ``goal``."""
        for t, xy in self.plans:
            if t >= since and len(xy) and np.allclose(xy[-1], goal, atol=1e-6):
                return xy
        return None

    def log_tails(self, lines: int = 6) -> str:
        """The last ``lines`` lines of every running process's log (for a failure's message)."""
        out = []
        for name, proc in self.procs.items():
            text = proc.log_path.read_text(errors="replace").splitlines()[-lines:]
            out.append(f"--- {name} ({proc.log_path}):\n" + "\n".join(text))
        return "\n".join(out)

    def log_count(self, name: str, text: str) -> int:
        """Lines of the running ``name`` process's log that contain ``text``."""
        return self.procs[name].log_path.read_text().count(text)

    def close(self) -> None:
        for name in list(self.procs):
            self.procs.pop(name).stop()
        self.executor.shutdown()
        self.probe.destroy_node()
        rclpy.try_shutdown(context=self.context)


@pytest.fixture(scope="class")
def process_graph(tmp_path_factory):
    g = ProcessGraph(tmp_path_factory.mktemp("faults"))
    yield g
    g.close()


@pytest.fixture
def graph(process_graph):
    process_graph.ensure_up()
    return process_graph


class TestProcessGraph:
    """Refiner, planner, goal burst, simulator; each test sets up what it needs (``graph``
    restarts any node an earlier test left dead). The two simulator restarts come last, the one
    that needs an old sim clock first: by then the clock has run long, so it need not wait."""

    def test_killed_refiner_stops_the_robot_and_a_restarted_one_resumes(self, graph):
        g = graph
        goal = g.far_end()
        g.drive(goal)
        g.kill("local_refiner")
        g.spin_until(lambda: g.odom[3] == 0.0 and g.odom[4] == 0.0, "the robot stops")
        stopped = g.odom
        # sim_bridge's control_timeout stopped it: judged by stamps, from the killed refiner's
        # last control tick (its last cmd_vel) to the first odom standing still after it
        last_tick = g.control_stamps[-1]
        stopped_t = next(o[5] for o in g.odom_log
                         if o[5] > last_tick and o[3] == 0.0 and o[4] == 0.0)
        assert stopped_t - last_tick <= CONTROL_TIMEOUT + STOP_MARGIN, (stopped_t, last_tick)
        cmds = g.cmds
        g.spin_until(lambda: g.odom[5] >= stopped[5] + 0.5, "0.5 s of sim time standing")
        assert g.odom[:2] == stopped[:2] and g.cmds == cmds  # stays put, nobody commands
        assert set(g.procs) == {"sim_bridge", "global_planner"}  # both still alive

        g.refiner_ready = False
        g.start("local_refiner")  # the latched map and plan are all it needs
        g.spin_until(lambda: g.refiner_ready, "the new refiner has its map", 30.0)
        g.advances(goal, 0.5, "the robot drives towards the goal again")

    def test_killed_planner_leaves_the_robot_driving_and_a_restarted_one_plans(self, graph):
        g = graph
        goal = g.far_end()
        g.drive(goal)
        g.kill("global_planner")
        # the refiner follows the plan it has: the episode goes on
        g.advances(goal, 0.3, "the robot keeps driving without the planner")
        assert set(g.procs) == {"sim_bridge", "local_refiner"}

        g.start("global_planner")
        goal = WEST if goal == EAST else EAST  # a new goal: only the new planner can plan it
        since = time.monotonic()
        # goal_pose is volatile: repeat it until the new planner (discovered when it is) plans
        while g.plan_to(goal, since) is None:
            assert time.monotonic() < since + 30.0, "the restarted planner never planned"
            g.goal_pub.publish(goal_msg(*goal))
            deadline = time.monotonic() + 1.0
            g.spin_until(lambda: g.plan_to(goal, since) is not None
                         or time.monotonic() > deadline, "never")
        g.advances(goal, 0.5, "the robot drives towards the new goal")

    def test_a_burst_of_goals_ends_in_a_plan_to_the_last_and_control_stays_at_rate(self,
                                                                                  graph):
        """40 goals in 0.4 s along the corridor: the last one is planned within 5 s, the
        planner stays alive, the refiner's cmd_vel stays at rate. (How many of the 40 get
        planned: test_a_burst_of_goals_is_coalesced, with a slow planner.)"""
        g = graph
        g.spin_for(0.5)
        xs = np.linspace(2.0, 6.0, 40)
        last = (float(xs[-1]) if g.distance((float(xs[-1]), Y)) > 1.0 else float(xs[0]), Y)
        goals = [(float(x), Y) for x in xs[:-1]] + [last]
        ticks_before = len(g.control_stamps)
        for goal in goals:  # 40 goals in 0.4 s
            g.goal_pub.publish(goal_msg(*goal))
            t_next = time.monotonic() + 0.01
            while time.monotonic() < t_next:
                g.executor.spin_once(timeout_sec=0.002)
        sent = time.monotonic()
        g.spin_until(lambda: g.plan_to(last, sent - 0.5) is not None,
                     "the last goal of the burst planned", 5.0)
        g.spin_for(1.0)
        # the refiner's ticks in sim time: at rate, and never a gap that would let sim_bridge's
        # control_timeout stop the robot. (With a 10-deep timing queue this once failed on a gap
        # of 0.6 s: records the probe had not read in time were dropped, not ticks missed.)
        gaps = np.diff(g.control_stamps[ticks_before:])
        period = 1.0 / CONTROL_RATE
        assert len(gaps) > 10 and np.median(gaps) <= 1.5 * period and \
            gaps.max() < CONTROL_TIMEOUT, (np.percentile(gaps, [50, 99]), gaps.max())

    def test_a_goal_after_a_simulator_restart_is_planned(self, graph):
        """A restarted simulator's clock starts again from 0: with the sim clock sent back by
        more than 10 s, a new goal is planned within 3 s (nothing waits for the old clock's
        time to come round again). Sets up its own restart, whatever ran before."""
        g = graph
        back = 10.0  # [s sim] how far the clock goes back, at least
        # on a fresh graph the clock may be young: let it pass 10 s (5 s of wall time at 2x)
        g.spin_until(lambda: g.odom[5] > back + 0.5, f"{back:g} s of sim time", 30.0)
        x, y, yaw, *_, before = g.odom
        maps_heard = g.log_count("global_planner", "map 'maze2d-large' received")
        g.kill("sim_bridge")
        g.start("sim_bridge", start_x=x, start_y=y, start_yaw=yaw)
        g.spin_until(lambda: g.odom[5] < before - back, "the new simulator's odom, 10 s back",
                     60.0)
        # the planner has the new simulator's map, so its clock follows the new /clock
        g.spin_until(lambda: g.log_count("global_planner", "map 'maze2d-large' received")
                     == maps_heard + 1, "the planner hears the new simulator")
        goal = g.far_end()
        since = time.monotonic()
        g.goal_pub.publish(goal_msg(*goal))
        g.spin_until(lambda: g.plan_to(goal, since) is not None, "a plan", 3.0)

    def test_killed_simulator_restarted_where_the_robot_was_resumes(self, graph):
        g = graph
        goal = g.far_end()
        g.drive(goal)
        maps_heard = g.log_count("global_planner", "map 'maze2d-large' received")
        g.kill("sim_bridge")
        x, y, yaw, *_ = g.odom
        g.spin_for(1.0)  # no simulator: no odom, no clock
        assert set(g.procs) == {"global_planner", "local_refiner"}
        before = g.odom
        g.start("sim_bridge", start_x=x, start_y=y, start_yaw=yaw)
        # a new process under a loaded CI machine: importing torch and pybullet and discovery
        # took over 20 s once (CI, stop 45); the first graph start has 60 s too
        g.spin_until(lambda: g.odom[5] < before[5], "the new simulator's odom", 60.0)
        # from where it was restarted: this process may hear the new simulator's odom only
        # once the robot has driven on (discovery of a new process takes a moment; in 2 of 6
        # runs the first odom heard was 2 m on, at the goal)
        g.advances(goal, 0.5, "the robot drives towards the goal again", since=(x, y))
        # the planner has the new simulator's map, so its clock follows the new /clock
        g.spin_until(lambda: g.log_count("global_planner", "map 'maze2d-large' received")
                     == maps_heard + 1, "the planner hears the new simulator")


# ------------------------------------------------------------------- in-process helpers
class Spinner:
    """``nodes`` on an executor (``threads`` > 1: multi-threaded) spun by ``ecahd_ros.spin.spin_forever`` on a
    thread, as ``spin_node`` spins them (exceptions logged, spinning goes on)."""

    def __init__(self, context, nodes, threads: int = 4) -> None:
        from ecahd_ros.spin import spin_forever

        self.context, self.nodes = context, nodes
        self.executor = (MultiThreadedExecutor(num_threads=threads, context=context)
                         if threads > 1 else SingleThreadedExecutor(context=context))
        for node in nodes:
            self.executor.add_node(node)
        self.thread = threading.Thread(target=spin_forever,
                                       args=(self.executor, nodes[0].get_logger()), daemon=True)
        self.thread.start()

    def close(self) -> None:
        rclpy.try_shutdown(context=self.context)
        self.thread.join(timeout=5.0)
        self.executor.shutdown()
        for node in self.nodes:
            node.destroy_node()


def wait_for(condition, what: str, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"not within {timeout:g} s: {what}"
        time.sleep(0.01)


def answered(send, condition, what: str, timeout: float = 20.0, every: float = 2.0,
             most: int = 5) -> None:
    """``send()``, then again every ``every`` s (at most ``most`` times) until ``condition()``:
    for a valid message that in-process DDS may lose (the test is of the node's answer)."""
    deadline, sent, last = time.monotonic() + timeout, 0, 0.0
    while not condition():
        assert time.monotonic() < deadline, f"not within {timeout:g} s: {what} (sent {sent}x)"
        if sent < most and (sent == 0 or time.monotonic() > last + every):
            send()
            sent, last = sent + 1, time.monotonic()
        time.sleep(0.01)


class Logs:
    """The error lines each node wrote to stderr (rcutils logs there), read through capfd.

    Lines passed to :meth:`settle` are answers already counted: the same text again later (a
    reliable sample that DDS re-sent after its heartbeat, seconds late, and the node answered
    twice) is not counted against the next message."""

    def __init__(self, capfd) -> None:
        self.capfd, self.text = capfd, ""
        self.settled: set[str] = set()

    def read(self) -> str:
        captured = self.capfd.readouterr()
        self.text += captured.out + captured.err
        return self.text

    def mark(self) -> int:
        return len(self.read())

    @staticmethod
    def _text(line: str) -> str:
        return line.split("] ", 2)[-1]  # without "[ERROR] [stamp] "

    def errors(self, node: str, since: int) -> list[str]:
        return [line for line in self.read()[since:].splitlines()
                if line.startswith("[ERROR]") and f"[{node}]" in line
                and self._text(line) not in self.settled]

    def settle(self, lines: list[str]) -> None:
        self.settled.update(self._text(line) for line in lines)


def odom_msg(x=1.5, y=Y, qz=0.0, qw=1.0, frame="map") -> Odometry:
    msg = Odometry()
    msg.header.frame_id, msg.child_frame_id = frame, "base_link"
    msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
    msg.pose.pose.orientation.z, msg.pose.pose.orientation.w = qz, qw
    return msg


# ----------------------------------------------------------------- 2. a stalled local stage
STALL = 1.5  # [s] the local stage's extra time
STALL_RATE = 10.0  # [Hz] control_rate


def test_a_stalled_local_stage_never_stops_cmd_vel(ros_context, monkeypatch):
    """The refiner's local stage (J check; DD off to skip loading it) sleeps STALL s: cmd_vel
    keeps coming at control_rate, zero until the refined segment is ready, then driving."""
    from ecahd_core.planning.dense import DenseStage
    from ecahd_ros.local_refiner import LocalRefiner

    original = DenseStage.local_stage
    finished = []  # monotonic times the slow stages returned

    def slow_local_stage(self, *args, **kwargs):
        time.sleep(STALL)
        out = original(self, *args, **kwargs)
        finished.append(time.monotonic())
        return out

    monkeypatch.setattr(DenseStage, "local_stage", slow_local_stage)
    refiner = LocalRefiner(context=ros_context, parameter_overrides=[
        Parameter("dd_enabled", value=False), Parameter("control_rate", value=STALL_RATE)])
    probe = rclpy.create_node("stall_probe", context=ros_context)
    cmds = []  # (monotonic, v, w)
    probe.create_subscription(Twist, "cmd_vel", lambda m: cmds.append(
        (time.monotonic(), m.linear.x, m.angular.z)), 100)
    map_pub = probe.create_publisher(OccupancyGrid, "map", MAP_QOS)
    plan_pub = probe.create_publisher(Path, "plan", PLAN_QOS)
    odom_pub = probe.create_publisher(Odometry, "odom", STREAM_QOS)
    probe.create_timer(0.05, lambda: odom_pub.publish(odom_msg()))
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(refiner)
    executor.add_node(probe)
    try:
        map_pub.publish(grid_to_msg(builtin_map(MAP)))
        spin_until(executor, lambda: refiner.planner is not None and cmds, what="map and cmd_vel")
        sent = time.monotonic()
        plan_pub.publish(xy_to_path(np.array([WEST, (4.5, Y)]), "map"))
        spin_until(executor, lambda: any(v > 0 for _, v, _ in cmds) and
                   time.monotonic() > cmds[-1][0] - 1.0 and
                   [t for t, v, _ in cmds if v > 0][0] + 0.5 < time.monotonic(),
                   timeout=STALL + 8.0, what="driving after the stall")
    finally:
        executor.shutdown()
        refiner.destroy_node()
        probe.destroy_node()
    window = [(t, v, w) for t, v, w in cmds if t >= sent]
    first_drive = next(t for t, v, _ in window if v > 0)
    assert finished and first_drive >= finished[0] - 0.01  # nothing before the stage is done
    assert first_drive - sent >= STALL - 0.1
    assert all(v == 0.0 and w == 0.0 for t, v, w in window if t < first_drive)
    gaps = np.diff([t for t, _, _ in window])
    period = 1.0 / STALL_RATE
    # at rate all along: no gap while the stage runs, ~STALL * rate zero commands
    assert np.percentile(gaps, 99) < 3 * period and gaps.max() < 5 * period, \
        (np.percentile(gaps, [50, 99]), gaps.max())
    assert sum(1 for t, _, _ in window if t < first_drive) >= 0.7 * STALL * STALL_RATE


# ---------------------------------------------------------------- 3. malformed messages
def test_malformed_input_to_sim_bridge(ros_context, capfd):
    """cmd_vel with NaN / inf, initialpose with NaN / inf / wrong frame / in a wall / off the
    map: one error line each, the robot untouched, every odom and clock finite; valid input
    then drives and teleports. Huge finite velocities are clamped to the limits."""
    from sim_bridge.node import SimBridge

    sim = SimBridge(context=ros_context, parameter_overrides=[
        Parameter("map", value=MAP), Parameter("start_x", value=WEST[0]),
        Parameter("start_y", value=Y), Parameter("realtime_factor", value=0.0),
        Parameter("publish_scan", value=False), Parameter("odom_frame", value="map")])
    probe = rclpy.create_node("sim_probe", context=ros_context)
    seen, bad = {"odom": None, "clock": 0}, []

    def on_odom(msg) -> None:
        seen["odom"] = msg
        twist = msg.twist.twist
        if not finite(*pose_values(msg.pose.pose), twist.linear.x, twist.angular.z):
            bad.append(msg)

    def on_clock(msg) -> None:
        seen["clock"] += 1
        if msg.clock.sec < 0:
            bad.append(msg)

    probe.create_subscription(Odometry, "odom", on_odom, STREAM_QOS)
    probe.create_subscription(Clock, "clock", on_clock, STREAM_QOS)
    cmd_pub = probe.create_publisher(Twist, "cmd_vel", STREAM_QOS)
    pose_pub = probe.create_publisher(PoseWithCovarianceStamped, "initialpose", STREAM_QOS)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(sim)
    executor.add_node(probe)
    logs = Logs(capfd)

    def twist(v, w) -> Twist:
        msg = Twist()
        msg.linear.x, msg.angular.z = v, w
        return msg

    def initialpose(x, y, qz=0.0, qw=1.0, frame="map") -> PoseWithCovarianceStamped:
        msg = PoseWithCovarianceStamped()
        msg.header.frame_id = frame
        msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
        msg.pose.pose.orientation.z, msg.pose.pose.orientation.w = qz, qw
        return msg

    def one_error_for(pub, msg, what: str) -> None:
        mark = logs.mark()
        pub.publish(msg)
        spin_until(executor, lambda: logs.errors("sim_bridge", mark), what=f"error for {what}")
        t = sim.sim.state.t
        spin_until(executor, lambda: sim.sim.state.t > t + 0.1, what="a few steps")
        lines = logs.errors("sim_bridge", mark)
        assert len(lines) == 1, (what, lines)

    try:
        spin_until(executor, lambda: cmd_pub.get_subscription_count() > 0
                   and pose_pub.get_subscription_count() > 0 and seen["odom"] is not None,
                   what="sim_bridge matched")
        for v, w in ((math.nan, 0.0), (0.0, math.inf), (-math.inf, math.nan)):
            one_error_for(cmd_pub, twist(v, w), f"cmd_vel ({v}, {w})")
        for what, msg in (("NaN x", initialpose(math.nan, Y)),
                          ("inf y", initialpose(WEST[0], math.inf)),
                          ("NaN quaternion", initialpose(*WEST, qz=math.nan, qw=math.nan)),
                          ("frame odom", initialpose(2.5, Y, frame="odom")),
                          ("in a wall", initialpose(0.5, 0.5)),
                          ("off the map", initialpose(1e30, -1e30))):
            one_error_for(pose_pub, msg, f"initialpose {what}")
        state = sim.sim.state
        assert (state.x, state.y, state.v) == (WEST[0], Y, 0.0)  # nothing moved it
        assert sim.rejected_commands == 3
        # huge but finite: clamped to max_v / max_w
        mark = logs.mark()
        cmd_pub.publish(twist(1e30, -1e30))
        spin_until(executor, lambda: sim.sim.state.v > 0, what="the huge command")
        assert (sim.sim.state.v, sim.sim.state.w) == (sim.params.max_v, -sim.params.max_w)
        assert not logs.errors("sim_bridge", mark)
        # valid input works
        pose_pub.publish(initialpose(2.5, Y))
        spin_until(executor, lambda: (sim.sim.state.x, sim.sim.state.y) == (2.5, Y),
                   what="teleported")
        cmd_pub.publish(twist(0.5, 0.0))
        spin_until(executor, lambda: sim.sim.state.x > 2.5, what="driven")
        spin_until(executor, lambda: seen["odom"].pose.pose.position.x > 2.5, what="odom")
    finally:
        executor.shutdown()
        sim.destroy_node()
        probe.destroy_node()
    assert not bad, bad[:3]
    assert seen["clock"] > 0
    assert "Traceback" not in logs.read()


def map_msg(**change) -> OccupancyGrid:
    """maze2d-large's OccupancyGrid with fields changed: frame, data, width, resolution,
    origin_x, qx, qz, qw."""
    msg = grid_to_msg(builtin_map(MAP))
    if "frame" in change:
        msg.header.frame_id = change["frame"]
    if "data" in change:
        msg.data = change["data"]
    if "width" in change:
        msg.info.width = change["width"]
    if "resolution" in change:
        msg.info.resolution = change["resolution"]
    origin = msg.info.origin
    if "origin_x" in change:
        origin.position.x = change["origin_x"]
    for k in ("qx", "qz", "qw"):
        if k in change:
            setattr(origin.orientation, k[1], change[k])
    return msg


def plan_msg(xy, frame: str = "map") -> Path:
    msg = xy_to_path(np.asarray(xy, dtype=np.float64), "map")
    msg.header.frame_id = frame
    return msg


def check_finite_json(text: str) -> None:
    def reject(constant):
        raise AssertionError(f"non-finite number {constant} in {text}")

    json.loads(text, parse_constant=reject)


def test_malformed_input_to_planner_and_refiner(ros_context, capfd, tmp_path):
    """global_planner and local_refiner (use_sim_time, /clock from the probe) and bag_recorder,
    spun as spin_node spins them. Every subscribed topic gets malformed messages: goal_pose,
    odom, plan, map, /clock. Each bad message costs one error line in each node that
    subscribes (the planner reads no orientation, so it may accept a NaN quaternion), nothing
    non-finite is published, and valid input afterwards gives a plan and motion."""
    from ecahd_ros.bag_recorder import BagRecorder, read_bag
    from ecahd_ros.global_planner import GlobalPlanner
    from ecahd_ros.local_refiner import LocalRefiner

    sim_time = [Parameter("use_sim_time", value=True)]
    planner = GlobalPlanner(context=ros_context, parameter_overrides=sim_time)
    refiner = LocalRefiner(context=ros_context, parameter_overrides=sim_time + [
        Parameter("dd_enabled", value=False)])
    recorder = BagRecorder(context=ros_context, parameter_overrides=[
        Parameter("output", value=str(tmp_path / "bag")), Parameter("discovery_period", value=0.1)])
    probe = rclpy.create_node("hostile", context=ros_context)
    got = {"plans": [], "cmds": [], "bad": []}

    def on_plan(msg) -> None:
        if msg.header.stamp.sec < 100:
            return  # one of the probe's own (unstamped); the planner stamps sim time >= 100 s
        xy = np.array([[p.pose.position.x, p.pose.position.y] for p in msg.poses])
        got["plans"].append(xy)
        if not all(finite(*pose_values(p.pose)) for p in msg.poses):
            got["bad"].append(("plan", xy))

    def on_cmd(msg) -> None:
        got["cmds"].append((msg.linear.x, msg.angular.z))
        if not finite(msg.linear.x, msg.angular.z):
            got["bad"].append(("cmd_vel", msg))

    def on_local(msg) -> None:
        if not all(finite(*pose_values(p.pose)) for p in msg.poses):
            got["bad"].append(("local_plan", msg))

    def on_timing(msg) -> None:
        try:
            check_finite_json(msg.data)
        except AssertionError as exc:
            got["bad"].append(("ecahd/timing", str(exc)))

    probe.create_subscription(Path, "plan", on_plan, PLAN_QOS)
    probe.create_subscription(Twist, "cmd_vel", on_cmd, STREAM_QOS)
    probe.create_subscription(Path, "local_plan", on_local, 10)
    probe.create_subscription(String, "ecahd/timing", on_timing, STREAM_QOS)
    pubs = {"map": probe.create_publisher(OccupancyGrid, "map", MAP_QOS),
            "goal_pose": probe.create_publisher(PoseStamped, "goal_pose", STREAM_QOS),
            "odom": probe.create_publisher(Odometry, "odom", STREAM_QOS),
            "plan": probe.create_publisher(Path, "plan", PLAN_QOS),
            "clock": probe.create_publisher(Clock, "/clock", STREAM_QOS)}
    t0 = time.monotonic()

    publishing = threading.Lock()  # the test thread and the probe's timer share publishers

    def publish(topic: str, msg) -> None:
        with publishing:
            pubs[topic].publish(msg)

    clock_on = [True]  # off while a bad /clock is sent: the time source keeps only the last

    def tick() -> None:  # a simulator's /clock (from 100 s) and a robot standing at WEST
        now = 100.0 + time.monotonic() - t0
        if clock_on[0]:
            publish("clock", Clock(clock=Time(sec=int(now), nanosec=int(now % 1 * 1e9))))
        publish("odom", odom_msg())

    probe.create_timer(0.05, tick)
    spinner = Spinner(ros_context, [planner, refiner, recorder, probe])
    logs = Logs(capfd)

    def bad_messages(topic: str, messages, nodes: dict[str, tuple[int, int]]) -> None:
        """Publish each message, then expect between lo and hi error lines per message in each
        node of ``nodes``. A message the nodes have not answered after 1 s is published again
        (at most 5 times): in-process delivery under a multi-threaded executor here now and then
        loses one (seen for valid and malformed messages alike), and what is tested is the
        nodes' answer, not DDS; hi is then per publication."""
        for what, msg in messages:
            mark = logs.mark()
            sent = 0
            deadline = time.monotonic() + 8.0
            while not all(len(logs.errors(n, mark)) >= lo for n, (lo, _) in nodes.items()):
                assert time.monotonic() < deadline, f"{topic} {what}: no error line from " \
                    f"{[n for n, (lo, _) in nodes.items() if len(logs.errors(n, mark)) < lo]}"
                if sent < 5 and (sent == 0 or time.monotonic() > last + 1.0):
                    publish(topic, msg)
                    sent, last = sent + 1, time.monotonic()
                time.sleep(0.01)
            # published again: the answer to the later publication may still come; wait for it
            # here, or it lands after the next message's mark (seen: a map's resolution error
            # counted against the next map)
            time.sleep(0.1 if sent == 1 else 2.0)
            for n, (lo, hi) in nodes.items():
                lines = logs.errors(n, mark)
                assert lo <= len(lines) <= hi * sent, (topic, what, n, lines)
                logs.settle(lines)

    try:
        publish("map", map_msg())
        wait_for(lambda: planner.ready and refiner.planner is not None and got["cmds"]
                 and "/goal_pose" in recorder._recording, "nodes up", 30.0)
        both, planner_only, refiner_only = ({"global_planner": (1, 1), "local_refiner": (1, 1)},
                                            {"global_planner": (1, 1)},
                                            {"local_refiner": (1, 1)})
        bad_messages("goal_pose", [
            ("NaN x", goal_msg(math.nan, Y)), ("inf y", goal_msg(4.5, math.inf)),
            ("huge", goal_msg(1e30, 1e30)), ("frame odom", goal_msg(4.5, Y, "odom")),
            ("no frame", goal_msg(4.5, Y, "")), ("in a wall", goal_msg(0.5, 0.5)),
            ("off the map", goal_msg(20.0, 20.0))], planner_only)
        assert planner.goal is None and not got["plans"]
        bad_messages("odom", [
            ("NaN x", odom_msg(x=math.nan)), ("inf y", odom_msg(y=-math.inf)),
            ("huge", odom_msg(x=1e30))], both)
        # odometry in a frame tf does not join to map (yet): a warning naming the missing
        # transform, at most every few seconds (a robot's first odometry comes before tf)
        # (re-published like the others: DDS here loses a message now and then)
        mark = logs.mark()
        answered(lambda: publish("odom", odom_msg(frame="odom")),
                 lambda: all(any(line.startswith("[WARN]") and f"[{node}]" in line
                                 and "no transform map -> odom" in line
                                 for line in logs.read()[mark:].splitlines())
                             for node in ("global_planner", "local_refiner")),
                 "a warning about odometry in odom without tf")
        assert not logs.errors("global_planner", mark) and not logs.errors("local_refiner", mark)
        bad_messages("odom", [("NaN quaternion", odom_msg(qz=math.nan, qw=math.nan))],
                     {"global_planner": (0, 1), "local_refiner": (1, 1)})
        bad_messages("plan", [
            ("NaN pose", plan_msg([WEST, (math.nan, Y), (4.5, Y)])),
            ("huge", plan_msg([WEST, (1e30, 1e30)])),
            ("frame odom", plan_msg([WEST, (4.5, Y)], frame="odom"))], refiner_only)
        assert refiner.waypoints is None
        data = map_msg().data
        bad_messages("map", [
            ("NaN origin quaternion", map_msg(qx=math.nan, qz=math.nan, qw=math.nan)),
            ("rotated", map_msg(qz=0.7071, qw=0.7071)),
            ("NaN origin", map_msg(origin_x=math.nan)), ("frame odom", map_msg(frame="odom")),
            ("data length", map_msg(data=data[:-1])), ("width 0", map_msg(width=0)),
            ("negative resolution", map_msg(resolution=-0.1)),
            ("NaN resolution", map_msg(resolution=math.nan)),
            ("value 127", map_msg(data=[127] * len(data)))], both)
        # rclpy's time source raises on a negative /clock: spin_forever logs it once
        mark = logs.mark()
        # (re-published like bad_messages: DDS here loses a message now and then; the valid
        # clock paused meanwhile, as the next one would replace it in a busy node's queue)
        clock_on[0] = False
        sent, deadline = 0, time.monotonic() + 10.0
        while "exception while spinning" not in logs.read()[mark:]:
            assert time.monotonic() < deadline, f"not within 10 s: the clock error ({sent} sent)"
            if sent < 5 and (sent == 0 or time.monotonic() > last + 1.0):
                publish("clock", Clock(clock=Time(sec=-5, nanosec=0)))
                sent, last = sent + 1, time.monotonic()
            time.sleep(0.01)
        time.sleep(0.2)
        clock_on[0] = True
        assert 1 <= logs.read()[mark:].count("exception while spinning") <= sent
        assert planner.get_clock().now().nanoseconds > 100e9  # the valid clock goes on

        # valid input again: a 10 000-pose plan is followed, a goal is planned and followed
        long_plan = np.stack([np.linspace(WEST[0], 4.5, 10_000), np.full(10_000, Y)], axis=1)
        mark = logs.mark()
        n = len(got["cmds"])
        # (re-published like bad_messages: in-process DDS here loses a message now and then;
        # one lost goal failed CI once, "not within 10 s: a plan to the valid goal")
        answered(lambda: publish("plan", plan_msg(long_plan)),
                 lambda: any(v > 0 for v, _ in got["cmds"][n:]), "driving the long plan")
        assert not logs.errors("local_refiner", mark)
        answered(lambda: publish("goal_pose", goal_msg(4.5, Y + 0.2)),
                 lambda: got["plans"], "a plan to the valid goal")
        assert np.allclose(got["plans"][-1][-1], (4.5, Y + 0.2))
        n = len(got["cmds"])
        wait_for(lambda: any(v > 0 for v, _ in got["cmds"][n:]), "driving the planned path")
        assert spinner.thread.is_alive() and recorder.recording
        assert not got["bad"], got["bad"][:3]
        assert "Traceback" not in logs.read()  # (teardown may race a callback: not checked)
    finally:
        spinner.close()
    bag = read_bag(tmp_path / "bag", topics=["/goal_pose", "/map"])
    assert len(bag["/goal_pose"]) >= 8  # the recorder took the malformed messages in its stride


# ------------------------------------------------------------------------ 4. a goal burst
SLOW_PLAN = 0.15  # [s] added to every SD plan


def test_a_burst_of_goals_is_coalesced(ros_context):
    """global_planner (wall time, SD made SLOW_PLAN s slower) spun as spin_node spins it; 40
    goals in 0.4 s arrive while its first plan runs: it plans the first and then the last
    (not every goal still queued), and the last within 3 plan times of being sent."""
    from ecahd_core.planning.sparse import SparseDiffusion
    from ecahd_ros.global_planner import GlobalPlanner

    original = SparseDiffusion.plan

    def slow_plan(self, *args, **kwargs):
        time.sleep(SLOW_PLAN)
        return original(self, *args, **kwargs)

    planner = GlobalPlanner(context=ros_context)
    probe = rclpy.create_node("burst_probe", context=ros_context)
    plans = []  # (monotonic, last point)
    probe.create_subscription(Path, "plan", lambda m: plans.append(
        (time.monotonic(), (m.poses[-1].pose.position.x, m.poses[-1].pose.position.y))),
        PLAN_QOS)
    map_pub = probe.create_publisher(OccupancyGrid, "map", MAP_QOS)
    odom_pub = probe.create_publisher(Odometry, "odom", STREAM_QOS)
    goal_pub = probe.create_publisher(PoseStamped, "goal_pose", STREAM_QOS)
    spinner = Spinner(ros_context, [planner], threads=1)  # as spin_node spins it
    watcher = Spinner(ros_context, [probe], threads=1)
    mp = pytest.MonkeyPatch()
    try:
        map_pub.publish(grid_to_msg(builtin_map(MAP)))
        wait_for(lambda: planner.ready and goal_pub.get_subscription_count() > 0
                 and odom_pub.get_subscription_count() > 0, "planner up", 30.0)
        odom_pub.publish(odom_msg())
        wait_for(lambda: planner.pose is not None, "odometry")
        mp.setattr(SparseDiffusion, "plan", slow_plan)
        goals = [(float(x), Y) for x in np.linspace(2.0, 6.0, 40)]
        for goal in goals:
            goal_pub.publish(goal_msg(*goal))
            time.sleep(0.01)
        sent = time.monotonic()
        wait_for(lambda: plans and plans[-1][1] == goals[-1], "the last goal planned", 8.0)
        time.sleep(SLOW_PLAN)
    finally:
        mp.undo()
        spinner.close()
        watcher.close()
    assert len(plans) <= 3, f"{len(plans)} plans for a burst of 40 goals"
    assert plans[-1][0] - sent < 3 * SLOW_PLAN + 0.5
