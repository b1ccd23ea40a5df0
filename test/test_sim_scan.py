"""The simulator's LiDAR and its obstacles that are not on the map (no rclpy): ranges against
hand-computed geometry, REP 117 inf / -inf, the robot's own body unseen, obstacles seen and
reported by kind when hit, moving ones where Obstacle.position says."""
import math

import numpy as np
import pytest

from ecahd_core.maps import FREE, OCCUPIED, GridMap, save_nav2_yaml
from ecahd_core.scenario import Obstacle
from sim_bridge.sim import RAY_BATCH, MazeSim, SimConfig, SimError, scan_angles

BEAMS = 360  # 1 degree apart, beam i at -pi + i deg: beam 180 straight ahead, beam 0 behind
AHEAD, BEHIND, LEFT = 180, 0, 270


@pytest.fixture
def open_map(tmp_path) -> str:
    """8 m x 8 m, a 0.5 m thick border: the inner wall faces are x, y = 0.5 and 7.5."""
    occ = np.zeros((80, 80), dtype=bool)
    occ[:5], occ[-5:], occ[:, :5], occ[:, -5:] = True, True, True, True
    grid = GridMap(data=np.where(occ, OCCUPIED, FREE).astype(np.int8), resolution=0.1,
                   name="open")
    return str(save_nav2_yaml(grid, tmp_path / "open.yaml"))


@pytest.fixture
def make_sim(open_map):
    sims = []

    def make(obstacles=(), start=(3.0, 4.0, 0.0), **kwargs) -> MazeSim:
        sims.append(MazeSim(SimConfig(map=open_map, robot="circle", start=start,
                                      obstacles=tuple(obstacles), **kwargs)))
        return sims[-1]

    yield make
    for sim in sims:
        sim.close()


def test_scan_angles_follow_laserscan_layout():
    angles, inc = scan_angles(4)  # a full turn: -pi, -pi/2, 0, pi/2 (angle_max = pi - inc)
    assert inc == pytest.approx(math.pi / 2)
    assert angles == pytest.approx([-math.pi, -math.pi / 2, 0.0, math.pi / 2])
    angles, inc = scan_angles(3, -1.0, 1.0)  # an explicit fan includes both ends
    assert (inc, angles[-1]) == pytest.approx((1.0, 1.0))
    with pytest.raises(SimError):
        scan_angles(0)


def test_wall_ahead_reads_its_distance_minus_the_mounting_offset(make_sim):
    sim = make_sim()  # robot (circle r = 0.4 m) at (3, 4) facing +x
    r = sim.scan((0.2, 0.0, 0.0), BEAMS, 0.1, 8.0)
    assert r.shape == (BEAMS,)
    assert r[AHEAD] == pytest.approx(7.5 - 3.0 - 0.2, abs=1e-6)  # wall face x = 7.5
    # behind: the ray crosses the robot's own body (it is not seen) up to the wall x = 0.5
    assert r[BEHIND] == pytest.approx(3.0 + 0.2 - 0.5, abs=1e-6)
    assert r[LEFT] == pytest.approx(7.5 - 4.0, abs=1e-6)  # face y = 7.5
    # a beam at angle a hits the wall x = 7.5 at 4.3 / cos(a) while |4.3 tan a| < 3.5
    a = np.deg2rad(np.arange(-30, 31))
    assert r[AHEAD - 30:AHEAD + 31] == pytest.approx(4.3 / np.cos(a), abs=1e-6)


def test_more_beams_than_one_ray_batch(make_sim):
    sim = make_sim()
    r = sim.scan((0.0, 0.0, 0.0), 2 * RAY_BATCH + 4, 0.1, 8.0)  # three rayTestBatch calls
    angles, _ = scan_angles(len(r))
    ahead = np.abs(angles) < 0.5  # the wall x = 7.5 at 4.5 / cos(a)
    assert r[ahead] == pytest.approx(4.5 / np.cos(angles[ahead]), abs=1e-6)
    assert np.all(np.isfinite(r))  # every beam ends on the 8 m x 8 m border


def test_offset_yaw_turns_the_fan_and_follows_the_robot(make_sim):
    sim = make_sim(start=(3.0, 4.0, math.pi / 2))  # facing +y
    r = sim.scan((0.0, 0.0, -math.pi / 2), BEAMS, 0.1, 8.0)  # sensor turned back to +x
    assert r[AHEAD] == pytest.approx(4.5, abs=1e-6)
    assert sim.sensor_pose((0.5, 0.0, 0.0)) == pytest.approx((3.0, 4.5, math.pi / 2))


def test_out_of_range_is_inf_too_close_is_minus_inf(make_sim):
    sim = make_sim()
    r = sim.scan((0.0, 0.0, 0.0), BEAMS, 0.1, 3.0)
    assert r[AHEAD] == math.inf  # 4.5 m > range_max
    assert r[BEHIND] == pytest.approx(2.5, abs=1e-6)
    r = sim.scan((0.0, 0.0, 0.0), BEAMS, 3.0, 8.0)
    assert r[BEHIND] == -math.inf and r[AHEAD] == pytest.approx(4.5, abs=1e-6)


def test_box_in_view_shortens_the_beams_in_its_sector(make_sim):
    # a 1 m box centred (5.5, 4): near face x = 5 (2 m ahead), y in [3.5, 4.5]. Beam a hits it
    # at 2 / cos(a) while 2 |tan a| < 0.5 (|a| < 14.04 deg); beyond, the wall at 4.5 / cos(a)
    # (the box's sides face away from the sensor).
    sim = make_sim([Obstacle("box", 5.5, 4.0, 0.0, (1.0, 1.0))])
    r = sim.scan((0.0, 0.0, 0.0), BEAMS, 0.1, 8.0)
    a = np.deg2rad(np.arange(-30, 31))
    expected = np.where(2 * np.abs(np.tan(a)) < 0.5, 2 / np.cos(a), 4.5 / np.cos(a))
    assert r[AHEAD - 30:AHEAD + 31] == pytest.approx(expected, abs=1e-6)
    assert np.sum(r[AHEAD - 30:AHEAD + 31] < 3) == 29  # -14 .. 14 degrees


def test_noise_is_seeded_and_has_the_asked_spread(make_sim):
    a, b = make_sim(seed=7), make_sim(seed=7)
    clean = a.scan(beams=BEAMS, range_max=8.0)
    noisy_a = a.scan(beams=BEAMS, range_max=8.0, noise_std=0.05)
    noisy_b = b.scan(beams=BEAMS, range_max=8.0, noise_std=0.05)
    assert np.array_equal(noisy_a, noisy_b)  # same seed, same noise
    assert np.std(noisy_a - clean) == pytest.approx(0.05, rel=0.25)
    other = a.scan(beams=BEAMS, range_max=8.0, noise_std=0.05,
                   rng=np.random.default_rng(1))
    assert not np.array_equal(other, noisy_a)


def test_moving_obstacle_contact_is_reported_with_its_kind(make_sim):
    # obstacle 1: a cylinder r = 0.3 from (5.5, 4) towards the robot at 1 m/s; it touches the
    # robot (r = 0.4, at x = 3) when its centre reaches x = 3.7, at t = 1.8 s
    static = Obstacle("box", 6.5, 6.5, 0.0, (0.4, 0.4))
    mover = Obstacle("cylinder", 5.5, 4.0, radius=0.3, path=((5.5, 4.0), (1.0, 4.0)), speed=1.0)
    sim = make_sim([static, mover], dt=0.02)
    states = [sim.step(0.0, 0.0) for _ in range(100)]  # 2 s standing still
    first = next(s for s in states if s.in_contact)
    assert first.t == pytest.approx(1.8, abs=0.02 + 1e-9)
    assert (first.collision_kind, first.collision_obstacle) == ("moving_obstacle", 1)
    assert states[0].collision_kind is None
    assert states[-1].contact_count == 100 - states.index(first)  # in contact ever since
    assert (sim.state.x, sim.state.y) == (3.0, 4.0)  # kinematic: it does not push the robot
    # the scan sees it where Obstacle.position puts it: centre (5.5 - 2, 4) - radius - 0
    assert sim.scan(beams=BEAMS)[AHEAD] == pytest.approx(3.5 - 0.3 - 3.0, abs=1e-3)


def test_static_obstacle_blocks_like_a_wall_and_is_told_apart(make_sim):
    sim = make_sim([Obstacle("box", 5.0, 4.0, 0.0, (0.4, 2.0))], dt=0.05)  # face x = 4.8
    for _ in range(60):
        s = sim.step(1.0, 0.0)
    assert s.x == pytest.approx(4.8 - 0.4, abs=sim.config.contact_tolerance + 1e-6)
    assert (s.in_contact, s.collision_kind, s.collision_obstacle) == (True, "static_obstacle", 0)
    sim.reset(7.0, 4.0, 0.0)  # 0.1 m from the wall face x = 7.5: 3 steps of 0.05 m hit it
    s = [sim.step(1.0, 0.0) for _ in range(3)][-1]
    assert (s.collision_kind, s.collision_obstacle) == ("wall", None)
    with pytest.raises(SimError, match="into obstacle 0"):
        sim.reset(5.0, 4.0)


def test_render_topdown_draws_obstacles(make_sim):
    sim = make_sim([Obstacle("box", 5.5, 4.0, 0.0, (1.0, 1.0))])
    img = sim.render_topdown(80)  # 8 m -> 10 px/m; (5.5, 4.0) is pixel row 40, column 55
    assert tuple(img[40, 55]) == (150, 100, 40)


def test_obstacles_on_the_start_or_off_the_map_are_left_out_with_a_line(make_sim):
    sim = make_sim([Obstacle("cylinder", 3.2, 4.0, radius=0.3),  # on the robot at (3, 4)
                    Obstacle("cylinder", 6.0, 6.0, radius=0.3),
                    Obstacle("box", 9.0, 4.0, 0.0, (1.0, 1.0)),  # off the 8 m map
                    Obstacle("cylinder", 5.0, 5.0, radius=0.2, path=((5, 5), (5, 12)), speed=1)])
    assert [i for i, _, _ in sim.obstacles] == [1]
    lines = sim.rejected_obstacles
    assert len(lines) == 3
    assert lines[0].startswith("obstacle 0 ") and "overlaps the robot's start pose" in lines[0]
    assert lines[1].startswith("obstacle 2 ") and "outside the map" in lines[1]
    assert lines[2].startswith("obstacle 3 ") and "outside the map" in lines[2]
