"""Table III metrics on hand-made episodes (no rclpy)."""
import numpy as np
import pytest

from ecahd_core.evaluation import (PAPER_TABLE_III, EpisodeData, control_times,
                                   evaluate_episode, markdown_table, split_episodes, summarize)
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import GridMap

GOAL = np.array([5.0, 0.0])


def straight_run(n_steps: int, speed: float, hz: float = 50.0) -> np.ndarray:
    """(N, 4) odometry driving along +x from (0, 0) at speed [m/s], sampled at hz."""
    t = np.arange(int(n_steps * 0.1 * hz) + 1) / hz
    x = np.minimum(speed * t, GOAL[0])
    return np.stack([t, x, np.zeros_like(t), np.zeros_like(t)], axis=1)


def test_reward_and_first_reach_count_control_steps():
    # 1 m/s along x towards (5, 0): after step k (0.1 s each) x = 0.1 k; within 0.5 m from
    # x > 4.5, i.e. k >= 46; 60 steps recorded -> reward 60 - 45 = 15, first reach 46
    m = evaluate_episode(EpisodeData(goal=GOAL, odom=straight_run(60, 1.0)))
    assert m.control_steps == 60
    assert m.first_reach == 46
    assert m.episode_reward == 15
    assert m.reached


def test_reward_is_capped_by_max_steps_and_never_reached_gives_none():
    m = evaluate_episode(EpisodeData(goal=GOAL, odom=straight_run(60, 1.0)), max_steps=50)
    assert (m.control_steps, m.episode_reward) == (50, 5)  # steps 46..50
    far = evaluate_episode(EpisodeData(goal=np.array([50.0, 0.0]), odom=straight_run(60, 1.0)))
    assert far.first_reach is None and far.episode_reward == 0 and not far.reached
    assert summarize([far]).first_reach is None


def test_collision_rate_and_inference_time():
    flags = np.zeros(1000, dtype=bool)
    flags[:3] = True  # 3 of 1000 sim steps in contact -> 0.3 %
    m = evaluate_episode(EpisodeData(goal=GOAL, odom=straight_run(10, 1.0), collisions=flags,
                                     timing_ms=np.array([1500.0, 250.0, 244.0]),
                                     timing_stages=["sd", "j_check", "dd"]))
    assert m.collision_rate == pytest.approx(0.3)
    assert m.contact_steps == 3 and m.sim_steps == 1000
    assert m.inference_time_s == pytest.approx(1.994)
    assert m.dd_calls == 1 and m.stage_ms == {"sd": 1500.0, "j_check": 250.0, "dd": 244.0}


def corridor() -> GridMap:
    # 0.1 m cells, 4 m x 2 m free with a one-cell wall frame; an obstacle block at
    # x in [2.0, 2.3), y in [0.8, 1.1): a circle of radius 0.4 driven along y = 1 hits it
    data = np.zeros((20, 40), dtype=np.int8)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    data[8:11, 20:23] = 100
    return GridMap(data=data, resolution=0.1)


def test_exact_checker_judges_the_driven_path():
    grid, fp = corridor(), make_footprint("circle")
    t = np.linspace(0, 2, 21)
    hit_path = np.stack([t, 0.5 + t, np.full_like(t, 1.0), np.zeros_like(t)], axis=1)
    m = evaluate_episode(EpisodeData(goal=np.array([2.5, 1.0]), odom=hit_path), grid=grid,
                         footprint=fp)
    assert m.path_collision_free is False and 0 < m.penetration_fraction < 1
    # x in [0.5, 1.5] on y = 1: the block starts at x = 2.0 > 1.5 + 0.4, the walls are
    # 0.9 m away (y <= 0.1 and y >= 1.9): collision free
    safe = np.stack([t, 0.5 + t / 2, np.full_like(t, 1.0), np.zeros_like(t)], axis=1)
    m = evaluate_episode(EpisodeData(goal=np.array([1.5, 1.0]), odom=safe), grid=grid,
                         footprint=fp)
    assert m.path_collision_free is True and m.penetration_fraction == 0.0
    # no grid: not checked
    assert evaluate_episode(EpisodeData(goal=GOAL, odom=safe)).path_collision_free is None


def test_split_episodes_at_goals():
    goals = [(10.0, 1.0, 1.0), (20.0, 2.0, 2.0)]
    odom = [(t, t - 5, 0.0, 0.0, 0.0) for t in (5.0, 10.0, 15.0, 19.9, 20.0, 30.0)]
    collisions = [(9.0, 1), (12.0, 1), (13.0, 0), (25.0, 0)]
    timing = [(11.0, 100.0, "sd"), (21.0, 50.0, "sd"), (22.0, 5.0, "j_check")]
    eps = split_episodes(goals, odom, collisions=collisions, timing=timing,
                         cmd_vel_times=[8.0, 10.5, 20.5, 21.0])
    assert len(eps) == 2
    # receive time 5 s (before the first goal) is dropped; columns are now stamp, x, y, yaw
    assert eps[0].odom[:, 0] == pytest.approx([5.0, 10.0, 14.9])
    assert eps[1].odom[:, 0].tolist() == [15.0, 25.0]  # a goal's own time starts its episode
    assert eps[0].collisions.tolist() == [True, False]
    assert eps[1].collisions.tolist() == [False]
    assert eps[0].timing_ms.tolist() == [100.0] and eps[1].timing_stages == ["sd", "j_check"]
    assert (eps[0].cmd_vel_count, eps[1].cmd_vel_count) == (1, 2)
    assert eps[1].goal.tolist() == [2.0, 2.0]


def test_summary_and_table_list_the_paper_rows():
    ms = [evaluate_episode(EpisodeData(goal=GOAL, odom=straight_run(60, 1.0)), index=0),
          evaluate_episode(EpisodeData(goal=np.array([50.0, 0.0]), odom=straight_run(60, 1.0)),
                           index=1)]
    s = summarize(ms)
    assert s.episode_reward == pytest.approx(7.5) and s.first_reach == pytest.approx(46)
    assert s.reached == pytest.approx(0.5)
    d = ms[0].to_dict()
    for key in ("episode_reward", "first_reach", "collision_rate", "inference_time_s", "reached"):
        assert key in d
    table = markdown_table(s, ms)
    assert all(name in table for name in PAPER_TABLE_III)
    assert PAPER_TABLE_III["ECAHD w/ DD"].episode_reward == 46.862


def test_control_ticks_are_latency_not_inference_time():
    # two planning records (1.0 s + 0.25 s) and 100 control ticks of 1..100 ms: the ticks
    # (which include a J check + DD started in them) must not add to the inference time
    ticks = np.arange(1.0, 101.0)
    data = EpisodeData(goal=GOAL, odom=straight_run(10, 1.0),
                       timing_ms=np.concatenate([[1000.0], ticks, [250.0]]),
                       timing_stages=["astar"] + ["control"] * 100 + ["j_check"])
    m = evaluate_episode(data)
    assert m.inference_time_s == pytest.approx(1.25)
    assert m.stage_ms == {"astar": 1000.0, "j_check": 250.0}
    assert m.control_ticks == 100
    # numpy's linear percentile of 1..100: p50 = 50.5, p99 = 1 + 0.99 * 99 = 99.01
    assert m.control_ms_p50 == pytest.approx(50.5) and m.control_ms_p99 == pytest.approx(99.01)
    s = summarize([m], control_ms=control_times(data))
    assert (s.control_ms_p50, s.control_ms_p99) == (pytest.approx(50.5), pytest.approx(99.01))
    assert "p99 99.01 ms" in markdown_table(s, [m])
    assert summarize([m]).control_ms_p50 is None  # no pooled ticks given: not reported
    # records without a stage count as inference (older bags)
    assert evaluate_episode(EpisodeData(goal=GOAL, odom=straight_run(10, 1.0),
                                        timing_ms=np.array([5.0]))).inference_time_s == 0.005
