"""The core of navigate_to_pose without ROS: a Mission's progress (distance along the plan, time
left, re-plans, reached only with the heading, a heading never reached fails), the local runner's
turn in place at the goal, and the dense path (Algorithm 1 + the safety net) of
compute_path_to_pose."""
import math

import numpy as np
import pytest

from ecahd_core.errors import EcahdError
from ecahd_core.planning.local import LocalRunner, LocalRunnerConfig
from ecahd_core.planning.mission import Mission, MissionConfig, distance_along, wrap_angle


def test_distance_along_a_plan_from_the_robots_projection():
    plan = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0]])
    assert distance_along(plan, np.array([0.0, 0.0])) == pytest.approx(7.0)
    assert distance_along(plan, np.array([1.0, 0.5])) == pytest.approx(6.0)  # 3 + 3
    assert distance_along(plan, np.array([4.2, 2.0])) == pytest.approx(1.0)
    assert distance_along(plan, np.array([9.0, 9.0])) == pytest.approx(0.0)  # past the end


def test_mission_progress_and_time_left():
    m = Mission((4.0, 0.0), None, start_time=10.0)
    m.planned(np.array([[0.0, 0.0], [4.0, 0.0]]))
    first = m.update((0.0, 0.0, 0.0), 10.0)
    assert (first.state, first.distance_remaining, first.elapsed) == ("driving", 4.0, 0.0)
    assert first.time_remaining == 0.0  # no speed known yet
    later = m.update((1.0, 0.0, 0.0), 12.0)  # 0.5 m/s
    assert later.distance_remaining == pytest.approx(3.0)
    assert later.time_remaining == pytest.approx(6.0)
    assert later.elapsed == pytest.approx(2.0)
    m.planned(np.array([[1.0, 0.0], [4.0, 0.0]]))
    m.planned(np.array([[1.0, 0.0], [4.0, 0.0]]))
    assert m.update((1.0, 0.0, 0.0), 12.5).replans == 2


def test_a_goal_with_a_heading_is_reached_only_facing_it():
    m = Mission((4.0, 0.0), math.pi / 2, 0.0, MissionConfig(xy_tolerance=0.3,
                                                           yaw_tolerance=0.2,
                                                           align_timeout=5.0))
    assert m.update((3.9, 0.0, 0.0), 1.0).state == "aligning"
    assert m.update((3.9, 0.0, 1.2), 2.0).state == "aligning"
    done = m.update((3.9, 0.0, 1.45), 3.0)
    assert done.state == "succeeded" and done.distance_remaining == 0.0
    assert m.update((0.0, 0.0, 0.0), 4.0).state == "succeeded"  # finished stays finished


def test_a_heading_never_reached_fails_after_the_timeout():
    m = Mission((0.0, 0.0), math.pi, 0.0, MissionConfig(align_timeout=5.0))
    assert m.update((0.1, 0.0, 0.0), 1.0).state == "aligning"
    assert m.update((0.1, 0.0, 0.0), 5.5).state == "aligning"
    failed = m.update((0.1, 0.0, 0.0), 6.5)
    assert failed.state == "failed" and "heading" in failed.message and "180" in failed.message


def test_mission_config_is_checked():
    with pytest.raises(EcahdError, match="yaw_tolerance"):
        MissionConfig(yaw_tolerance=0.0)
    assert wrap_angle(3 * math.pi) == pytest.approx(-math.pi)


def _runner(**config):
    return LocalRunner(LocalRunnerConfig(**config), synchronous=True)


def test_the_runner_turns_in_place_to_the_goals_heading():
    r = _runner(max_w=1.0, yaw_goal_tolerance=0.1)
    r.set_pose((0.0, 0.0, 0.0), 0.0)
    r.set_plan(np.array([[0.0, 0.0], [0.1, 0.0]]), 0.0, goal_yaw=math.pi / 2)
    cmd = r.tick(0.05)
    assert (cmd.reason, cmd.v) == ("aligning", 0.0) and cmd.w == pytest.approx(1.0)  # max_w
    r.set_pose((0.0, 0.0, math.pi / 2 - 0.1), 0.1)  # gain * error, at least MIN_ALIGN_W
    cmd = r.tick(0.15)
    assert cmd.reason == "aligning" and cmd.w == pytest.approx(0.2)
    r.set_pose((0.0, 0.0, -3.0), 0.2)  # the short way round: clockwise past -pi
    assert r.tick(0.25).w < 0
    r.set_pose((0.0, 0.0, math.pi / 2 - 0.05), 0.3)
    assert r.tick(0.35).reason == "goal_reached"
    assert ("goal_reached", None) in r.pop_events()


def test_no_heading_or_a_blocked_turn_ends_at_the_position():
    r = _runner()
    r.set_pose((0.0, 0.0, 0.0), 0.0)
    r.set_plan(np.array([[0.0, 0.0], [0.1, 0.0]]), 0.0)
    assert r.tick(0.05).reason == "goal_reached"
    r = _runner()
    r.can_turn = lambda pose: False  # a long robot beside a wall
    r.set_pose((0.0, 0.0, 0.0), 0.0)
    r.set_plan(np.array([[0.0, 0.0], [0.1, 0.0]]), 0.0, goal_yaw=2.0)
    assert r.tick(0.05).reason == "goal_reached"
    kinds = [k for k, _ in r.pop_events()]
    assert kinds == ["heading_blocked", "goal_reached"]
    with pytest.raises(EcahdError, match="heading"):
        r.set_plan(np.array([[0.0, 0.0], [1.0, 0.0]]), 0.0, goal_yaw=math.nan)


def test_segment_refiner_can_turn_by_the_walls_distance():
    from ecahd_core.footprint import make_footprint
    from ecahd_core.maps import builtin_map
    from ecahd_core.planning.local import SegmentRefiner

    grid = builtin_map("maze2d-large")
    long_robot = make_footprint("quadruped")
    refiner = SegmentRefiner(None, grid, long_robot)
    # the corridor x in [1, 2] at y = 1.5: 0.5 m to the walls in its middle, 0.2 m at x = 1.15,
    # where the quadruped stands free (inscribed radius 0.15 m) but could not turn (0.36 m)
    assert refiner.can_turn((1.5, 1.5, 0.0))
    assert grid.is_free(np.array([1.15, 1.5]))
    assert not refiner.can_turn((1.15, 1.5, 0.0))
    assert SegmentRefiner(None, grid, make_footprint("circle")).can_turn((1.15, 1.5, 0.0))


def test_dense_path_planner_never_returns_a_colliding_path_as_safe():
    import torch

    from ecahd_core.collision import check_collision
    from ecahd_core.footprint import make_footprint
    from ecahd_core.maps import builtin_map
    from ecahd_core.planning.dense_path import DensePathPlanner
    from ecahd_core.planning.sparse import SparseDiffusion

    torch.set_num_threads(1)
    grid, robot = builtin_map("maze2d-large"), make_footprint("circle")
    planner = DensePathPlanner.for_map(grid, robot, SparseDiffusion.for_map(grid, robot))
    for start, goal in [((1.5, 1.5), (6.5, 5.5)), ((10.5, 1.5), (1.5, 7.5))]:
        found = planner.plan(start, goal, generator=torch.Generator().manual_seed(0))
        assert found.safe
        assert check_collision(found.path, robot, grid).collision_free
        assert found.path[0] == pytest.approx(start, abs=1e-3)
        assert found.path[-1] == pytest.approx(goal, abs=1e-3)
    with pytest.raises(EcahdError, match="inside an obstacle"):
        planner.plan((0.2, 0.2), (6.5, 5.5))
