"""The PyBullet simulator core: walls where the map is occupied, contacts that stop the robot,
exact unicycle motion, limits, footprint orientation and D4RL episode bookkeeping (no rclpy)."""
import math

import numpy as np
import pytest

from ecahd_core.maps import FREE, OCCUPIED, GridMap, builtin_map, save_nav2_yaml
from sim_bridge.sim import (MazeSim, SimConfig, SimError,
                            wall_rectangles)

TINY_SQUARE = "[[0.02, 0.02], [-0.02, 0.02], [-0.02, -0.02], [0.02, -0.02]]"  # 4 cm robot


def _yaml_map(tmp_path, occupied: np.ndarray, resolution: float, name: str = "custom") -> str:
    """Write a Nav2 map (YAML + PGM) whose obstacle mask is ``occupied`` (row 0 = lowest y)."""
    data = np.where(occupied, OCCUPIED, FREE).astype(np.int8)
    grid = GridMap(data=data, resolution=resolution, name=name)
    return str(save_nav2_yaml(grid, tmp_path / f"{name}.yaml"))


@pytest.fixture
def open_map(tmp_path) -> str:
    """8 m x 8 m of free space inside a 0.5 m thick border, 0.1 m/cell."""
    occ = np.zeros((80, 80), dtype=bool)
    occ[:5], occ[-5:], occ[:, :5], occ[:, -5:] = True, True, True, True
    return _yaml_map(tmp_path, occ, 0.1, "open")


@pytest.fixture
def sim_factory():
    sims = []

    def make(**kwargs) -> MazeSim:
        sims.append(MazeSim(SimConfig(**kwargs)))
        return sims[-1]

    yield make
    for sim in sims:
        sim.close()


# ------------------------------------------------------------------------------ wall boxes
def test_wall_rectangles_merge_runs_and_cover_exactly():
    # rows listed from row 0 (lowest y):      expected rectangles (row0, col0, row1, col1)
    occ = np.array([[1, 1, 1, 1],           # (0, 0, 1, 4): the full bottom row
                    [1, 0, 0, 1],           # (1, 0, 3, 1) and (1, 3, 3, 4): two 2-row pillars
                    [1, 0, 0, 1],
                    [0, 1, 1, 0]], bool)    # (3, 1, 4, 3)
    rects = wall_rectangles(occ)
    assert rects == [(0, 0, 1, 4), (1, 0, 3, 1), (1, 3, 3, 4), (3, 1, 4, 3)]
    cover = np.zeros((4, 4), int)
    for r0, c0, r1, c1 in rects:
        cover[r0:r1, c0:c1] += 1
    assert np.array_equal(cover, occ.astype(int))  # every wall cell once, no free cell


def test_maze2d_large_is_a_few_boxes(sim_factory):
    sim = sim_factory(map="maze2d-large", resolution=0.1)
    assert sim.n_wall_boxes < 100  # 17 merged maze walls + 4 fence boxes, not 3000 cells


@pytest.mark.parametrize("name", ["maze2d-umaze", "maze2d-large"])
def test_walls_exactly_where_the_map_is_occupied(sim_factory, name):
    # A 4 cm square at each 0.1 m cell centre: the nearest wall face of a free cell is at least
    # 0.05 m away (> 0.02 m half size) and a wall cell's centre is 0.05 m deep inside the wall.
    # maze2d-large has 21 boxes: more than the 16 children PyBullet keeps in one compound shape.
    sim = sim_factory(map=name, resolution=0.1, robot=TINY_SQUARE)
    grid = builtin_map(name, 0.1)
    rows, cols = np.indices(grid.occupied.shape)
    centres = grid.cell_to_world(rows.ravel(), cols.ravel())
    hits = np.array([sim.collides(x, y) for x, y in centres]).reshape(grid.occupied.shape)
    assert np.array_equal(hits, grid.occupied)


def test_hundreds_of_speckle_boxes_are_all_walls(sim_factory, tmp_path):
    # 2% random speckle on a 40 x 40 map at 0.1 m/cell: hundreds of boxes in bodies of <= 16
    rng = np.random.default_rng(0)
    occ = rng.random((40, 40)) < 0.02
    occ[:3, :3] = False
    sim = sim_factory(map=_yaml_map(tmp_path, occ, 0.1, "speckle"), robot=TINY_SQUARE,
                      start=(0.15, 0.15, 0.0))
    assert sim.n_wall_boxes == len(wall_rectangles(occ)) + 4 > 16
    assert sim.n_wall_bodies == math.ceil((sim.n_wall_boxes - 4) / 16) + 1
    rows, cols = np.indices(occ.shape)
    centres = sim.grid.cell_to_world(rows.ravel(), cols.ravel())
    hits = np.array([sim.collides(x, y) for x, y in centres]).reshape(occ.shape)
    assert np.array_equal(hits, occ)


def test_circle_at_wall_cell_collides_at_free_cell_does_not(sim_factory):
    sim = sim_factory(map="maze2d-umaze", robot="circle")
    assert sim.collides(0.5, 0.5)  # maze cell (0, 0) is wall
    assert not sim.collides(1.5, 1.5)  # free cell, 0.5 m from each wall > radius 0.4 m
    assert sim.penetration(1.5, 1.0) == pytest.approx(0.4, abs=1e-6)  # centre on the wall face
    with pytest.raises(SimError, match="into a wall"):
        sim.reset(0.5, 0.5, 0.0)


# ---------------------------------------------------------------------------------- contact
def test_driving_into_a_wall_stops_at_the_wall_and_reports_contact(sim_factory):
    # umaze row y in [1, 2]: "#OOO#", the wall face ahead is x = 4.0; circle radius 0.4 m
    sim = sim_factory(map="maze2d-umaze", robot="circle", dt=0.02, max_v=1.0)
    sim.reset(1.5, 1.5, 0.0)
    states = [sim.step(1.0, 0.0) for _ in range(200)]  # would travel 4 m without walls
    xs = np.array([s.x for s in states])
    tol = sim.config.contact_tolerance
    assert xs.max() <= 4.0 - 0.4 + tol + 1e-9  # never through the wall
    assert xs[-1] == pytest.approx(3.6, abs=tol + 1e-6)  # but right up to it
    assert all(s.y == pytest.approx(1.5) for s in states)
    free = [s for s in states if s.x < 3.5]
    assert free and not any(s.in_contact for s in free)
    assert states[-1].in_contact and states[-1].v == pytest.approx(0.0)
    # 2.1 m to the wall at 0.02 m per step: 105 free steps, the other 95 push against it
    # (the 105th ends exactly touching, which round-off may count either way)
    assert states[-1].contact_count == sum(s.in_contact for s in states)
    assert states[-1].contact_count in (95, 96)


def test_big_steps_do_not_tunnel_through_a_thin_wall(sim_factory, tmp_path):
    # a 0.1 m thick wall at x in [2.0, 2.1]; one 1 m step would jump over it without sub-steps
    occ = np.zeros((40, 40), dtype=bool)
    occ[:, 20] = True
    sim = sim_factory(map=_yaml_map(tmp_path, occ, 0.1, "thin"), robot="circle", dt=1.0,
                      max_v=1.0, start=(1.0, 2.0, 0.0))
    for _ in range(3):
        s = sim.step(1.0, 0.0)
    assert s.x == pytest.approx(2.0 - 0.4, abs=sim.config.contact_tolerance + 1e-6)
    assert s.in_contact


def test_diagonal_push_slides_along_the_wall(sim_factory, open_map):
    # heading 45 deg into the top wall (face y = 7.5): the y part is rejected, x keeps going
    sim = sim_factory(map=open_map, robot="circle", start=(3.0, 7.0, math.pi / 4))
    for _ in range(100):
        s = sim.step(1.0, 0.0)
    assert s.y == pytest.approx(7.5 - 0.4, abs=sim.config.contact_tolerance + 1e-6)
    assert s.x > 3.0 + 1.0  # slid about 1.4 m along x
    assert s.in_contact


# ------------------------------------------------------------------------------- kinematics
@pytest.mark.parametrize("v, w", [(0.5, 0.8), (0.7, -1.3), (-0.4, 0.5), (0.6, 0.0)])
def test_unicycle_matches_closed_form(sim_factory, open_map, v, w):
    x0, y0, yaw0, dt = 4.0, 4.0, 0.3, 0.02
    sim = sim_factory(map=open_map, robot="circle", dt=dt, start=(x0, y0, yaw0))
    for k in range(1, 151):
        s = sim.step(v, w)
        t = k * dt
        if w == 0.0:
            x, y = x0 + v * t * math.cos(yaw0), y0 + v * t * math.sin(yaw0)
        else:  # x(t) = x0 + v/w (sin(yaw0 + w t) - sin yaw0), y(t) = y0 - v/w (cos(...) - cos yaw0)
            x = x0 + v / w * (math.sin(yaw0 + w * t) - math.sin(yaw0))
            y = y0 - v / w * (math.cos(yaw0 + w * t) - math.cos(yaw0))
        yaw = math.atan2(math.sin(yaw0 + w * t), math.cos(yaw0 + w * t))
        assert (s.x, s.y, s.yaw) == pytest.approx((x, y, yaw), abs=1e-9)
        assert s.t == pytest.approx(t) and not s.in_contact


def test_limits_clamp_the_command(sim_factory, open_map):
    sim = sim_factory(map=open_map, robot="circle", dt=0.1, max_v=0.5, max_w=1.0,
                      start=(4.0, 4.0, 0.0))
    s = sim.step(5.0, -10.0)
    assert (s.v, s.w) == (0.5, -1.0)
    assert s.yaw == pytest.approx(-0.1)  # w dt with the clamped w
    chord = 2 * 0.5 / 1.0 * math.sin(1.0 * 0.1 / 2)  # 2 v/w sin(w dt / 2), clamped v and w
    assert math.hypot(s.x - 4.0, s.y - 4.0) == pytest.approx(chord)


def test_non_finite_input_is_refused(sim_factory):
    sim = sim_factory(map="maze2d-umaze")
    with pytest.raises(SimError, match="not finite"):
        sim.step(float("nan"), 0.0)
    with pytest.raises(SimError, match="outside the map"):
        sim.reset(-3.0, 1.5)
    with pytest.raises(SimError, match="dt"):
        SimConfig(dt=0.0)


def test_reset_zeroes_contacts_but_time_keeps_running(sim_factory):
    sim = sim_factory(map="maze2d-umaze", dt=0.1, start=(3.5, 1.5, 0.0))
    for _ in range(3):
        s = sim.step(1.0, 0.0)  # into the wall at x = 4
    assert s.contact_count > 0
    s = sim.reset(1.5, 1.5, 0.0)
    assert (s.x, s.y, s.contact_count, s.v) == (1.5, 1.5, 0, 0.0)
    assert s.t == pytest.approx(0.3)


# ------------------------------------------------------------------------------- footprints
@pytest.mark.parametrize("robot, fits_yaw, blocked_yaw", [
    ("quadruped", 0.0, math.pi / 2),  # 0.65 m long, 0.30 m wide: fits along the gap
    ("humanoid", math.pi / 2, 0.0),  # 0.25 m deep, 0.50 m wide: fits sideways only
])
def test_rectangle_footprints_are_oriented_by_yaw(sim_factory, tmp_path, robot, fits_yaw,
                                                  blocked_yaw):
    # a corridor 0.35 m wide (7 cells of 0.05 m, y in [0.80, 1.15]) running along x
    occ = np.ones((40, 80), dtype=bool)
    occ[16:23, 4:76] = False
    sim = sim_factory(map=_yaml_map(tmp_path, occ, 0.05, "gap"), robot=robot, dt=0.05,
                      start=(1.0, 0.975, fits_yaw))
    assert sim.collides(2.0, 0.975, blocked_yaw)
    assert not sim.collides(2.0, 0.975, fits_yaw)


def test_quadruped_drives_along_the_gap_humanoid_forward_hits_its_side(sim_factory, tmp_path):
    occ = np.ones((40, 80), dtype=bool)
    occ[16:23, 4:76] = False  # the same 0.35 m corridor along x, centre line y = 0.975
    gap = _yaml_map(tmp_path, occ, 0.05, "gap")
    quadruped = sim_factory(map=gap, robot="quadruped", dt=0.05, start=(1.0, 0.975, 0.0))
    states = [quadruped.step(0.5, 0.0) for _ in range(40)]  # 1 m along the corridor
    assert states[-1].x == pytest.approx(2.0) and not any(s.in_contact for s in states)
    # the humanoid fits sideways (yaw pi/2), so "forward" is +y: the wall at y = 1.15 is
    # 1.15 - 0.975 - 0.125 (half depth) = 0.05 m ahead, two 0.025 m steps
    humanoid = sim_factory(map=gap, robot="humanoid", dt=0.05, start=(1.0, 0.975, math.pi / 2))
    states = [humanoid.step(0.5, 0.0) for _ in range(10)]
    assert states[-1].in_contact
    assert states[-1].y == pytest.approx(1.025, abs=humanoid.config.contact_tolerance + 1e-6)


def test_convex_polygon_footprint_collides_by_its_shape(sim_factory):
    # a triangle, tip 0.45 m ahead, base 0.2 m behind and 0.4 m wide, in umaze's corridor
    # x in [1, 4], y in [1, 2] (wall above for x < 3, below everywhere)
    sim = sim_factory(map="maze2d-umaze", robot="[[0.45, 0.0], [-0.2, 0.2], [-0.2, -0.2]]")
    assert not sim.collides(1.5, 1.5, 0.0)  # tip at x = 1.95, base y in [1.3, 1.7]
    assert not sim.collides(1.5, 1.4, 0.0)  # base y in [1.2, 1.6]
    assert sim.collides(1.5, 1.4, -math.pi / 2)  # tip at y = 0.95: 5 cm into the wall below
    assert not sim.collides(1.5, 1.5, -math.pi / 2)  # tip at y = 1.05


# ---------------------------------------------------------------------------------- drawing
def test_render_topdown_draws_walls_and_robot(sim_factory):
    sim = sim_factory(map="maze2d-umaze", robot="circle", start=(1.5, 1.5, 0.0))
    img = sim.render_topdown(100)  # 5 m x 5 m -> 20 px/m
    assert img.shape == (100, 100, 3) and img.dtype == np.uint8
    assert tuple(img[100 - 30, 24]) == (40, 90, 220)  # (1.2, 1.5), behind the centre: robot
    assert tuple(img[100 - 10, 10]) == (64, 64, 64)  # (0.5, 0.5): wall
    assert tuple(img[100 - 30, 70]) == (255, 255, 255)  # (3.5, 1.5): free

