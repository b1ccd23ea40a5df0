"""The online Algorithm 1 runtimes (ecahd_core.planning.online and .local) driven by fake clocks and poses: no
ROS, no models (a fake refine function), so each rule is pinned on its own."""
import math
import threading
import time
from concurrent.futures import Future

import numpy as np
import pytest

from ecahd_core.controller import PathTracker
from ecahd_core.errors import EcahdError, PlanningError
from ecahd_core.planning.horizon import replan_horizon
from ecahd_core.planning.local import LocalRunner, LocalRunnerConfig, SegmentResult
from ecahd_core.planning.online import GlobalRunner, GlobalRunnerConfig, PlanRequest
from ecahd_core.validation import MAX_PLAN_POINTS, simplify, validate_plan

PLAN = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [2.0, 1.0]])


# ------------------------------------------------------------------------------ GlobalRunner
def test_goal_then_waypoints_shrink_the_horizon():
    r = GlobalRunner(GlobalRunnerConfig(horizon=4, waypoint_tolerance=0.3))
    r.set_goal((2.0, 1.0))
    req = r.step((0.0, 0.0), 0.0)
    assert isinstance(req, PlanRequest) and req.horizon == 4 and req.reason == "goal"
    r.accept(PLAN, 0.0)
    assert r.step((0.5, 0.0), 0.1) is None  # between waypoints
    req = r.step((0.9, 0.05), 0.2)  # within 0.3 m of waypoint 1: P^g - 1
    assert req.horizon == 3 and req.reason == "waypoint" and r.iteration == 1
    r.accept(PLAN[1:], 0.2)
    assert r.step((1.95, 1.0), 0.3) == "reached" and r.goal is None
    assert r.step((1.95, 1.0), 0.4) is None


def test_replan_horizon_shrinks_with_the_distance_left_when_spaced():
    S, G = (0.0, 0.0), (34.0, 0.0)
    assert [replan_horizon(10, p, S, G) for p in (0, 7, 8, 12)] == [10, 3, 2, 2]  # Alg. 1
    # 3 m spacing: 34 m left needs 13 waypoints, capped at P^g, whatever p is
    assert replan_horizon(10, 8, S, G, 3.0) == 10
    assert replan_horizon(10, 8, S, (8.2, 0.0), 3.0) == 4  # ceil(2.73) + 1
    assert replan_horizon(10, 8, S, (3.0, 0.0), 3.0) == 2  # within one spacing: straight
    assert replan_horizon(10, 2, S, (3.0, 0.0), 3.0) == 8  # never below P^g - p


def test_replan_spacing_by_the_map_and_the_model():
    from types import SimpleNamespace

    from ecahd_core.planning.horizon import REPLAN_SPACING, auto_replan_spacing, replan_spacing_for

    big, small = SimpleNamespace(width=1000, height=1667), SimpleNamespace(width=120, height=90)
    assert auto_replan_spacing(small, 6.5) is None  # maze2d-large: Algorithm 1's rule
    assert auto_replan_spacing(big) == REPLAN_SPACING  # a model without a recorded spacing
    assert auto_replan_spacing(big, 2.6) == REPLAN_SPACING  # never below 3 m
    assert auto_replan_spacing(big, 6.5) == 6.5  # the office's expert spacing
    assert replan_spacing_for(big, None, 6.5) == 6.5
    assert replan_spacing_for(big, 0.0, 6.5) is None and replan_spacing_for(big, 4.0, 6.5) == 4.0
    with pytest.raises(EcahdError, match="replan spacing"):
        replan_spacing_for(big, -1.0, 6.5)


def test_a_spaced_runner_asks_for_the_horizon_the_distance_needs():
    r = GlobalRunner(GlobalRunnerConfig(horizon=4, waypoint_tolerance=0.3, replan_spacing=0.5))
    r.set_goal((2.0, 1.0))
    assert r.step((0.0, 0.0), 0.0).horizon == 4
    r.accept(PLAN, 0.0)
    req = r.step((0.9, 0.05), 0.2)  # waypoint 1 reached, 1.5 m left: 4, not P^g - 1 = 3
    assert req.reason == "waypoint" and r.iteration == 1 and req.horizon == 4
    with pytest.raises(EcahdError, match="replan_spacing"):
        GlobalRunnerConfig(replan_spacing=0.0)


def test_a_waypoint_at_the_start_does_not_count_as_reached():
    """Leg repair can put a waypoint within waypoint_tolerance of the robot in every plan; it
    must not ask for the next plan from the same pose (a storm of plans at the planning rate,
    seen on the office)."""
    r = GlobalRunner(GlobalRunnerConfig(horizon=2, waypoint_tolerance=0.3))
    r.set_goal((3.0, 0.0))
    assert r.step((0.0, 0.0), 0.0).reason == "goal"
    plan = np.array([[0.0, 0.0], [0.1, 0.1], [0.2, -0.1], [1.5, 0.0], [3.0, 0.0]])
    r.accept(plan, 0.0)
    for t in (0.05, 0.1, 0.15):  # standing at the start, beside two such waypoints
        assert r.step((0.05, 0.0), t) is None
    assert r.step((1.4, 0.0), 1.0).reason == "waypoint"  # the first beyond them
    r.accept(np.array([[1.4, 0.0], [1.5, 0.2], [3.0, 0.0]]), 1.0)  # only such a waypoint
    assert r.step((1.4, 0.0), 1.05) is None
    assert r.step((2.9, 0.0), 1.5) == "reached"


def test_replan_once_and_timeout():
    once = GlobalRunner(GlobalRunnerConfig(replan="once", replan_timeout=0.0))
    once.set_goal((2.0, 1.0))
    once.accept(PLAN, 0.0) if isinstance(once.step((0, 0), 0.0), PlanRequest) else None
    assert once.step((0.95, 0.0), 0.1) is None  # waypoint reached: no replan with "once"
    timed = GlobalRunner(GlobalRunnerConfig(replan_timeout=2.0))
    timed.set_goal((2.0, 1.0))
    timed.step((0.0, 0.0), 0.0)
    timed.accept(PLAN, 0.0)
    assert timed.step((0.2, 0.0), 1.9) is None
    req = timed.step((0.2, 0.0), 2.1)  # stuck for > 2 s: replan from here, same horizon
    assert req.reason == "timeout" and req.horizon == 10
    assert timed.step((0.2, 0.0), 2.2) is None  # once per period


def test_timeout_replans_back_off_until_a_waypoint_is_reached():
    # a local stage slower than the timeout (a busy CPU) must not be restarted for ever: each
    # timeout replan with no waypoint reached in between doubles the timeout (2, 4, 8, 16, 16 s)
    r = GlobalRunner(GlobalRunnerConfig(replan_timeout=2.0))
    r.set_goal((2.0, 1.0))
    r.accept(PLAN, 0.0) if isinstance(r.step((0.0, 0.0), 0.0), PlanRequest) else None
    fired, t = [], 0.0
    while t < 50.0:
        t = round(t + 0.1, 1)
        req = r.step((0.2, 0.0), t)
        if isinstance(req, PlanRequest):
            assert req.reason == "timeout"
            fired.append(t)
            r.accept(PLAN, t)
    assert fired == [2.1, 6.2, 14.3, 30.4, 46.5]
    assert (r.stalls, r.stall_timeout) == (5, 16.0)
    req = r.step((0.95, 0.0), 47.0)  # a waypoint reached: back to 2 s
    assert req.reason == "waypoint" and r.stalls == 0
    r.accept(PLAN[1:], 47.0)
    assert r.step((1.0, 0.1), 49.0) is None  # 0.1 m on from the plan's start: no progress
    assert r.step((1.0, 0.1), 49.1).reason == "timeout"


def test_a_settled_plan_is_followed_whole_and_still_replans_on_a_timeout_or_a_blockage():
    # the settle rule: no re-plan at a settled plan's waypoints, but each one reached counts as
    # progress (iteration and timeout); the next plan that is not settled re-plans again
    r = GlobalRunner(GlobalRunnerConfig(horizon=4, replan_timeout=2.0))
    r.set_goal((2.0, 1.0))
    r.step((0.0, 0.0), 0.0)
    r.accept(PLAN, 0.0, follow=len(PLAN) - 1)
    assert r.step((0.95, 0.0), 1.5) is None and r.iteration == 1  # waypoint 1: no re-plan
    assert r.step((1.0, 0.5), 3.0) is None  # 1.5 s after waypoint 1: no timeout yet
    assert r.step((1.0, 0.95), 3.2) is None and r.iteration == 2  # waypoint 2
    req = r.step((1.05, 1.0), 5.3)  # stuck 2.1 s after waypoint 2: a timeout re-plan
    assert req.reason == "timeout" and req.iteration == 2
    rest = np.array([[1.05, 1.0], [1.5, 1.0], [2.0, 1.0]])
    r.accept(rest, 5.3)  # not settled
    r.request_replan("blocked")
    assert r.step((1.05, 1.0), 5.4).reason == "blocked"
    r.accept(rest, 5.4)
    req = r.step((1.45, 1.0), 5.5)
    assert req.reason == "waypoint" and req.iteration == 3
    r.set_goal((0.0, 0.0))  # a new goal starts unsettled
    r.step((2.0, 1.0), 6.0)
    r.accept(PLAN[::-1].copy(), 6.0)
    assert r.step((1.0, 1.0), 6.5).reason == "waypoint"
    rest = np.array([[1.0, 1.0], [1.0, 0.5], [1.0, 0.0], [0.5, 0.0], [0.0, 0.0]])
    r.accept(rest, 6.5, follow=2)  # followed to its waypoint 2 (a subgoal), then re-planned
    assert r.step((1.0, 0.55), 7.0) is None and r.iteration == 2
    req = r.step((1.0, 0.05), 7.5)
    assert req is not None and req.reason == "waypoint" and req.iteration == 3


def test_progress_toward_the_next_waypoint_holds_off_the_timeout():
    # a long leg driven at walking pace reaches no waypoint for longer than the timeout, but
    # every PROGRESS_STEP nearer the next waypoint restarts its clock; standing still does not
    from ecahd_core.planning.online import PROGRESS_STEP

    r = GlobalRunner(GlobalRunnerConfig(replan_timeout=2.0))
    r.set_goal((12.0, 0.0))
    r.step((0.0, 0.0), 0.0)
    r.accept(np.array([[0.0, 0.0], [10.0, 0.0], [12.0, 0.0]]), 0.0)
    t = 0.0
    for x in np.arange(0.0, 9.0, 1.2 * PROGRESS_STEP):  # 30 s at 0.3 m/s without a waypoint
        t += 1.0
        assert r.step((x, 0.0), t) is None
    last, req = t, None
    while req is None and t < last + 20:  # stopped short of it: a timeout re-plan 2 s on
        t = round(t + 0.1, 1)
        req = r.step((x, 0.0), t)
    assert last == 30 and req.reason == "timeout" and t == pytest.approx(last + 2.1)
    assert r.step((x - 0.1, 0.0), t + 2.0) is None and r.step((x, 0.0), t + 4.2).reason == \
        "timeout"  # backing and forth is no progress (the nearest distance stays the mark)


def test_a_burst_of_goals_is_coalesced():
    r = GlobalRunner(GlobalRunnerConfig(min_plan_interval=0.05))
    requests = 0
    for i in range(40):  # 40 goals in 0.4 s
        r.set_goal((1.0 + 0.01 * i, 1.0))
        if isinstance(r.step((0.0, 0.0), 0.01 * i), PlanRequest):
            requests += 1
    assert requests == 8  # one per 0.05 s
    assert r.pending and r.goal == pytest.approx((1.39, 1.0))  # the latest goal waits for its plan


@pytest.mark.parametrize("bad", [(math.nan, 0.0), (0.0, math.inf)])
def test_non_finite_positions_raise(bad):
    r = GlobalRunner(GlobalRunnerConfig())
    with pytest.raises(PlanningError):
        r.set_goal(bad)
    r.set_goal((1.0, 1.0))
    with pytest.raises(PlanningError, match="not finite"):
        r.step(bad, 0.0)


def test_bad_config_is_named():
    with pytest.raises(EcahdError, match="replan"):
        GlobalRunnerConfig(replan="sometimes")


# ------------------------------------------------------------------------- plan checking
def test_validate_plan_rejects_absurd_and_off_map_plans():
    bounds = (0.0, 0.0, 10.0, 5.0)
    with pytest.raises(PlanningError, match="pose 1 is not finite"):
        validate_plan([[0, 0], [math.nan, 1]], bounds)
    with pytest.raises(PlanningError, match="pose 1 .* off the map"):
        validate_plan([[1, 1], [1e30, 1]], bounds)
    with pytest.raises(PlanningError, match="off the map"):
        validate_plan([[1, 1], [1e39, 1]])  # no map: the absolute limit
    with pytest.raises(PlanningError, match="more than"):
        validate_plan(np.zeros((MAX_PLAN_POINTS + 1, 2)), bounds)
    np.testing.assert_array_equal(validate_plan([[1, 1], [10.5, 5.5]], bounds),
                                  [[1, 1], [10.5, 5.5]])  # within the 1 m margin


def test_simplify_keeps_the_shape_not_the_sampling():
    line = np.linspace([0.0, 0.0], [10.0, 0.0], 10_000)
    np.testing.assert_allclose(simplify(line), [[0, 0], [10, 0]])
    corner = np.concatenate([np.linspace([0, 0], [1, 0], 50), np.linspace([1, 0], [1, 1], 50)])
    np.testing.assert_allclose(simplify(corner), [[0, 0], [1, 0], [1, 1]])


def test_path_tracker_searches_a_bounded_window():
    tracker = PathTracker(np.array([[0.0, 0.0], [100.0, 0.0]]), window=2.0)
    target, remaining = tracker.lookahead(np.array([0.2, 0.0]), 0.25)
    np.testing.assert_allclose(target, [0.45, 0.0], atol=1e-9)
    assert remaining == pytest.approx(99.8)
    # the window is 2 m of arc (40 points), whatever the path's length
    assert tracker._window == 40


# ------------------------------------------------------------------------------ LocalRunner
def runner(refine=None, **over):
    config = LocalRunnerConfig(**{"control_period": 0.1, **over})
    return LocalRunner(config, refine, synchronous=True)


def test_follows_the_plan_within_the_limits_and_stops_at_the_goal():
    r = runner()
    r.set_pose((0.0, 0.0, 0.0), 0.0)
    r.set_plan(PLAN, 0.0)
    pose, t, reasons = np.array([0.0, 0.0, 0.0]), 0.0, []
    for _ in range(200):  # integrate the unicycle with the commands
        cmd = r.tick(t)
        reasons.append(cmd.reason)
        assert 0 <= cmd.v <= 0.5 + 1e-9 and abs(cmd.w) <= 1.5 + 1e-9
        pose += [cmd.v * math.cos(pose[2]) * 0.1, cmd.v * math.sin(pose[2]) * 0.1, cmd.w * 0.1]
        t += 0.1
        r.set_pose(pose, t)
        if cmd.reason == "goal_reached":
            break
    assert reasons[-1] == "goal_reached" and np.hypot(*(pose[:2] - PLAN[-1])) < 0.25
    assert ("goal_reached", None) in r.pop_events()


@pytest.mark.parametrize("reason,kwargs,t", [("no_odom", {}, 0.0),
                                             ("stale_odom", {"stale_timeout": 0.5}, 1.0),
                                             ("plan_timeout", {"plan_timeout": 0.5}, 0.9)])
def test_zero_velocity_without_fresh_inputs(reason, kwargs, t):
    r = runner(**kwargs)
    if reason != "no_odom":
        r.set_pose((0.0, 0.0, 0.0), 0.0)
        r.set_plan(PLAN, 0.0)
        if reason == "plan_timeout":
            r.set_pose((0.0, 0.0, 0.0), t)  # fresh odometry, old plan
    cmd = r.tick(t)
    assert (cmd.v, cmd.w, cmd.reason) == (0.0, 0.0, reason)


def test_a_blocked_segment_is_never_followed():
    def refine(a, b):
        return SegmentResult(plan=np.stack([a, b]), safe=False, c_before=5.0, c_after=5.0,
                             stage="dd")

    r = runner(refine)
    r.set_pose((0.0, 0.0, 0.0), 0.0)
    r.set_plan(PLAN, 0.0)
    for t in (0.0, 0.1, 0.2):
        cmd = r.tick(t)
        assert (cmd.v, cmd.w, cmd.reason) == (0.0, 0.0, "blocked")
    assert [k for k, _ in r.pop_events()] == ["blocked"]  # reported once


def test_recheck_in_two_steps_drops_plans_a_scan_blocked_and_skips_replaced_ones():
    """recheck = recheck_items (under a node's lock), judging (without it), apply_recheck:
    the followed plan judged unsafe stops the robot and is refined again from its pose; a
    verdict on a plan replaced meanwhile changes nothing."""
    calls = []

    def refine(a, b):
        calls.append((tuple(a), tuple(b)))
        return SegmentResult(plan=np.linspace(a, b, 4), c_before=0.0, c_after=0.0,
                             stage="j_check")

    r = runner(refine)
    r.set_pose((0.0, 0.0, 0.0), 0.0)
    r.set_plan(PLAN, 0.0)
    assert r.tick(0.0).v > 0  # following segment 0, the next ones prepared
    items = r.recheck_items()
    kinds = [kind for kind, *_ in items]
    assert kinds[0] == "followed" and "prepared" in kinds
    assert all(plan is not None and plan.shape[1] == 2 for *_, plan in items)
    # all still safe: nothing changes
    assert r.apply_recheck([(item, True) for item in items]) == 0
    n = len(calls)
    # the followed plan is blocked now: dropped, refined again from the robot's pose
    assert r.apply_recheck([(items[0], False)]) == 1
    assert len(calls) == n + 1 and calls[-1][0] == (0.0, 0.0)
    # the same stale verdict again (that tracker is gone): skipped
    assert r.apply_recheck([(items[0], False)]) == 0 and len(calls) == n + 1
    # the one-step form agrees
    assert r.recheck(lambda plan: True) == 0


def test_control_never_waits_for_the_local_stage():
    """The refine job runs on the worker; ticks meanwhile give zero (nothing safe yet), then
    the refined plan is followed."""
    release = threading.Event()

    def slow_refine(a, b):
        release.wait(5.0)
        return SegmentResult(plan=np.linspace(a, b, 4), c_before=0.0, c_after=0.0,
                             stage="j_check")

    r = LocalRunner(LocalRunnerConfig(control_period=0.1), slow_refine)
    try:
        r.set_pose((0.0, 0.0, 0.0), 0.0)
        r.set_plan(PLAN, 0.0)
        assert r.tick(0.0).reason == "waiting"  # returns at once although refine blocks
        release.set()
        for _ in range(500):
            cmd = r.tick(0.1)
            if cmd.reason == "follow":
                break
            time.sleep(0.01)
        assert cmd.reason == "follow" and cmd.v > 0
    finally:
        release.set()
        r.close()


def test_segments_are_prepared_ahead_and_a_new_plan_cancels_them():
    calls = []

    def refine(a, b):
        calls.append((tuple(a), tuple(b)))
        return SegmentResult(plan=np.linspace(a, b, 4))

    r = runner(refine, prepare_ahead=1)
    r.set_pose((0.0, 0.0, 0.0), 0.0)
    r.set_plan(PLAN, 0.0)
    assert calls == [((0.0, 0.0), (1.0, 0.0)), ((1.0, 0.0), (1.0, 1.0))]
    r.tick(0.0)  # takes over segment 1, prepares segment 3 (1 ahead of the next, 2)
    assert calls[-1] == ((1.0, 1.0), (2.0, 1.0))

    pending = []
    deferred = LocalRunner(LocalRunnerConfig(), refine,
                           submit=lambda fn: pending.append(Future()) or pending[-1])
    deferred.set_pose((0.0, 0.0, 0.0), 0.0)
    deferred.set_plan(PLAN, 0.0)
    deferred.set_plan(PLAN[::-1], 0.1)  # supersedes: the first plan's jobs are cancelled
    assert all(f.cancelled() for f in pending[:3])


def test_a_failing_local_stage_is_reported_and_blocks():
    def broken(a, b):
        raise RuntimeError("boom")

    r = runner(broken)
    r.set_pose((0.0, 0.0, 0.0), 0.0)
    r.set_plan(PLAN, 0.0)
    assert r.tick(0.0).reason == "blocked"
    events = r.pop_events()
    assert events[0][0] == "error" and "boom" in events[0][1]


def test_nan_odometry_and_absurd_plans_leave_the_state_alone():
    r = runner()
    r.set_pose((0.0, 0.0, 0.0), 0.0)
    r.set_plan(PLAN, 0.0)
    with pytest.raises(PlanningError, match="not finite"):
        r.set_pose((math.nan, 0.0, 0.0), 0.1)
    with pytest.raises(PlanningError):
        r.set_plan([[0.0, 0.0], [1e30, 0.0]], 0.1, bounds=(0, 0, 10, 10))
    assert r.pose == (0.0, 0.0, 0.0)
    np.testing.assert_array_equal(r.waypoints, PLAN)


def test_tick_work_does_not_grow_with_plan_length():
    """A 10 000-pose wiggly plan: ticks search only their window (the tracker holds one
    segment), so the points a tick looks at are bounded."""
    xs = np.linspace(0, 50, 10_000)
    wiggly = np.stack([xs, 0.02 * np.sin(xs * 40)], axis=1)
    r = runner()
    r.set_pose((0.0, 0.0, 0.0), 0.0)
    r.set_plan(wiggly, 0.0)
    r.tick(0.0)
    assert len(r.tracker.points) < 50  # one segment of the simplified plan


# ------------------------------------------------------------------ blocked corridor -> detour
def two_corridor_map():
    """A 6 x 4 m room at 0.1 m/cell split by a wall block x in [1, 5], y in [1.5, 2.5]: a
    bottom corridor y in [0, 1.5] and a top corridor y in [2.5, 4], both 1.5 m wide."""
    from ecahd_core.maps import GridMap

    data = np.zeros((40, 60), dtype=np.int8)
    data[15:25, 10:50] = 100
    return GridMap(data, 0.1, (0.0, 0.0), name="two-corridors")


def test_the_detour_keeps_room_to_spare_round_corners_where_it_costs_little():
    """A* hugs the footprint's clearance round a corner; the detour keeps DETOUR_SPARE more
    where that path is at most SPARE_STRETCH times as long, and squeezes through a gap with
    no room to spare when that is the only way."""
    from ecahd_core.astar import clearance_for_footprint
    from ecahd_core.footprint import make_footprint
    from ecahd_core.maps import GridMap
    from ecahd_core.planning.detour import DETOUR_SPARE, detour

    robot = make_footprint("circle")
    clearance = clearance_for_footprint(robot)
    # a 10 x 6 m room at 0.05 m/cell with a 2 x 2 m pillar in the middle (x 4-6, y 2-4)
    data = np.zeros((120, 200), dtype=np.int8)
    data[:2], data[-2:], data[:, :2], data[:, -2:] = 100, 100, 100, 100
    data[40:80, 80:120] = 100
    room = GridMap(data, 0.05, (0.0, 0.0), name="pillar")
    start, goal = np.array([2.0, 3.0]), np.array([8.0, 3.0])

    def closest(path):  # the path's least distance to the pillar [m]
        dense = np.concatenate([np.linspace(a, b, 50) for a, b in zip(path[:-1], path[1:])])
        dx = np.maximum(np.maximum(4.0 - dense[:, 0], dense[:, 0] - 6.0), 0.0)
        dy = np.maximum(np.maximum(2.0 - dense[:, 1], dense[:, 1] - 4.0), 0.0)
        return float(np.hypot(dx, dy).min())

    tight = detour(room, robot, start, goal, spare=0.0)
    roomy = detour(room, robot, start, goal)
    assert closest(tight) < clearance + 0.5 * DETOUR_SPARE
    assert closest(roomy) >= clearance + DETOUR_SPARE - 0.01
    length = lambda p: np.linalg.norm(np.diff(p, axis=0), axis=1).sum()  # noqa: E731
    assert length(tight) < length(roomy) < 1.25 * length(tight)
    # a gap just wide enough for the robot: no room to spare, the tight path through it
    gate_data = np.zeros((40, 60), dtype=np.int8)
    gate_data[:, 28:32] = 100
    gap = int(np.ceil(2 * clearance / 0.1)) + 1  # cells
    gate_data[20:20 + gap, 28:32] = 0
    gate = GridMap(gate_data, 0.1, (0.0, 0.0), name="gate")
    through = detour(gate, robot, np.array([1.0, 2.5]), np.array([5.0, 2.5]))
    np.testing.assert_allclose(through, detour(gate, robot, np.array([1.0, 2.5]),
                                               np.array([5.0, 2.5]), spare=0.0))


def test_a_scanned_blockage_sends_the_detour_through_the_other_corridor():
    from ecahd_core.cost import CollisionCost
    from ecahd_core.footprint import make_footprint
    from ecahd_core.planning.detour import detour
    from ecahd_core.sensing import LocalWorld, ObstacleMemory, Scan

    grid, robot = two_corridor_map(), make_footprint("circle")
    start, goal = (0.5, 0.75), (5.5, 0.75)
    assert np.all(detour(grid, robot, start, goal)[:, 1] < 1.5)  # unblocked: the bottom way
    # a robot at (2, 0.75) facing +x scans a box wall to wall across the bottom corridor at
    # x = 3: beams within +-60 deg hit the plane x = 3 at range 1 / cos(angle)
    angles = np.linspace(-np.pi / 3, np.pi / 3, 121)
    world = LocalWorld(grid, CollisionCost.build(grid, robot))
    world.add_scan((2.0, 0.75, 0.0), Scan(ranges=1.0 / np.cos(angles), angle_min=-np.pi / 3,
                                          angle_increment=angles[1] - angles[0],
                                          range_min=0.1, range_max=8.0, stamp=0.0))
    fused, _ = world.fused(force=True)
    # the collision monitor's input: the unmapped returns (the box, not the corridor's walls)
    # with a velocity each (0: one scan, nothing known to move); the escape check reads the map
    seen = world.seen
    assert seen.stamp == 0.0 and seen.velocities.shape == seen.points.shape
    assert len(seen.points) > 80 and np.allclose(seen.points[:, 0], 3.0, atol=1e-6)
    assert not seen.velocities.any() and seen.bounds is None  # no shuttle search asked for
    depths = world.depths(np.array([[2.0, 0.75, 0.0], [2.0, 1.2, 0.0]]), robot)
    assert depths[0] <= 0 < depths[1]  # the second overlaps the wall block above (y >= 1.5)
    # column x in [3.0, 3.1] blocked from y = 0 up to the wall block; the row next to the block
    # (y in [1.4, 1.5]) counts as the block's own (marks within one cell of a known obstacle)
    assert fused.occupied[:14, 30].all() and not grid.occupied[:14, 30].any()
    # the planner's memory of that window routes round it through the top corridor
    memory = ObstacleMemory(grid, persistence=60.0)
    from ecahd_core.maps import GridMap

    layout = world.window.to_occupancy()
    window = GridMap(layout.data.reshape(layout.height, layout.width), layout.resolution,
                     layout.origin_xy, unknown_is_occupied=False)
    memory.update(window, now=0.0)
    path = detour(memory.fused(1.0), robot, start, goal)
    assert path[:, 1].max() > 2.5  # through the top corridor
    # seen free again: the blockage is forgotten and the short way comes back
    window.data.setflags(write=True)
    cleared = GridMap(np.where(window.data >= 65, 0, window.data).astype(np.int8),
                      window.resolution, window.origin, unknown_is_occupied=False)
    memory.update(cleared, now=2.0)
    assert np.all(detour(memory.fused(3.0), robot, start, goal)[:, 1] < 1.5)


@pytest.mark.parametrize("robot", ["circle", "quadruped"])
def test_static_clearance_agrees_with_the_exact_checker(robot):
    from ecahd_core.collision import DEFAULT_TOLERANCE, pose_depths
    from ecahd_core.footprint import make_footprint
    from ecahd_core.maps import load_map
    from ecahd_core.sensing import StaticClearance

    grid, fp = load_map("maze2d-large"), make_footprint(robot)
    rng = np.random.default_rng(0)
    poses = np.stack([rng.uniform(-0.5, 12.5, 3000), rng.uniform(-0.5, 9.5, 3000),
                      rng.uniform(-np.pi, np.pi, 3000)], axis=1)  # some off the map
    exact = pose_depths(poses, fp, grid) <= DEFAULT_TOLERANCE
    fast = StaticClearance(grid).depths(poses, fp) <= DEFAULT_TOLERANCE
    assert np.array_equal(fast, exact)
    assert 0.05 < exact.mean() < 0.95  # both answers occur


def test_detour_searches_near_first_and_falls_back_to_the_whole_map():
    from ecahd_core.collision import check_collision
    from ecahd_core.footprint import make_footprint
    from ecahd_core.maps import GridMap
    from ecahd_core.planning.detour import detour

    data = two_corridor_map().data.copy()
    data[:15, 30] = 100  # the bottom corridor closed wall to wall at x = 3
    grid = GridMap(data, 0.1, (0.0, 0.0), name="closed")
    robot = make_footprint("circle")
    start, goal = (0.5, 0.75), (5.5, 0.75)
    # the box round start and goal grown by 0.3 m holds no way: the whole map is searched
    near = detour(grid, robot, start, goal, margin=0.3)
    assert near[:, 1].max() > 2.5 and check_collision(near, robot, grid).collision_free
    np.testing.assert_allclose(near, detour(grid, robot, start, goal, margin=None))
    # a box that holds the way gives a path inside it
    open_grid = two_corridor_map()
    inside = detour(open_grid, robot, start, goal, margin=0.5)
    assert inside[:, 1].max() < 1.5 and check_collision(inside, robot, open_grid).collision_free


@pytest.mark.parametrize("mark_moving", [False, True])
def test_a_cylinder_crossing_the_corridor_is_not_a_wall_in_the_local_costmap(mark_moving):
    """A cylinder shuttling across the corridor ahead (turning round at each wall) and a box
    beside it: the box is marked; the cylinder only clears its rays (the collision monitor
    judges it by its velocity), also in the scans where it turns round, unless mark_moving."""
    from conftest import ray_cast

    from ecahd_core.cost import CollisionCost
    from ecahd_core.footprint import make_footprint
    from ecahd_core.sensing import LocalWorld, Scan

    grid, robot = two_corridor_map(), make_footprint("circle")
    world = LocalWorld(grid, CollisionCost.build(grid, robot), mark_moving=mark_moving,
                       shuttles=True)
    angles = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    box = (2.5, 1.0, 2.8, 1.3)  # below the wall block, leaving the corridor's lower part
    cyl_cells, box_marked, turns = [], [], []
    for k in range(40):  # 4 s at 10 Hz: the cylinder turns round at y = 0.25 and y = 0.95
        t = 0.1 * k
        s = (0.3 * t) % 1.4
        y = 0.25 + (s if s <= 0.7 else 1.4 - s)
        ranges = ray_cast((1.0, 0.75), angles, [(3.7, y, 0.2)], [box])
        world.add_scan((1.0, 0.75, 0.0), Scan(ranges=ranges, angle_min=-np.pi,
                                              angle_increment=angles[1] - angles[0],
                                              range_min=0.1, range_max=8.0, stamp=t))
        pts = world.window.points()  # (K, 2) marked cell centres
        cyl_cells.append(int(np.count_nonzero(np.hypot(pts[:, 0] - 3.7, pts[:, 1] - y) < 0.35)))
        box_marked.append(bool(np.any((np.abs(pts[:, 0] - 2.5) < 0.1)
                                      & (pts[:, 1] > 0.95) & (pts[:, 1] < 1.3))))
        seen = world.seen
        on_cyl = np.hypot(seen.points[:, 0] - 3.7, seen.points[:, 1] - y) < 0.25
        bounds = seen.bounds[on_cyl] if seen.bounds is not None else None
        # going down (-y): where its returns turn round, y - (bound ahead)
        turns.append(None if bounds is None or not np.isfinite(bounds).all() else
                     float(np.median(seen.points[on_cyl, 1] - bounds[:, 1])))
    assert all(box_marked)
    # going up (before 2.33 s) it was never seen going the other way: no turn is known; once
    # it comes back down, where it turns round is known: the stretch it went up (its returns
    # face the sensor, so it reaches about y = 0.25 - 0.2 at the bottom end)
    assert all(turn is None for turn in turns[:23])
    assert all(turn is not None and -0.05 < turn < 0.3 for turn in turns[26:]), turns
    # the tracker needs a scan 0.3 s old before anything is known to move: the first scans
    # mark the cylinder, and those marks last their 2 s persistence (rays behind a cylinder
    # do not reach them); after that nothing is marked, also while it turns round at 2.33 s
    # (where its velocity estimate is 0 for two scans)
    if mark_moving:
        assert min(cyl_cells) > 0
    else:
        assert cyl_cells[0] > 0 and max(cyl_cells[21:]) == 0, cyl_cells


def _shuttle_trail(length: float, speed: float, now: float, memory: float, dt: float = 0.1):
    """A mover going back and forth on y = 0 between x = 0 and x = length from x = 0 at t = 0:
    its trail (points, velocities, ages) of the last ``memory`` s before ``now`` and its
    point and velocity at ``now``."""
    def at(t):
        s = (speed * t) % (2 * length)
        going = s <= length
        return (s if going else 2 * length - s), (speed if going else -speed)

    times = np.arange(max(0.0, now - memory + dt), now - 1e-9, dt)
    xs, vs = zip(*(at(t) for t in times))
    trail = np.stack([np.array(xs), np.zeros(len(xs))], axis=1)
    vel = np.stack([np.array(vs), np.zeros(len(vs))], axis=1)
    x, v = at(now)
    return trail, vel, now - times, np.array([[x, 0.0]]), np.array([[v, 0.0]])


def test_shuttle_bounds_trust_the_end_ahead_only_when_it_is_known():
    from ecahd_core.sensing import shuttle_bounds

    # a 6 m stretch at 0.3 m/s (20 s a leg) with a 12 s memory, at t = 45 s: going +x at
    # x = 1.5 since its turn at x = 0 (t = 40); the trail still holds the way back from x = 2.1.
    # Where it turned last (1.5 m behind) is known; the end ahead (x = 6, 4.5 m on) is not in
    # the trail: no turn is predicted ahead (the trail's far end, 0.6 m on, is not one)
    trail, vel, ages, p, v = _shuttle_trail(6.0, 0.3, 45.0, 12.0)
    bounds = shuttle_bounds(p, v, trail, vel, ages, memory=12.0)
    assert bounds[0, 0] == pytest.approx(-1.5, abs=0.05) and bounds[0, 1] == np.inf
    # nor are returns going back behind p, 2 s ago (a second mover's, its velocity misjudged
    # where it crosses this one's line): a turn behind p says nothing of the end ahead
    other = np.array([[0.6, 0.05], [0.7, -0.05]])
    bounds = shuttle_bounds(p, v, np.concatenate([trail, other]),
                            np.concatenate([vel, [[-0.2, 0.0], [-0.2, 0.0]]]),
                            np.concatenate([ages, [2.0, 2.0]]), memory=12.0)
    assert bounds[0, 1] == np.inf
    # on a 1.5 m stretch (5 s a leg) the trail holds both turns: the stretch is known
    trail, vel, ages, p, v = _shuttle_trail(1.5, 0.3, 31.0, 12.0)  # x = 0.3, going +x
    bounds = shuttle_bounds(p, v, trail, vel, ages, memory=12.0)
    np.testing.assert_allclose(bounds[0], [-0.3, 1.2], atol=0.05)
    # a trail not cut off by the memory starts where the mover was first seen: trusted
    trail, vel, ages, p, v = _shuttle_trail(6.0, 0.3, 25.0, 30.0)  # x = 4.5, going -x
    np.testing.assert_allclose(shuttle_bounds(p, v, trail, vel, ages, memory=30.0)[0],
                               [-1.5, 4.5], atol=0.05)
    # never seen going the other way: nothing known
    trail, vel, ages, p, v = _shuttle_trail(6.0, 0.3, 10.0, 12.0)
    assert np.all(np.isinf(shuttle_bounds(p, v, trail, vel, ages, memory=12.0)))


@pytest.fixture(scope="module")
def small_office():
    from ecahd_core.mapgen import MapGenConfig, generate

    return generate(MapGenConfig("office", 16, 12, 0.05, 3))  # 76 800 cells: coarse A*


def test_detour_on_a_big_grid_is_coarse_and_near_the_exact_one(small_office):
    from ecahd_core.astar import COARSE_ABOVE_CELLS, path_length
    from ecahd_core.collision import check_collision
    from ecahd_core.footprint import make_footprint
    from ecahd_core.planning.detour import detour
    from ecahd_core.sensing import ObstacleMemory

    grid, robot = small_office.grid, make_footprint("circle")
    assert grid.height * grid.width > COARSE_ABOVE_CELLS
    anchors = small_office.anchors
    rng = np.random.default_rng(1)
    ratios = []
    for _ in range(6):
        i, j = rng.choice(len(anchors), 2, replace=False)
        exact = detour(grid, robot, anchors[i], anchors[j], coarse=False)
        # a box remembered on the exact way's middle: both go round it, or neither can
        memory = ObstacleMemory(grid)
        from ecahd_core.bench.replan import _remember_boxes

        _remember_boxes(memory, grid, exact[len(exact) // 2][None], 0.5, now=0.0)
        fused = memory.fused(0.0)
        assert memory.crosses(exact, robot, 0.0) == (
            not check_collision(exact, robot, memory.fused(0.0)).collision_free)
        try:
            ref = detour(fused, robot, anchors[i], anchors[j], coarse=False)
        except PlanningError:
            with pytest.raises(PlanningError):
                detour(fused, robot, anchors[i], anchors[j])
            continue
        path = detour(fused, robot, anchors[i], anchors[j])
        np.testing.assert_array_equal(path[[0, -1]], anchors[[i, j]])
        assert check_collision(path, robot, fused).collision_free
        assert not memory.crosses(path, robot, 0.0)
        ratios.append(path_length(path) / path_length(ref))
    assert ratios and max(ratios) < 1.1


@pytest.mark.parametrize("tile", [None, 16])
def test_remembered_obstacles_in_j_equal_a_whole_new_cost_map_in_free_space(small_office, tile):
    import torch

    from ecahd_core.cost import CollisionCost
    from ecahd_core.costmap import add_obstacles
    from ecahd_core.footprint import make_footprint
    from ecahd_core.sensing import ObstacleMemory

    grid, robot = small_office.grid, make_footprint("circle")
    static = CollisionCost.build(grid, robot)
    memory = ObstacleMemory(grid)
    assert memory.fused_cost(0.0, static) is static  # nothing remembered
    from ecahd_core.bench.replan import _remember_boxes

    # three boxes far apart (three tiles), one touching a wall
    _remember_boxes(memory, grid, small_office.anchors[:3], 0.4, now=0.0)
    fused = memory.fused(0.0)
    whole = CollisionCost.build(fused, robot).costmap.grid
    rows, cols = np.nonzero(fused.occupied & ~grid.occupied)
    got = add_obstacles(static.costmap, rows, cols, lambda r, c: grid.occupied[r, c], tile=tile).grid
    free = torch.as_tensor(~fused.occupied)
    # equal up to float32 rounding: cv2's distance transform of a window can round a distance
    # one ulp apart from the whole map's (the 0.5 m building margin shows it, 168 cells of 49 227)
    torch.testing.assert_close(got[free], whole[free], rtol=0, atol=1e-6)
    assert bool((got >= static.costmap.grid).all())  # never below the static cost
    cached = memory.fused_cost(0.0, static)
    assert memory.fused_cost(0.0, static) is cached  # kept until the marks change
    torch.testing.assert_close(cached.costmap.grid[free], whole[free], rtol=0, atol=1e-6)
    assert cached.footprint_points is static.footprint_points and cached.config is static.config


def test_memory_detour_tries_what_was_seen_lately_when_the_whole_memory_closes_every_way():
    from ecahd_core.footprint import make_footprint
    from ecahd_core.maps import GridMap
    from ecahd_core.sensing import RECENT_OBSTACLES, ObstacleMemory

    grid, robot = two_corridor_map(), make_footprint("circle")
    start, goal = (0.5, 0.75), (5.5, 0.75)

    def marks(*columns):  # walls across the corridors at these columns (window = whole map)
        data = np.full(grid.data.shape, -1, dtype=np.int8)
        for c in columns:
            data[:, c] = 100
        return GridMap(data, grid.resolution, grid.origin, unknown_is_occupied=False)

    memory = ObstacleMemory(grid, persistence=60.0)
    memory.update(marks(30), now=0.0)  # long ago: both corridors closed at x = 3
    with pytest.raises(PlanningError):
        memory.detour(robot, start, goal, now=1.0)  # seen lately too: no way
    now = 10.0
    data = np.full(grid.data.shape, -1, dtype=np.int8)
    data[:15, 40] = 100  # lately: the bottom corridor closed at x = 4 (the trail is older)
    memory.update(GridMap(data, grid.resolution, grid.origin, unknown_is_occupied=False),
                  now=now - 0.5 * RECENT_OBSTACLES)
    path, tried = memory.detour(robot, start, goal, now=now)
    assert tried == 2 and path[:, 1].max() > 2.5  # round the recent mark, through the top
    memory.update(marks(35), now=now)  # now both closed lately too
    with pytest.raises(PlanningError, match="no way round the obstacles the scans found"):
        memory.detour(robot, start, goal, now=now)


def test_a_fused_grid_gets_a_distance_bound_that_keeps_the_checker_exact(small_office):
    """fuse_grid derives the fused grid's free_distance from the static map's and the marks'
    (a lower bound); the exact checker's verdicts, depths and first contacts stay those of a
    check that tests every pose."""
    from ecahd_core import collision
    from ecahd_core.footprint import make_footprint
    from ecahd_core.sensing import fuse_grid

    grid = small_office.grid
    rng = np.random.default_rng(3)
    mask = np.zeros((80, 80), dtype=bool)
    mask[30:38, 20:60] = True  # a wall of boxes across a 4 x 4 m window
    mask[rng.integers(0, 80, 40), rng.integers(0, 80, 40)] = True  # and speckle
    anchors = small_office.anchors
    origin = tuple(anchors[0] - 2.0 - np.mod(anchors[0] - 2.0, grid.resolution))
    fused = fuse_grid(grid, mask, origin)
    assert "free_distance" in fused.__dict__  # derived, not a whole-map transform
    exact = np.pad(~fused.occupied, 1).astype(np.uint8)
    import cv2

    true = cv2.distanceTransform(exact, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[1:-1, 1:-1] \
        * grid.resolution
    assert np.all(fused.free_distance <= true + 1e-5)  # a lower bound everywhere
    hits = []
    for robot in ("circle", "quadruped"):
        fp = make_footprint(robot)
        for _ in range(8):
            a = anchors[0] + rng.uniform(-3, 3, 2)
            b = anchors[rng.integers(len(anchors))]
            path = np.stack([a, b])
            fast = collision.check_collision(path, fp, fused)
            poses = fast.dense_poses
            slow = collision._pose_depths(poses, fp, fused) > collision.DEFAULT_TOLERANCE
            np.testing.assert_array_equal(fast.colliding, slow)
            hits.append(bool(slow.any()))
    assert any(hits) and not all(hits)


def test_waypoints_the_robot_passed_while_the_plan_came_are_dropped():
    """A plan made from where the robot was 0.6 m ago: its first waypoint, now behind the
    robot, is dropped (counted), so the first segment runs from the robot's pose on to the next
    one instead of back; a waypoint beside or ahead of the robot, a far one, and the goal stay."""
    calls = []

    def refine(a, b):
        calls.append((tuple(np.round(a, 6)), tuple(np.round(b, 6))))
        return SegmentResult(plan=np.linspace(a, b, 4))

    plan = np.array([[0.0, 0.0], [0.4, 0.3], [2.0, 0.3], [2.0, 2.0]])
    r = runner(refine, prepare_ahead=0)
    r.set_pose((0.6, 0.05, 0.0), 0.0)  # past W[1] = (0.4, 0.3) along W[0] -> W[1]
    r.set_plan(plan, 0.0)
    assert r.waypoints.tolist() == [[0.0, 0.0], [2.0, 0.3], [2.0, 2.0]]
    assert r.waypoints_passed == 1 and calls == [((0.6, 0.05), (2.0, 0.3))]
    # not yet at W[1]: kept
    r = runner(refine)
    r.set_pose((0.3, 0.0, 0.0), 0.0)
    assert r.passed_waypoints(plan) == 0
    # beyond W[1]'s line but far from it (another part of the map): kept
    r.set_pose((5.0, -3.0, 0.0), 0.0)
    assert r.passed_waypoints(plan) == 0
    # past every interior waypoint: the goal stays
    r.set_pose((0.6, 0.35, 0.0), 0.0)
    assert r.passed_waypoints(plan[:3]) == 1 and r.passed_waypoints(plan[:2]) == 0


def test_a_re_plan_asked_for_where_the_goals_last_plans_started_is_stalled():
    """The runner marks a re-plan stalled (rules.stalled) when the goal's last STALL_PLANS plans,
    itself included, were asked for within STALL_RADIUS of where it is: the robot turning in
    loops; plans that move on, or a new goal, are not."""
    from ecahd_core.planning.rules import STALL_PLANS, STALL_RADIUS, stalled

    assert not stalled(np.zeros((STALL_PLANS - 1, 2)))
    assert stalled(np.zeros((STALL_PLANS, 2)))
    spread = np.zeros((STALL_PLANS, 2))
    spread[0] = [STALL_RADIUS + 0.05, 0.0]
    assert not stalled(spread) and stalled(np.concatenate([spread, np.zeros((STALL_PLANS, 2))]))
    r = GlobalRunner(GlobalRunnerConfig(replan_timeout=2.0))
    r.set_goal((2.0, 1.0))
    seen, t = [], 0.0
    for xy in [(0.0, 0.0), (0.3, 0.0), (0.2, 0.3), (0.1, 0.1), (2.5, 0.0)]:
        req = r.step(xy, t)
        while not isinstance(req, PlanRequest):  # wait out the timeout where the robot is
            t = round(t + 0.1, 1)
            req = r.step(xy, t)
        seen.append(req.stalled)
        r.accept(PLAN, t)
    assert seen == [False, False, True, True, False]
    r.set_goal((2.0, 1.0))  # a new goal starts afresh
    assert not r.step((0.1, 0.1), t + 1.0).stalled
