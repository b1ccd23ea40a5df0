"""The global_planner node in-process on maze2d-large (the shipped SD model's map): a goal becomes
a sparse plan from the robot to the goal, bad goals are rejected without a plan, a goal before the
map is queued, a new goal pre-empts, and reaching a waypoint replans with a shorter horizon."""
import json
import math
import os
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
from conftest import rig_factory  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from nav_msgs.msg import OccupancyGrid, Odometry, Path  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from std_msgs.msg import String  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402

from ecahd_core.errors import EcahdError  # noqa: E402
from ecahd_core.maps import builtin_map  # noqa: E402
from ecahd_ros.conversions import grid_to_msg, path_to_xy  # noqa: E402
from ecahd_ros.qos import PLAN_QOS  # noqa: E402
from ecahd_ros.global_planner import (ASTAR_SPACING, PARAMETERS,  # noqa: E402
                                      GlobalPlanner, GlobalPlannerParams)
from ecahd_ros.qos import MAP_QOS  # noqa: E402

ROBOT = (1.5, 1.5)  # free corridor cell of maze2d-large
GOAL = (6.5, 5.5)  # free, a few corridors away



class Rig:
    """The planner, a probe node that plays map server / odometry / RViz, and an executor."""

    def __init__(self, context, **params) -> None:
        self.planner = GlobalPlanner(context=context, parameter_overrides=[
            Parameter(k, value=v) for k, v in params.items()])
        self.probe = rclpy.create_node("probe", context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.planner)
        self.executor.add_node(self.probe)
        self.plans, self.markers, self.timings = [], [], []
        self.closed = False
        self.probe.create_subscription(Path, "plan", self.plans.append, PLAN_QOS)
        self.probe.create_subscription(MarkerArray, "plan_candidates", self.markers.append, 10)
        self.probe.create_subscription(String, "ecahd/timing", self.timings.append, 10)
        self.map_pub = self.probe.create_publisher(OccupancyGrid, "map", MAP_QOS)
        self.odom_pub = self.probe.create_publisher(Odometry, "odom", 10)
        self.goal_pub = self.probe.create_publisher(PoseStamped, "goal_pose", 10)

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        self.executor.shutdown()
        self.planner.destroy_node()
        self.probe.destroy_node()

    def spin_until(self, condition, timeout: float = 10.0) -> None:
        deadline = time.monotonic() + timeout
        while not condition():
            assert time.monotonic() < deadline, "condition not met within the time limit"
            self.executor.spin_once(timeout_sec=0.01)

    def spin_for(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.01)

    def _matched(self, pub, msg) -> None:
        self.spin_until(lambda: pub.get_subscription_count() > 0)
        pub.publish(msg)

    def send_map(self) -> None:
        self.map_pub.publish(grid_to_msg(builtin_map("maze2d-large")))

    def send_odom(self, xy, frame: str = "map") -> None:
        msg = Odometry()
        msg.header.frame_id, msg.child_frame_id = frame, "base_link"
        msg.pose.pose.position.x, msg.pose.pose.position.y = map(float, xy)
        msg.pose.pose.orientation.w = 1.0
        self._matched(self.odom_pub, msg)

    def send_goal(self, xy, frame: str = "map") -> None:
        msg = PoseStamped()
        msg.header.frame_id = frame
        msg.pose.position.x, msg.pose.position.y = map(float, xy)
        msg.pose.orientation.w = 1.0
        self._matched(self.goal_pub, msg)


@pytest.fixture
def rig(ros_context):
    yield from rig_factory(Rig, ros_context)


def ready(rig):
    """Map and odometry received, planner built."""
    rig.send_map()
    rig.send_odom(ROBOT)
    rig.spin_until(lambda: rig.planner.ready and rig.planner.pose is not None)


def test_goal_gives_a_plan_from_the_robot_to_the_goal(rig):
    r = rig()
    ready(r)
    r.send_goal(GOAL)
    r.spin_until(lambda: r.plans and r.markers and r.timings)
    plan = r.plans[-1]
    xy = path_to_xy(plan)
    assert plan.header.frame_id == "map"
    assert xy.shape == (10, 2)  # P^g
    assert np.allclose(xy[0], ROBOT)  # the robot's pose, exactly
    assert tuple(xy[-1]) == GOAL  # the goal, exactly
    # every waypoint lies on the map
    assert np.all((xy >= 0) & (xy <= [12.0, 9.0]))
    markers = r.markers[-1].markers
    assert len(markers) == 1 + 10  # DELETEALL + N candidates
    widths = [m.scale.x for m in markers[1:]]
    assert widths.count(max(widths)) == 1  # exactly one highlighted
    timing = json.loads(r.timings[-1].data)
    assert timing["stage"] == "sd" and timing["horizon"] == 10 and timing["ms"] > 0
    assert math.isfinite(timing["stamp"])


def test_planner_ready_is_latched_once_the_map_is_built(rig):
    """ecahd/planner_ready: once per map, after the planner (and its warm-up plan) is built;
    a subscriber that comes later still gets it (ecahd demo waits for it)."""
    r = rig()
    ready(r)
    got = []
    r.probe.create_subscription(String, "ecahd/planner_ready", got.append, MAP_QOS)
    r.spin_until(lambda: got)
    record = json.loads(got[-1].data)
    assert record["map"] == "maze2d-large" and record["method"] == "sd" and record["ms"] > 0


@pytest.mark.parametrize("goal,frame", [
    ((0.5, 0.5), "map"),  # inside the outer wall
    ((50.0, 50.0), "map"),  # off the map
    ((math.nan, 5.5), "map"),  # NaN
    (GOAL, "odom"),  # wrong frame
])
def test_bad_goal_is_rejected_and_the_node_keeps_working(rig, goal, frame):
    r = rig()
    ready(r)
    r.send_goal(goal, frame)
    r.spin_for(0.3)
    assert r.plans == [] and r.planner.goal is None
    r.send_goal(GOAL)
    r.spin_until(lambda: r.plans)
    assert tuple(path_to_xy(r.plans[-1])[-1]) == GOAL


def test_goal_before_the_map_is_queued(rig):
    r = rig()
    r.send_odom(ROBOT)
    r.send_goal(GOAL)
    r.spin_for(0.2)
    assert r.plans == [] and r.planner.goal is not None
    r.send_map()
    r.spin_until(lambda: r.plans)
    xy = path_to_xy(r.plans[-1])
    assert np.allclose(xy[0], ROBOT) and tuple(xy[-1]) == GOAL


def test_new_goal_preempts_and_waypoints_shrink_the_horizon(rig):
    r = rig(num_candidates=4)
    ready(r)
    r.send_goal(GOAL)
    r.spin_until(lambda: r.plans)
    other = (10.5, 7.5)
    r.send_goal(other)
    r.spin_until(lambda: len(r.plans) >= 2)
    xy = path_to_xy(r.plans[-1])
    assert tuple(xy[-1]) == other and len(xy) == 10
    # Algorithm 1: the robot reaches the next waypoint -> replan from there with P^g - 1
    r.send_odom(xy[1] + [0.1, 0.0])
    r.spin_until(lambda: len(r.plans) >= 3)
    xy2 = path_to_xy(r.plans[-1])
    assert len(xy2) == 9 and tuple(xy2[-1]) == other
    assert np.allclose(xy2[0], xy[1] + [0.1, 0.0])


def test_warm_fraction_starts_a_waypoint_replan_from_the_rest_of_the_plan(rig):
    r = rig(num_candidates=4, warm_fraction=0.3)
    ready(r)
    warm = []  # each SD plan's warm start (None: from noise)
    sd = r.planner.planning.stage.sd
    original = sd.plan
    sd.plan = lambda *a, **k: warm.append(k.get("warm_start")) or original(*a, **k)
    r.send_goal(GOAL)
    r.spin_until(lambda: r.plans)
    xy = path_to_xy(r.plans[-1])
    r.send_odom(xy[1] + [0.1, 0.0])  # the next waypoint reached
    r.spin_until(lambda: len(r.plans) >= 2)
    assert warm[0] is None  # a goal's first plan samples from noise
    assert warm[-1] is not None and warm[-1].shape == (9, 2)  # P^g - 1 waypoints
    np.testing.assert_allclose(warm[-1][1:], xy[-8:], atol=1e-5)  # the rest of the plan
    assert len(path_to_xy(r.plans[-1])) == 9 and tuple(path_to_xy(r.plans[-1])[-1]) == GOAL


@pytest.mark.parametrize("place_reach, replan, want", [(1.0, "every_waypoint", True),
                                                       (0.0, "every_waypoint", False),
                                                       (1.0, "once", False)])
def test_the_free_first_leg_rule_acts_where_the_robot_follows_only_the_first_leg(
        rig, place_reach, replan, want):
    """With placement on and re-plans at each waypoint, SD judges candidates' first legs with
    the node's placer (SparseConfig.leg_batches; the gate is SparseStage.leg_rule, the offline
    planner's own), and only the first leg of a re-plan is repaired (the robot follows it)."""
    r = rig(num_candidates=4, place_reach=place_reach, replan=replan)
    ready(r)
    seen = []
    stage = r.planner.planning.stage
    original = stage.sd.plan

    def spy(*a, **k):
        seen.append(k.get("repair_legs"))
        return original(*a, **k)

    stage.sd.plan = spy
    r.send_goal(GOAL)
    r.spin_until(lambda: r.plans)
    assert stage.leg_rule() == want
    assert (seen[-1] == 1) == (replan == "every_waypoint")
    assert (stage.sd.placer is not None) == (place_reach > 0)
    from ecahd_core.placement import LEG_BATCHES

    assert stage.sd.config.leg_batches == LEG_BATCHES  # the parameter's default


def test_same_seed_reproduces_the_plan(rig):
    paths = []
    for _ in range(2):
        r = rig(seed=7, num_candidates=4)
        ready(r)
        r.send_goal(GOAL)
        r.spin_until(lambda: r.plans)
        paths.append(path_to_xy(r.plans[-1]))
        r.close()
    np.testing.assert_allclose(paths[0], paths[1], atol=1e-6)


@pytest.mark.parametrize("name,value", [("horizon", 1), ("num_candidates", 0),
                                        ("selection", "random"), ("epsilon", -1.0),
                                        ("warm_fraction", 1.5), ("replan_spacing", -2.0),
                                        ("cost_margin", 0.0), ("cost_margin", -0.5),
                                        ("repair_reach", 0.0), ("leg_batches", -2)])
def test_bad_parameters_are_named(name, value):
    values = {spec.name: spec.default for spec in PARAMETERS}  # the declared defaults
    values[name] = value
    with pytest.raises(EcahdError, match=name):
        GlobalPlannerParams(**values)


def test_no_progress_replans_from_the_current_pose(rig):
    r = rig(replan_timeout=0.3)
    ready(r)
    r.send_goal(GOAL)
    r.spin_until(lambda: r.plans)
    first = len(r.plans)
    stuck = (1.6, 1.5)  # moved a little, nowhere near the next waypoint
    deadline = time.monotonic() + 10.0
    while len(r.plans) == first:
        assert time.monotonic() < deadline, "no replanning after replan_timeout"
        r.send_odom(stuck)
        r.spin_for(0.1)
    xy = path_to_xy(r.plans[-1])
    assert np.allclose(xy[0], stuck) and tuple(xy[-1]) == GOAL
    assert len(xy) == 10  # no waypoint was reached: the horizon stays


def test_replan_timeout_zero_never_replans(rig):
    r = rig(replan_timeout=0.0)
    ready(r)
    r.send_goal(GOAL)
    r.spin_until(lambda: r.plans)
    first = len(r.plans)
    for _ in range(5):
        r.send_odom((1.6, 1.5))
        r.spin_for(0.1)
    assert len(r.plans) == first


@pytest.mark.parametrize("method,stage", [("astar", "astar"), ("fd", "fd")])
def test_baseline_methods_publish_one_whole_path_per_goal(rig, method, stage):
    r = rig(method=method)
    ready(r)
    r.send_goal(GOAL)
    r.spin_until(lambda: r.plans and r.timings)
    xy = path_to_xy(r.plans[-1])
    assert np.allclose(xy[0], ROBOT) and tuple(xy[-1]) == GOAL  # pose to goal, exactly
    if method == "astar":  # resampled: no step longer than ASTAR_SPACING
        assert np.linalg.norm(np.diff(xy, axis=0), axis=1).max() <= ASTAR_SPACING + 1e-9
        # A* keeps the footprint's clearance: the circle's 0.4 m from every wall
        from ecahd_core.collision import check_collision
        from ecahd_core.footprint import make_footprint

        report = check_collision(xy, make_footprint("circle"), builtin_map("maze2d-large"))
        assert report.collision_free
    else:
        assert len(xy) == 100  # the FD model's sequence, published whole
    timing = json.loads(r.timings[-1].data)
    assert timing["stage"] == stage and timing["ms"] > 0 and timing["horizon"] == len(xy)
    # no per-waypoint replanning: reaching the path's next points publishes nothing new
    count = len(r.plans)
    for p in xy[1:len(xy) // 2:3]:
        r.send_odom(p)
        r.spin_for(0.05)
    assert len(r.plans) == count and r.planner.goal is not None
    r.send_odom(GOAL)  # the goal reached ends it
    r.spin_until(lambda: r.planner.goal is None)
    assert len(r.plans) == count


def test_astar_from_a_pose_without_clearance_and_an_unreachable_goal(rig):
    r = rig(method="astar")
    r.send_map()
    near_wall = (1.5, 1.15)  # free, 0.15 m from the wall below: no 0.4 m clearance
    r.send_odom(near_wall)
    r.spin_until(lambda: r.planner.ready and r.planner.pose is not None)
    r.send_goal(GOAL)
    r.spin_until(lambda: r.plans)
    xy = path_to_xy(r.plans[-1])
    assert np.allclose(xy[0], near_wall) and tuple(xy[-1]) == GOAL
    r.send_goal((1.5, 1.15))  # free but without the circle's clearance: rejected
    r.spin_for(0.3)
    assert len(r.plans) == 1 and r.planner.goal is None


def test_replan_spacing_is_decided_by_the_map_and_the_model():
    from types import SimpleNamespace

    from ecahd_core.planning.horizon import REPLAN_SPACING

    values = {spec.name: spec.default for spec in PARAMETERS}  # -1: by the map
    config = GlobalPlannerParams(**values).online_config()
    big, small = SimpleNamespace(width=1000, height=1667), SimpleNamespace(width=120, height=90)
    assert config.spacing_on(big) == REPLAN_SPACING  # a building
    # the SD model's expert spacing where it is wider (an office's 6.5 m), never below 3 m
    assert config.spacing_on(big, 6.5) == 6.5
    assert config.spacing_on(big, 2.6) == REPLAN_SPACING
    assert config.spacing_on(small) is None  # maze2d-large: the paper's
    assert config.spacing_on(small, 6.5) is None
    for value, want in ((0.0, None), (2.5, 2.5)):
        values["replan_spacing"] = value
        assert GlobalPlannerParams(**values).online_config().spacing_on(big, 6.5) == want


def test_cost_margin_is_decided_by_the_map_unless_set():
    """cost_margin -1: J's margin by the map (0.5 m on a building, 0.1 m on maze2d-large); a
    value > 0 is used as given, by both nodes (the same shared parameter)."""
    from ecahd_core.costmap import BUILDING_MARGIN, DEFAULT_MARGIN
    from ecahd_core.footprint import make_footprint
    from ecahd_core.maps import GridMap, builtin_map
    from ecahd_ros.local_refiner import PARAMETERS as REFINER_PARAMETERS
    from ecahd_ros.local_refiner import LocalRefinerParams
    from ecahd_ros.params import collision_cost

    building = GridMap(np.zeros((300, 300), dtype=np.int8), 0.03, (0.0, 0.0), name="b")
    maze, fp = builtin_map("maze2d-large"), make_footprint("circle")
    for specs, cls in ((PARAMETERS, GlobalPlannerParams),
                       (REFINER_PARAMETERS, LocalRefinerParams)):
        values = {spec.name: spec.default for spec in specs}
        params = cls(**values)
        assert params.cost_margin == -1
        assert collision_cost(params, building, fp).config.margin == BUILDING_MARGIN
        assert collision_cost(params, maze, fp).config.margin == DEFAULT_MARGIN
        values["cost_margin"] = 0.25
        assert collision_cost(cls(**values), building, fp).config.margin == 0.25
        values["cost_margin"] = 0.0
        with pytest.raises(EcahdError, match="cost_margin"):
            cls(**values)


def test_bad_method_is_named():
    values = {spec.name: spec.default for spec in PARAMETERS}
    values["method"] = "rrt"
    with pytest.raises(EcahdError, match=r"parameter method must be one of \['sd', 'astar', "
                                         r"'fd'\], got 'rrt'"):
        GlobalPlannerParams(**values)


def test_bad_method_node_raises_at_construction(ros_context):
    # spin_node turns this into exit code 1 with one line (test_node_failures.py)
    with pytest.raises(EcahdError, match="parameter method must be one of"):
        GlobalPlanner(context=ros_context, parameter_overrides=[
            Parameter("method", value="rrt")])


def test_a_blockage_the_refiner_scanned_is_avoided_by_the_fallback(rig):
    """The refiner's local costmap marks a box wall to wall across the y = 5.5 corridor at
    x = 3.5; at the first 'blocked' replan request SD's best plan still crosses the remembered
    box (SD never saw it), so the planner falls back to A* on the map with it at once, and the
    detour leaves the corridor (the direct way stays on y ~ 5.5)."""
    import json

    from ecahd_core.maps import OccupancyGridLayout
    from ecahd_ros.conversions import layout_to_msg
    from ecahd_ros.qos import STREAM_QOS, VIZ_QOS

    r = rig()
    costmap_pub = r.probe.create_publisher(OccupancyGrid, "local_costmap", VIZ_QOS)
    replan_pub = r.probe.create_publisher(String, "ecahd/replan", STREAM_QOS)
    r.send_map()
    start, goal = (1.5, 5.5), (5.5, 5.5)  # both in the corridor y in [5, 6]
    r.send_odom(start)
    r.spin_until(lambda: r.planner.ready and r.planner.pose is not None)
    r.send_goal(goal)
    r.spin_until(lambda: r.plans)
    # a 2 x 2 m window (0.1 m cells) from (2.5, 4.5): column x in [3.5, 3.6] marked for y in
    # [5.0, 6.0] (rows 5..14), everything else seen free
    data = np.zeros((20, 20), dtype=np.int8)
    data[5:15, 10] = 100
    window = layout_to_msg(OccupancyGridLayout(data=data.reshape(-1), width=20, height=20,
                                               resolution=0.1, origin_xy=(2.5, 4.5)))
    r._matched(costmap_pub, window)
    r.spin_until(lambda: r.planner.planning.memory is not None
                 and r.planner.planning.memory.mask(r.planner._now()).any())
    n = len(r.plans)
    r._matched(replan_pub, String(data=json.dumps({"reason": "blocked"})))
    r.spin_until(lambda: len(r.plans) > n)
    r.spin_until(lambda: any(json.loads(m.data)["stage"] == "fallback_astar"
                             for m in r.timings))  # its record follows the plan
    assert r.planner.planning.fallbacks == 1
    path = path_to_xy(r.plans[-1])
    assert np.allclose(path[0], start) and np.allclose(path[-1], goal)
    assert np.abs(path[:, 1] - 5.5).max() > 1.0  # round the block through another corridor


CORRIDOR = (6.5, 1.5)  # the foot of maze2d-large's longest straight corridor (6 m)


def straight_goal(grid, placer, start, rng_seed=0):
    """A free point 2.5-4 m from ``start`` (2,) [m] that a straight leg reaches by the leg test."""
    free = np.argwhere(~grid.occupied)
    rng = np.random.default_rng(rng_seed)
    for _ in range(2000):
        xy = grid.cell_to_world(*free[rng.integers(len(free))])
        if 2.5 < np.linalg.norm(xy - start) < 4.0 and placer.wall_length(start, xy[None])[0] == 0:
            return xy
    raise AssertionError("no straight free leg from the start")


@pytest.mark.parametrize("settle", [True, False])
def test_a_plan_whose_legs_are_all_free_is_followed_whole_when_settle_is_on(rig, settle):
    """The settle rule (replan spacing and placement on): a plan whose every straight leg is
    free by the leg test is followed whole: reaching its next waypoint asks for no re-plan."""
    from ecahd_core.planning.sparse import SparsePlan

    r = rig(num_candidates=4, place_reach=1.0, replan_spacing=3.0, settle=settle)
    ready(r)
    start = np.array(CORRIDOR)
    r.send_odom(start)
    r.spin_until(lambda: np.allclose(r.planner.pose, start))
    stage = r.planner.planning.stage
    goal = straight_goal(r.planner.planning.grid, stage.sd.placer, start)
    wp = np.linspace(start, goal, 4)
    stage.sd.replan = lambda *a, **k: SparsePlan(
        waypoints=wp.copy(), candidates=wp[None], best=0, collision_costs=None, time_ms=0.0)
    r.send_goal(goal)
    r.spin_until(lambda: r.plans)
    np.testing.assert_allclose(path_to_xy(r.plans[-1]), wp, atol=1e-6)
    r.send_odom(wp[1] + [0.05, 0.0])  # the next waypoint reached
    if settle:
        r.spin_for(0.5)
        assert len(r.plans) == 1 and r.planner.runner.iteration == 1
    else:
        r.spin_until(lambda: len(r.plans) >= 2)


def test_the_subgoal_rule_is_built_with_the_map_and_acts_past_p_g_minus_one_waypoints(rig):
    from ecahd_core.planning.online import PlanRequest

    assert rig(num_candidates=4, place_reach=1.0, replan_spacing=0.0).planner.planning.stage \
        is None  # before a map, and
    off = rig(num_candidates=4, place_reach=1.0, replan_spacing=0.0)
    ready(off)
    # without a replan spacing (the paper's setting)
    assert not off.planner.planning.stage.subgoaling()
    assert off.planner.planning.stage._subgoal_rule is None
    r = rig(num_candidates=4, place_reach=1.0, replan_spacing=3.0, horizon=10)
    ready(r)
    rule = r.planner.planning.stage._subgoal_rule
    assert rule is not None and rule.field._graph is not None  # its graph built with the map
    seen = []
    real = rule.apply
    rule.apply = lambda sd, s, g, plan, it, **k: seen.append(it) or real(sd, s, g, plan, it, **k)
    r.planner.runner.set_goal(GOAL)
    stage = r.planner.planning.stage
    for roundabout, expected in ((False, [9, 12]), (True, [8, 9, 12])):
        # a goal round the walls (its route > 1.5x the blocked straight line): from the first
        # plan on; else past P^g - 1
        stage._roundabout = lambda sd, S, G, times, v=roundabout: v
        seen.clear()
        for it in (8, 9, 12):
            r.planner.planning._plan(PlanRequest(np.array(ROBOT), np.array(GOAL), 10,
                                                 "waypoint", it))
        assert seen == expected


def test_a_plan_toward_a_subgoal_is_followed_to_the_subgoal_when_its_legs_there_are_free(rig):
    """The settle rule's follow index (SparseStage.step, the offline planner's own) as the node
    builds it: to the subgoal when its legs there are free, whole when every leg is, else 1."""
    from dataclasses import replace

    from ecahd_core.planning.sparse import SparsePlan

    r = rig(num_candidates=4, place_reach=1.0, replan_spacing=3.0)
    ready(r)
    stage = r.planner.planning.stage
    placer, start = stage.sd.placer, np.array(CORRIDOR)
    sub = straight_goal(r.planner.planning.grid, placer, start)
    far = np.array(ROBOT)  # no straight free leg from the corridor's far end to here
    assert placer.wall_length(sub, far[None])[0] > 0
    wp = np.stack([start, 0.5 * (start + sub), sub, far])
    plan = SparsePlan(waypoints=wp, candidates=wp[None], best=0, collision_costs=None,
                      time_ms=0.0, first_leg="subgoal")

    def follow(sparse):
        stage.sd.replan = lambda *a, **k: sparse
        return stage.step(start, sparse.waypoints[-1], iteration=0).follow

    assert follow(plan) == 2  # to the subgoal, then a re-plan
    assert follow(replace(plan, first_leg="")) == 1  # Algorithm 1
    assert follow(replace(plan, waypoints=wp[:3])) == 2  # every leg free: the whole plan
    stage.settle = False
    assert follow(replace(plan, waypoints=wp[:3])) == 1


def test_health_is_on_diagnostics(rig):
    """/diagnostics: 'waiting for a map' (WARN) before the map; then OK with the plans'
    latency once a goal is planned."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

    r = rig(num_candidates=4)
    got = []
    r.probe.create_subscription(DiagnosticArray, "/diagnostics", got.append, 10)
    r.spin_until(lambda: got, timeout=5.0)
    first = got[-1].status[0]
    assert first.name == "ecahd_ros: global_planner" and first.level == DiagnosticStatus.WARN
    assert first.message == "waiting for a map"
    ready(r)
    r.send_goal(GOAL)
    r.spin_until(lambda: r.plans)
    n = len(got)
    r.spin_until(lambda: len(got) > n, timeout=5.0)
    status = got[-1].status[0]
    values = {kv.key: kv.value for kv in status.values}
    assert status.level == DiagnosticStatus.OK and status.message == "planning"
    assert values["map"] == "maze2d-large" and values["method"] == "sd"
    assert int(values["plans"]) >= 1 and float(values["plan_ms_p50"]) > 0
    assert values["fallbacks"] == "0" and values["goal"] == "6.50, 5.50"


def test_odometry_in_odom_is_placed_in_map_through_tf(rig):
    """REP-105: the base driver's odometry in `odom`, the localisation's `map -> odom` on /tf
    (here odom's origin at map (1, 0.5), turned 90 deg): the planner's pose is in `map`; without
    the transform the odometry is refused, naming the missing transform."""
    import math

    from geometry_msgs.msg import TransformStamped
    from tf2_msgs.msg import TFMessage

    r = rig(num_candidates=4)
    r.send_map()
    r.spin_until(lambda: r.planner.ready)
    r.send_odom((0.5, 0.5), frame="odom")  # before any tf: refused
    r.spin_for(0.2)
    assert r.planner.pose is None
    tf_pub = r.probe.create_publisher(TFMessage, "/tf", 10)
    t = TransformStamped()
    t.header.frame_id, t.child_frame_id = "map", "odom"
    t.transform.translation.x, t.transform.translation.y = 1.0, 0.5
    t.transform.rotation.z, t.transform.rotation.w = math.sin(math.pi / 4), math.cos(math.pi / 4)
    r.spin_until(lambda: tf_pub.get_subscription_count() > 0)
    tf_pub.publish(TFMessage(transforms=[t]))
    r.spin_until(lambda: r.planner.tf.received >= 1)
    r.send_odom((1.0, -0.5), frame="odom")  # odom's (1, -0.5) is map's (1 + 0.5, 0.5 + 1)
    r.spin_until(lambda: r.planner.pose is not None)
    np.testing.assert_allclose(r.planner.pose, [1.5, 1.5], atol=1e-9)


def test_a_lifecycle_manager_configures_and_activates_it(rig, ros_context):
    """autostart false: the node waits unconfigured; a lifecycle manager's change_state calls
    (Nav2's protocol) configure it (map and odometry taken, goals not planned while inactive),
    activate it (goals planned), deactivate it (goals refused) and clean it up."""
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState, GetState

    r = rig(num_candidates=4, autostart=False)
    change = r.probe.create_client(ChangeState, "/global_planner/change_state")
    get = r.probe.create_client(GetState, "/global_planner/get_state")
    r.spin_until(lambda: change.service_is_ready() and get.service_is_ready())

    def call(client, request):
        future = client.call_async(request)
        r.spin_until(future.done)
        return future.result()

    def state() -> str:
        return call(get, GetState.Request()).current_state.label

    def transition(tid) -> bool:
        return call(change, ChangeState.Request(transition=Transition(id=tid))).success

    assert state() == "unconfigured" and r.planner.planning is None
    assert transition(Transition.TRANSITION_CONFIGURE) and state() == "inactive"
    ready(r)
    r.send_goal(GOAL)  # inactive: refused, nothing planned
    r.spin_for(0.3)
    assert not r.plans and r.planner.goal is None
    assert transition(Transition.TRANSITION_ACTIVATE) and state() == "active"
    r.send_goal(GOAL)
    r.spin_until(lambda: r.plans)
    assert transition(Transition.TRANSITION_DEACTIVATE) and state() == "inactive"
    assert transition(Transition.TRANSITION_CLEANUP) and state() == "unconfigured"
    assert r.planner.planning is None


def test_a_configuration_that_fails_under_a_manager_keeps_the_node(rig):
    """autostart false and an unknown robot: configure answers FAILURE (one error line), the
    node stays unconfigured and keeps answering its lifecycle services."""
    from rclpy.lifecycle import TransitionCallbackReturn

    r = rig(num_candidates=4, autostart=False, robot="spaceship")
    assert r.planner.trigger_configure() == TransitionCallbackReturn.FAILURE
    assert r.planner.planning is None and not r.planner.active
    assert r.planner._state_machine.current_state[1] == "unconfigured"
    assert "spaceship" in (r.planner._configure_error or "")


def blocked_update(grid, x0: float, x1: float, y0: float, y1: float):
    """``grid`` (a GridMap) with the box [x0, x1] x [y0, y1] [m] occupied: an updated map of the
    same site (a SLAM update, an edited map)."""
    from ecahd_core.maps import GridMap

    data = grid.data.copy()
    (r0, c0), (r1, c1) = grid.world_to_cell((x0, y0)), grid.world_to_cell((x1, y1))
    data[min(r0, r1):max(r0, r1) + 1, min(c0, c1):max(c0, c1) + 1] = 100
    return GridMap(data, grid.resolution, grid.origin, name=grid.name, frame_id=grid.frame_id)


def test_an_updated_map_of_the_site_keeps_the_model_and_is_planned_round(rig):
    """A map update with a box across the y = 5.5 corridor (walls SD never learnt): the node
    keeps the site's model, records the share of changed cells, plans the active goal again at
    once, and the plan goes round the box (the straight way stays on y ~ 5.5) without touching
    the new map (exact checker). A map of another extent is refused and the old one kept."""
    from ecahd_core.collision import check_collision

    r = rig()
    site = builtin_map("maze2d-large")
    start, goal = (1.5, 5.5), (5.5, 5.5)
    r.send_map()
    r.send_odom(start)
    r.spin_until(lambda: r.planner.ready and r.planner.pose is not None)
    r.send_goal(goal)
    r.spin_until(lambda: r.plans)
    updated = blocked_update(site, 3.5, 4.0, 5.0, 6.0)
    n = len(r.plans)
    r._matched(r.map_pub, grid_to_msg(updated))
    r.spin_until(lambda: len(r.plans) > n)
    assert r.planner.grid.fingerprint() == updated.fingerprint()
    assert r.planner.map_changed == pytest.approx(float(np.mean(updated.occupied
                                                               != site.occupied)))
    assert r.planner.planning.memory.unlearnt.sum() == (updated.occupied & ~site.occupied).sum()
    path = path_to_xy(r.plans[-1])
    assert np.allclose(path[0], start) and np.allclose(path[-1], goal)
    assert np.abs(path[:, 1] - 5.5).max() > 1.0  # round the box through another corridor
    assert check_collision(path, r.planner.footprint, updated).collision_free
    # another extent (maze2d-medium's cells): refused with the reason, the update kept
    n = len(r.plans)
    r._matched(r.map_pub, grid_to_msg(builtin_map("maze2d-medium")))
    r.spin_for(1.0)
    assert r.planner.grid.fingerprint() == updated.fingerprint()
    assert len(r.plans) == n


def test_with_the_generalist_a_map_of_another_extent_is_planned_on_at_once(rig, tmp_path):
    """sd_model: a generalist checkpoint (here a tiny untrained one: the plumbing, not the
    plans' quality): the node plans on maze2d-large, then takes maze2d-medium (another extent,
    which a per-map model refuses) and plans the active goal on it at once."""
    import torch

    from ecahd_core.diffusion.scheduler import ScheduleConfig
    from ecahd_core.general.checkpoint import GeneralCheckpoint
    from ecahd_core.general.model import GeneralDenoiserConfig, MapConditionedDenoiser

    torch.manual_seed(0)
    config = GeneralDenoiserConfig(max_horizon=10, d_model=32, n_layers=2, n_heads=2, ff_mult=2,
                                   global_channels=(8, 8, 16), local_channels=(8, 8, 8))
    path = GeneralCheckpoint(
        model_config=config, schedule_config=ScheduleConfig(), conditioned_indices=(0, -1),
        horizons=tuple(range(2, 11)), ema_state_dict=MapConditionedDenoiser(config).state_dict(),
        step=0, train_config={}, data={}).save(tmp_path / "g.pt", include_training_state=False)
    r = rig(sd_model=str(path))
    ready(r)
    r.send_goal((2.5, 3.5))  # free on both mazes
    r.spin_until(lambda: r.plans)
    n = len(r.plans)
    medium = builtin_map("maze2d-medium")
    r._matched(r.map_pub, grid_to_msg(medium))
    r.spin_until(lambda: len(r.plans) > n)
    assert r.planner.grid.fingerprint() == medium.fingerprint()
    path_xy = path_to_xy(r.plans[-1])
    assert np.allclose(path_xy[0], ROBOT) and np.allclose(path_xy[-1], (2.5, 3.5))


def test_lanes_keep_out_places_are_planned_round(rig, tmp_path):
    """``lanes``: a lane field whose keep-out place spans the y = 5.5 corridor at x 3.5..4 m
    (never driven there, though the expert's routes cross it): the node plans round it as
    round a wall, on the site's own model; the map it was given stays as it is."""
    from ecahd_core.lanes import LaneConfig, LaneField

    site = builtin_map("maze2d-large")
    cfg = LaneConfig()
    H, W = round(site.height * site.resolution / cfg.cell), round(site.width * site.resolution
                                                                   / cfg.cell)
    keep = np.zeros((H, W), dtype=bool)
    keep[round(5.0 / cfg.cell):round(6.0 / cfg.cell), round(3.5 / cfg.cell):round(4.0 / cfg.cell)] \
        = True
    field = LaneField(density=np.zeros((cfg.bins, H, W), dtype=np.float32), origin=site.origin,
                      config=cfg, map_name=site.name, map_fingerprint=site.fingerprint(),
                      paths=1, length=1.0, keep_out=keep)
    r = rig(lanes=str(field.save(tmp_path / "lanes.npz")))
    start, goal = (1.5, 5.5), (5.5, 5.5)
    r.send_map()
    r.send_odom(start)
    r.spin_until(lambda: r.planner.ready and r.planner.pose is not None)
    assert not r.planner.grid.is_free(np.array([3.75, 5.5]))  # the keep-out: a wall to plan round
    r.send_goal(goal)
    r.spin_until(lambda: r.plans)
    path = path_to_xy(r.plans[-1])
    assert np.allclose(path[0], start) and np.allclose(path[-1], goal)
    assert np.abs(path[:, 1] - 5.5).max() > 1.0  # round the keep-out through another corridor
    assert site.is_free(np.array([3.75, 5.5]))
