"""The safety net (ecahd_core.safety) on tiny hand-built grids: a plan through a wall is repaired
by the A* fallback, a free plan passes untouched, an enclosed goal is unsafe, DD retries act
first; the exact checker is the judge throughout."""
import numpy as np
import pytest
import torch

from ecahd_core.collision import check_collision
from ecahd_core.errors import EcahdError
from ecahd_core.footprint import circle_footprint, make_footprint
from ecahd_core.maps import OCCUPIED, GridMap
from ecahd_core.safety import SafetyNet, SafetyNetConfig

RES = 0.1
ROBOT = circle_footprint(0.3)  # clearance 0.3 m


def grid_from_mask(occ: np.ndarray) -> GridMap:
    """(H, W) bool, row 0 at the lowest y, origin (0, 0), 0.1 m cells."""
    return GridMap(data=np.where(occ, OCCUPIED, 0).astype(np.int8), resolution=RES)


def wall_map() -> GridMap:
    """6 m x 4 m; a wall x in [2.8, 3.2), y in [0, 2.8): the only way from the left half to the
    right half is the 1.2 m gap y in [2.8, 4.0) above it (its centre line at y = 3.4 keeps
    0.6 m > 0.3 m from the wall top and from the map edge, which counts as occupied)."""
    occ = np.zeros((40, 60), dtype=bool)
    occ[:28, 28:32] = True
    return grid_from_mask(occ)


def ring_map() -> GridMap:
    """6 m x 4 m; a closed ring of wall 0.2 m thick around the square x, y in [3.6, 5.4) x
    [1.2, 3.0) (inner free square 1.4 m): a goal inside at (4.5, 2.1) keeps 0.7 m from the ring
    but no path reaches it from outside."""
    occ = np.zeros((40, 60), dtype=bool)
    occ[10:32, 34:56] = True
    occ[12:30, 36:54] = False
    return grid_from_mask(occ)


def line(a, b, n=12):
    return np.linspace(np.asarray(a, float), np.asarray(b, float), n)


def test_straight_plan_through_a_wall_is_repaired_by_the_fallback():
    grid = wall_map()
    start, goal = np.array([1.0, 1.0]), np.array([5.0, 1.0])
    plan = line(start, goal)
    assert not check_collision(plan, ROBOT, grid).collision_free  # crosses x in [2.8, 3.2)
    safe = SafetyNet(grid, ROBOT).apply(plan)
    assert safe.rule == "fallback" and safe.safe and safe.collided_before and not safe.reason
    assert check_collision(safe.path, ROBOT, grid).collision_free  # the referee agrees
    assert np.allclose(safe.path[0], start) and np.allclose(safe.path[-1], goal)
    assert len(safe.stretches) == 1
    stretch = safe.stretch_paths()[0]
    # the detour goes over the wall's top (y >= 2.8 + 0.3 at x = 3) and nowhere else
    over = stretch[np.abs(stretch[:, 0] - 3.0) < 0.5]
    assert len(over) and over[:, 1].min() >= 2.8 + 0.3 - 1e-9
    a, b = safe.stretches[0]
    assert np.array_equal(safe.path[:a + 1], plan[:a + 1])  # before the stretch: untouched


def test_collision_free_plan_passes_untouched():
    grid = wall_map()
    plan = line([1.0, 1.0], [1.0, 3.0])  # left of the wall, 1.8 m from it
    safe = SafetyNet(grid, ROBOT).apply(plan)
    assert safe.rule == "none" and not safe.collided_before and safe.stretches == ()
    assert np.array_equal(safe.path, plan)


def test_enclosed_goal_is_unsafe_with_a_reason():
    grid = ring_map()
    plan = line([1.0, 2.0], [4.5, 2.1])
    safe = SafetyNet(grid, ROBOT).apply(plan)
    assert safe.rule == "unsafe" and not safe.safe and safe.collided_before
    assert "no A* path" in safe.reason


def test_fallback_off_makes_a_colliding_plan_unsafe():
    grid = wall_map()
    safe = SafetyNet(grid, ROBOT, SafetyNetConfig(fallback="none")).apply(line([1, 1], [5, 1]))
    assert safe.rule == "unsafe" and "fallback is off" in safe.reason


class DetourPlanner:
    """A stand-in for HierarchicalPlanner's hooks: its "DD" returns one straight candidate
    (still through the wall) and one that detours over the wall's top at y = 3.4; its whole
    plans (``plan``) go straight through the wall the first ``bad_plans`` times, then over the
    top."""

    dd = object()

    def __init__(self, bad_plans: int = 10 ** 6):
        self.calls, self.plans, self.bad_plans = 0, 0, bad_plans

    def plan(self, start, goal, *, generator=None):
        from types import SimpleNamespace

        self.plans += 1
        if self.plans <= self.bad_plans:
            return SimpleNamespace(trajectory=line(start, goal))
        return SimpleNamespace(trajectory=np.array(
            [start, [start[0], 3.4], [goal[0], 3.4], goal], dtype=np.float64))

    def resample_segment(self, a, b, *, samples, generator=None):
        self.calls += 1
        straight = a + torch.linspace(0, 1, 4)[:, None] * (b - a)
        detour = torch.stack([a, torch.tensor([a[0].item(), 3.4]),
                              torch.tensor([b[0].item(), 3.4]), b])
        return torch.stack([straight, detour]), torch.zeros(2)


def test_retry_replaces_the_colliding_segment_before_any_fallback():
    grid = wall_map()
    segs = [line([0.5, 1.0], [1.5, 1.0], 4), line([1.5, 1.0], [4.5, 1.0], 4),
            line([4.5, 1.0], [5.5, 1.0], 4)]
    path = np.concatenate([segs[0]] + [s[1:] for s in segs[1:]])
    planner = DetourPlanner()
    safe = SafetyNet(grid, ROBOT, planner=planner).apply(path, segments=segs)
    assert safe.rule == "retry" and safe.retried_segments == 1 and planner.calls == 1
    assert check_collision(safe.path, ROBOT, grid).collision_free
    assert np.allclose(safe.path[3:7], [[1.5, 1.0], [1.5, 3.4], [4.5, 3.4], [4.5, 1.0]])
    assert planner.plans == 0  # the retry made it free: no plan drawn again
    # without segments (e.g. an SD or FD plan) the retry rule cannot act; the plans drawn
    # again (twice, the default) still cross the wall: A* does
    assert SafetyNet(grid, ROBOT, planner=planner).apply(path).rule == "fallback"
    assert planner.plans == 2


def test_a_plan_drawn_again_comes_before_the_fallback():
    grid = wall_map()
    start, goal = np.array([1.0, 1.0]), np.array([5.0, 1.0])
    planner = DetourPlanner(bad_plans=1)
    safe = SafetyNet(grid, ROBOT, planner=planner).apply(line(start, goal))
    assert safe.rule == "resample" and safe.resampled == 2 and planner.plans == 2
    assert safe.collided_before and safe.stretches == ()
    assert check_collision(safe.path, ROBOT, grid).collision_free
    assert np.allclose(safe.path[0], start) and np.allclose(safe.path[-1], goal)
    # the rule off: straight to A*
    planner = DetourPlanner(bad_plans=0)
    safe = SafetyNet(grid, ROBOT, SafetyNetConfig(resamples=0), planner=planner).apply(
        line(start, goal))
    assert safe.rule == "fallback" and planner.plans == 0 and safe.resampled == 0


def test_bad_segments_match_a_segment_by_segment_check():
    grid = wall_map()
    path = np.array([[1.0, 1.0], [2.0, 1.0], [2.6, 1.5], [3.4, 1.5], [4.0, 3.4], [5.0, 3.4]])
    net = SafetyNet(grid, make_footprint("quadruped"))
    one_by_one = [not net.check(path[k:k + 2]).collision_free for k in range(len(path) - 1)]
    assert net._bad_segments(path).tolist() == one_by_one
    assert one_by_one[2] and one_by_one[3] and not one_by_one[0]


def test_config_is_validated():
    with pytest.raises(EcahdError, match="fallback"):
        SafetyNetConfig(fallback="rrt")
    with pytest.raises(EcahdError):
        SafetyNetConfig(retries=-1)
    with pytest.raises(EcahdError, match="resamples"):
        SafetyNetConfig(resamples=-1)
