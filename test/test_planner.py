"""Algorithm 1 with the shipped models: the executed path joins start to goal, DD runs exactly
when the straight local plan's collision cost exceeds c_th."""
import numpy as np
import pytest
import torch

from ecahd_core.cost import CollisionCost, CostConfig
from ecahd_core.errors import EcahdError
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import builtin_map
from ecahd_core.model_zoo import load_model
from ecahd_core.planning.dense import DenseConfig
from ecahd_core.planning.hierarchical import HierarchicalPlanner
from ecahd_core.planning.sparse import SparseConfig, SparseDiffusion

GRID = builtin_map("maze2d-large")


def make_planner(c_th=0.1, enabled=True, robot="circle", **kwargs):
    """ECAHD on maze2d-large with SD best of 4; ``kwargs`` go to HierarchicalPlanner."""
    fp = make_footprint(robot)
    cc = CostConfig()
    sd = SparseDiffusion(load_model("sd", GRID, footprint=fp), SparseConfig(num_candidates=4))
    return HierarchicalPlanner(sd, load_model("dd", GRID, footprint=fp),
                               costmap=cc.make_costmap(GRID), footprint_points=fp.points,
                               cost_config=cc, dense=DenseConfig(c_th=c_th, enabled=enabled),
                               **kwargs)


def test_algorithm1_reaches_goal_in_pg_iterations():
    planner = make_planner()
    start, goal = np.array([1.5, 1.5]), np.array([10.5, 7.5])
    plan = planner.plan(start, goal, generator=torch.Generator().manual_seed(0))
    P_g = planner.sparse.config.horizon
    assert len(plan.segments) == P_g - 1
    assert [len(g) for g in plan.global_plans] == list(range(P_g, 1, -1))  # shrinking horizon
    assert np.allclose(plan.trajectory[0], start) and np.allclose(plan.trajectory[-1], goal, atol=1e-5)
    # consecutive local plans are joined end to start
    for a, b in zip(plan.segments, plan.segments[1:]):
        assert np.allclose(a[-1], b[0])
    assert set(plan.timings_ms) == {"sd", "j_check", "dd", "polish", "exact", "total"}


def test_a_replan_spacing_keeps_waypoints_until_the_goal_is_near():
    start, goal = np.array([1.5, 1.5]), np.array([10.5, 7.5])
    planner = make_planner(replan_spacing=1.0)
    plan = planner.plan(start, goal, generator=torch.Generator().manual_seed(0))
    P_g = planner.sparse.config.horizon
    ends = [(g[0], g[-1]) for g in plan.global_plans]
    for (s, g), wp in zip(ends, plan.global_plans):  # each plan as long as its distance asks
        need = min(P_g, int(np.ceil(np.linalg.norm(g - s) / 1.0 - 1e-9)) + 1)
        assert len(wp) >= need
    # only the last plan goes straight to the goal, and only from within 1 m of it
    assert len(plan.global_plans[-1]) == 2 and all(len(w) > 2 for w in plan.global_plans[:-1])
    assert np.linalg.norm(ends[-1][1] - ends[-1][0]) <= 1.0 + 1e-5
    assert np.allclose(plan.trajectory[-1], goal, atol=1e-5)
    with pytest.raises(EcahdError, match="replan_spacing"):
        make_planner(replan_spacing=-1.0)


def test_out_of_iterations_the_last_sd_plan_is_followed_whole(monkeypatch):
    # a replan spacing of 0.1 m keeps every re-plan at the full horizon; with no extra
    # iterations allowed, iteration P^g - 2 is the last SD call, and its plan is followed to the
    # goal leg by leg instead of one straight leg through the maze's walls
    import ecahd_core.planning.rules as rules_module

    monkeypatch.setattr(rules_module, "MAX_EXTRA_ITERATIONS", 0)
    start, goal = np.array([1.5, 1.5]), np.array([10.5, 7.5])
    planner = make_planner(replan_spacing=0.1)
    plan = planner.plan(start, goal, generator=torch.Generator().manual_seed(0))
    P_g = planner.sparse.config.horizon
    last = plan.global_plans[P_g - 2]
    assert len(last) == P_g  # the full horizon still
    assert len(plan.global_plans) == P_g - 2 + len(last) - 1 == len(plan.segments)
    for q, wp in enumerate(plan.global_plans[P_g - 2:]):
        np.testing.assert_array_equal(wp, last[q:])
    assert len(plan.first_leg) == len(plan.global_plans)
    np.testing.assert_allclose(plan.trajectory[-1], goal, atol=1e-5)
    for a, b in zip(plan.segments, plan.segments[1:]):
        assert np.allclose(a[-1], b[0])


@pytest.mark.parametrize("c_th", [0.1, 1e9])
def test_dd_runs_only_above_threshold(c_th):
    planner = make_planner(c_th=c_th)
    calls = []
    original = planner.refine

    def counting_refine(starts, *a, **k):
        calls.append(len(starts))
        return original(starts, *a, **k)

    planner.refine = counting_refine
    plan = planner.plan(np.array([1.5, 1.5]), np.array([6.5, 5.5]),
                        generator=torch.Generator().manual_seed(1))
    above = [c > c_th for c, _ in plan.local_costs]
    assert plan.dd_segments == above
    # every segment above c_th, and only those, refined in one DD batch after the SD calls
    assert calls == ([sum(above)] if any(above) else [])
    assert sum(above) == plan.dd_calls
    if c_th > 1e8:
        assert plan.dd_calls == 0


def test_replan_once_samples_sd_once_and_follows_it():
    fp = make_footprint("quadruped")
    cc = CostConfig()
    sd = SparseDiffusion(load_model("sd", GRID, footprint=fp), SparseConfig(num_candidates=4))
    calls = []
    original = sd.plan
    sd.plan = lambda *a, **k: calls.append(1) or original(*a, **k)
    hd = HierarchicalPlanner(sd, load_model("dd", GRID, footprint=fp), costmap=cc.make_costmap(GRID),
                             footprint_points=fp.points, cost_config=cc, replan="once")
    plan = hd.plan(np.array([1.5, 1.5]), np.array([10.5, 7.5]),
                   generator=torch.Generator().manual_seed(0))
    assert len(calls) == 1
    first = plan.global_plans[0]
    for p, g in enumerate(plan.global_plans):
        assert np.allclose(g, first[p:])  # the same plan, shrinking from the front
    assert np.allclose(plan.trajectory[-1], [10.5, 7.5], atol=1e-5)
    # all segments checked and refined in one batch: DD exactly where c^l > c_th
    assert plan.dd_segments == [c > hd.dense.c_th for c, _ in plan.local_costs]
    for a, b in zip(plan.segments, plan.segments[1:]):
        assert np.allclose(a[-1], b[0])


@pytest.mark.parametrize("replan", ["every_waypoint", "once"])
def test_polishing_moves_only_colliding_local_plans_and_keeps_start_and_goal(replan):
    fp = make_footprint("circle")
    cc = CostConfig()
    sd = SparseDiffusion(load_model("sd", GRID, footprint=fp), SparseConfig(num_candidates=4))
    start, goal = np.array([1.5, 1.5]), np.array([10.5, 7.5])
    plans = {}
    for steps in (0, 30):
        hd = HierarchicalPlanner(sd, load_model("dd", GRID, footprint=fp),
                                 costmap=cc.make_costmap(GRID), footprint_points=fp.points,
                                 cost_config=cc, dense=DenseConfig(polish_steps=steps),
                                 replan=replan)
        plans[steps] = hd.plan(start, goal, generator=torch.Generator().manual_seed(0))
    paper, ours = plans[0], plans[30]
    assert not any(paper.polished) and paper.timings_ms["polish"] == 0.0
    assert any(ours.polished)
    assert np.allclose(ours.trajectory[0], start) and np.allclose(ours.trajectory[-1], goal, atol=1e-5)
    for a, b in zip(ours.segments, ours.segments[1:]):
        assert np.allclose(a[-1], b[0])  # still joined end to start
    # the polished path's total collision cost is below the paper's
    assert sum(c for _, c in ours.local_costs) < sum(c for _, c in paper.local_costs)


@pytest.mark.parametrize("keep_better", [True, False])
def test_keep_better_never_accepts_a_dd_plan_costlier_than_the_straight_one(keep_better):
    fp = make_footprint("quadruped")
    cc = CostConfig()
    sd = SparseDiffusion(load_model("sd", GRID, footprint=fp), SparseConfig(num_candidates=4))
    hd = HierarchicalPlanner(sd, load_model("dd", GRID, footprint=fp), costmap=cc.make_costmap(GRID),
                             footprint_points=fp.points, cost_config=cc, replan="once",
                             dense=DenseConfig(c_th=0.0, polish_steps=0, keep_better=keep_better))
    wall = torch.tensor([4.5, 1.5])  # maze2d-large: (4.5, 1.5) is inside a wall

    def worse_refine(starts, goals, **_):  # a "DD" that detours every segment through a wall
        frac = torch.linspace(0.0, 1.0, hd.dense.points)[None, :, None]
        segs = starts[:, None] + frac * (goals - starts)[:, None]
        segs[:, 1:-1] = wall
        return segs, hd.local_cost(segs, goals)

    hd.refine = worse_refine
    plan = hd.plan(np.array([1.5, 1.5]), np.array([10.5, 7.5]),
                   generator=torch.Generator().manual_seed(0))
    for (c_before, c_after), seg in zip(plan.local_costs, plan.segments):
        through_wall = np.allclose(seg[1], wall.numpy())
        if keep_better:  # the cheaper straight plan stays wherever the detour costs more
            assert c_after <= c_before and not (through_wall and c_after > c_before)
        elif c_before > 0.0:
            assert through_wall  # the paper accepts DD's plan whatever it costs


def _speck_checker(specks, radius):
    """A stand-in exact checker: segment i -> i + 1 of a path collides when it passes within
    ``radius`` of a speck. path (N, 2) -> (N - 1,) bool."""
    def check(path):
        a, b = path[:-1, None], path[1:, None]  # (N - 1, 1, 2)
        ab = b - a
        t = np.clip(((specks[None] - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12),
                    0.0, 1.0)
        d = np.linalg.norm(a + t[..., None] * ab - specks[None], axis=-1)  # (N - 1, S)
        return (d < radius).any(axis=1)
    return check


@pytest.mark.parametrize("replan", ["every_waypoint", "once"])
def test_exact_rule_puts_back_a_free_plan_where_the_refined_one_collides(replan):
    start, goal = np.array([1.5, 1.5]), np.array([10.5, 7.5])

    def plan_with(check):  # the shortcut rule off: this test is about the joined local plans
        hd = make_planner(replan=replan, exact_check=check, shortcut=False)
        return hd.plan(start, goal, generator=torch.Generator().manual_seed(0))

    base = plan_with(None)
    assert base.exact_kept == [False] * len(base.segments)
    # a speck on every refined segment's point farthest from its straight line, so that the
    # refined plan collides and the straight one (and DD's plan when it is near it) does not
    specks, radii = [], []
    for seg, used, pol in zip(base.segments, base.dd_segments, base.polished):
        if not (used or pol):
            continue
        line = np.linspace(seg[0], seg[-1], len(seg))
        off = np.linalg.norm(seg - line, axis=1)
        if off.max() > 1e-3:
            specks.append(seg[int(off.argmax())])
            radii.append(0.4 * off.max())
    assert specks, "no refined segment on this problem"
    specks = np.array(specks)
    radius = min(radii)
    check = _speck_checker(specks, radius)
    assert check(base.trajectory).any()
    ours = plan_with(check)
    assert any(ours.exact_kept)
    # every kept segment is free by the checker, and is the straight or an unpolished plan
    for seg, kept in zip(ours.segments, ours.exact_kept):
        if kept:
            assert not check(seg).any()
    assert check(ours.trajectory).sum() < check(base.trajectory).sum()
    assert np.allclose(ours.trajectory[0], start) and np.allclose(ours.trajectory[-1], goal,
                                                                  atol=1e-5)
    for a, b in zip(ours.segments, ours.segments[1:]):
        assert np.allclose(a[-1], b[0])  # still joined end to start
    # a checker that finds everything free changes nothing
    same = plan_with(lambda path: np.zeros(len(path) - 1, dtype=bool))
    assert np.array_equal(same.trajectory, base.trajectory) and not any(same.exact_kept)


def test_the_shortcut_rule_pulls_a_free_plan_taut_and_keeps_its_segments():
    """On a building (a held-out generated office, the shipped generalists): maze2d-large's 1 m
    corridors leave no straight shortcut within J's margin."""
    from ecahd_core.bench.replan import load_bench_map
    from ecahd_core.collision import check_collision
    from ecahd_core.cost import CollisionCost
    from ecahd_core.problems import make_problems

    grid, fp = load_bench_map("office:16x16:0.05:7001"), make_footprint("circle")
    sd = SparseDiffusion.for_map(grid, fp, SparseConfig(), cost=CollisionCost.build(grid, fp),
                                 model="general")
    problem = make_problems(grid, 4, seed=5)[3]
    plans = {}
    for on in (False, True):
        hd = HierarchicalPlanner.for_map(grid, fp, sd, model="general", shortcut=on)
        plans[on] = hd.plan(problem.start, problem.goal,
                            generator=torch.Generator().manual_seed(0))
    off, ours = plans[False], plans[True]
    assert check_collision(off.trajectory, fp, grid).collision_free  # else the rule stays out
    assert not off.shortcut and ours.shortcut and "shortcut" in ours.timings_ms
    assert check_collision(ours.trajectory, fp, grid).collision_free
    assert np.array_equal(ours.trajectory[[0, -1]], off.trajectory[[0, -1]])
    length = lambda p: np.linalg.norm(np.diff(p, axis=0), axis=1).sum()  # noqa: E731
    assert length(ours.trajectory) < length(off.trajectory) - 0.2
    # the same iterations and local plans: the rule only pulls the joined path
    assert len(ours.segments) == len(off.segments)
    for a, b in zip(ours.segments, off.segments):
        assert np.array_equal(a, b)
    assert ours.timings_ms["total"] >= ours.timings_ms["shortcut"]


def test_resample_segment_gives_a_batch_of_dd_plans_between_fixed_ends():
    planner = make_planner()
    a, b = torch.tensor([1.5, 1.5]), torch.tensor([3.5, 2.5])  # the straight line clips a wall
    gen = torch.Generator().manual_seed(0)
    segs, cost = planner.resample_segment(a, b, samples=5, generator=gen)
    assert segs.shape == (5, planner.dense.points, 2) and cost.shape == (5,)
    assert torch.allclose(segs[:, 0], a.expand(5, 2), atol=1e-5)
    assert torch.allclose(segs[:, -1], b.expand(5, 2), atol=1e-5)
    assert torch.allclose(cost, planner.local_cost(segs, b.expand(5, 2)).float(), atol=1e-4)
    assert len({tuple(s[1].tolist()) for s in segs}) > 1  # fresh samples, not one copy


def test_safety_net_with_the_planner_leaves_a_collision_free_plan_as_it_is():
    from ecahd_core.safety import SafetyNet

    planner = make_planner()
    gen = torch.Generator().manual_seed(0)
    plan = planner.plan(np.array([1.5, 1.5]), np.array([10.5, 7.5]), generator=gen)
    net = SafetyNet(GRID, make_footprint("circle"), planner=planner)
    safe = net.apply(plan.trajectory, segments=plan.segments, generator=gen)
    assert safe.safe and net.check(safe.path).collision_free
    if safe.rule == "none":
        assert np.array_equal(safe.path, plan.trajectory)
    assert np.allclose(safe.path[0], [1.5, 1.5]) and np.allclose(safe.path[-1], [10.5, 7.5], atol=1e-5)


def _cost_triple(robot="circle"):
    fp = make_footprint(robot)
    cc = CostConfig()
    return fp, CollisionCost(costmap=cc.make_costmap(GRID),
                             footprint_points=torch.as_tensor(fp.points, dtype=torch.float64),
                             config=cc)


def test_max_spacing_densifies_long_legs_and_keeps_the_ends():
    fp, cost = _cost_triple()
    ckpt = load_model("sd", GRID, footprint=fp)
    start, goal = np.array([1.5, 1.5]), np.array([10.5, 7.5])
    plain = SparseDiffusion(ckpt, SparseConfig(num_candidates=4, selection="collision_aware"),
                            cost=cost).plan(start, goal, generator=torch.Generator().manual_seed(0))
    assert plain.waypoints.shape == (10, 2)
    sd = SparseDiffusion(ckpt, SparseConfig(num_candidates=4, selection="collision_aware",
                                            max_spacing=0.5), cost=cost)
    dense = sd.plan(start, goal, generator=torch.Generator().manual_seed(0)).waypoints
    legs = np.linalg.norm(np.diff(dense, axis=0), axis=-1)
    assert len(dense) > 10
    assert np.array_equal(dense[0], start) and np.array_equal(dense[-1], goal)
    # the first round's legs are ~length / (h - 1); two rounds leave most legs short
    assert np.median(legs) <= 0.5 and legs.max() < np.linalg.norm(np.diff(plain.waypoints, axis=0),
                                                                  axis=-1).max()
    # off: bit for bit the paper's plan
    again = SparseDiffusion(ckpt, SparseConfig(num_candidates=4, selection="collision_aware"),
                            cost=cost).plan(start, goal, generator=torch.Generator().manual_seed(0))
    assert np.array_equal(again.waypoints, plain.waypoints)


@pytest.mark.parametrize("replan", ["every_waypoint", "once"])
def test_algorithm1_with_max_spacing_reaches_the_goal_through_every_waypoint(replan):
    fp, cost = _cost_triple()
    sd = SparseDiffusion(load_model("sd", GRID, footprint=fp),
                         SparseConfig(num_candidates=4, selection="collision_aware",
                                      max_spacing=0.6), cost=cost)
    hd = HierarchicalPlanner(sd, load_model("dd", GRID, footprint=fp), costmap=cost.costmap,
                             footprint_points=fp.points, cost_config=cost.config, replan=replan)
    start, goal = np.array([1.5, 1.5]), np.array([10.5, 7.5])
    plan = hd.plan(start, goal, generator=torch.Generator().manual_seed(0))
    assert len(plan.segments) > 9  # more iterations than P^g - 1
    assert np.allclose(plan.trajectory[0], start) and np.allclose(plan.trajectory[-1], goal,
                                                                  atol=1e-5)
    for a, b in zip(plan.segments, plan.segments[1:]):
        assert np.allclose(a[-1], b[0])
    assert len(plan.global_plans) == len(plan.segments)


def test_a_batch_of_local_stages_gives_each_segment_what_it_gets_alone():
    # DD replaced by a deterministic stand-in (a detour through a wall for some segments), so
    # the batch and the one-by-one runs can be compared exactly; polishing on, the last end free
    fp = make_footprint("quadruped")
    cc = CostConfig()
    sd = SparseDiffusion(load_model("sd", GRID, footprint=fp), SparseConfig(num_candidates=4))
    hd = HierarchicalPlanner(sd, load_model("dd", GRID, footprint=fp), costmap=cc.make_costmap(GRID),
                             footprint_points=fp.points, cost_config=cc,
                             dense=DenseConfig(c_th=0.0))

    def fake_refine(starts, goals, **_):  # the straight plan bent 0.3 m sideways in the middle
        frac = torch.linspace(0.0, 1.0, hd.dense.points)[None, :, None]
        segs = starts[:, None] + frac * (goals - starts)[:, None]
        segs[:, 1:-1, 1] += 0.3
        return segs, hd.local_cost(segs, goals)

    hd.refine = fake_refine
    # maze2d-large: (1.5, 1.5) -> (2.5, 1.5) free, (3.5, 2.5) clips a wall, (1.5, 1.5) -> (1.5, 3.5)
    a = torch.tensor([[1.5, 1.5], [2.5, 1.5], [1.5, 1.5], [3.5, 5.5]])
    b = torch.tensor([[2.5, 1.5], [3.5, 2.5], [1.5, 3.5], [4.5, 5.5]])
    end_fixed = torch.tensor([True, True, False, False])
    batch = hd.local_stages(a, b, end_fixed=end_fixed)
    assert batch.plans.shape == (4, hd.dense.points, 2)
    assert batch.polished.any() and batch.dd_used.any()
    for k in range(4):
        alone = hd.local_stage(a[k], b[k], end_fixed=bool(end_fixed[k]))
        assert torch.allclose(batch.plans[k], alone.plan, atol=1e-6)
        assert float(batch.c_before[k]) == pytest.approx(alone.c_before, rel=1e-5, abs=1e-7)
        assert float(batch.c_after[k]) == pytest.approx(alone.c_after, rel=1e-5, abs=1e-7)
        assert (bool(batch.dd_used[k]), bool(batch.polished[k])) == (alone.dd_used, alone.polished)
        assert torch.equal(batch.plans[k, 0], a[k])
        if end_fixed[k]:
            assert torch.equal(batch.plans[k, -1], b[k])


def test_local_plans_have_the_points_the_dd_checkpoint_learnt(tmp_path):
    # P^l is the DD checkpoint's (DenseConfig.points None): the paper's 4 for the shipped model;
    # a DD trained on 7-point segments (a big map's "auto" P^l) gives 7-point local plans
    from ecahd_core.diffusion import DenoiserConfig, Normalizer, TrainConfig, train
    from ecahd_core.model_zoo import dense_points

    fp = make_footprint("circle")
    cc = CostConfig()
    shipped = load_model("dd", GRID, footprint=fp)
    assert dense_points(shipped) == 4 and make_planner().dense.points == 4
    sd = SparseDiffusion(load_model("sd", GRID, footprint=fp), SparseConfig(num_candidates=2))
    common = dict(costmap=cc.make_costmap(GRID), footprint_points=fp.points, cost_config=cc)
    with pytest.raises(EcahdError, match=r"learnt P\^l in \[4\]"):
        HierarchicalPlanner(sd, shipped, dense=DenseConfig(points=7), **common)
    assert HierarchicalPlanner(sd, None, dense=DenseConfig(enabled=False),
                               **common).dense.points == 4
    rng = np.random.default_rng(0)
    a = rng.uniform([1, 1], [11, 8], size=(32, 2))
    segs = a[:, None] + np.linspace(0, 1, 7)[None, :, None] * rng.normal(0, 0.5, (32, 1, 2))
    meta = {**shipped.meta}
    result = train(DenoiserConfig(max_horizon=7, d_model=16, n_layers=1, n_heads=2),
                   {7: segs.astype(np.float32)}, Normalizer.from_bounds(*GRID.bounds),
                   TrainConfig(steps=2, batch_size=8, warmup_steps=0, device="cpu"), kind="dd",
                   out_path=tmp_path / "dd7.pt", meta=meta, progress=False)
    hd = HierarchicalPlanner(sd, result.checkpoint, dense=DenseConfig(c_th=-1.0), **common)
    assert hd.dense.points == 7
    stages = hd.local_stages(torch.tensor([[1.5, 1.5]]), torch.tensor([[1.5, 3.5]]),
                             end_fixed=torch.tensor([True]))
    assert stages.plans.shape == (1, 7, 2) and bool(stages.dd_used[0])
    np.testing.assert_allclose(stages.plans[0, [0, -1]].numpy(), [[1.5, 1.5], [1.5, 3.5]],
                               atol=1e-5)


def test_dd_guidance_weight_follows_the_cost_map_margin():
    """omega is chosen at the 0.1 m margin; on a wider one (a building's 0.5 m) DD is guided by
    omega x 0.1 / margin, so the paper's tables keep 0.03."""
    from ecahd_core.planning.dense import guidance_weight_for

    fp = make_footprint("circle")
    sd = SparseDiffusion(load_model("sd", GRID, footprint=fp), SparseConfig(num_candidates=4))
    for margin, want in ((0.1, 0.03), (0.5, 0.006), (0.2, 0.015)):
        cc = CostConfig(margin=margin)
        hd = HierarchicalPlanner(sd, load_model("dd", GRID, footprint=fp),
                                 costmap=cc.make_costmap(GRID), footprint_points=fp.points,
                                 cost_config=cc, dense=DenseConfig())
        assert hd.dd.config.guidance_weight == pytest.approx(want)
        assert guidance_weight_for(0.03, margin) == pytest.approx(want)


def test_a_straight_last_leg_through_a_wall_gets_leg_repair_unless_forced():
    """A horizon-2 plan (start, goal) is one leg: the placer's leg repair bends it like any other
    SD leg; HierarchicalPlanner's forced last plan (densify False) stays straight."""
    from ecahd_core.placement import WaypointPlacer

    fp = make_footprint("circle")
    placer = WaypointPlacer(GRID, fp, reach=1.0)
    sd = SparseDiffusion(load_model("sd", GRID, footprint=fp), SparseConfig(num_candidates=4),
                         placer=placer)
    start, goal = np.array([1.5, 1.5]), np.array([1.5, 3.5])  # a wall between, free round it
    assert placer.leg_walls(np.stack([start, goal]))[0] > 0
    bent = sd.plan(start, goal, horizon=2).waypoints
    assert len(bent) > 2 and np.array_equal(bent[[0, -1]], np.stack([start, goal]))
    assert placer.leg_walls(bent).sum() < placer.leg_walls(np.stack([start, goal]))[0]
    forced = sd.plan(start, goal, horizon=2, densify=False).waypoints
    assert np.array_equal(forced, np.stack([start, goal]))


def test_every_waypoint_repairs_only_the_followed_leg_and_plans_the_same():
    """HierarchicalPlanner's every_waypoint loop follows only each re-plan's first leg, so leg
    repair on that leg alone (``repair_legs=1``) gives the very same trajectory as on all."""
    from ecahd_core.placement import WaypointPlacer

    fp = make_footprint("circle")
    cc = CostConfig()
    # the free-first-leg rule acts on the followed leg only, so it is off in both runs here
    sd = SparseDiffusion(load_model("sd", GRID, footprint=fp),
                         SparseConfig(num_candidates=4, leg_batches=-1),
                         placer=WaypointPlacer(GRID, fp, reach=1.0))
    hd = HierarchicalPlanner(sd, load_model("dd", GRID, footprint=fp),
                             costmap=cc.make_costmap(GRID), footprint_points=fp.points,
                             cost_config=cc)
    start, goal = np.array([1.5, 1.5]), np.array([10.5, 7.5])
    asked = []
    plain = sd.plan

    def spy(*args, repair_legs=None, **kwargs):
        asked.append(repair_legs)
        return plain(*args, repair_legs=repair_legs, **kwargs)

    sd.plan = spy
    one = hd.plan(start, goal, generator=torch.Generator().manual_seed(0))
    assert set(asked) == {1}
    assert one.first_leg == [""] * len(one.global_plans) and not one.first_leg_changed
    sd.plan = lambda *args, repair_legs=None, **kwargs: plain(*args, **kwargs)
    every = hd.plan(start, goal, generator=torch.Generator().manual_seed(0))
    np.testing.assert_array_equal(one.trajectory, every.trajectory)


# maze2d-large's corner: (1.5, 1.5) and (1.5, 3.5) lie in free bands 1 m apart with a wall between
# (x 0-2, y 2-3); the way round is the 1 m gap at x 2-3
S_, G_ = np.array([1.5, 1.5]), np.array([1.5, 3.5])
THROUGH = np.array([S_, [1.5, 2.5], G_])  # the shortest: its first leg ends in the wall
ROUND = np.array([S_, [2.5, 1.5], G_])  # longer; its first leg is free


def scripted_sd(batches, *, leg_batches=3, num_candidates=4):
    """A SparseDiffusion whose sampler returns ``batches[horizon]`` (N, horizon, 2) [m] and
    records the horizons asked; placement only (a 0.1 m reach, no leg repair), so the test's
    candidates keep their legs."""
    from types import SimpleNamespace

    from ecahd_core.placement import WaypointPlacer

    fp = make_footprint("circle")
    sd = SparseDiffusion(load_model("sd", GRID, footprint=fp),
                         SparseConfig(num_candidates=num_candidates, leg_batches=leg_batches),
                         placer=WaypointPlacer(GRID, fp, reach=0.1, leg_rounds=0))
    asked = []

    def sample(*, batch, horizon, **kwargs):
        asked.append(horizon)
        return SimpleNamespace(trajectories=torch.as_tensor(batches[horizon], dtype=torch.float32))

    sd.sampler.sample = sample
    return sd, asked


def test_rank_candidates_starts_with_the_rules_choice_and_lists_every_candidate():
    from ecahd_core.planning.sparse import rank_candidates, select_best

    rng = np.random.default_rng(0)
    cands = rng.uniform(0, 10, (6, 4, 2))
    cands[:, -1] = [9.0, 9.0]
    col = rng.uniform(0, 1, 6)
    for rule, costs in (("shortest_reaching", None), ("collision_aware", col)):
        order = rank_candidates(cands, np.array([9.0, 9.0]), rule=rule, collision_costs=costs)
        assert sorted(order) == list(range(6))
        assert order[0] == select_best(cands, np.array([9.0, 9.0]), rule=rule,
                                       collision_costs=costs)
    order = rank_candidates(cands, np.array([9.0, 9.0]), rule="collision_aware",
                            collision_costs=col)
    assert list(col[order[1:]]) == sorted(col[order[1:]])


def test_a_first_leg_through_a_wall_gives_way_to_a_candidate_whose_first_leg_is_free():
    sd, asked = scripted_sd({3: np.stack([THROUGH, ROUND, THROUGH, THROUGH])})
    assert sd.placer.leg_walls(THROUGH)[0] > 0 and sd.placer.leg_walls(ROUND)[0] == 0
    plan = sd.plan(S_, G_, horizon=3, repair_legs=1)
    assert plan.first_leg == "other" and plan.best == 1 and asked == [3]
    np.testing.assert_allclose(plan.waypoints, ROUND, atol=1e-6)
    # the paper's choice where the caller follows every leg, or with the rule off
    for legs, batches in ((None, 3), (1, -1)):
        sd, asked = scripted_sd({3: np.stack([THROUGH, ROUND, THROUGH, THROUGH])},
                                leg_batches=batches)
        plan = sd.plan(S_, G_, horizon=3, repair_legs=legs)
        assert plan.first_leg == "" and plan.best == 0 and asked == [3]
        np.testing.assert_allclose(plan.waypoints, THROUGH, atol=1e-6)


def test_with_no_free_first_leg_further_batches_get_one_waypoint_more_each():
    through = {h: np.repeat(np.linspace(S_, G_, h)[None], 4, axis=0) for h in range(2, 12)}
    sd, asked = scripted_sd(through, leg_batches=3)
    plan = sd.plan(S_, G_, horizon=3, repair_legs=1)
    assert asked == [3, 4, 5, 6] and plan.first_leg == "none"
    np.testing.assert_allclose(plan.waypoints, THROUGH, atol=1e-6)  # the selected one stays
    # found in the second further batch: its candidates and index come with the plan
    found = dict(through)
    found[5] = found[5].copy()
    found[5][2] = np.array([S_, [2.5, 1.5], [2.5, 2.5], [2.5, 3.5], G_])
    sd, asked = scripted_sd(found, leg_batches=3)
    plan = sd.plan(S_, G_, horizon=3, repair_legs=1)
    assert asked == [3, 4, 5] and plan.first_leg == "batch" and plan.best == 2
    assert plan.candidates.shape == (4, 5, 2)
    np.testing.assert_allclose(plan.waypoints, found[5][2], atol=1e-6)
    # a straight last leg (horizon 2) into the next room gets a waypoint to place; never more
    # waypoints than the model learnt
    top = sd.sampler.model.config.max_horizon
    sd, asked = scripted_sd(through, leg_batches=top + 2)
    assert sd.plan(S_, G_, horizon=2, repair_legs=1).first_leg == "none"
    assert asked[:2] == [3, 4] and max(asked) == top and len(asked) == top + 2
    with pytest.raises(EcahdError, match="leg_batches"):
        SparseConfig(leg_batches=-2)


def test_backtracking_takes_another_candidate_where_a_local_plan_still_collides():
    """A stand-in checker with a speck on the first re-plan's waypoint: every local plan to it
    collides, so without backtracking the plan keeps the collision; with it the first iteration
    takes another candidate of its SD batch and the iterations after it are planned again."""
    from ecahd_core.placement import WaypointPlacer

    fp = make_footprint("circle")
    cc = CostConfig()

    def planner(check, backtracks, placer=True):
        sd = SparseDiffusion(load_model("sd", GRID, footprint=fp), SparseConfig(num_candidates=10),
                             placer=WaypointPlacer(GRID, fp, reach=1.0) if placer else None)
        return HierarchicalPlanner(sd, load_model("dd", GRID, footprint=fp),
                                   costmap=cc.make_costmap(GRID), footprint_points=fp.points,
                                   cost_config=cc, exact_check=check, backtracks=backtracks)

    start, goal = np.array([1.5, 1.5]), np.array([10.5, 7.5])
    run = lambda hd: hd.plan(start, goal, generator=torch.Generator().manual_seed(0))  # noqa: E731
    free = lambda path: np.zeros(len(path) - 1, dtype=bool)  # noqa: E731
    base = run(planner(free, 2))
    assert base.backtracked == 0 and "backtrack" not in base.first_leg
    check = _speck_checker(base.global_plans[0][1][None], 0.3)
    off = run(planner(check, 0))
    assert check(off.trajectory).any() and off.backtracked == 0
    ours = run(planner(check, 2))
    assert ours.backtracked >= 1 and "backtrack" in ours.first_leg
    assert check(ours.trajectory).sum() < check(off.trajectory).sum()
    assert len(ours.first_leg) == len(ours.global_plans) == len(ours.segments)
    assert np.allclose(ours.trajectory[0], start) and np.allclose(ours.trajectory[-1], goal,
                                                                  atol=1e-5)
    for a, b in zip(ours.segments, ours.segments[1:]):
        assert np.allclose(a[-1], b[0])
    # without waypoint placement (maze2d-large's setting) it never acts: the paper's plans
    plain = run(planner(check, 2, placer=False))
    assert plain.backtracked == 0
    with pytest.raises(EcahdError, match="backtracks"):
        planner(free, -1)


@pytest.mark.parametrize("warm_plan", ["through", "round"])
def test_a_warm_replan_whose_first_leg_crosses_a_wall_is_drawn_again_from_noise(warm_plan):
    """SparseStage with warm starts: a warm re-plan's first leg through a wall sends the re-plan
    back to noise under the free-first-leg rule; a warm re-plan whose first leg is free stays."""
    from types import SimpleNamespace

    from ecahd_core.placement import WaypointPlacer
    from ecahd_core.planning.rules import SparseStage

    fp = make_footprint("circle")
    sd = SparseDiffusion(load_model("sd", GRID, footprint=fp),
                         SparseConfig(num_candidates=4, leg_batches=3, warm_fraction=0.3),
                         placer=WaypointPlacer(GRID, fp, reach=0.1, leg_rounds=0))
    warm_draw = THROUGH if warm_plan == "through" else ROUND
    calls = []

    def sample(*, batch, horizon, warm_start=None, **kwargs):
        calls.append(warm_start is not None)
        plan = warm_draw if warm_start is not None else ROUND
        return SimpleNamespace(trajectories=torch.as_tensor(np.stack([plan] * batch),
                                                            dtype=torch.float32))

    sd.sampler.sample = sample
    step = SparseStage(sd).step(S_, G_, previous=THROUGH, iteration=1, horizon=3)
    np.testing.assert_allclose(step.waypoints, ROUND, atol=1e-6)
    if warm_plan == "through":
        assert calls == [True, False]
        assert step.sparse.first_leg == "cold" and not step.sparse.warm
    else:
        assert calls == [True] and step.sparse.warm and step.sparse.first_leg == ""
    # a goal's first plan is never warm
    calls.clear()
    SparseStage(sd).step(S_, G_, iteration=0, horizon=3)
    assert calls == [False]
