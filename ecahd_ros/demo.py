"""``ecahd demo``: the ROS 2 graph run as a robot runs it, driven through seeded goals,
recorded and scored against the paper's Table III.

Composition: ``sim_bridge`` (PyBullet, its own simulated clock), ``global_planner`` (SD) and
``local_refiner`` (J check + DD on a worker, 20 Hz control) each run in **their own process**
(``python -m <module> --ros-args --params-file``, as ``ros2 launch`` starts them; their logs go
to OUT/logs/), on a private ROS domain. This process hosts ``bag_recorder`` (every default topic
into OUT/bag) and a small ``demo`` node that publishes ``goal_pose`` and watches ``odom``,
``cmd_vel`` and ``plan``. ``DemoConfig.planner_params`` / ``refiner_params`` override the
planner's and refiner's parameters (e.g. ``{"method": "astar"}``, ``{"dd_enabled": False}``:
the baselines of ``ecahd bench navigation``).

Time is honest: the simulator steps on its own wall-clock timer whatever the planners do, so
the robot keeps moving (on its last command, until ``control_timeout``) while SD and DD think,
as on a robot. The planner, refiner and recorder follow ``/clock`` (``use_sim_time``). The
default realtime factor is 1 (real time); with a factor k > 1 the simulation runs k times
faster than the wall clock, so every millisecond of planning costs k milliseconds of simulated
time: planning latency is scaled into sim time, not hidden. (Before 2026-11-28 the demo ran
every node on one executor in one process: planning stopped the simulated clock; docs/RESULTS.md
keeps those "lock-step" figures beside the concurrent ones.)

Episodes: goals come from ``make_problems(map, episodes, seed)``; the robot starts at the first
problem's start, later episodes start where the previous one ended and head for the next
problem's goal. An episode ends when the robot has been within ``goal_radius`` of the goal with
zero commanded velocity (the refiner reached the goal) for ``hold_steps`` Table III steps
(0.1 s of sim time each), or after ``max_steps`` steps; the next goal then starts the next
episode. The episode reward therefore counts the steps within 0.5 m until the episode ends.

Goal -> plan latency: per episode, the wall time (``time.perf_counter``) from publishing the
goal to the demo node receiving the first ``plan`` that ends at that goal (within the 0.2 m a
goal the footprint cannot reach exactly is snapped by) (None if none came
before the episode ended), across processes; in DemoResult and metrics.json as
``goal_to_plan_ms``.

After the last episode the nodes get SIGINT, the bag is closed and scored by ``ecahd
eval-bag``'s :func:`~ecahd_ros.eval_bag.evaluate_bag`: OUT/metrics.json, OUT/metrics.md,
OUT/trajectories.png.
"""
from __future__ import annotations

import argparse
import logging
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

from ecahd_core.maps import DEFAULT_MAP

log = logging.getLogger("ecahd.demo")

STARTUP_TIMEOUT = 120.0  # [s wall] processes up, models loaded and recorder subscribed
STOP_TIMEOUT = 10.0  # [s wall] a node process has this long to exit on SIGINT
# [s wall] spinning after the last episode, simulator stopped, so the bag gets what is queued
SETTLE_TIME = 0.5


@dataclass(frozen=True, kw_only=True)
class DemoConfig:
    """Settings of one demo run (units as in the module docstring)."""

    out: Path
    episodes: int = 3
    first_episode: int = 0  # run the seeded episodes first_episode .. + episodes - 1 (start:
    #   the goal before the first one; its obstacles: the same seed as in a full run)
    robot: str = "circle"
    map: str = DEFAULT_MAP
    seed: int = 0
    realtime_factor: float = 1.0
    max_steps: int = 800
    hold_steps: int = 10
    goal_radius: float = 0.5
    goals: tuple[tuple[float, float], ...] | None = None  # explicit goals; None: seeded problems
    start: tuple[float, float] | None = None  # explicit start; None: the first problem's
    wall_timeout: float | None = None  # [s] the whole episode loop; None: every episode's
    #   full length at the realtime factor, doubled, plus a minute
    # obstacles that are not on the map, per episode (ecahd_core.scenario.generate_scenario on
    # the leg previous goal -> goal, seeded by seed and the episode): static boxes, moving
    # cylinders
    obstacles: int = 0
    moving: int = 0
    models: Path | None = None  # folder of <map name>_{sd,dd,fd}.pt (train-all --out-dir)
    domain_id: int | None = None  # None: derived from the process id
    view_port: int | None = None  # serve the live view (web_view) on this port; None: no view
    # parameter overrides of the global_planner / local_refiner nodes (name -> value)
    planner_params: dict = field(default_factory=dict)
    refiner_params: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        from ecahd_core.errors import EcahdError

        if self.episodes < 1 or self.max_steps < 1 or self.hold_steps < 0 \
                or self.first_episode < 0:
            raise EcahdError("demo needs episodes >= 1, first_episode >= 0, max_steps >= 1 and "
                             "hold_steps >= 0")
        if not (math.isfinite(self.realtime_factor) and self.realtime_factor > 0):
            raise EcahdError(f"realtime_factor must be a finite number > 0 (planning runs "
                             f"concurrently: there is no lock-step), got {self.realtime_factor}")
        if self.obstacles < 0 or self.moving < 0:
            raise EcahdError("obstacles and moving must be >= 0")
        if self.goals is not None and len(self.goals) < self.first_episode + self.episodes:
            last = self.first_episode + self.episodes - 1
            raise EcahdError(f"episodes {self.first_episode}..{last} need {last + 1} goals, "
                             f"got {self.goals}")


@dataclass(frozen=True)
class DemoResult:
    bag: Path
    json: Path
    md: Path
    png: Path
    wall_s: float  # [s] the episode loop
    sim_s: float  # [s of sim time] the episode loop
    table: str
    evaluation: object  # eval_bag.BagEvaluation
    goal_to_plan_ms: tuple  # per episode: [ms wall] goal published -> its first plan, or None


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--episodes", type=int, default=3, help="goals to drive to")
    p.add_argument("--robot", default="circle",
                   help="footprint: circle | quadruped | humanoid | Nav2 polygon '[[x, y], ...]'")
    p.add_argument("--map", default=DEFAULT_MAP,
                   help="built-in maze or Nav2 map YAML (models: shipped, or --models)")
    p.add_argument("--models", default=None, metavar="DIR",
                   help="folder of <map name>_{sd,dd,fd}.pt, as `ecahd train-all --out-dir` "
                        "writes them")
    p.add_argument("--method", choices=("sd", "astar", "fd"), default="sd",
                   help="global planner (astar needs no model)")
    p.add_argument("--no-dd", action="store_true",
                   help="local_refiner without Dense Diffusion (no DD model needed)")
    p.add_argument("--seed", type=int, default=0, help="seed of the goals and the samplers")
    p.add_argument("--out", default=None, help="output folder (default runs/demo-<timestamp>)")
    p.add_argument("--realtime-factor", type=float, default=1.0,
                   help="sim seconds per wall second (> 1: faster than real time, planning "
                        "time scaled into sim time)")
    p.add_argument("--max-steps", type=int, default=800, help="control steps per episode")
    p.add_argument("--hold-steps", type=int, default=10,
                   help="control steps the reached goal is held before the next episode")
    p.add_argument("--view", nargs="?", type=int, const=8080, default=None, metavar="PORT",
                   help="serve a live view of the run for a web browser on PORT (default "
                        "8080): http://localhost:PORT (the web_view node)")
    p.add_argument("--domain-id", type=int, default=None,
                   help="ROS_DOMAIN_ID of the private context (default: from the process id)")
    p.add_argument("--lanes", default=None, metavar="FIELD",
                   help="a lane field of the map (`ecahd lanes`): the nodes' `lanes` "
                        "parameter (plans moved onto where the robot was driven)")
    add_obstacle_arguments(p)


def add_obstacle_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--obstacles", type=int, default=0,
                   help="static boxes not on the map, per episode, on its route (every goal "
                        "stays reachable for the footprint)")
    p.add_argument("--moving", type=int, default=0,
                   help="moving cylinders crossing each episode's route")
    p.add_argument("--planner-param", action="append", default=[], metavar="NAME=VALUE",
                   help="a global_planner parameter (repeatable), e.g. warm_fraction=0; the "
                        "value is read as JSON where it parses (numbers, true/false), else "
                        "as a string")
    p.add_argument("--refiner-param", action="append", default=[], metavar="NAME=VALUE",
                   help="a local_refiner parameter (repeatable), as --planner-param")
    p.add_argument("--first-episode", type=int, default=0, metavar="I",
                   help="start at seeded episode I (its start: goal I-1, its obstacles as in a "
                        "run from episode 0): rerun one episode of a long run alone")


def control_clock(realtime_factor: float) -> str:
    """local_refiner's ``control_clock`` for a simulation at ``realtime_factor``: the steady
    clock as on a robot at real time; off real time, sim time ("ros"), since 20 Hz of wall time
    would not be 20 Hz of the robot's time."""
    return "steady" if realtime_factor == 1 else "ros"


def _node_parameters(config: DemoConfig, start) -> dict[str, dict]:
    """Each node's parameters (name -> value) for its params file."""
    from ecahd_core.maps import load_map

    name = load_map(config.map).name  # what the models were trained for
    common = {"map_name": name, "robot": config.robot, "seed": config.seed,
              "use_sim_time": True}
    models = {}
    if config.models is not None:
        models = {f"{kind}_model": str(config.models / f"{name}_{kind}.pt")
                  for kind in ("sd", "fd", "dd")}
    return {
        "sim_bridge": {"map": config.map, "robot": config.robot, "start_x": float(start[0]),
                       "start_y": float(start[1]),
                       "realtime_factor": float(config.realtime_factor)},
        "global_planner": {**common, **{k: v for k, v in models.items() if k != "dd_model"},
                           **config.planner_params},
        "local_refiner": {**common, **{k: v for k, v in models.items() if k == "dd_model"},
                          "control_clock": control_clock(config.realtime_factor),
                          **config.refiner_params},
        **({"web_view": {"robot": config.robot, "port": config.view_port,
                         "use_sim_time": True}} if config.view_port is not None else {}),
    }


NODE_MODULES = {"sim_bridge": "sim_bridge.node", "global_planner": "ecahd_ros.global_planner",
                "local_refiner": "ecahd_ros.local_refiner", "web_view": "ecahd_ros.web_view"}


class NodeProcess:
    """One node in its own process, as ``ros2 run`` starts it: ``python -m MODULE --ros-args
    --params-file F``, on ``domain``, its output in ``log_path``."""

    def __init__(self, name: str, params: dict, *, domain: int, out: Path) -> None:
        import subprocess
        import sys

        import yaml

        self.name = name
        params_file = out / "params" / f"{name}.yaml"
        params_file.parent.mkdir(parents=True, exist_ok=True)
        params_file.write_text(yaml.safe_dump({name: {"ros__parameters": params}}))
        self.log_path = out / "logs" / f"{name}.log"
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        env = {**os.environ, "ROS_DOMAIN_ID": str(domain), "PYTHONUNBUFFERED": "1",
               "ECAHD_DIE_WITH_PARENT": str(os.getpid()),  # ecahd_ros.spin.die_with_parent
               "ROS_AUTOMATIC_DISCOVERY_RANGE": os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE",
                                                               "LOCALHOST")}
        self._log = open(self.log_path, "w")  # noqa: SIM115 (closed in stop())
        self.proc = subprocess.Popen(
            [sys.executable, "-m", NODE_MODULES[name], "--ros-args", "--params-file",
             str(params_file)], stdout=self._log, stderr=subprocess.STDOUT, env=env)

    def check(self) -> None:
        """EcahdError if the process has exited (its log's last line says why)."""
        from ecahd_core.errors import EcahdError

        if self.proc.poll() is not None:
            lines = self.log_path.read_text().strip().splitlines() or ["(no output)"]
            raise EcahdError(f"{self.name} exited with code {self.proc.returncode}: "
                             f"{lines[-1]} (log: {self.log_path})")

    def stop(self) -> None:
        import signal
        import subprocess

        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=STOP_TIMEOUT)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._log.close()


def _set_parameter(executor, client, name: str, value, spin, timeout: float = 10.0) -> None:
    """Set a parameter of another node and wait for its answer (EcahdError if refused)."""
    from rclpy.parameter import Parameter

    from ecahd_core.errors import EcahdError

    future = client.set_parameters([Parameter(name, value=value)])
    t0 = time.monotonic()
    while not future.done():
        spin()
        if time.monotonic() - t0 > timeout:
            raise EcahdError(f"setting {name} timed out")
    result = future.result().results[0]
    if not result.successful:
        raise EcahdError(f"{name} refused: {result.reason}")


def _goals(config: DemoConfig):
    """(start (2,), [goal (2,), ...]) from the config or seeded problems on the map: episodes
    first_episode .. first_episode + episodes - 1; the start is the goal before the first one
    (as in a full run that reached it) unless given."""
    import numpy as np

    from ecahd_core.maps import load_map
    from ecahd_core.problems import make_problems

    first, end = config.first_episode, config.first_episode + config.episodes
    if config.goals is not None:
        every = [np.asarray(g, dtype=np.float64) for g in config.goals[:end]]
        start = (1.5, 1.5) if first == 0 else every[first - 1]
    else:
        problems = make_problems(load_map(config.map), end, seed=config.seed)
        every = [p.goal for p in problems]
        start = problems[0].start if first == 0 else every[first - 1]
    if config.start is not None:
        start = config.start
    return np.asarray(start, dtype=np.float64), every[first:]


def _scenarios(config: DemoConfig, start, goals) -> list[Path] | None:
    """One scenario file per episode (OUT/scenarios/episode_<i>.yaml) with ``obstacles`` static
    and ``moving`` moving obstacles on the leg (previous goal or start) -> goal, or None."""
    if config.obstacles == 0 and config.moving == 0:
        return None
    from ecahd_core.footprint import make_footprint
    from ecahd_core.maps import load_map
    from ecahd_core.scenario import ScenarioError, generate_scenario, write_scenario

    grid, footprint = load_map(config.map), make_footprint(config.robot)
    folder = config.out / "scenarios"
    folder.mkdir(parents=True, exist_ok=True)
    files, previous = [], start
    for i, goal in enumerate(goals):
        try:
            scenario = generate_scenario(grid, footprint, [previous, goal],
                                         static=config.obstacles, moving=config.moving,
                                         seed=config.seed * 1000 + config.first_episode + i,
                                         strict=False)
            obstacles = scenario.obstacles
            log.info("episode %d: %d of %d obstacles placed: %s", i, len(obstacles),
                     config.obstacles + config.moving, ", ".join(scenario.kinds) or "none")
        except ScenarioError as exc:  # e.g. a leg too short to hold them: none this episode
            obstacles = ()
            log.warning("episode %d: no obstacles (%s)", i, exc)
        files.append(write_scenario(folder / f"episode_{i}.yaml", obstacles))  # i: of this run
        previous = goal
    return files


def run_demo(config: DemoConfig) -> DemoResult:
    """Start the node processes, run the episodes, close the bag, score it, write the outputs."""
    import rclpy
    from geometry_msgs.msg import PoseStamped, Twist
    from nav_msgs.msg import Odometry
    from ecahd_core.frames import TRANSFORM_TOLERANCE
    from ecahd_ros.tf_listener import (TransformUnavailable, TfListener,
                                          odometry_pose)
    from nav_msgs.msg import Path as PathMsg
    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import String

    from ecahd_core.errors import EcahdError
    from ecahd_core.evaluation import CONTROL_PERIOD, CONTROL_STAGE
    from ecahd_core.planning.horizon import SNAP_DISTANCE
    from ecahd_ros.bag_recorder import BagRecorder
    from ecahd_ros.eval_bag import evaluate_bag, write_outputs
    from ecahd_ros.qos import MAP_QOS, PLAN_QOS, STREAM_QOS

    start, goals = _goals(config)
    config.out.mkdir(parents=True, exist_ok=True)
    scenarios = _scenarios(config, start, goals)
    params = _node_parameters(config, start)
    domain = config.domain_id if config.domain_id is not None else 1 + os.getpid() % 100
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=domain)
    procs: list[NodeProcess] = []
    nodes = []
    try:
        # the recorder first, so it hears everything from the nodes' first message on
        from rclpy.parameter import Parameter

        recorder = BagRecorder(context=ctx, parameter_overrides=[
            Parameter("output", value=str(config.out / "bag")),
            Parameter("use_sim_time", value=True)])
        demo = rclpy.create_node("demo", context=ctx)
        nodes += [recorder, demo]
        procs += [NodeProcess(name, params[name], domain=domain, out=config.out)
                  for name in NODE_MODULES if name in params]
        if config.view_port is not None:
            print(f"live view: http://localhost:{config.view_port}", flush=True)
        goal_pub = demo.create_publisher(PoseStamped, "goal_pose", STREAM_QOS)
        state = {"odom": None, "cmd": None, "refiner_ready": False, "planner_ready": False}
        # goal -> first plan latency of the current episode: goal (x, y), perf_counter when it
        # was published, the latency [ms] once its first plan arrived
        latency = {"goal": None, "sent": 0.0, "ms": None}

        tf = TfListener(demo)  # the robot's odometry is in odom (REP-105): placed in map

        def on_odom(msg) -> None:
            try:
                x, y, _ = odometry_pose(msg, tf.buffer, "map", TRANSFORM_TOLERANCE)
            except TransformUnavailable:
                return  # before the first map -> odom
            state["odom"] = (x, y, msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9)

        def on_cmd(msg) -> None:
            state["cmd"] = (msg.linear.x, msg.angular.z)

        def on_timing(msg) -> None:
            import json

            record = json.loads(msg.data)
            if record.get("stage") == CONTROL_STAGE and record.get("map_ready"):
                state["refiner_ready"] = True

        def on_plan(msg) -> None:
            if latency["goal"] is None or latency["ms"] is not None or not msg.poses:
                return
            end = msg.poses[-1].pose.position
            # a goal the footprint cannot reach exactly is snapped (at most SNAP_DISTANCE)
            if math.hypot(end.x - latency["goal"][0],
                          end.y - latency["goal"][1]) <= SNAP_DISTANCE + 1e-6:
                latency["ms"] = (time.perf_counter() - latency["sent"]) * 1e3

        demo.create_subscription(Odometry, "odom", on_odom, STREAM_QOS)
        demo.create_subscription(Twist, "cmd_vel", on_cmd, STREAM_QOS)
        demo.create_subscription(String, "ecahd/timing", on_timing, STREAM_QOS)
        demo.create_subscription(PathMsg, "plan", on_plan, PLAN_QOS)
        demo.create_subscription(String, "ecahd/planner_ready",
                                 lambda _: state.update(planner_ready=True), MAP_QOS)
        goal_to_plan: list[float | None] = []
        executor = SingleThreadedExecutor(context=ctx)
        for node in nodes:
            executor.add_node(node)

        def spin(seconds: float = 0.01) -> None:
            executor.spin_once(timeout_sec=seconds)
            for proc in procs:
                proc.check()

        # start-up: processes up, the refiner's cost map (and DD) and the planner's model on
        # the latched map (a goal before then would wait for it, and episode 0's goal -> plan
        # latency would be start-up time), the planner listening for goals, all recorded
        t0 = time.monotonic()
        while not (state["refiner_ready"] and state["planner_ready"]
                   and state["odom"] is not None
                   and not recorder.pending_topics and goal_pub.get_subscription_count() >= 2):
            spin()
            if time.monotonic() - t0 > STARTUP_TIMEOUT:
                raise EcahdError(f"start-up took over {STARTUP_TIMEOUT:g} s: refiner ready "
                                 f"{state['refiner_ready']}, planner ready "
                                 f"{state['planner_ready']}, odometry "
                                 f"{state['odom'] is not None}, recorder still waiting for "
                                 f"{recorder.pending_topics} (logs: {config.out / 'logs'})")
        log.info("graph ready in %.1f s (domain %d, one process per node); %d episodes",
                 time.monotonic() - t0, domain, len(goals))

        wall_timeout = config.wall_timeout or (
            2.0 * len(goals) * config.max_steps * CONTROL_PERIOD / config.realtime_factor + 60.0)
        wall0, sim0 = time.monotonic(), state["odom"][2]
        sim_params = None
        if scenarios is not None:
            from rclpy.parameter_client import AsyncParameterClient

            sim_params = AsyncParameterClient(demo, "sim_bridge")
            if not sim_params.wait_for_services(timeout_sec=10.0):
                raise EcahdError("sim_bridge's parameter services did not come up")
        for i, goal in enumerate(goals):
            if sim_params is not None:  # this episode's obstacles replace the last one's
                _set_parameter(executor, sim_params, "obstacles_file", str(scenarios[i]),
                               spin)
            msg = PoseStamped()
            msg.header.frame_id = "map"
            msg.header.stamp = demo.get_clock().now().to_msg()
            msg.pose.position.x, msg.pose.position.y = float(goal[0]), float(goal[1])
            # orientation all zeros (w defaults to 1: heading 0): any heading at the goal, the
            # benchmarks time the trip
            msg.pose.orientation.w = 0.0
            latency.update(goal=(float(goal[0]), float(goal[1])), ms=None)
            latency["sent"] = time.perf_counter()
            state["cmd"] = None
            goal_pub.publish(msg)
            x, y, t_start = state["odom"]
            held_since = None
            log.info("episode %d: (%.2f, %.2f) -> (%.2f, %.2f)", i, x, y, goal[0], goal[1])
            while True:
                spin()
                x, y, t = state["odom"]
                steps = (t - t_start) / CONTROL_PERIOD
                near = math.hypot(x - goal[0], y - goal[1]) < config.goal_radius
                stopped = state["cmd"] is not None and state["cmd"] == (0.0, 0.0)
                if near and stopped and latency["ms"] is not None:
                    held_since = t if held_since is None else held_since
                else:
                    held_since = None
                if held_since is not None and \
                        t - held_since >= config.hold_steps * CONTROL_PERIOD - 1e-9:
                    log.info("episode %d: reached, %.0f steps", i, steps)
                    break
                if steps >= config.max_steps - 1e-9:
                    log.info("episode %d: %d steps without reaching", i, config.max_steps)
                    break
                if time.monotonic() - wall0 > wall_timeout:
                    raise EcahdError(f"the episodes took over {wall_timeout:g} s wall time")
            goal_to_plan.append(latency["ms"])
            if latency["ms"] is None:
                log.warning("episode %d: no plan to the goal arrived", i)
        wall_s, sim_s = time.monotonic() - wall0, state["odom"][2] - sim0
        procs[0].stop()  # the simulator first: the last episode ends here in the bag too
        t_end = time.monotonic()
        while time.monotonic() - t_end < SETTLE_TIME:
            executor.spin_once(timeout_sec=0.01)
        recorder.close()
        log.info("episodes: %.1f s wall for %.1f s of sim time (%.2fx real time)", wall_s, sim_s,
                 sim_s / max(wall_s, 1e-9))
    finally:
        for proc in reversed(procs):
            proc.stop()
        for node in reversed(nodes):
            node.destroy_node()  # the recorder's closes the bag (idempotent)
        rclpy.try_shutdown(context=ctx)

    bag = config.out / "bag"
    evaluation = evaluate_bag(bag, robot=config.robot, map_name=config.map,
                              goal_radius=config.goal_radius, max_steps=config.max_steps)
    paths = {k: config.out / n for k, n in (("json", "metrics.json"), ("md", "metrics.md"),
                                            ("png", "trajectories.png"))}
    shown = ", ".join("-" if ms is None else f"{ms:.1f}" for ms in goal_to_plan)
    drawn = None
    if scenarios is not None:
        from ecahd_core.scenario import load_scenario

        drawn = [load_scenario(f) for f in scenarios]
    table = write_outputs(evaluation, bag, json_path=paths["json"], md_path=paths["md"],
                          png_path=paths["png"], extra={"goal_to_plan_ms": goal_to_plan},
                          notes=f"\nGoal -> first plan (wall time, per episode): {shown} ms.\n",
                          scenarios=drawn)
    return DemoResult(bag=bag, wall_s=wall_s, sim_s=sim_s, table=table, evaluation=evaluation,
                      goal_to_plan_ms=tuple(goal_to_plan), **paths)


def parse_params(items, flag: str) -> dict:
    """``NAME=VALUE`` strings -> {name: value}, each value read as JSON where it parses (1,
    0.3, true) and as a string otherwise; EcahdError naming ``flag`` and the item if malformed."""
    import json

    from ecahd_core.errors import EcahdError

    out = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or not name.strip():
            raise EcahdError(f"{flag} {item!r}: expected NAME=VALUE")
        try:
            value = json.loads(text)
        except ValueError:
            value = text
        out[name.strip()] = value
    return out


def run(args: argparse.Namespace) -> int:
    out = Path(args.out) if args.out else Path("runs") / time.strftime("demo-%Y%m%d-%H%M%S")
    config = DemoConfig(out=out, episodes=args.episodes, robot=args.robot, map=args.map,
                        seed=args.seed, realtime_factor=args.realtime_factor,
                        max_steps=args.max_steps, hold_steps=args.hold_steps,
                        domain_id=args.domain_id, obstacles=args.obstacles,
                        view_port=args.view,
                        moving=args.moving, first_episode=args.first_episode,
                        models=Path(args.models) if args.models else None,
                        planner_params={"method": args.method,
                                        **({"lanes": str(Path(args.lanes).resolve())}
                                           if args.lanes else {}),
                                        **parse_params(args.planner_param, "--planner-param")},
                        refiner_params={"dd_enabled": not args.no_dd,
                                        **({"lanes": str(Path(args.lanes).resolve())}
                                           if args.lanes else {}),
                                        **parse_params(args.refiner_param, "--refiner-param")})
    result = run_demo(config)
    print(result.table)
    print(f"episodes: {result.wall_s:.1f} s wall, {result.sim_s:.1f} s sim time; bag "
          f"{result.bag}; metrics {result.json}, {result.md}; figure {result.png}")
    return 0
