"""Table III metrics on hand-made episodes (no rclpy)."""
import numpy as np
import pytest

from ecahd_core.evaluation import (PAPER_TABLE_III, EpisodeData, cmd_intervals, control_times,
                                   evaluate_episode, interval_stats, markdown_table,
                                   split_episodes, summarize)
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


# ------------------------------------------------ obstacles, monitor, replans, jitter (issue 9, 11)
def test_contacts_by_kind_monitor_blocked_and_replans_are_counted():
    data = EpisodeData(
        goal=GOAL, odom=straight_run(60, 1.0),
        collisions=np.array([False, True, True, True, True, True]),
        # one collision_detail record per contact step: 1 wall, 3 static, 1 moving
        contact_kinds=["wall", "static_obstacle", "static_obstacle", "moving_obstacle",
                       "static_obstacle"],
        # global plans: sd, sd, fallback_astar, astar = 4 (1 fallback); j_check, dd, control
        # are not plans
        timing_ms=np.array([900.0, 2.0, 1.0, 800.0, 30.0, 1.0, 20.0, 40.0]),
        timing_stages=["sd", "j_check", "control", "sd", "fallback_astar", "control",
                       "astar", "dd"],
        # five ticks: monitor stop, stop, slowdown -> 2 stops, 1 slowdown; 3 blocked ticks
        control_reasons=["follow", "blocked", "blocked", "blocked", "follow"],
        control_monitor=["none", "stop", "stop", "slowdown", "none"])
    m = evaluate_episode(data)
    assert (m.contact_steps_wall, m.contact_steps_static, m.contact_steps_moving) == (1, 3, 1)
    assert m.contact_steps == 5  # the collision flags, unchanged
    assert (m.monitor_stops, m.monitor_slowdowns, m.blocked_ticks) == (2, 1, 3)
    assert (m.global_plans, m.fallbacks) == (4, 1)
    # first reach 46 (test_reward_and_first_reach_count_control_steps) x 0.1 s = 4.6 s
    assert m.first_reach == 46 and m.time_to_goal_s == pytest.approx(4.6)
    # with a 0.05 s step: x = 0.05 k > 4.5 from k = 91 -> 4.55 s
    assert evaluate_episode(data, period=0.05).time_to_goal_s == pytest.approx(4.55)
    # the inference time still counts every planning record (fallback_astar included)
    assert m.inference_time_s == pytest.approx((900 + 2 + 800 + 30 + 20 + 40) / 1000)


def test_an_episode_without_the_new_records_evaluates_as_before():
    # an older bag: no collision_detail, control records without monitor / reason / wall
    m = evaluate_episode(EpisodeData(goal=GOAL, odom=straight_run(10, 1.0),
                                     timing_ms=np.array([3.0, 1.0]),
                                     timing_stages=["astar", "control"]))
    assert (m.contact_steps_wall, m.contact_steps_static, m.contact_steps_moving) == (None,) * 3
    assert (m.monitor_stops, m.monitor_slowdowns, m.blocked_ticks, m.fallbacks) == (0, 0, 0, 0)
    assert m.global_plans == 1 and m.time_to_goal_s is None  # 1 m driven of 5
    assert (m.cmd_interval_ms_p50, m.cmd_interval_ms_p99, m.cmd_jitter_ms_p99) == (None,) * 3
    s = summarize([m])
    assert (s.wall_contact_episodes, s.static_contact_episodes,
            s.moving_contact_episodes) == (None,) * 3
    assert s.cmd_jitter_ms_p99 is None and s.time_to_goal_s is None
    assert "contact kinds not recorded" in markdown_table(s, [m])


def test_cmd_vel_interval_and_jitter_from_the_control_ticks_wall_stamps():
    # wall stamps [s]; the NaN tick (no "wall" in its record) is left out, so the intervals
    # are 50, 50, 60, 40, 50, 150 ms; sorted 40 50 50 50 60 150:
    #   p50 = 50; p99 at rank 0.99 * 5 = 4.95: 60 + 0.95 * (150 - 60) = 145.5
    #   nominal = median = 50: |d| = 0 0 10 10 0 100, sorted 0 0 0 10 10 100:
    #   p99 = 10 + 0.95 * 90 = 95.5
    wall = np.array([0.0, 0.05, 0.10, 0.16, np.nan, 0.20, 0.25, 0.40])
    data = EpisodeData(goal=GOAL, odom=straight_run(10, 1.0), control_wall=wall)
    assert cmd_intervals(data) == pytest.approx([50, 50, 60, 40, 50, 150])
    m = evaluate_episode(data)
    assert m.cmd_interval_ms_p50 == pytest.approx(50.0)
    assert m.cmd_interval_ms_p99 == pytest.approx(145.5)
    assert m.cmd_interval_nominal_ms == pytest.approx(50.0)
    assert m.cmd_jitter_ms_p99 == pytest.approx(95.5)
    # a nominal 45 ms given: |d| = 5 5 15 5 5 105, sorted 5 5 5 5 15 105: p99 = 15 + 0.95 * 90
    m45 = evaluate_episode(data, nominal_interval_ms=45.0)
    assert m45.cmd_jitter_ms_p99 == pytest.approx(100.5)
    assert interval_stats([]).p50 is None and interval_stats([], 50.0).jitter_p99 is None
    # pooled with a second episode's 50, 50 ms: 40 50 50 50 50 50 60 150, rank 0.99 * 7 = 6.93:
    #   p99 = 60 + 0.93 * 90 = 143.7; nominal 50: |d| sorted 0 0 0 0 0 10 10 100:
    #   jitter p99 = 10 + 0.93 * 90 = 93.7
    other = EpisodeData(goal=GOAL, odom=straight_run(10, 1.0),
                        control_wall=np.array([1.0, 1.05, 1.10]))
    s = summarize([m, evaluate_episode(other)],
                  intervals_ms=np.concatenate([cmd_intervals(data), cmd_intervals(other)]))
    assert s.cmd_interval_ms_p50 == pytest.approx(50.0)
    assert s.cmd_interval_ms_p99 == pytest.approx(143.7)
    assert s.cmd_jitter_ms_p99 == pytest.approx(93.7)
    assert "jitter (|interval - nominal|) p99 93.70 ms" in markdown_table(s, [m])


def test_split_episodes_carries_contact_kinds_and_control_records():
    goals = [(10.0, 1.0, 1.0), (20.0, 2.0, 2.0)]
    odom = [(t, t, 0.0, 0.0, 0.0) for t in (10.0, 15.0, 20.0, 25.0)]
    timing = [(11.0, 1.0, "control", {"reason": "follow", "monitor": "none", "wall": 100.0}),
              (11.5, 300.0, "sd", {"stage": "sd", "ms": 300.0}),
              (12.0, 2.0, "control", {"reason": "blocked", "monitor": "stop", "wall": 100.05}),
              (21.0, 1.5, "control"),  # an older 3-tuple: no record
              (22.0, 1.0, "control", {"reason": "follow", "wall": "not a number"})]
    contacts = [(9.0, "wall"),  # before the first goal: dropped
                (12.5, "static_obstacle"), (13.0, "static_obstacle"), (21.0, "moving_obstacle")]
    eps = split_episodes(goals, odom, timing=timing, contacts=contacts)
    assert eps[0].contact_kinds == ["static_obstacle", "static_obstacle"]
    assert eps[1].contact_kinds == ["moving_obstacle"]
    assert eps[0].timing_stages == ["control", "sd", "control"]
    assert eps[0].control_reasons == ["follow", "blocked"]
    assert eps[0].control_monitor == ["none", "stop"]
    assert eps[0].control_wall == pytest.approx([100.0, 100.05])
    # missing keys: reason "", monitor "none", wall NaN
    assert eps[1].control_reasons == ["", "follow"] and eps[1].control_monitor == ["none"] * 2
    assert np.isnan(eps[1].control_wall).all()
    ms = [evaluate_episode(ep, index=i) for i, ep in enumerate(eps)]
    assert (ms[0].monitor_stops, ms[0].blocked_ticks, ms[0].global_plans) == (1, 1, 1)
    assert ms[0].cmd_interval_ms_p50 == pytest.approx(50.0) and ms[1].cmd_interval_ms_p50 is None
    # episodes with a contact of each kind: static in episode 0, moving in episode 1, no wall
    s = summarize(ms)
    assert (s.wall_contact_episodes, s.static_contact_episodes,
            s.moving_contact_episodes) == (0, 1, 1)
    assert s.monitor_stops == pytest.approx(0.5) and s.global_plans == pytest.approx(0.5)
    table = markdown_table(s, ms)
    assert "wall / static-obstacle / moving-obstacle contact: 0 / 1 / 1 of 2" in table
    assert "| 0 | 0 / 2 / 0 | 1 / 0 / 0 | 1 | 1 | 0 |" in table
    # no collision_detail in the recording: kinds None; recorded but empty: no contacts
    assert split_episodes(goals, odom)[0].contact_kinds is None
    assert [ep.contact_kinds for ep in split_episodes(goals, odom, contacts=[])] == [[], []]
