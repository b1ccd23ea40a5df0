"""``ecahd demo``: the whole ROS 2 graph in one process, driven through seeded goals, recorded
and scored against the paper's Table III.

Composition (one private rclpy Context and domain, one SingleThreadedExecutor spun with
``spin_once`` by the episode loop): ``sim_bridge`` (PyBullet, its own simulated clock),
``global_planner`` (SD), ``local_refiner`` (J check + DD, 10 Hz control), ``bag_recorder``
(every default topic into OUT/bag) and a small ``demo`` node that publishes ``goal_pose`` and
listens to ``plan``. ``DemoConfig.planner_params`` / ``refiner_params`` override the planner's
and refiner's parameters (e.g. ``{"method": "astar"}``, ``{"dd_enabled": False}``: the
baselines of ``ecahd bench navigation``).
The planner, refiner and recorder run with ``use_sim_time``: the refiner's 10 Hz control timer,
its staleness checks and the bag's receive stamps follow ``/clock``, so a control step is 0.1 s
of simulated time whatever the realtime factor, and planning time stalls simulated time instead
of letting the robot drive blind (one thread: while a plan is computed nothing steps).

Episodes: goals come from ``make_problems(map, episodes, seed)``; the robot starts at the first
problem's start, later episodes start where the previous one ended and head for the next
problem's goal. An episode ends when the robot has been within ``goal_radius`` of the goal with
the refiner stopped (goal reached) for ``hold_steps`` control steps, or after ``max_steps``
control steps (max_steps / 10 s of simulated time); the next goal then starts the next episode.
The episode reward therefore counts the steps within 0.5 m until the episode ends.

Goal -> plan latency: per episode, the wall time (``time.perf_counter``) from publishing the
goal to the demo node receiving the first ``plan`` that ends at that goal (None if none came
before the episode ended); in DemoResult and in metrics.json as ``goal_to_plan_ms``.

After the last episode the bag is closed and scored by ``ecahd eval-bag``'s
:func:`~ecahd_ros.eval_bag.evaluate_bag`: OUT/metrics.json, OUT/metrics.md,
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

log = logging.getLogger("ecahd.demo")

CONTROL_PERIOD = 0.1  # [s of sim time] the local refiner's default 10 Hz
STARTUP_TIMEOUT = 120.0  # [s wall] models loaded and recorder subscribed
# [s wall] spinning after the last episode, simulator stopped, so the bag gets what is queued
SETTLE_TIME = 0.5


@dataclass(frozen=True, kw_only=True)
class DemoConfig:
    """Settings of one demo run (units as in the module docstring)."""

    out: Path
    episodes: int = 3
    robot: str = "circle"
    map: str = "maze2d-large"
    seed: int = 0
    realtime_factor: float = 4.0
    max_steps: int = 800
    hold_steps: int = 10
    goal_radius: float = 0.5
    goals: tuple[tuple[float, float], ...] | None = None  # explicit goals; None: seeded problems
    start: tuple[float, float] | None = None  # explicit start; None: the first problem's
    wall_timeout: float = 540.0  # [s] the whole episode loop
    domain_id: int | None = None  # None: derived from the process id
    # parameter overrides of the global_planner / local_refiner nodes (name -> value)
    planner_params: dict = field(default_factory=dict)
    refiner_params: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        from ecahd_core.errors import EcahdError

        if self.episodes < 1 or self.max_steps < 1 or self.hold_steps < 0:
            raise EcahdError("demo needs episodes >= 1, max_steps >= 1 and hold_steps >= 0")
        if not math.isfinite(self.realtime_factor):
            raise EcahdError(f"realtime_factor must be finite (<= 0: as fast as possible), got "
                             f"{self.realtime_factor}")
        if self.goals is not None and len(self.goals) < self.episodes:
            raise EcahdError(f"{self.episodes} episodes need as many goals, got {self.goals}")


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
    p.add_argument("--map", default="maze2d-large", help="built-in maze with shipped models")
    p.add_argument("--seed", type=int, default=0, help="seed of the goals and the samplers")
    p.add_argument("--out", default=None, help="output folder (default runs/demo-<timestamp>)")
    p.add_argument("--realtime-factor", type=float, default=4.0,
                   help="sim seconds per wall second (0: as fast as possible)")
    p.add_argument("--max-steps", type=int, default=800, help="control steps per episode")
    p.add_argument("--hold-steps", type=int, default=10,
                   help="control steps the reached goal is held before the next episode")
    p.add_argument("--domain-id", type=int, default=None,
                   help="ROS_DOMAIN_ID of the private context (default: from the process id)")


def _node_parameters(config: DemoConfig, start) -> dict[str, list]:
    from rclpy.parameter import Parameter

    sim_time = Parameter("use_sim_time", value=True)
    common = [Parameter("map_name", value=config.map), Parameter("robot", value=config.robot),
              Parameter("seed", value=config.seed), sim_time]
    return {
        "sim": [Parameter("map", value=config.map), Parameter("robot", value=config.robot),
                Parameter("start_x", value=float(start[0])),
                Parameter("start_y", value=float(start[1])),
                Parameter("realtime_factor", value=float(config.realtime_factor))],
        "planner": common + [Parameter(k, value=v) for k, v in config.planner_params.items()],
        "refiner": common + [Parameter(k, value=v) for k, v in config.refiner_params.items()],
        "recorder": [Parameter("output", value=str(config.out / "bag")), sim_time],
    }


def _goals(config: DemoConfig):
    """(start (2,), [goal (2,), ...]) from the config or seeded problems on the map."""
    import numpy as np

    from ecahd_core.maps import load_map
    from ecahd_core.problems import make_problems

    if config.goals is not None:
        goals = [np.asarray(g, dtype=np.float64) for g in config.goals[:config.episodes]]
        start = np.asarray(config.start if config.start is not None else (1.5, 1.5))
        return start, goals
    problems = make_problems(load_map(config.map), config.episodes, seed=config.seed)
    start = np.asarray(config.start) if config.start is not None else problems[0].start
    return start, [p.goal for p in problems]


def run_demo(config: DemoConfig) -> DemoResult:
    """Run the episodes, close the bag, score it and write the outputs."""
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from nav_msgs.msg import Path as PathMsg
    from rclpy.executors import SingleThreadedExecutor

    from ecahd_core.errors import EcahdError
    from ecahd_ros.bag_recorder import BagRecorder
    from ecahd_ros.eval_bag import evaluate_bag, write_outputs
    from ecahd_ros.global_planner import GlobalPlanner
    from ecahd_ros.qos import PLAN_QOS
    from ecahd_ros.local_refiner import LocalRefiner
    from sim_bridge.node import SimBridge

    start, goals = _goals(config)
    config.out.mkdir(parents=True, exist_ok=True)
    params = _node_parameters(config, start)
    domain = config.domain_id if config.domain_id is not None else 1 + os.getpid() % 100
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=domain)
    nodes = []
    try:
        sim = SimBridge(context=ctx, parameter_overrides=params["sim"])
        nodes.append(sim)
        if sim.sim is None:
            raise EcahdError("the simulator did not start (see its log)")
        planner = GlobalPlanner(context=ctx, parameter_overrides=params["planner"])
        refiner = LocalRefiner(context=ctx, parameter_overrides=params["refiner"])
        recorder = BagRecorder(context=ctx, parameter_overrides=params["recorder"])
        demo = rclpy.create_node("demo", context=ctx)
        nodes += [planner, refiner, recorder, demo]
        if recorder.bag_path is None or not recorder.recording:  # its log says why
            raise EcahdError(f"cannot record into {config.out / 'bag'} (see the recorder's log)")
        goal_pub = demo.create_publisher(PoseStamped, "goal_pose", 10)
        # goal -> first plan latency of the current episode: goal (x, y), perf_counter when it
        # was published, the latency [ms] once its first plan arrived
        latency = {"goal": None, "sent": 0.0, "ms": None}

        def on_plan(msg) -> None:
            if latency["goal"] is None or latency["ms"] is not None or not msg.poses:
                return
            end = msg.poses[-1].pose.position
            if math.hypot(end.x - latency["goal"][0], end.y - latency["goal"][1]) < 1e-6:
                latency["ms"] = (time.perf_counter() - latency["sent"]) * 1e3

        demo.create_subscription(PathMsg, "plan", on_plan, PLAN_QOS)
        goal_to_plan: list[float | None] = []
        executor = SingleThreadedExecutor(context=ctx)
        for node in nodes:
            executor.add_node(node)

        # start-up: models loaded (on the latched map), every topic recorded
        t0 = time.monotonic()
        while not (planner.ready and refiner.planner is not None
                   and not recorder.pending_topics and goal_pub.get_subscription_count() >= 2):
            executor.spin_once(timeout_sec=0.01)
            if time.monotonic() - t0 > STARTUP_TIMEOUT:
                raise EcahdError(f"start-up took over {STARTUP_TIMEOUT:g} s: planner "
                                 f"{planner.ready}, refiner "
                                 f"{refiner.planner is not None}, recorder still waiting for "
                                 f"{recorder.pending_topics}")
        log.info("graph ready in %.1f s (domain %d); %d episodes", time.monotonic() - t0,
                 domain, len(goals))

        wall0, sim0 = time.monotonic(), sim.sim.state.t
        for i, goal in enumerate(goals):
            msg = PoseStamped()
            msg.header.frame_id = "map"
            msg.header.stamp = planner.get_clock().now().to_msg()
            msg.pose.position.x, msg.pose.position.y = float(goal[0]), float(goal[1])
            msg.pose.orientation.w = 1.0
            latency.update(goal=(float(goal[0]), float(goal[1])), ms=None)
            latency["sent"] = time.perf_counter()
            goal_pub.publish(msg)
            t_start, held_since = sim.sim.state.t, None
            s = sim.sim.state
            log.info("episode %d: (%.2f, %.2f) -> (%.2f, %.2f)", i, s.x, s.y, goal[0], goal[1])
            while True:
                executor.spin_once(timeout_sec=0.01)
                s = sim.sim.state
                steps = (s.t - t_start) / CONTROL_PERIOD
                near = math.hypot(s.x - goal[0], s.y - goal[1]) < config.goal_radius
                if near and refiner.waypoints is None:
                    held_since = s.t if held_since is None else held_since
                else:
                    held_since = None
                if held_since is not None and \
                        s.t - held_since >= config.hold_steps * CONTROL_PERIOD - 1e-9:
                    log.info("episode %d: reached, %.0f control steps", i, steps)
                    break
                if steps >= config.max_steps - 1e-9:
                    log.info("episode %d: %d control steps without reaching", i,
                             config.max_steps)
                    break
                if time.monotonic() - wall0 > config.wall_timeout:
                    raise EcahdError(f"the episodes took over {config.wall_timeout:g} s wall "
                                     "time")
            goal_to_plan.append(latency["ms"])
            if latency["ms"] is None:
                log.warning("episode %d: no plan to the goal arrived", i)
        wall_s, sim_s = time.monotonic() - wall0, sim.sim.state.t - sim0
        executor.remove_node(sim)  # no more steps: the last episode ends here in the bag too
        t_end = time.monotonic()
        while time.monotonic() - t_end < SETTLE_TIME:
            executor.spin_once(timeout_sec=0.01)
        recorder.close()
        log.info("episodes: %.1f s wall for %.1f s of sim time (%.2fx real time)", wall_s, sim_s,
                 sim_s / max(wall_s, 1e-9))
    finally:
        for node in reversed(nodes):
            node.destroy_node()  # the recorder's closes the bag (idempotent)
        rclpy.try_shutdown(context=ctx)

    bag = config.out / "bag"
    evaluation = evaluate_bag(bag, robot=config.robot, map_name=config.map,
                              goal_radius=config.goal_radius, max_steps=config.max_steps)
    paths = {k: config.out / n for k, n in (("json", "metrics.json"), ("md", "metrics.md"),
                                            ("png", "trajectories.png"))}
    shown = ", ".join("-" if ms is None else f"{ms:.1f}" for ms in goal_to_plan)
    table = write_outputs(evaluation, bag, json_path=paths["json"], md_path=paths["md"],
                          png_path=paths["png"], extra={"goal_to_plan_ms": goal_to_plan},
                          notes=f"\nGoal -> first plan (wall time, per episode): {shown} ms.\n")
    return DemoResult(bag=bag, wall_s=wall_s, sim_s=sim_s, table=table, evaluation=evaluation,
                      goal_to_plan_ms=tuple(goal_to_plan), **paths)


def run(args: argparse.Namespace) -> int:
    out = Path(args.out) if args.out else Path("runs") / time.strftime("demo-%Y%m%d-%H%M%S")
    config = DemoConfig(out=out, episodes=args.episodes, robot=args.robot, map=args.map,
                        seed=args.seed, realtime_factor=args.realtime_factor,
                        max_steps=args.max_steps, hold_steps=args.hold_steps,
                        domain_id=args.domain_id)
    result = run_demo(config)
    print(result.table)
    print(f"episodes: {result.wall_s:.1f} s wall, {result.sim_s:.1f} s sim time; bag "
          f"{result.bag}; metrics {result.json}, {result.md}; figure {result.png}")
    return 0
