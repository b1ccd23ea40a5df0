"""The goal's cost-to-go (progress.GoalField), and the re-plan loop's subgoal and settle rules
(issue 10)."""
import numpy as np
import torch

from ecahd_core.cost import CostConfig
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import GridMap, builtin_map
from ecahd_core.model_zoo import load_model
from ecahd_core.placement import WaypointPlacer
from ecahd_core.planning.hierarchical import HierarchicalPlanner
from ecahd_core.planning.sparse import SparseConfig, SparseDiffusion, SparsePlan
from ecahd_core.progress import SUBGOAL_GAIN, GoalField


def gap_map():
    """A 10 x 6 m room at 0.05 m/cell: a wall 0.3 m thick at y in [2.85, 3.15] from x = 0 to
    x = 8, so the only way between the bottom half and the top half is the 2 m gap x in [8, 10];
    and a closed 1 x 1 m box (walls 0.2 m) at x in [4, 5], y in [4.5, 5.5]."""
    data = np.zeros((120, 200), dtype=np.int8)
    data[57:63, :160] = 100
    data[90:110, 80:100] = 100
    data[94:106, 84:96] = 0  # the box's inside, closed all round
    return GridMap(data, 0.05, (0.0, 0.0), name="gap")


def test_cost_to_go_goes_round_the_wall_through_the_gap_and_its_route_heads_there():
    grid, fp = gap_map(), make_footprint("circle")
    field = GoalField(grid, fp)
    goal, below = np.array([2.0, 4.5]), np.array([2.0, 1.5])
    to_go = field.to(goal)
    g = to_go(np.stack([goal, below, np.array([9.0, 3.0])]))
    assert g[0] < 0.3  # the goal itself
    # round the wall's end: about 7.2 m to the gap and 7.2 m back, far more than the 3 m across
    detour = 2 * np.hypot(7.0, 1.5)
    assert detour - 0.5 < g[1] < detour + 1.5
    assert abs(g[2] - np.hypot(7.0, 1.5)) < 1.0  # from the gap
    # a point without the clearance (beside the wall) snaps to free cells within reach; one
    # deep in the wall, or in the closed box, has no cost-to-go
    near, deep, boxed = np.array([2.0, 2.75]), np.array([12.0, 3.0]), np.array([4.5, 5.0])
    g2 = to_go(np.stack([near, deep, boxed]))
    assert np.isfinite(g2[0]) and g2[0] > g[1] - 1.0
    assert np.isinf(g2[1]) and np.isinf(g2[2])
    # the route from below heads for the gap (x grows), never across the wall, and its points
    # come nearer the goal by the cost-to-go one after another
    route = to_go.route(below, 4.0)
    assert route.shape[1] == 2 and len(route) >= 3
    assert route[-1][0] > below[0] + 3.0 and np.all(route[:, 1] < 2.85)
    assert np.all(np.diff(to_go(route)) < 0)
    assert np.linalg.norm(to_go.route(goal, 4.0)[-1] - goal) < 0.3  # at the goal: stays
    assert to_go.route(boxed, 4.0) is None
    # a goal with no free space round it has none
    assert field.to(np.array([12.0, 3.0])) is None


def maze_planner(**kw) -> HierarchicalPlanner:
    """ECAHD on maze2d-large for the circle robot, with a placer (the rules' precondition)."""
    grid, fp = builtin_map("maze2d-large"), make_footprint("circle")
    cc = CostConfig()
    sd = SparseDiffusion(load_model("sd", grid, footprint=fp), SparseConfig(num_candidates=10),
                         placer=WaypointPlacer(grid, fp, reach=1.0))
    return HierarchicalPlanner(sd, load_model("dd", grid, footprint=fp),
                               costmap=cc.make_costmap(grid), footprint_points=fp.points,
                               cost_config=cc, **kw)


def test_the_subgoal_rule_replaces_a_first_leg_that_makes_no_progress_by_one_that_does():
    """On maze2d-large, a re-plan whose first leg runs into a wall between the robot and the
    goal: the rule has SD plan toward a point along the shortest route instead, whose first leg
    is free and gains on the cost-to-go; a first leg that makes progress is left alone; off,
    and without a replan spacing (the paper's setting), it never acts."""
    grid, fp = builtin_map("maze2d-large"), make_footprint("circle")
    planner = maze_planner
    hd = planner(replan_spacing=3.0)
    assert hd.stage.subgoaling()
    assert not planner(replan_spacing=3.0, subgoals=False).stage.subgoaling()
    assert not planner().stage.subgoaling()  # Algorithm 1's horizon: no extra iterations
    # a start and a goal either side of a wall, the route round it much longer than straight
    field = GoalField(grid, fp)
    free = np.argwhere(field.graph.labels >= 0)
    rng = np.random.default_rng(3)
    S = G = None
    for _ in range(500):
        a, b = grid.cell_to_world(*free[rng.integers(len(free), size=2)].T)
        if 1.5 < np.linalg.norm(b - a) < 3.0 and hd.sparse.placer.wall_length(a, b[None])[0] > 0:
            to_go = field.to(b)
            if to_go is not None and to_go(a[None])[0] > 3 * np.linalg.norm(b - a):
                S, G = a, b
                break
    assert S is not None
    straight = SparsePlan(waypoints=np.stack([S, G]), candidates=np.stack([S, G])[None],
                          best=0, collision_costs=None, time_ms=0.0)
    gen = torch.Generator().manual_seed(0)
    times = {}
    rule = hd.stage.subgoal_rule()
    out = rule.apply(hd.sparse, S, G, straight, 20, generator=gen, times=times)
    assert out.first_leg == "subgoal" and "goal_field" in times
    w = out.waypoints
    assert np.allclose(w[0], S) and np.allclose(w[-1], G)
    assert hd.sparse.placer.wall_length(w[0], w[1][None])[0] == 0
    to_go = field.to(G)
    assert to_go(w[1:2])[0] < to_go(S[None])[0] - SUBGOAL_GAIN
    # a plan whose first leg already makes progress stays as it is
    assert rule.apply(hd.sparse, S, G, out, 20, generator=gen, times=times) is out
    # the plan toward the subgoal keeps a waypoint per replan spacing of its distance, also on
    # a goal's first plan (not Algorithm 1's P^g - p: P^g waypoints over 3 m dithered)
    first = rule.apply(hd.sparse, S, G, straight, 0, generator=gen, times=times)
    assert first.first_leg == "subgoal" and hd.sparse.config.horizon > 4
    sub = first.waypoints[-2]
    assert len(first.waypoints) - 1 == max(3, int(np.ceil(np.linalg.norm(sub - S) / 3.0)) + 1)
    # S and G either side of the wall, the route over 3x the straight line: roundabout, so
    # the rule acts from the goal's first plan; a free straight leg never is
    assert rule.roundabout(hd.sparse, S, G)
    assert not rule.roundabout(hd.sparse, S, S + 0.05 * (G - S) / np.linalg.norm(G - S))



def test_the_settle_rule_follows_a_plan_whose_legs_are_free_whole_and_only_then():
    """With a replan spacing, an SD plan whose every straight leg is free by the leg test is
    followed whole (one SD call for its legs); a plan with a leg near a wall is drawn again at
    the next waypoint; off, and without a replan spacing, every waypoint is re-planned."""
    from ecahd_core.problems import make_problems

    grid = builtin_map("maze2d-large")
    on, off = maze_planner(replan_spacing=3.0), maze_planner(replan_spacing=3.0, settle=False)
    assert maze_planner().stage.settle  # on by default, but it needs a replan spacing (the end)
    calls = []
    for hd in (on, off):
        real = hd.sparse.replan
        hd.sparse.replan = lambda *a, _r=real, **k: calls.append(hd) or _r(*a, **k)
    seen = 0
    for prob in make_problems(grid, 6, seed=5):
        n0 = len(calls)
        plan = on.plan(prob.start, prob.goal, generator=torch.Generator().manual_seed(0))
        sd_calls = len(calls) - n0
        if plan.settled is None:  # every plan drawn again had a leg near a wall
            assert all(on.sparse.placer.leg_walls(w).any() for w in plan.global_plans
                       if len(w) > 2)
            continue
        seen += 1
        followed = plan.global_plans[plan.settled]
        assert not on.sparse.placer.leg_walls(followed).any()
        assert len(plan.global_plans) == plan.settled + len(followed) - 1
        assert sd_calls <= plan.settled + 1 < len(plan.global_plans)
        assert np.allclose(plan.trajectory[-1], prob.goal, atol=1e-4)
        assert off.plan(prob.start, prob.goal,
                        generator=torch.Generator().manual_seed(0)).settled is None
    assert seen >= 2
    assert maze_planner().plan(grid.cell_to_world(*np.argwhere(~grid.occupied)[0]),
                               grid.cell_to_world(*np.argwhere(~grid.occupied)[-1]),
                               generator=torch.Generator().manual_seed(0)).settled is None


def test_a_colliding_leg_of_a_settled_plan_is_cut_and_re_planned_from_its_start():
    """Backtracking: when the exact checker finds a leg of the followed plan (after its first)
    still in collision, the iterations from that leg's start re-plan at each waypoint."""
    from ecahd_core.collision import exact_check_for
    from ecahd_core.problems import make_problems

    grid, fp = builtin_map("maze2d-large"), make_footprint("circle")
    hd = maze_planner(replan_spacing=3.0, exact_check=exact_check_for(grid, fp))
    assert hd._backtracking
    real = hd._colliding
    for prob in make_problems(grid, 6, seed=5):
        first = hd.plan(prob.start, prob.goal, generator=torch.Generator().manual_seed(0))
        if first.settled is not None and len(first.global_plans) > first.settled + 3:
            break
    else:
        raise AssertionError("no settled plan of 4 legs or more")
    cut = first.settled + 2  # neither it nor the leg before it has SD candidates to take
    leg = torch.as_tensor(first.global_plans[cut][:2], dtype=torch.float32)

    def colliding(plans, joined):  # the followed plan's leg `cut` collides wherever it is
        out = real(plans, joined)
        if len(plans) > cut and torch.allclose(plans[cut, [0, -1]], leg, atol=0.3):
            out = out.clone()
            out[cut] = True
        return out

    hd._colliding = colliding
    plan = hd.plan(prob.start, prob.goal, generator=torch.Generator().manual_seed(0))
    # cut at `cut` (re-planned at each waypoint from there; a later round may settle again)
    assert plan.backtracked >= 1 and (plan.settled is None or plan.settled >= cut)
    assert plan.backtracked > plan.first_leg.count("backtrack")  # a round took no candidate
    assert np.allclose(plan.global_plans[cut - 1], first.global_plans[cut - 1])  # kept
    assert np.allclose(plan.global_plans[cut][0], first.global_plans[cut][0])  # from its start
    assert np.allclose(plan.trajectory[-1], prob.goal, atol=1e-4)


def test_route_sight_lets_a_robot_standing_in_a_tight_door_see_along_the_route_through_it():
    from ecahd_core.progress import route_sight

    # a wall at x in [4.8, 5.0] m with a door 0.85 m wide (y in [2.85, 3.7]) for the 0.8 m
    # circle: A*'s clearance fits it, the leg test (conservative by half a cell diagonal) finds
    # the coarse route's own points a few centimetres near the jambs
    data = np.zeros((120, 200), dtype=np.int8)
    data[:, 96:100] = 100
    data[57:74, 96:100] = 0
    grid, fp = GridMap(data, 0.05, (0.0, 0.0), name="door"), make_footprint("circle")
    placer = WaypointPlacer(grid, fp, reach=1.0)
    to_go = GoalField(grid, fp).to(np.array([7.0, 1.0]))
    door = np.array([4.9, 3.27])
    route = to_go.route(door, 6.0)
    walls = placer.wall_length(door, route)
    assert walls[0] == 0 and walls[1] > 0  # a straight leg free of walls sees no further
    seen = np.flatnonzero(route_sight(placer, door, route))
    assert seen[-1] >= 1 and np.linalg.norm(route[seen[-1]] - door) > placer.step
    own = np.cumsum(placer.leg_walls(np.concatenate([door[None], route])))
    assert np.all(walls[seen] <= own[seen] + grid.resolution)
    # a leg cutting a corner that the route goes round is not seen: from the room, the points
    # past the door stay hidden (as with the strict test), those before it are seen
    room = np.array([3.0, 4.5])
    route = to_go.route(room, 6.0)
    sight = route_sight(placer, room, route)
    free = placer.wall_length(room, route) == 0
    assert np.array_equal(sight, free) and free[0] and not free[-1]


def test_a_stalled_re_plan_gets_the_subgoal_rule_whatever_its_iteration():
    """SparseStage.step applies the subgoal rule to a stalled re-plan (the caller's
    rules.stalled) at any iteration; not stalled, within Algorithm 1's P^g - 1 iterations and
    with a goal not round the walls, it does not (the rule's apply spied on)."""
    hd = maze_planner(replan_spacing=3.0)
    stage, grid = hd.stage, builtin_map("maze2d-large")
    rule = stage.subgoal_rule()
    applied = []
    rule.apply = lambda sd, S, G, sparse, iteration, **kw: applied.append(iteration) or sparse
    stage._roundabout = lambda *a: False
    free = grid.cell_to_world(*np.argwhere(~grid.occupied)[[0, -1]].T)
    S, G = free[0], free[1]
    for stalled, want in ((False, []), (True, [0])):
        applied.clear()
        stage.step(S, G, iteration=0, generator=torch.Generator().manual_seed(0),
                   stalled=stalled)
        assert applied == want
