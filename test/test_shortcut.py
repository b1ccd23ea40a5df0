"""The shortcut rule (ecahd_core.shortcut): a free plan pulled taut by straight segments that pass
J's local test and the exact checker, never into a wall, never changing its ends."""
import numpy as np
import pytest
import torch

from ecahd_core.collision import check_collision, exact_check_for
from ecahd_core.cost import CollisionCost, CostConfig
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import GridMap
from ecahd_core.shortcut import shortcut_path

RES = 0.05


def room_with_pillar():
    """A 10 x 6 m room with a wall round it and a 2 x 2 m pillar in the middle (x 4-6, y 2-4)."""
    occ = np.zeros((120, 200), dtype=bool)
    occ[:2], occ[-2:], occ[:, :2], occ[:, -2:] = True, True, True, True
    occ[40:80, 80:120] = True
    return GridMap(data=np.where(occ, 100, 0).astype(np.int8), resolution=RES, name="pillar")


def pieces(robot="circle"):
    grid = room_with_pillar()
    fp = make_footprint(robot)
    cost = CollisionCost.build(grid, fp, CostConfig(margin=0.3))
    return grid, fp, cost, exact_check_for(grid, fp)


def length(path):
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())


def pull(path, cost, check, c_th=0.1):
    return shortcut_path(path, terms=cost.terms, c_th=c_th, points=4, exact_check=check)


def wiggly(points, amplitude=0.15, per_leg=6):
    """A free zig-zag along the polyline ``points``: what joined DD plans look like."""
    out = [np.asarray(points[0], dtype=float)]
    for a, b in zip(points[:-1], points[1:]):
        a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        normal = np.array([-(b - a)[1], (b - a)[0]]) / np.linalg.norm(b - a)
        for k in range(1, per_leg + 1):
            t = k / per_leg
            side = amplitude * (1 if k % 2 else -1) * (k < per_leg)
            out.append(a + t * (b - a) + side * normal)
    return np.array(out)


@pytest.mark.parametrize("robot", ["circle", "quadruped"])
def test_a_wiggly_path_round_the_pillar_is_pulled_taut_and_stays_free(robot):
    grid, fp, cost, check = pieces(robot)
    corners = np.array([(1.0, 1.0), (7.0, 1.0), (9.0, 5.0)])
    path = wiggly(corners, amplitude=0.3)
    assert check_collision(path, fp, grid).collision_free
    out = pull(path, cost, check)
    assert np.array_equal(out[0], path[0]) and np.array_equal(out[-1], path[-1])
    # a subset of the path's vertices, in order
    idx = [int(np.flatnonzero((path == p).all(axis=1))[0]) for p in out]
    assert idx == sorted(idx) and len(out) < len(path)
    # no longer than the polyline it wiggled round (the straight line crosses the pillar)
    assert length(out) <= length(corners) + 1e-9 < length(path) - 0.5
    assert check_collision(out, fp, grid).collision_free
    # every kept segment passes J's local test
    t = torch.linspace(0, 1, 4)[None, :, None]
    a, b = torch.as_tensor(out[:-1], dtype=torch.float32), torch.as_tensor(out[1:],
                                                                          dtype=torch.float32)
    assert (cost.collision_cost(a[:, None] + t * (b - a)[:, None]) <= 0.1).all()


def test_a_detour_round_the_pillar_is_never_cut_through_it():
    grid, fp, cost, check = pieces()
    # from left of the pillar to right of it, round its top; the straight line crosses it
    path = wiggly([(2.5, 3.0), (3.2, 4.9), (6.8, 4.9), (7.5, 3.0)], amplitude=0.05)
    assert check_collision(path, fp, grid).collision_free
    assert not check_collision(np.stack([path[0], path[-1]]), fp, grid).collision_free
    out = pull(path, cost, check)
    assert check_collision(out, fp, grid).collision_free
    assert len(out) > 2 and out[:, 1].max() > 4.0  # still goes over the pillar
    assert length(out) <= length(path)


def test_nothing_to_pull_when_no_shortcut_passes_j():
    grid, fp, cost, check = pieces()
    path = wiggly([(1.0, 1.0), (7.0, 1.0), (9.0, 5.0)])
    out = pull(path, cost, check, c_th=-1.0)  # no straight plan costs <= -1
    assert np.array_equal(out, path)


def test_a_pulled_path_that_collides_whole_is_given_back_unchanged():
    grid, fp, cost, check = pieces()
    path = wiggly([(1.0, 1.0), (7.0, 1.0), (9.0, 5.0)])

    def picky(p):  # every single segment free, a path of more vertices collides
        return np.full(len(p) - 1, len(p) > 2 and len(p) < len(path), dtype=bool)

    out = pull(path, cost, picky)
    assert np.array_equal(out, path) and out is not path


def test_short_paths_come_back_as_they_are():
    grid, fp, cost, check = pieces()
    for path in (np.array([[1.0, 1.0]]), np.array([[1.0, 1.0], [2.0, 1.0]])):
        assert np.array_equal(pull(path, cost, check), path)


def corridor():
    """A 10 x 3 m room split by a wall into a corridor 0.9 m wide (y 1.0-1.9): 5 cm beside the
    0.4 m circle robot, nearer than J's 0.3 m margin lets any straight plan pass c_th."""
    occ = np.zeros((60, 200), dtype=bool)
    occ[:20], occ[38:] = True, True
    occ[:, :2], occ[:, -2:] = True, True
    return GridMap(data=np.where(occ, 100, 0).astype(np.int8), resolution=RES, name="corridor")


def test_with_peak_a_wiggle_in_a_corridor_narrower_than_the_margin_is_pulled_taut_keeping_room():
    """No straight plan down the corridor passes c_th (J's margin exceeds its room), so the
    c_th test keeps every wiggle; with ``by_peak`` a shortcut that comes no nearer a wall than
    the stretch it replaces passes: the path is pulled taut and its least room does not shrink."""
    from ecahd_core.bench.planning import least_room

    grid, fp = corridor(), make_footprint("circle")
    cost = CollisionCost.build(grid, fp, CostConfig(margin=0.3))
    check = exact_check_for(grid, fp)
    path = wiggly(np.array([(0.8, 1.45), (9.2, 1.45)]), amplitude=0.03, per_leg=24)
    assert check_collision(path, fp, grid).collision_free
    plain = pull(path, cost, check)
    assert len(plain) == len(path)  # the c_th test alone finds no shortcut
    out = shortcut_path(path, terms=cost.terms, c_th=0.1, points=4, exact_check=check,
                        by_peak=True)
    assert np.array_equal(out[0], path[0]) and np.array_equal(out[-1], path[-1])
    assert len(out) < len(path) // 4 and length(out) < 0.99 * length(path)
    assert not check(out).any()
    assert least_room(out, fp, grid) >= least_room(path, fp, grid) - 1e-3

