"""Closed-loop navigation metrics of the paper's Table III (Sec. IV-C), from plain arrays.

An *episode* starts when a goal is sent and ends when the next goal is sent (or the recording
ends). Its inputs are what the ROS graph records: odometry samples, the simulator's per-step
contact flags, the planners' timing records and the count of cmd_vel messages; nothing here
imports rclpy, so ``ecahd eval-bag`` and tests share it.

Metrics (D4RL maze2d-large-v1 conventions, as the paper uses them):

- Episode Reward: the sparse maze2d reward, 1 for every control step after which the robot is
  within ``goal_radius`` (0.5 m) of the goal, over at most ``max_steps`` (800) control steps.
  A control step is one control period (0.1 s of simulated time at the local refiner's 10 Hz);
  the state after step k (k = 1, 2, ...) is the latest odometry sample at or before
  t_0 + k * period, t_0 the episode's first odometry stamp.
- First Reach: the first k whose state is within ``goal_radius``; None if never.
- Collision Rate: the percentage of simulation steps whose contact flag is set (the ``collision``
  topic, one flag per step); a recording without the simulator's flags (a real robot's) takes
  them from the exact checker instead, one per odometry pose (:func:`exact_contacts`: the
  footprint at that pose overlaps an occupied map cell). Separately, the driven path
  (odometry x, y, yaw) is judged by the exact swept-footprint checker
  (``collision.check_collision``): collision free or not, and the fraction of its dense poses
  that penetrate a wall.
- Inference Time: the sum of the episode's planning timing records [ms] / 1000, in seconds:
  every stage but "control" (SD / FD / A* global plans, J checks, DD).
- reached: the goal was within ``goal_radius`` at some control step.

Beyond Table III: the wall time of the local refiner's control callback ("control" timing
records, one per tick, a J check + DD started in the tick included, hence not inference time),
as its median and 99th percentile over an episode's ticks and over all ticks of a run.

Beyond Table III, for maps that do not know every obstacle (issues 9 and 11):

- Contact steps by kind: the simulator's ``collision_detail`` records (one per contact step,
  "wall" | "static_obstacle" | "moving_obstacle"), counted per kind; None when the recording
  has no ``collision_detail`` topic (older bags), 0 when it has one without contacts.
- Monitor stops / slowdowns / yields: control ticks whose cmd_vel the collision monitor
  stopped, slowed, or replaced by an escape from a moving obstacle ("monitor" of the
  "control" record); blocked ticks: control ticks with reason
  "blocked" (the local plan is in collision; the robot waits for a new global plan).
- Global plans: the global planner's records ("sd", "astar", "fd", "fallback_astar"): the
  first plan of the goal and every replan (SD replans at each waypoint); fallbacks: the
  "fallback_astar" ones (A* round a blockage after repeated blocked replans).
- Time to goal: first reach x the control period [s of sim time]; None if never reached.
- cmd_vel jitter: the intervals between consecutive control ticks' ``wall`` stamps
  (time.time() when the tick published its cmd_vel) [ms], their p50 / p99, and the p99 of
  |interval - nominal|, nominal the median interval (or the control period given) [ms].
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from ecahd_core.errors import TrajectoryError
from ecahd_core.footprint import Footprint
from ecahd_core.maps import GridMap

GOAL_RADIUS = 0.5  # [m] maze2d "within reach" radius of the sparse reward
MAX_STEPS = 800  # control steps per episode in maze2d-large-v1
CONTROL_PERIOD = 0.1  # [s of sim time] one Table III step (D4RL maze2d: 800 steps per episode)
_STILL = 1e-6  # [m] odometry samples closer than this to the previous one are dropped
CONTROL_STAGE = "control"  # timing stage of a control tick: latency, not inference time
PLAN_STAGES = ("sd", "astar", "fd", "fallback_astar")  # one global plan each
FALLBACK_STAGE = "fallback_astar"  # A* round a blockage after repeated blocked replans
CONTACT_KINDS = ("wall", "static_obstacle", "moving_obstacle")  # collision_detail "kind"
PLAN_GOAL_SHIFT = 0.05  # [m] a plan whose end moved farther than this starts a new goal


@dataclass(frozen=True)
class PaperRow:
    """One row of the paper's Table III (maze2d-large, circular robot)."""

    episode_reward: float
    first_reach: float
    collision_rate: float  # [%] of simulation steps in contact
    inference_time_s: float  # [s] per episode


PAPER_TABLE_III: dict[str, PaperRow] = {
    "ECAHD w/ DD": PaperRow(46.862, 182.797, 0.0921, 1.994),
    "ECAHD w/o DD": PaperRow(37.969, 187.977, 0.1062, 1.963),
    "Diffuser": PaperRow(34.820, 569.414, 0.1820, 2.762),
    "DiPPeR": PaperRow(67.672, 676.422, 0.1551, 2.364),
    "LDP+A*": PaperRow(55.516, 570.281, 0.0940, 12.501),
}


@dataclass
class EpisodeData:
    """The raw inputs of one episode (plain arrays, times in seconds).

    Attributes:
        goal: (2,) [m] the goal in the map frame.
        odom: (N, 4) t [s of sim time], x [m], y [m], yaw [rad], in time order.
        collisions: (M,) bool, one contact flag per simulation step.
        timing_ms: (T,) [ms] timing records of the episode (SD / FD / A*, J check, DD, control
            ticks).
        timing_stages: (T,) stage names ("sd", "astar", "fd", "j_check", "dd", "control").
        cmd_vel_count: cmd_vel messages in the episode (informative; steps come from odom).
        start_time: [s] the episode's start on the recording's clock (informative).
        contact_kinds: the kind of every contact step ("wall", "static_obstacle",
            "moving_obstacle"; ``collision_detail``); None: not recorded.
        control_reasons: (C,) each control tick's reason ("follow", "blocked", ...).
        control_monitor: (C,) each control tick's collision monitor action ("none",
            "slowdown", "stop", "yield").
        control_wall: (C,) [s, wall clock] when each control tick published its cmd_vel (NaN:
            not recorded).
    """

    goal: np.ndarray
    odom: np.ndarray
    collisions: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    timing_ms: np.ndarray = field(default_factory=lambda: np.zeros(0))
    timing_stages: list[str] = field(default_factory=list)
    cmd_vel_count: int = 0
    start_time: float = 0.0
    contact_kinds: list[str] | None = None
    control_reasons: list[str] = field(default_factory=list)
    control_monitor: list[str] = field(default_factory=list)
    control_wall: np.ndarray = field(default_factory=lambda: np.zeros(0))


@dataclass(frozen=True)
class EpisodeMetrics:
    """Table III metrics of one episode (plus what they were computed from)."""

    index: int
    goal: tuple[float, float]
    episode_reward: int
    first_reach: int | None
    collision_rate: float  # [%] of sim steps in contact
    inference_time_s: float
    reached: bool
    control_steps: int  # steps evaluated (<= max_steps)
    sim_steps: int
    contact_steps: int
    path_collision_free: bool | None  # exact checker on the driven path; None: not checked
    penetration_fraction: float | None
    path_length: float  # [m] driven
    final_distance: float  # [m] to the goal at the last odometry sample
    duration_s: float  # [s of sim time]
    cmd_vel_count: int
    dd_calls: int
    stage_ms: dict[str, float]  # [ms] summed per inference stage (no "control")
    control_ticks: int = 0  # "control" timing records
    control_ms_p50: float | None = None  # [ms] wall time of the control callback
    control_ms_p99: float | None = None
    contact_steps_wall: int | None = None  # contact steps by kind; None: no collision_detail
    contact_steps_static: int | None = None
    contact_steps_moving: int | None = None
    monitor_stops: int = 0  # control ticks the collision monitor stopped
    monitor_slowdowns: int = 0
    monitor_yields: int = 0  # control ticks it drove an escape from a moving obstacle
    blocked_ticks: int = 0  # control ticks with reason "blocked"
    global_plans: int = 0  # sd / astar / fd / fallback_astar records: first plan + replans
    fallbacks: int = 0  # fallback_astar records
    time_to_goal_s: float | None = None  # [s of sim time] first_reach * period
    cmd_interval_ms_p50: float | None = None  # [ms] between consecutive control ticks (wall)
    cmd_interval_ms_p99: float | None = None
    cmd_jitter_ms_p99: float | None = None  # [ms] p99 of |interval - nominal|
    cmd_interval_nominal_ms: float | None = None  # [ms] the nominal interval used

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class Summary:
    """Means over episodes; first_reach over the episodes that reached (None if none did)."""

    episodes: int
    episode_reward: float
    first_reach: float | None
    collision_rate: float
    inference_time_s: float
    reached: float  # fraction of episodes that reached the goal
    path_collision_free: float | None  # fraction judged collision free by the exact checker
    control_ms_p50: float | None = None  # [ms] over all control ticks of the episodes
    control_ms_p99: float | None = None
    wall_contact_episodes: int | None = None  # episodes with >= 1 contact of the kind; None:
    static_contact_episodes: int | None = None  # no episode recorded collision_detail
    moving_contact_episodes: int | None = None
    monitor_stops: float = 0.0  # means per episode
    monitor_slowdowns: float = 0.0
    monitor_yields: float = 0.0
    blocked_ticks: float = 0.0
    global_plans: float = 0.0
    fallbacks: float = 0.0
    time_to_goal_s: float | None = None  # [s of sim time] over the reaching episodes
    cmd_interval_ms_p50: float | None = None  # [ms] pooled over all episodes' intervals
    cmd_interval_ms_p99: float | None = None
    cmd_jitter_ms_p99: float | None = None

    def to_dict(self) -> dict:
        return asdict(self)


# ------------------------------------------------------------------------------ metrics
def states_at_control_steps(odom: np.ndarray, *, period: float = CONTROL_PERIOD,
                            max_steps: int = MAX_STEPS) -> np.ndarray:
    """(N, 4) odometry -> (K, 2) x, y after each control step k = 1..K, K the whole periods
    the odometry spans (at most max_steps); the state after step k is the latest sample at or
    before t_0 + k * period."""
    odom = np.asarray(odom, dtype=np.float64).reshape(-1, 4)
    if len(odom) == 0:
        return np.zeros((0, 2))
    t = odom[:, 0]
    span = t[-1] - t[0]
    k = min(int(math.floor(span / period + 1e-9)), max_steps)
    step_t = t[0] + period * np.arange(1, k + 1)
    idx = np.searchsorted(t, step_t + 1e-9, side="right") - 1  # latest sample at or before
    return odom[idx, 1:3]


def evaluate_episode(data: EpisodeData, *, index: int = 0, grid: GridMap | None = None,
                     footprint: Footprint | None = None, goal_radius: float = GOAL_RADIUS,
                     max_steps: int = MAX_STEPS, period: float = CONTROL_PERIOD,
                     nominal_interval_ms: float | None = None) -> EpisodeMetrics:
    """Table III metrics of one episode; the exact path check runs when grid and footprint are
    given. nominal_interval_ms: [ms] the cmd_vel period the jitter is measured against (None:
    the median interval). Raises TrajectoryError for a malformed goal or odometry."""
    goal = np.asarray(data.goal, dtype=np.float64).reshape(-1)
    if goal.shape != (2,) or not np.all(np.isfinite(goal)):
        raise TrajectoryError(f"episode goal must be a finite (2,) point, got {data.goal!r}")
    odom = np.asarray(data.odom, dtype=np.float64).reshape(-1, 4)
    if len(odom) and np.any(np.diff(odom[:, 0]) < 0):
        raise TrajectoryError("episode odometry must be in time order")
    states = states_at_control_steps(odom, period=period, max_steps=max_steps)  # (K, 2)
    within = np.linalg.norm(states - goal, axis=1) < goal_radius  # (K,)
    hits = np.flatnonzero(within)
    collisions = np.asarray(data.collisions, dtype=bool).reshape(-1)
    timing = np.asarray(data.timing_ms, dtype=np.float64).reshape(-1)
    is_control = _control_mask(data)
    control, timing = timing[is_control], timing[~is_control]  # latency vs inference
    stage_ms: dict[str, float] = {}
    for stage, ms in zip(data.timing_stages, data.timing_ms):
        if stage != CONTROL_STAGE:
            stage_ms[stage] = stage_ms.get(stage, 0.0) + float(ms)
    free = penetration = None
    xy = odom[:, 1:3]
    if grid is not None and footprint is not None and len(odom):
        from ecahd_core.collision import check_collision

        keep = np.concatenate([[True], np.linalg.norm(np.diff(xy, axis=0), axis=1) > _STILL])
        report = check_collision(xy[keep], footprint, grid, headings=odom[keep, 3])
        free, penetration = report.collision_free, report.penetration_fraction
    kinds = None if data.contact_kinds is None else list(data.contact_kinds)
    stats = interval_stats(cmd_intervals(data), nominal_interval_ms)
    first_reach = int(hits[0]) + 1 if hits.size else None
    return EpisodeMetrics(
        index=index, goal=(float(goal[0]), float(goal[1])),
        episode_reward=int(within.sum()),
        first_reach=first_reach,
        collision_rate=100.0 * float(collisions.mean()) if collisions.size else 0.0,
        inference_time_s=float(timing.sum()) / 1000.0,
        reached=bool(hits.size),
        control_steps=len(states), sim_steps=int(collisions.size),
        contact_steps=int(collisions.sum()),
        path_collision_free=free, penetration_fraction=penetration,
        path_length=float(np.linalg.norm(np.diff(xy, axis=0), axis=1).sum()) if len(xy) else 0.0,
        final_distance=float(np.linalg.norm(xy[-1] - goal)) if len(xy) else float("nan"),
        duration_s=float(odom[-1, 0] - odom[0, 0]) if len(odom) else 0.0,
        cmd_vel_count=int(data.cmd_vel_count),
        dd_calls=sum(1 for s in data.timing_stages if s == "dd"),
        stage_ms=stage_ms, control_ticks=len(control),
        control_ms_p50=_percentile(control, 50), control_ms_p99=_percentile(control, 99),
        contact_steps_wall=None if kinds is None else kinds.count("wall"),
        contact_steps_static=None if kinds is None else kinds.count("static_obstacle"),
        contact_steps_moving=None if kinds is None else kinds.count("moving_obstacle"),
        monitor_stops=list(data.control_monitor).count("stop"),
        monitor_slowdowns=list(data.control_monitor).count("slowdown"),
        monitor_yields=list(data.control_monitor).count("yield"),
        blocked_ticks=list(data.control_reasons).count("blocked"),
        global_plans=sum(1 for s in data.timing_stages if s in PLAN_STAGES),
        fallbacks=sum(1 for s in data.timing_stages if s == FALLBACK_STAGE),
        time_to_goal_s=None if first_reach is None else first_reach * period,
        cmd_interval_ms_p50=stats.p50, cmd_interval_ms_p99=stats.p99,
        cmd_jitter_ms_p99=stats.jitter_p99, cmd_interval_nominal_ms=stats.nominal)


def exact_contacts(poses, footprint: Footprint, grid: GridMap) -> np.ndarray:
    """The contact flag of each step where no simulator reports one: (N, 3) poses x [m],
    y [m], yaw [rad] in the map frame -> (N,) bool, the footprint placed at the pose overlaps
    an occupied cell (or off-map space) deeper than the exact checker's tolerance: the test
    ``collision.check_collision`` applies to each of its dense poses. Only what the map holds
    is seen: an obstacle that was not on it is never a contact here. Raises TrajectoryError for
    non-finite poses."""
    from ecahd_core.collision import DEFAULT_TOLERANCE, pose_depths

    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    if len(poses) == 0:
        return np.zeros(0, dtype=bool)
    return pose_depths(poses, footprint, grid) > DEFAULT_TOLERANCE


def _control_mask(data: EpisodeData) -> np.ndarray:
    """(T,) bool: which timing records are control ticks (a record without a stage is not)."""
    n = np.asarray(data.timing_ms).reshape(-1).size
    stages = list(data.timing_stages)[:n]
    return np.array([s == CONTROL_STAGE for s in stages] + [False] * (n - len(stages)),
                    dtype=bool)


def control_times(data: EpisodeData) -> np.ndarray:
    """(C,) [ms] the episode's "control" timing records (wall time of each control tick)."""
    return np.asarray(data.timing_ms, dtype=np.float64).reshape(-1)[_control_mask(data)]


def cmd_intervals(data: EpisodeData) -> np.ndarray:
    """(C - 1,) [ms] the wall-clock intervals between consecutive control ticks' cmd_vel
    publishes (ticks without a ``wall`` stamp are left out)."""
    wall = np.asarray(data.control_wall, dtype=np.float64).reshape(-1)
    wall = wall[np.isfinite(wall)]
    return np.diff(wall) * 1e3


@dataclass(frozen=True)
class IntervalStats:
    """Inter-publish intervals [ms]: p50, p99, and the p99 of |interval - nominal|."""

    p50: float | None
    p99: float | None
    jitter_p99: float | None
    nominal: float | None  # the nominal interval the jitter is measured against


def interval_stats(intervals_ms, nominal_ms: float | None = None) -> IntervalStats:
    """p50 / p99 of the intervals [ms] and the p99 of their deviation from nominal_ms (None:
    their median); all None without intervals."""
    d = np.asarray(intervals_ms, dtype=np.float64).reshape(-1)
    if d.size == 0:
        return IntervalStats(None, None, None, nominal_ms)
    nominal = float(np.median(d)) if nominal_ms is None else float(nominal_ms)
    return IntervalStats(_percentile(d, 50), _percentile(d, 99),
                         _percentile(np.abs(d - nominal), 99), nominal)


def _percentile(values: np.ndarray, q: float) -> float | None:
    return float(np.percentile(values, q)) if len(values) else None


def _episodes_with(metrics: list[EpisodeMetrics], attribute: str) -> int | None:
    """How many episodes have a contact of one kind; None when none recorded the kinds."""
    counts = [getattr(m, attribute) for m in metrics if getattr(m, attribute) is not None]
    return sum(1 for c in counts if c > 0) if counts else None


def summarize(metrics: list[EpisodeMetrics], *, control_ms=None, intervals_ms=None,
              nominal_interval_ms: float | None = None) -> Summary:
    """Means over the episodes (all NaN-free; first_reach and time_to_goal_s over reaching
    episodes only). control_ms: (C,) [ms] the control ticks of all episodes
    (:func:`control_times`), pooled for the p50 / p99 (None: not reported). intervals_ms: the
    cmd_vel intervals of all episodes (:func:`cmd_intervals`), pooled for the interval p50 /
    p99 and the jitter p99 against nominal_interval_ms (None: their median)."""
    control = np.asarray(control_ms if control_ms is not None else [], dtype=np.float64)
    p50, p99 = _percentile(control, 50), _percentile(control, 99)
    stats = interval_stats(intervals_ms if intervals_ms is not None else [],
                           nominal_interval_ms)
    pooled = dict(cmd_interval_ms_p50=stats.p50, cmd_interval_ms_p99=stats.p99,
                  cmd_jitter_ms_p99=stats.jitter_p99)
    n = len(metrics)
    if n == 0:
        return Summary(0, 0.0, None, 0.0, 0.0, 0.0, None, p50, p99, **pooled)
    reach = [m.first_reach for m in metrics if m.first_reach is not None]
    to_goal = [m.time_to_goal_s for m in metrics if m.time_to_goal_s is not None]
    checked = [m.path_collision_free for m in metrics if m.path_collision_free is not None]

    def mean(attribute: str) -> float:
        return float(np.mean([getattr(m, attribute) for m in metrics]))

    return Summary(
        episodes=n,
        episode_reward=float(np.mean([m.episode_reward for m in metrics])),
        first_reach=float(np.mean(reach)) if reach else None,
        collision_rate=float(np.mean([m.collision_rate for m in metrics])),
        inference_time_s=float(np.mean([m.inference_time_s for m in metrics])),
        reached=float(np.mean([m.reached for m in metrics])),
        path_collision_free=float(np.mean(checked)) if checked else None,
        control_ms_p50=p50, control_ms_p99=p99,
        wall_contact_episodes=_episodes_with(metrics, "contact_steps_wall"),
        static_contact_episodes=_episodes_with(metrics, "contact_steps_static"),
        moving_contact_episodes=_episodes_with(metrics, "contact_steps_moving"),
        monitor_stops=mean("monitor_stops"), monitor_slowdowns=mean("monitor_slowdowns"),
        monitor_yields=mean("monitor_yields"),
        blocked_ticks=mean("blocked_ticks"), global_plans=mean("global_plans"),
        fallbacks=mean("fallbacks"), time_to_goal_s=float(np.mean(to_goal)) if to_goal else None,
        **pooled)


# ---------------------------------------------------------------------------- splitting
def episode_index(goal_times, times) -> np.ndarray:
    """Which episode each time belongs to: i for goal_times[i] <= t < goal_times[i + 1], -1
    before the first goal. goal_times must be sorted."""
    goal_times = np.asarray(goal_times, dtype=np.float64).reshape(-1)
    if np.any(np.diff(goal_times) < 0):
        raise TrajectoryError("goal times must be in time order")
    return np.searchsorted(goal_times, np.asarray(times, dtype=np.float64), side="right") - 1


def goals_from_plans(plans, *, shift: float = PLAN_GOAL_SHIFT) -> np.ndarray:
    """Goals from global plans, for a recording whose goals went through an action (Nav2's
    navigate_to_pose) rather than a topic: a plan whose last point lies more than ``shift``
    [m] from the previous plan's last point starts a goal at that point; replans of the same
    goal (their ends within ``shift``) do not, nor do empty plans (ignored). Two goals sent in
    a row to the same point (within ``shift``) are one.

    Args:
        plans: [(receive time [s], (P, 2) x, y [m] of the plan's points)] in time order.
    Returns:
        (G, 3) receive time [s], x, y [m] of each goal, as :func:`split_episodes` takes them.
    """
    goals, last = [], None
    for t, points in plans:
        points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if len(points) == 0:
            continue
        end = points[-1]
        if last is None or float(np.linalg.norm(end - last)) > shift:
            goals.append((float(t), float(end[0]), float(end[1])))
        last = end
    return np.asarray(goals, dtype=np.float64).reshape(-1, 3)


def split_episodes(goals, odom, *, collisions=None, timing=None, cmd_vel_times=None,
                   contacts=None) -> list[EpisodeData]:
    """Cut a recording into episodes at its goals.

    Args:
        goals: (G, 3) receive time [s], x, y [m] of each goal, in time order.
        odom: (N, 5) receive time [s], stamp [s of sim time], x, y, yaw.
        collisions: (M, 2) receive time [s], flag (0/1).
        timing: list of (receive time [s], ms, stage) or (receive time [s], ms, stage, record),
            record the whole ``ecahd/timing`` JSON dict: a "control" record's "reason",
            "monitor" and "wall" fill the episode's control_* lists ("", "none", NaN when
            absent).
        cmd_vel_times: (C,) receive times [s].
        contacts: list of (receive time [s], kind) from ``collision_detail``; None: the
            recording has none (the episodes' contact_kinds stay None).
    All receive times are on the one clock of the recording; data before the first goal is
    dropped.
    """
    goals = np.asarray(goals, dtype=np.float64).reshape(-1, 3)
    odom = np.asarray(odom, dtype=np.float64).reshape(-1, 5)
    collisions = np.asarray(collisions if collisions is not None else [],
                            dtype=np.float64).reshape(-1, 2)
    timing = list(timing or [])
    cmd_t = np.asarray(cmd_vel_times if cmd_vel_times is not None else [], dtype=np.float64)
    g = goals[:, 0]
    o_ep = episode_index(g, odom[:, 0])
    c_ep = episode_index(g, collisions[:, 0])
    t_ep = episode_index(g, [entry[0] for entry in timing])
    v_ep = episode_index(g, cmd_t)
    k_ep = episode_index(g, [t for t, _ in contacts]) if contacts is not None else None
    episodes = []
    for i, (t0, x, y) in enumerate(goals):
        ours = [timing[k] for k, e in enumerate(t_ep) if e == i]
        ticks = [entry[3] if len(entry) > 3 else {} for entry in ours
                 if entry[2] == CONTROL_STAGE]
        episodes.append(EpisodeData(
            goal=np.array([x, y]), odom=odom[o_ep == i, 1:5],
            collisions=collisions[c_ep == i, 1] > 0.5,
            timing_ms=np.array([entry[1] for entry in ours], dtype=np.float64),
            timing_stages=[str(entry[2]) for entry in ours],
            cmd_vel_count=int(np.sum(v_ep == i)), start_time=float(t0),
            contact_kinds=(None if contacts is None else
                           [str(contacts[k][1]) for k, e in enumerate(k_ep) if e == i]),
            control_reasons=[str(r.get("reason", "")) for r in ticks],
            control_monitor=[str(r.get("monitor", "none")) for r in ticks],
            control_wall=np.array([_float_or_nan(r.get("wall")) for r in ticks],
                                  dtype=np.float64)))
    return episodes


def _float_or_nan(value) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return float("nan")


# ------------------------------------------------------------------------------- tables
def _fmt(value, digits: int) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def markdown_table(summary: Summary, metrics: list[EpisodeMetrics], *,
                   label: str = "this run (ROS 2 closed loop)") -> str:
    """A markdown table of this run's means next to Table III, then one row per episode."""
    lines = ["| Method | Episode Reward | First Reach | Collision Rate [%] | Inference Time [s] |",
             "|---|---:|---:|---:|---:|",
             f"| **{label}** | {summary.episode_reward:.3f} | {_fmt(summary.first_reach, 3)} | "
             f"{summary.collision_rate:.4f} | {summary.inference_time_s:.3f} |"]
    for name, row in PAPER_TABLE_III.items():
        lines.append(f"| {name} (paper) | {row.episode_reward:.3f} | {row.first_reach:.3f} | "
                     f"{row.collision_rate:.4f} | {row.inference_time_s:.3f} |")
    if summary.control_ms_p50 is not None:
        lines += ["", f"Control callback (wall time of a control tick, J check + DD included, "
                      f"not in the inference time): p50 {summary.control_ms_p50:.2f} ms, "
                      f"p99 {summary.control_ms_p99:.2f} ms."]
    lines += ["", "| Episode | Goal | Reward | First Reach | Collision Rate [%] | Exact check "
              "| Inference [s] | Reached | Steps | DD calls | Control p50 / p99 [ms] |",
              "|---:|---|---:|---:|---:|---|---:|---|---:|---:|---:|"]
    for m in metrics:
        exact = ("-" if m.path_collision_free is None else
                 "free" if m.path_collision_free else f"hit ({100 * m.penetration_fraction:.1f}%)")
        lines.append(f"| {m.index} | ({m.goal[0]:.2f}, {m.goal[1]:.2f}) | {m.episode_reward} | "
                     f"{_fmt(m.first_reach, 0)} | {m.collision_rate:.4f} | {exact} | "
                     f"{m.inference_time_s:.3f} | {'yes' if m.reached else 'no'} | "
                     f"{m.control_steps} | {m.dd_calls} | {_fmt(m.control_ms_p50, 2)} / "
                     f"{_fmt(m.control_ms_p99, 2)} |")
    lines += ["", _safety_paragraph(summary), "",
              "| Episode | Contact steps wall / static / moving | Monitor stops / slowdowns / yields "
              "| Blocked ticks | Global plans | Fallbacks | Time to goal [s] "
              "| cmd_vel interval p50 / p99 [ms] | Jitter p99 [ms] |",
              "|---:|---|---|---:|---:|---:|---:|---:|---:|"]
    for m in metrics:
        contacts = " / ".join(_fmt(c, 0) for c in (m.contact_steps_wall,
                                                   m.contact_steps_static,
                                                   m.contact_steps_moving))
        lines.append(f"| {m.index} | {contacts} | {m.monitor_stops} / {m.monitor_slowdowns} / "
                     f"{m.monitor_yields} | "
                     f"{m.blocked_ticks} | {m.global_plans} | {m.fallbacks} | "
                     f"{_fmt(m.time_to_goal_s, 1)} | {_fmt(m.cmd_interval_ms_p50, 2)} / "
                     f"{_fmt(m.cmd_interval_ms_p99, 2)} | {_fmt(m.cmd_jitter_ms_p99, 2)} |")
    return "\n".join(lines) + "\n"


def _safety_paragraph(s: Summary) -> str:
    """The run's obstacle contacts, monitor, replanning and cmd_vel timing in one paragraph."""
    kinds = (s.wall_contact_episodes, s.static_contact_episodes, s.moving_contact_episodes)
    contacts = ("contact kinds not recorded (no collision_detail)" if all(k is None for k in kinds)
                else "episodes with a wall / static-obstacle / moving-obstacle contact: "
                     + " / ".join(_fmt(k, 0) for k in kinds) + f" of {s.episodes}")
    return (f"Obstacles and replanning: {contacts}; per episode, means: "
            f"{s.monitor_stops:.1f} collision monitor stops, {s.monitor_slowdowns:.1f} "
            f"slowdowns, {s.monitor_yields:.1f} yields to moving obstacles, "
            f"{s.blocked_ticks:.1f} blocked control ticks, {s.global_plans:.1f} "
            f"global plans (first + replans), {s.fallbacks:.1f} A* fallbacks; time to goal "
            f"{_fmt(s.time_to_goal_s, 1)} s of sim time (reaching episodes). cmd_vel "
            f"inter-publish interval (wall clock) p50 {_fmt(s.cmd_interval_ms_p50, 2)} ms, p99 "
            f"{_fmt(s.cmd_interval_ms_p99, 2)} ms; jitter (|interval - nominal|) p99 "
            f"{_fmt(s.cmd_jitter_ms_p99, 2)} ms.")
