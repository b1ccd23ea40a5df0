"""What happened around a contact in an `ecahd bench navigation` / `ecahd demo` run: a timeline
of one episode from its bag (robot pose, cmd_vel, the collision monitor's action and the
controller's reason, distance to each moving obstacle, contact steps), and with ``--tracker``
the bag's scans replayed through LocalWorld + MotionTracker next to each moving obstacle's
true velocity (from the episode's scenario file). A diagnostic for issue 11, not a benchmark.

    python scripts/replay_episode.py RUN/ecahd EPISODE [--from T0] [--to T1] [--tracker]

RUN/ecahd holds ``bag/`` and ``scenarios/episode_<i>.yaml``. Times are the bag's sim time [s];
a moving obstacle's clock starts at its episode's goal (the simulator loads the scenario then,
so positions may lag by the load time).
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from ecahd_core.bag_io import read_bag
from ecahd_core.scenario import load_scenario


def _nearest(rows, t: float):
    i = int(np.searchsorted([r[0] for r in rows], t))
    return rows[min(i, len(rows) - 1)]


def _yaw(q) -> float:
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


def timeline(run: Path, episode: int, lo: float | None, hi: float | None) -> None:
    bag = read_bag(run / "bag", ["/collision_detail", "/odom", "/ecahd/timing", "/cmd_vel",
                                 "/goal_pose"])
    goals = [t * 1e-9 for t, _ in bag["/goal_pose"]]
    t0 = goals[episode]
    t1 = goals[episode + 1] if episode + 1 < len(goals) else math.inf
    movers = [o for o in load_scenario(run / "scenarios" / f"episode_{episode}.yaml")
              if o.moving]
    odom = [(t * 1e-9, m.pose.pose.position.x, m.pose.pose.position.y) for t, m in bag["/odom"]]
    cmd = [(t * 1e-9, m.linear.x, m.angular.z) for t, m in bag["/cmd_vel"]]
    ctl = [(t * 1e-9, r.get("monitor"), r.get("reason")) for t, r in
           ((t, json.loads(m.data)) for t, m in bag["/ecahd/timing"])
           if r.get("stage") == "control"]
    records = [r for r in (json.loads(m.data) for _, m in bag["/collision_detail"])
               if t0 <= r["t"] < t1]
    contacts = sorted(r["t"] for r in records)
    kinds = {k: sum(r["kind"] == k for r in records) for k in {r["kind"] for r in records}}
    if not contacts and lo is None:
        print("no contact in this episode; give --from / --to")
        return
    lo = contacts[0] - 6.0 if lo is None else lo
    hi = contacts[-1] + 1.0 if hi is None else hi
    print(f"contact steps {len(contacts)} {kinds}"
          + (f", {contacts[0]:.2f}-{contacts[-1]:.2f} s" if contacts else ""))
    for t in np.arange(lo, hi, 0.2):
        _, x, y = _nearest(odom, t)
        _, v, w = _nearest(cmd, t)
        _, action, reason = _nearest(ctl, t)
        d = " ".join(f"{math.hypot(*(np.array(o.position(t - t0)) - (x, y))):.2f}"
                     for o in movers)
        hit = any(abs(c - t) < 0.1 for c in contacts)
        print(f"{t:7.2f} robot ({x:.2f}, {y:.2f}) cmd ({v:+.2f}, {w:+.2f}) {action:8s} "
              f"{reason:10s} moving obstacles at {d} m{'  CONTACT' if hit else ''}")


def tracker(run: Path, episode: int, lo: float, hi: float, map_name: str) -> None:
    from ecahd_core.cost import CollisionCost
    from ecahd_core.footprint import make_footprint
    from ecahd_core.maps import load_map
    from ecahd_core.sensing import SHUTTLE_MEMORY, LocalWorld, Scan

    bag = read_bag(run / "bag", ["/scan", "/odom", "/goal_pose"])
    t0 = [t * 1e-9 for t, _ in bag["/goal_pose"]][episode]
    movers = [o for o in load_scenario(run / "scenarios" / f"episode_{episode}.yaml")
              if o.moving]
    grid = load_map(map_name)
    world = LocalWorld(grid, CollisionCost.build(grid, make_footprint("circle")), shuttles=True)
    odom = [(m.header.stamp.sec + m.header.stamp.nanosec * 1e-9, m) for _, m in bag["/odom"]]
    for _, m in bag["/scan"]:
        stamp = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
        if not lo - 2 * SHUTTLE_MEMORY <= stamp <= hi:  # the shuttle memory filled, as live
            continue
        p = _nearest(odom, stamp)[1].pose.pose
        pose = (p.position.x, p.position.y, _yaw(p.orientation))
        world.add_scan(pose, Scan(ranges=np.array(m.ranges), angle_min=m.angle_min,
                                  angle_increment=m.angle_increment, range_min=m.range_min,
                                  range_max=m.range_max, stamp=stamp))
        if stamp < lo:
            continue
        seen, out = world.seen, []
        for o in movers:
            c = np.array(o.position(stamp - t0))
            near = np.hypot(*(seen.points - c).T) < o.radius + 0.1
            true = (np.array(o.position(stamp - t0 + 0.05))
                    - np.array(o.position(stamp - t0 - 0.05))) / 0.1
            est = seen.velocities[near].mean(axis=0) if near.any() else None
            turn = ""
            if near.any() and seen.bounds is not None:
                ahead = seen.bounds[near, 1]
                ahead = ahead[np.isfinite(ahead)]
                speed = float(np.hypot(*true))
                if len(ahead) and speed > 0:  # true: the centre's way to the end it heads for
                    end = max(o.path, key=lambda q: np.dot(np.asarray(q) - c, true))
                    left = float(np.dot(np.asarray(end) - c, true / speed))
                    turn = f", turns in {np.median(ahead):.2f} m predicted / {left:.2f} m true"
                elif not len(ahead):
                    turn = ", no turn known ahead"
            out.append(f"true ({true[0]:+.2f}, {true[1]:+.2f}) estimated "
                       + ("-" if est is None else f"({est[0]:+.2f}, {est[1]:+.2f})")
                       + f" from {int(near.sum())} returns{turn}")
        print(f"{stamp:7.2f} robot ({pose[0]:.2f}, {pose[1]:.2f}) | " + " | ".join(out))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path, help="a variant's folder: bag/ and scenarios/")
    ap.add_argument("episode", type=int)
    ap.add_argument("--from", dest="lo", type=float, default=None, help="[s] sim time")
    ap.add_argument("--to", dest="hi", type=float, default=None, help="[s] sim time")
    ap.add_argument("--tracker", action="store_true",
                    help="replay the scans through the tracker between --from and --to")
    ap.add_argument("--map", default="maze2d-large", help="the run's map")
    args = ap.parse_args()
    if args.tracker:
        if args.lo is None or args.hi is None:
            ap.error("--tracker needs --from and --to")
        tracker(args.run, args.episode, args.lo, args.hi, args.map)
    else:
        timeline(args.run, args.episode, args.lo, args.hi)


if __name__ == "__main__":
    main()
