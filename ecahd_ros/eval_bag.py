"""``ecahd eval-bag BAG``: the paper's Table III metrics from a recorded closed-loop run.

The bag (as ``bag_recorder`` or ``ros2 bag record`` writes it, in our simulator or on a robot
running Nav2-style software) must hold ``map``, goals and the robot's pose; ``collision``,
``cmd_vel`` and ``ecahd/timing`` are used when present. Every goal starts an episode that ends
at the next one or at the end of the bag (``ecahd_core.evaluation``). Episodes are cut on the
bag's receive times (one clock for all topics); control steps and durations come from the pose
stamps (simulated time in the simulator).

Where each input comes from (``BagSources``, in the JSON and under the table):

- Namespace: the topics may live under one (``/robot1/odom``, ``/robot1/map``, ...;
  ``--namespace``). By default the root is used when it has ``map`` and a pose source
  (``odom``, or ``tf`` / ``tf_static``), else the one namespace that has them (several:
  BagError naming them). ``tf`` and ``tf_static`` are the namespace's own when it recorded
  them, else the global ones.
- Poses: ``odom`` (in ``map``, or in another frame placed in ``map`` through the recorded tf,
  REP-105). Without odometry: ``--base-frame`` (Nav2's ``robot_base_frame``, ``base_link``) in
  ``map`` from ``tf`` + ``tf_static``, sampled at the stamps of the lowest dynamic transform
  of its chain (the one ending in the base frame, or in its first ancestor that is not
  attached by a static transform, e.g. ``odom -> base_footprint``).
- Goals: ``goal_pose``. Without it (goals sent through Nav2's navigate_to_pose action are on
  no topic): the global ``plan``s; a plan whose last point moved more than 0.05 m from the
  previous plan's starts a goal there (``evaluation.goals_from_plans``), so an episode begins
  when its first plan is received.
- Contacts: the simulator's ``collision`` flags ("simulator"). Without them (a real robot):
  one flag per pose from the exact checker, the footprint at the pose against the map
  ("exact_checker", ``evaluation.exact_contacts``); obstacles that are not on the map are not
  seen.

Inference time counts the planning records of ``ecahd/timing`` (SD / FD / A*, J checks, DD);
the local refiner's "control" records (the wall time of each control tick) are reported apart,
as their median and 99th percentile (``control_ms_p50``, ``control_ms_p99``; per episode and
pooled over the run in the means).

From the same records and ``collision_detail`` (``ecahd_core.evaluation`` defines each):
contact steps by kind (wall / static obstacle / moving obstacle), collision monitor stops and
slowdowns, blocked control ticks, global plans and A* fallbacks, time to goal, and the cmd_vel
inter-publish interval and jitter from the control records' ``wall`` stamps. A bag without
these (recorded before them) still evaluates: the counts are 0, the kinds and jitter None.

Only ``rosbags`` reads the bag (``ecahd_core.bag_io``): this module imports neither rclpy nor
a ROS message package, so it runs where ROS is not installed.

Writes the per-episode records and their means as JSON (``--json``), the table next to the
paper's as markdown (``--md``) and the driven paths over the map (``--png``, Fig. 4 style: each
episode's path, its goal as a star, the poses where the exact checker finds a wall in red);
prints the table.
"""
from __future__ import annotations

import argparse
import json
import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ecahd_core.bench.output import write_json

log = logging.getLogger("ecahd.eval_bag")

TOPICS = ("/map", "/goal_pose", "/odom", "/collision", "/collision_detail", "/cmd_vel",
          "/ecahd/timing", "/plan", "/tf", "/tf_static")
TF_TOPICS = ("/tf", "/tf_static")  # a namespace's own when recorded, else the global ones
GLOBAL_FRAME = "map"  # the frame of the map, the goals and the scored poses
BASE_FRAME = "base_link"  # Nav2's robot_base_frame: the pose scored when there is no odometry
COLORS = ("tab:purple", "tab:blue", "tab:orange", "tab:green", "tab:brown", "tab:pink",
          "tab:olive", "tab:cyan")


@dataclass(frozen=True)
class BagSources:
    """Where ``evaluate_bag`` took its inputs from (see the module docstring)."""

    namespace: str  # "" (none) or "/robot1"
    topics: dict  # [str, str] the name read ("/odom") -> the bag's topic ("/robot1/odom")
    poses_from: str  # "odom" | "tf"
    goals_from: str  # "goal_pose" | "plan"
    contacts_from: str  # "simulator" | "exact_checker"
    base_frame: str = BASE_FRAME  # the frame whose pose tf gives (poses_from "tf")

    def to_dict(self) -> dict:
        return {"namespace": self.namespace, "poses_from": self.poses_from,
                "goals_from": self.goals_from, "contacts_from": self.contacts_from}

    def markdown(self) -> str:
        """One line saying where the poses, goals and contact figures came from."""
        t = self.topics
        poses = (f"`{t['/odom']}`" if self.poses_from == "odom" else
                 f"`{self.base_frame}` in `{GLOBAL_FRAME}` from `{t['/tf']}` + "
                 f"`{t['/tf_static']}`")
        goals = (f"`{t['/goal_pose']}`" if self.goals_from == "goal_pose" else
                 f"the ends of `{t['/plan']}` (no goal_pose recorded)")
        contacts = (f"the simulator's `{t['/collision']}` flags"
                    if self.contacts_from == "simulator" else
                    "the exact checker (the footprint at each pose against the map; no contact "
                    "flags recorded, obstacles not on the map unseen)")
        return f"\nSources: poses {poses}; goals {goals}; contacts from {contacts}.\n"


@dataclass
class BagEvaluation:
    """What ``evaluate_bag`` found: the map, the episodes' data and metrics, their means, and
    where each input came from."""

    grid: object  # GridMap
    footprint: object  # Footprint
    episodes: list  # [EpisodeData]
    metrics: list  # [EpisodeMetrics]
    summary: object  # Summary
    sources: BagSources

    def to_dict(self, bag: str = "") -> dict:
        from ecahd_core.evaluation import PAPER_TABLE_III

        return {"bag": bag, "map": {"name": self.grid.name, "fingerprint": self.grid.fingerprint(),
                                    "resolution": self.grid.resolution},
                "robot": self.footprint.name, **self.sources.to_dict(),
                "mean": self.summary.to_dict(),
                "episodes": [m.to_dict() for m in self.metrics],
                "paper_table_iii": {k: vars(v) for k, v in PAPER_TABLE_III.items()}}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("bag", help="rosbag2 directory (MCAP or SQLite3)")
    p.add_argument("--json", default=None, help="write per-episode records and means here")
    p.add_argument("--md", default=None, help="write the markdown table here")
    p.add_argument("--png", default=None, help="write the trajectories figure here")
    p.add_argument("--scenarios", default=None, metavar="FOLDER",
                   help="draw each episode's obstacles from FOLDER/episode_<i>.yaml (the "
                        "scenarios folder of `ecahd demo` / `ecahd bench navigation`)")
    p.add_argument("--snapshot", type=float, default=None, metavar="T",
                   help="instead: draw what the robot knew T s (sim time) after the first goal "
                        "(map, local costmap, scan, plans, driven path) into --png")
    p.add_argument("--zones", default=None, metavar="SCENARIO",
                   help="scenario YAML with a 'zones:' list: count the episodes whose driven "
                        "path entered one (the no-go habit)")
    p.add_argument("--robot", default="circle",
                   help="footprint for the exact path check: circle | quadruped | humanoid | "
                        "Nav2 polygon (the bag does not record it)")
    p.add_argument("--map-name", default="recorded", help="name given to the recorded map")
    p.add_argument("--namespace", default=None, metavar="NS",
                   help="the robot's topic namespace, e.g. /robot1 (default: auto, the root or "
                        "the one namespace with map and odom or tf)")
    p.add_argument("--base-frame", default=BASE_FRAME,
                   help="the robot's frame whose pose in map tf gives when the bag has no odom")
    p.add_argument("--goal-radius", type=float, default=0.5, help="[m] reward / reach radius")
    p.add_argument("--max-steps", type=int, default=800, help="control steps per episode")
    p.add_argument("--control-period", type=float, default=0.1,
                   help="[s of sim time] one control step")
    p.add_argument("--nominal-interval-ms", type=float, default=None,
                   help="[ms] the cmd_vel period the jitter is measured against (default: the "
                        "median interval between control ticks)")


def _json_records(messages, topic: str, required: tuple[str, ...]) -> list[tuple[float, dict]]:
    """std_msgs/String JSON messages -> [(receive time [s], record)], skipping (and logging)
    what is not a JSON object with the required keys."""
    out = []
    for t, m in messages:
        try:
            record = json.loads(m.data)
            if not isinstance(record, dict) or any(k not in record for k in required):
                raise ValueError
        except (ValueError, TypeError):
            log.warning("skipping a malformed %s record: %r", topic, str(m.data)[:80])
            continue
        out.append((t * 1e-9, record))
    return out


def _namespaces(counts: dict) -> list[str]:
    """The namespaces of a bag's topics: each prefix P ("/robot1") of a topic P + one of
    TOPICS."""
    found = {topic[:-len(name)] for topic in counts for name in TOPICS
             if topic.endswith(name) and len(topic) > len(name)}
    return sorted(found)


def resolve_topics(counts: dict, namespace: str | None, path, *,
                   require_map: bool = True) -> tuple[str, dict]:
    """Which of the bag's topics to read: ``counts`` {topic: messages} (``bag_topics``),
    ``namespace`` "/robot1" (a missing leading '/' is added; "" or "/": the root) or None:
    auto, the root when it has /map and a pose source (/odom, /tf, /tf_static), else the one
    namespace that has them (``require_map`` False: a pose source alone). -> (namespace, {name in TOPICS: the bag's topic}); tf's are the
    namespace's own when it recorded messages on them, else the global ones. Raises BagError
    for several candidate namespaces or a namespace with no topic in the bag."""
    from ecahd_core.errors import BagError

    def has(topic: str) -> bool:
        return counts.get(topic, 0) > 0

    def tf_of(ns: str) -> dict:
        return {t: ns + t if has(ns + t) else t for t in TF_TOPICS}

    def usable(ns: str) -> bool:
        return (has(ns + "/map") or not require_map) and (has(ns + "/odom") or any(map(has, tf_of(ns).values())))

    spaces = _namespaces(counts)
    if namespace is None:
        ns, found = "", [s for s in spaces if usable(s)]
        if not usable("") and len(found) > 1:
            raise BagError(f"bag {str(path)!r} has the robot topics under several namespaces "
                           f"({', '.join(found)}); pick one with --namespace")
        if not usable("") and found:
            ns = found[0]
            log.info("%s: namespace %s (auto-detected)", path, ns)
    else:
        ns = "/" + namespace.strip().strip("/") if namespace.strip().strip("/") else ""
        if ns and not any(t.startswith(ns + "/") for t in counts):
            raise BagError(f"bag {str(path)!r} has no topic under namespace {ns!r} "
                           f"(namespaces in it: {', '.join(spaces) or 'none'})")
    return ns, {**{t: ns + t for t in TOPICS}, **tf_of(ns)}


def _read_transforms(data: dict):
    """The bag's /tf_static and /tf in one TransformBuffer (every transform of the run kept)
    -> (buffer, links {child: (parent, static)}, stamps {child: [(receive time [s], stamp [s])]}
    of the dynamic transforms, count of malformed transforms skipped)."""
    from ecahd_core.bag_io import stamp_seconds
    from ecahd_core.frames import FrameError, TransformBuffer

    buffer = TransformBuffer(cache_time=1e12)  # the whole recording
    links, stamps, bad = {}, {}, 0
    for topic, static in (("/tf_static", True), ("/tf", False)):
        for t, msg in data.get(topic, []):
            for transform in msg.transforms:
                try:
                    parent, child = buffer.add_stamped(transform, static=static)
                except FrameError:
                    bad += 1
                    continue
                links[child] = (parent, static)
                if not static:
                    stamps.setdefault(child, []).append(
                        (t * 1e-9, stamp_seconds(transform.header.stamp)))
    return buffer, links, stamps, bad


def _in_global_frame(odom: list, frames: list, data: dict, path) -> list:
    """Odometry records (receive time, stamp, x, y, yaw) in ``frames`` placed in GLOBAL_FRAME by
    the bag's /tf and /tf_static (every transform of the run kept); a record with no transform
    at its stamp is left out and counted in the log. BagError when none can be placed."""
    from ecahd_core.errors import BagError
    from ecahd_core.frames import TRANSFORM_TOLERANCE, FrameError

    buffer, _, _, bad = _read_transforms(data)
    out, missing = [], 0
    for (t, stamp, x, y, yaw), frame in zip(odom, frames):
        if frame in ("", GLOBAL_FRAME):
            out.append((t, stamp, x, y, yaw))
            continue
        try:
            out.append((t, stamp, *buffer.pose_in(GLOBAL_FRAME, frame, stamp, (x, y, yaw),
                                                  tolerance=TRANSFORM_TOLERANCE)))
        except FrameError:
            missing += 1
    if bad or missing:
        log.warning("%s: %d malformed transform(s) skipped, %d odometry pose(s) without a "
                    "transform to %s left out", path, bad, missing, GLOBAL_FRAME)
    if not out:
        raise BagError(f"bag {str(path)!r}: no odometry pose could be placed in "
                       f"{GLOBAL_FRAME!r} (frames {sorted(set(frames))}; record /tf and "
                       f"/tf_static with it)")
    return out


def _poses_from_tf(data: dict, base_frame: str, topics: dict, path) -> list:
    """Without odometry: ``base_frame``'s pose in GLOBAL_FRAME from the bag's tf, as records
    (receive time, stamp, x, y, yaw) in stamp order, one per stamp of the lowest dynamic
    transform of its chain (the one whose child is the base frame, or the first ancestor not
    attached by a static transform). A stamp with no transform to GLOBAL_FRAME is left out and
    counted in the log. BagError when there is no tf, no such frame, or no pose at all."""
    from ecahd_core.errors import BagError
    from ecahd_core.frames import TRANSFORM_TOLERANCE, FrameError

    where = f"bag {str(path)!r} has no {topics['/odom']} messages"
    tf = f"{topics['/tf']} / {topics['/tf_static']}"
    buffer, links, stamps, bad = _read_transforms(data)
    if not links:
        raise BagError(f"{where} and no transforms on {tf}: no pose source; cannot evaluate")
    if base_frame not in buffer.frames():
        raise BagError(f"{where} and its {tf} has no frame {base_frame!r} (frames: "
                       f"{', '.join(sorted(buffer.frames()))}); pass --base-frame")
    frame = base_frame
    while frame in links and links[frame][1]:  # up through the static links (mountings)
        frame = links[frame][0]
    if frame not in links:
        raise BagError(f"{where} and {base_frame!r} moves on no dynamic transform of {tf} "
                       f"(static up to {frame!r}); cannot evaluate")
    first = {}  # stamp -> its first receive time (a transform sent twice is one sample)
    for t, stamp in stamps[frame]:
        first.setdefault(stamp, t)
    out, missing, error = [], 0, None
    for stamp in sorted(first):
        try:
            x, y, yaw = buffer.lookup(GLOBAL_FRAME, base_frame, stamp,
                                      tolerance=TRANSFORM_TOLERANCE).xy_yaw()
        except FrameError as exc:
            missing, error = missing + 1, error or exc
            continue
        out.append((first[stamp], stamp, x, y, yaw))
    if bad or missing:
        log.warning("%s: %d malformed transform(s) skipped, %d stamp(s) of %s without a "
                    "transform to %s left out", path, bad, missing, frame, GLOBAL_FRAME)
    if not out:
        raise BagError(f"{where}, and no pose of {base_frame!r} could be placed in "
                       f"{GLOBAL_FRAME!r} from {tf}: {error}")
    return out


def odometry_record(t_ns: int, msg) -> tuple[tuple, str]:
    """One nav_msgs/Odometry received at ``t_ns`` [ns] -> ((receive time [s], stamp [s], x,
    y, yaw), its frame without a leading '/')."""
    from ecahd_core.bag_io import quaternion_yaw, stamp_seconds

    p = msg.pose.pose
    return ((t_ns * 1e-9, stamp_seconds(msg.header.stamp), p.position.x, p.position.y,
             quaternion_yaw(p.orientation)), msg.header.frame_id.lstrip("/"))


def robot_poses(odom: list, frames: list, data: dict, topics: dict, path,
                base_frame: str = BASE_FRAME) -> tuple[list, str]:
    """The robot's poses in GLOBAL_FRAME as records (receive time [s], stamp [s], x, y, yaw)
    and where they came from ("odom" | "tf"): ``odom`` records (:func:`odometry_record`) in
    ``frames`` placed in map through the recorded tf where they are in another frame
    (REP-105); without odometry, ``base_frame``'s pose from ``data``'s /tf and /tf_static
    (:func:`_poses_from_tf`). Raises BagError as those do."""
    if odom:
        if set(frames) - {"", GLOBAL_FRAME}:  # a robot's odometry: placed in map through tf
            odom = _in_global_frame(odom, frames, data, path)
        return odom, "odom"
    return _poses_from_tf(data, base_frame, topics, path), "tf"  # its base frame from tf


def _goals(data: dict, topics: dict, path) -> tuple[list, str]:
    """The goals (receive time [s], x, y) and their source: goal_pose, else the plans' ends
    (``evaluation.goals_from_plans``); BagError when there are neither."""
    from ecahd_core.errors import BagError
    from ecahd_core.evaluation import goals_from_plans

    if data.get("/goal_pose"):
        return [(t * 1e-9, m.pose.position.x, m.pose.position.y)
                for t, m in data["/goal_pose"]], "goal_pose"
    plans = [(t * 1e-9, [(p.pose.position.x, p.pose.position.y) for p in m.poses])
             for t, m in data.get("/plan", [])]
    goals = goals_from_plans(plans)
    if not len(goals):
        raise BagError(f"bag {str(path)!r} has no {topics['/goal_pose']} messages and no "
                       f"non-empty {topics['/plan']} to take goals from; cannot evaluate")
    return [tuple(g) for g in goals.tolist()], "plan"


def evaluate_bag(path, *, robot: str = "circle", map_name: str = "recorded",
                 goal_radius: float = 0.5, max_steps: int = 800, control_period: float = 0.1,
                 nominal_interval_ms: float | None = None, namespace: str | None = None,
                 base_frame: str = BASE_FRAME) -> BagEvaluation:
    """Read a bag and compute the metrics of each episode; raises BagError when the map, goals
    or poses are missing. ``namespace``: the robot's topics' namespace (None: auto);
    ``base_frame``: the frame whose pose tf gives when there is no odometry."""
    from ecahd_core.bag_io import bag_topics, read_bag
    from ecahd_core.errors import BagError
    from ecahd_core.evaluation import (cmd_intervals, control_times, evaluate_episode,
                                       exact_contacts, split_episodes, summarize)
    from ecahd_core.footprint import make_footprint
    from ecahd_core.maps import grid_from_occupancy_message

    counts = bag_topics(path)
    ns, topics = resolve_topics(counts, namespace, path)
    recorded = read_bag(path, topics=sorted(set(topics.values())))
    data = {name: recorded[topic] for name, topic in topics.items() if topic in recorded}
    if not data.get("/map"):
        spaces = _namespaces(counts) if not ns else []
        hint = f" (namespaces in it: {', '.join(spaces)}; pass --namespace)" if spaces else ""
        raise BagError(f"bag {str(path)!r} has no {topics['/map']} messages{hint}; cannot "
                       f"evaluate")
    # the rosbags dataclass has the rclpy message's field names; the float32 resolution is
    # restored (0.1 stays 0.1) as for a received map
    grid = grid_from_occupancy_message(data["/map"][-1][1], name=map_name)
    footprint = make_footprint(robot)
    goals, goals_from = _goals(data, topics, path)
    records = [odometry_record(t, m) for t, m in data.get("/odom", [])]
    odom, poses_from = robot_poses([r[0] for r in records], [r[1] for r in records], data,
                                   topics, path, base_frame)
    if data.get("/collision"):
        collisions = [(t * 1e-9, float(m.data)) for t, m in data["/collision"]]
        contacts_from = "simulator"
    else:  # no simulator: a contact is a pose whose footprint overlaps the map
        flags = exact_contacts(np.array([o[2:5] for o in odom]), footprint, grid)
        collisions = [(o[0], float(f)) for o, f in zip(odom, flags)]
        contacts_from = "exact_checker"
    sources = BagSources(namespace=ns, topics=topics, poses_from=poses_from,
                         goals_from=goals_from, contacts_from=contacts_from,
                         base_frame=base_frame)
    log.info("%s: poses from %s, goals from %s (%d), contacts from %s", path,
             topics["/odom"] if poses_from == "odom" else f"tf ({base_frame} in {GLOBAL_FRAME})",
             topics["/" + goals_from], len(goals), contacts_from.replace("_", " "))
    timing = []
    for t, record in _json_records(data.get("/ecahd/timing", []), "ecahd/timing", ("ms",)):
        try:
            timing.append((t, float(record["ms"]), str(record.get("stage", "?")), record))
        except (ValueError, TypeError):
            log.warning("skipping an ecahd/timing record whose ms is not a number: %r", record)
    # None when the bag has no collision_detail topic at all (recorded before it existed)
    contacts = (None if "/collision_detail" not in data else
                [(t, str(r["kind"])) for t, r in _json_records(
                    data["/collision_detail"], "collision_detail", ("kind",))])
    cmd_times = [t * 1e-9 for t, _ in data.get("/cmd_vel", [])]
    episodes = split_episodes(goals, odom, collisions=collisions, timing=timing,
                              cmd_vel_times=cmd_times, contacts=contacts)
    metrics = [evaluate_episode(ep, index=i, grid=grid, footprint=footprint,
                                goal_radius=goal_radius, max_steps=max_steps,
                                period=control_period, nominal_interval_ms=nominal_interval_ms)
               for i, ep in enumerate(episodes)]
    control = np.concatenate([control_times(ep) for ep in episodes]) if episodes else None
    intervals = np.concatenate([cmd_intervals(ep) for ep in episodes]) if episodes else None
    return BagEvaluation(grid=grid, footprint=footprint, episodes=episodes, metrics=metrics,
                         summary=summarize(metrics, control_ms=control, intervals_ms=intervals,
                                           nominal_interval_ms=nominal_interval_ms),
                         sources=sources)


def draw_trajectories(result: BagEvaluation, path, *, title: str = "",
                      scenarios: list | None = None) -> Path:
    """Fig. 4 style: every episode's driven path over the map, goals as stars, the poses the
    exact checker finds in a wall in red. ``scenarios``: per episode, the obstacles that were
    not on the map (ecahd_core.scenario.Obstacle list, None for none), drawn in the episode's
    colour: static ones filled, moving ones as their run (dashed) with their start outline."""
    from ecahd_core.collision import check_collision
    from ecahd_core.viz import pyplot, draw_map

    plt = pyplot()
    xmin, ymin, xmax, ymax = result.grid.bounds
    wide = 2.0 if len(result.metrics) > 6 else 0.0  # [in] room for the legend beside the map
    fig, ax = plt.subplots(figsize=(8 + wide, 8 * (ymax - ymin) / max(xmax - xmin, 1e-9) + 0.6))
    draw_map(ax, result.grid)
    for ep, m in zip(result.episodes, result.metrics):
        color = COLORS[m.index % len(COLORS)]
        xy = ep.odom[:, 1:3]
        if len(xy):
            ax.plot(xy[:, 0], xy[:, 1], color=color, lw=1.6,
                    label=f"episode {m.index} ({'reached' if m.reached else 'not reached'})")
            ax.plot(*xy[0], marker="s", color=color, ms=7)
            if m.path_collision_free is False:
                keep = np.concatenate([[True],
                                       np.linalg.norm(np.diff(xy, axis=0), axis=1) > 1e-6])
                report = check_collision(xy[keep], result.footprint, result.grid,
                                         headings=ep.odom[keep, 3])
                hit = report.dense_poses[report.colliding]
                ax.plot(hit[:, 0], hit[:, 1], ".", color="red", ms=3)
        ax.plot(*ep.goal, marker="*", color="gold", mec=color, mew=1.5, ms=16)
        if scenarios is not None and m.index < len(scenarios):
            _draw_obstacles(ax, scenarios[m.index] or [], color)
    if scenarios is not None and any(scenarios):
        ax.fill([], [], color="0.5", alpha=0.55, label="obstacle not on the map")
        ax.plot([], [], "--", color="0.4", label="moving obstacle's run")
    ax.plot([], [], ".", color="red", label="collision (exact check)")
    ax.plot([], [], "*", color="gold", mec="k", ms=12, ls="none", label="goal")
    if len(result.metrics) > 6:  # many episodes: the legend beside the map, not over it
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7, framealpha=0.8)
    else:
        ax.legend(loc="best", fontsize=7, framealpha=0.8)
    s = result.summary
    ax.set_title(title or f"{len(result.metrics)} episodes: reward {s.episode_reward:.1f}, "
                          f"collision rate {s.collision_rate:.3f}%", fontsize=9)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _draw_obstacles(ax, obstacles, color) -> None:
    """Static obstacles filled, moving ones as the polyline they shuttle along."""
    for o in obstacles:
        poly = o.footprint(0.0)  # (K, 2) [m]
        if o.moving:
            run = np.asarray(o.path)
            ax.plot(run[:, 0], run[:, 1], "--", color=color, lw=1.2, alpha=0.9)
            ax.fill(poly[:, 0], poly[:, 1], fill=False, ec=color, lw=1.0)
        else:
            ax.fill(poly[:, 0], poly[:, 1], color=color, alpha=0.55, ec="k", lw=0.5)


def driven_habit(result: BagEvaluation, zones=None):
    """The keep-right measure of issue 41 over the driven paths of every episode
    (``operator.habit_metrics``: the share of the corridor length, corridors wider than twice
    the robot and at most 4 m, driven on the right half relative to the direction of travel)
    and, with ``zones`` ([scenario.Zone]), the episodes whose driven path entered one."""
    from ecahd_core.operator import habit_metrics

    paths = [np.asarray(ep.odom, dtype=np.float64)[:, 1:3] for ep in result.episodes
             if len(ep.odom) >= 2]
    return habit_metrics(paths, result.grid, result.footprint, zones)


def habit_line(habit, zones: bool = False) -> str:
    """One markdown line for :func:`driven_habit`'s measure (``zones``: it counted zones)."""
    zone = (f" {habit.zone_entries} of {habit.paths} episodes entered a zone." if zones
            else "")
    if math.isnan(habit.right_share):
        return ("\nHabit: the robot drove through no corridor wider than twice its size."
                + zone + "\n")
    return (f"\nHabit: the robot drove on the right half of its corridors for "
            f"{100 * habit.right_share:.1f}% of {habit.corridor_length:.0f} m (corridors wider "
            f"than twice the robot, at most 4 m; relative to its direction of travel)."
            + zone + "\n")


def write_outputs(result: BagEvaluation, bag, *, json_path=None, md_path=None,
                  png_path=None, extra: dict | None = None, notes: str = "",
                  scenarios: list | None = None, zones: list | None = None) -> str:
    """Write the requested files; returns the markdown table. ``extra``: more top-level keys
    of the JSON; ``notes``: markdown appended to the table (in the return value too);
    ``scenarios``: per episode, the obstacles not on the map, for the figure."""
    from ecahd_core.evaluation import markdown_table

    habit = driven_habit(result, zones)
    table = (markdown_table(result.summary, result.metrics) + result.sources.markdown()
             + habit_line(habit, bool(zones)) + notes)
    if json_path:
        write_json(json_path, {**result.to_dict(str(bag)), "habit": {
            "corridor_m": round(habit.corridor_length, 2),
            "right_share": None if math.isnan(habit.right_share)
            else round(habit.right_share, 4),
            **({"zone_entries": habit.zone_entries} if zones else {})}, **(extra or {})})
    if md_path:
        rate = ("% of sim steps in contact" if result.sources.contacts_from == "simulator" else
                "% of poses whose footprint overlaps the map, by the exact checker")
        Path(md_path).parent.mkdir(parents=True, exist_ok=True)
        Path(md_path).write_text(f"# Closed-loop evaluation of `{bag}`\n\n"
                                 "Table III metrics (maze2d-large conventions: reward 1 per "
                                 "control step within 0.5 m of the goal, at most 800 steps; "
                                 f"collision rate: {rate}).\n\n" + table)
    if png_path:
        draw_trajectories(result, png_path, scenarios=scenarios)
    return table


def draw_snapshot(bag, at: float, path, *, map_name: str = "recorded") -> Path:
    """What the robot knew ``at`` seconds (sim time) after the bag's first goal: the map, the
    latest local costmap window (its marks red, cells seen free light green), the latest scan's
    returns (blue dots), the global plan (purple) and local plan (orange) in force, the path
    driven so far (black) and contacts (red crosses). Needs the topics bag_recorder records by
    default; raises BagError without map, goal_pose or odom."""
    import math

    from ecahd_core.bag_io import quaternion_yaw, read_bag
    from ecahd_core.errors import BagError
    from ecahd_core.maps import grid_from_occupancy_message
    from ecahd_core.viz import draw_map, pyplot

    data = read_bag(bag, topics=["/map", "/goal_pose", "/odom", "/scan", "/local_costmap",
                                 "/plan", "/local_plan", "/collision_detail"])
    for topic in ("/map", "/goal_pose", "/odom"):
        if not data.get(topic):
            raise BagError(f"bag {str(bag)!r} has no {topic} messages; cannot draw")
    t0 = data["/goal_pose"][0][0]
    cut = t0 + int(at * 1e9)

    def latest(topic):
        msgs = [m for t, m in data.get(topic, []) if t <= cut]
        return msgs[-1] if msgs else None

    grid = grid_from_occupancy_message(data["/map"][-1][1], name=map_name)
    plt = pyplot()
    xmin, ymin, xmax, ymax = grid.bounds
    fig, ax = plt.subplots(figsize=(8, 8 * (ymax - ymin) / (xmax - xmin) + 0.6))
    draw_map(ax, grid)
    window = latest("/local_costmap")
    if window is not None:
        w = grid_from_occupancy_message(window, name="local_costmap", unknown_is_occupied=False)
        wx0, wy0, wx1, wy1 = w.bounds
        rgba = np.zeros(w.data.shape + (4,))
        rgba[w.data == 0] = (0.2, 0.8, 0.2, 0.18)
        rgba[w.data >= 65] = (0.9, 0.1, 0.1, 0.9)
        ax.imshow(rgba, origin="lower", extent=(wx0, wx1, wy0, wy1), interpolation="nearest")
        ax.plot([wx0, wx1, wx1, wx0, wx0], [wy0, wy0, wy1, wy1, wy0], color="green", lw=0.8,
                label="local costmap window (red: marked)")
    odom = [(t, m.pose.pose) for t, m in data["/odom"] if t <= cut]
    xy = np.array([[p.position.x, p.position.y] for _, p in odom])
    ax.plot(xy[:, 0], xy[:, 1], color="black", lw=1.2, label="driven")
    pose = odom[-1][1]
    yaw = quaternion_yaw(pose.orientation)
    scan = latest("/scan")
    if scan is not None:
        r = np.asarray(scan.ranges, dtype=float)
        a = yaw + scan.angle_min + scan.angle_increment * np.arange(len(r))
        ok = np.isfinite(r)
        ax.plot(pose.position.x + r[ok] * np.cos(a[ok]), pose.position.y + r[ok] * np.sin(a[ok]),
                ".", color="tab:blue", ms=2, label="scan returns")
    for topic, color, label in (("/plan", "tab:purple", "global plan"),
                                ("/local_plan", "tab:orange", "local plan")):
        msg = latest(topic)
        if msg is not None and msg.poses:
            pts = np.array([[p.pose.position.x, p.pose.position.y] for p in msg.poses])
            ax.plot(pts[:, 0], pts[:, 1], "o-", color=color, ms=3, lw=1.2, label=label)
    goal = latest("/goal_pose")
    if goal is not None:
        ax.plot(goal.pose.position.x, goal.pose.position.y, "*", color="gold", ms=16,
                markeredgecolor="black", label="goal")
    contacts = [m for t, m in data.get("/collision_detail", []) if t <= cut]
    if contacts:
        import json

        pts = np.array([[json.loads(m.data)["x"], json.loads(m.data)["y"]] for m in contacts])
        ax.plot(pts[:, 0], pts[:, 1], "x", color="red", ms=5, label="contact")
    ax.plot(pose.position.x, pose.position.y, "o", color="black", ms=6)
    ax.arrow(pose.position.x, pose.position.y, 0.3 * math.cos(yaw), 0.3 * math.sin(yaw),
             width=0.02, color="black")
    ax.legend(loc="best", fontsize=7, framealpha=0.8)
    ax.set_title(f"t = {at:g} s (sim) after the first goal of {bag}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def _read_scenarios(folder, episodes: int) -> list | None:
    """Per episode, the obstacles of FOLDER/episode_<i>.yaml (None where there is no file);
    None without a folder. A bad file raises ScenarioError naming it."""
    if folder is None:
        return None
    from ecahd_core.errors import EcahdError
    from ecahd_core.scenario import load_scenario

    folder = Path(folder)
    if not folder.is_dir():
        raise EcahdError(f"--scenarios {folder}: not a folder")
    files = [folder / f"episode_{i}.yaml" for i in range(episodes)]
    return [load_scenario(f) if f.is_file() else None for f in files]


def _read_zones(path) -> list | None:
    if not path:
        return None
    from ecahd_core.scenario import read_zones

    return read_zones(path)


def run(args: argparse.Namespace) -> int:
    if args.snapshot is not None:
        if not args.png:
            from ecahd_core.errors import EcahdError

            raise EcahdError("--snapshot needs --png")
        log.info("wrote %s", draw_snapshot(args.bag, args.snapshot, args.png,
                                           map_name=args.map_name))
        return 0
    result = evaluate_bag(args.bag, robot=args.robot, map_name=args.map_name,
                          goal_radius=args.goal_radius, max_steps=args.max_steps,
                          control_period=args.control_period,
                          nominal_interval_ms=args.nominal_interval_ms,
                          namespace=args.namespace, base_frame=args.base_frame)
    table = write_outputs(result, args.bag, json_path=args.json, md_path=args.md,
                          png_path=args.png, scenarios=_read_scenarios(args.scenarios,
                                                                        len(result.metrics)),
                          zones=_read_zones(args.zones))
    print(table)
    for what, p in (("json", args.json), ("markdown", args.md), ("figure", args.png)):
        if p:
            log.info("wrote %s %s", what, p)
    return 0
