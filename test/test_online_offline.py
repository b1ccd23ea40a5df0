"""One Algorithm 1, two drivers: the online planner behind global_planner, driven by a fake
clock and a robot that reaches each waypoint it is sent to, makes the same global plans as the
offline planner behind ``ecahd plan`` and the benchmarks, for the same seed (both call
``SparseStage.step`` for every SD plan; the offline planner's MoveAgent puts the agent on the
next waypoint as the robot does here). No rclpy."""
import numpy as np
import pytest
import torch

from ecahd_core.cost import CollisionCost, CostConfig
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import builtin_map
from ecahd_core.model_zoo import load_model
from ecahd_core.placement import placer_for
from ecahd_core.planning.hierarchical import HierarchicalPlanner
from ecahd_core.planning.online import GlobalRunnerConfig, OnlinePlanner, OnlinePlannerConfig
from ecahd_core.planning.rules import SparseStage
from ecahd_core.planning.sparse import SparseConfig, SparseDiffusion
from ecahd_core.problems import make_problems

SEED = 3
PLACE_REACH, SPACING = 1.0, 3.0  # the building rules on: placement, leg rule, subgoal, settle


def record_steps(monkeypatch):
    """Every SparseStage.step call's (iteration, waypoints, follow), in order."""
    seen = []
    real = SparseStage.step

    def spy(self, *args, **kw):
        out = real(self, *args, **kw)
        seen.append((kw.get("iteration", 0), out.waypoints.copy(), out.follow))
        return out

    monkeypatch.setattr(SparseStage, "step", spy)
    return seen


def drive_online(online: OnlinePlanner, start, goal, max_steps: int = 300) -> None:
    """Teleport the robot from ``start`` to each waypoint the runner heads for, one clock
    second a step, until the goal is reached."""
    clock = [0.0]
    online.clock = lambda: clock[0]
    online.set_goal(goal)
    pose = np.asarray(start, dtype=np.float64)
    for _ in range(max_steps):
        clock[0] += 1.0
        if online.step(pose) == "reached":
            return
        pose = online.runner.waypoints[online.runner.next_index].copy()
    raise AssertionError("the online planner did not reach the goal")


@pytest.mark.parametrize("robot", ["circle", "quadruped"])
def test_the_online_planner_makes_the_offline_planners_global_plans(monkeypatch, robot):
    grid, fp = builtin_map("maze2d-large"), make_footprint(robot)
    cost_config = CostConfig.for_map(grid)
    costmap = cost_config.make_costmap(grid)
    cost = CollisionCost(costmap=costmap, footprint_points=torch.as_tensor(fp.points,
                                                                         dtype=costmap.dtype),
                         config=cost_config)
    sd_ckpt, dd_ckpt = load_model("sd", grid, footprint=fp), load_model("dd", grid, footprint=fp)
    config = SparseConfig(num_candidates=10, selection="collision_aware")
    offline = HierarchicalPlanner(
        SparseDiffusion(sd_ckpt, config, cost=cost, placer=placer_for(grid, fp, PLACE_REACH)),
        dd_ckpt, costmap=costmap, footprint_points=fp.points, cost_config=cost_config,
        replan_spacing=SPACING, backtracks=0)  # backtracking needs DD's plans: offline only
    online = OnlinePlanner(OnlinePlannerConfig(place_reach=PLACE_REACH, replan_spacing=SPACING),
                           GlobalRunnerConfig(horizon=config.horizon, replan_timeout=0.0), fp,
                           clock=lambda: 0.0)
    online.set_map(grid, sd=SparseDiffusion(sd_ckpt, config, cost=cost))
    assert online.stage.subgoaling() and online.stage.settling()  # every rule can act
    compared = 0
    problems = make_problems(grid, 6, seed=SEED)
    for k, prob in enumerate(problems):
        steps = record_steps(monkeypatch)
        offline.plan(prob.start, prob.goal, generator=torch.Generator().manual_seed(k))
        want, steps[:] = list(steps), []
        online.generator = torch.Generator().manual_seed(k)
        drive_online(online, prob.start, prob.goal)
        got = list(steps)
        monkeypatch.undo()
        # the online robot stops within waypoint_tolerance of the goal, where the offline loop
        # may still make one more plan: the online plans are the offline ones up to there
        assert 1 <= len(got) <= len(want)
        assert len(want) - len(got) <= 1
        for (it_a, wp_a, f_a), (it_b, wp_b, f_b) in zip(want, got):
            assert it_a == it_b and f_a == f_b
            np.testing.assert_allclose(wp_b, wp_a, atol=1e-5)
        compared += len(got)
    assert compared > len(problems)  # re-plans were compared, not only first plans
