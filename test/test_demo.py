"""``ecahd demo`` end to end, short: one near goal on maze2d-large (the shipped models' map),
recorded, then scored by ``ecahd eval-bag``."""
import argparse
import json

import pytest

from ecahd_ros import eval_bag
from ecahd_ros.bag_recorder import DEFAULT_TOPICS, read_bag
from ecahd_ros.demo import DemoConfig, run_demo

pytestmark = pytest.mark.slow  # the closed loop: node processes, a recorded bag

# (1.5, 1.5) -> (2.5, 1.5): 1 m along the bottom-left corridor of maze2d-large
START, GOAL = (1.5, 1.5), (2.5, 1.5)


def test_short_demo_records_every_topic_and_eval_bag_scores_it(tmp_path):
    result = run_demo(DemoConfig(out=tmp_path / "demo", episodes=1, goals=(GOAL,), start=START,
                                 max_steps=300, realtime_factor=1.0))
    bag = read_bag(result.bag)
    # every default topic is recorded; all but the event-only ones carry messages in a run
    # without obstacles (collision_detail: contact steps only; ecahd/replan: blocked only)
    events = {"collision_detail", "ecahd/replan"}
    for topic in DEFAULT_TOPICS:
        name = topic if topic.startswith("/") else "/" + topic
        assert name in bag, f"{name} was not recorded"
        if topic not in events:
            assert bag[name], f"no {name} messages in the bag"
    # one collision_detail record per contact step of the collision flags
    assert len(bag["/collision_detail"]) == sum(m.data for _, m in bag["/collision"])
    assert len(bag["/goal_pose"]) == 1
    for path in (result.json, result.md, result.png):
        assert path.is_file() and path.stat().st_size > 0
    episode = json.loads(result.json.read_text())["episodes"][0]
    assert episode["reached"] and episode["first_reach"] is not None
    assert 0 < episode["control_steps"] <= 300
    assert episode["inference_time_s"] > 0
    # goal -> first plan latency, per episode, in the result and metrics.json
    assert len(result.goal_to_plan_ms) == 1 and 0 < result.goal_to_plan_ms[0] < 10_000
    assert json.loads(result.json.read_text())["goal_to_plan_ms"] == list(result.goal_to_plan_ms)
    # every control tick was timed; the ticks are not inference time
    mean = json.loads(result.json.read_text())["mean"]
    assert 0 < mean["control_ms_p50"] <= mean["control_ms_p99"]
    assert episode["control_ticks"] > 0 and "control" not in episode["stage_ms"]
    assert episode["inference_time_s"] == pytest.approx(sum(episode["stage_ms"].values()) / 1000)
    assert "p99" in result.md.read_text()

    # the command on the same bag writes the same keys
    parser = argparse.ArgumentParser()
    eval_bag.add_arguments(parser)
    out = tmp_path / "again.json"
    assert eval_bag.run(parser.parse_args([str(result.bag), "--json", str(out)])) == 0
    data = json.loads(out.read_text())
    for key in ("episode_reward", "first_reach", "collision_rate", "inference_time_s",
                "reached"):
        assert key in data["mean"] and key in data["episodes"][0]
    assert data["episodes"][0]["episode_reward"] == episode["episode_reward"]


def test_first_episode_reruns_one_episode_of_a_seeded_run_alone(tmp_path):
    """Episode i alone: the goals and obstacles it had in the full run, starting at goal i-1."""
    from ecahd_ros.demo import _goals, _scenarios

    full = DemoConfig(out=tmp_path / "full", episodes=4, seed=2, obstacles=1, moving=1)
    alone = DemoConfig(out=tmp_path / "alone", episodes=1, seed=2, obstacles=1, moving=1,
                       first_episode=3)
    start_full, goals_full = _goals(full)
    start, goals = _goals(alone)
    assert len(goals) == 1 and goals[0].tolist() == goals_full[3].tolist()
    assert start.tolist() == goals_full[2].tolist() != start_full.tolist()
    files_full = _scenarios(full, start_full, goals_full)
    files = _scenarios(alone, start, goals)
    assert files[0].read_text() == files_full[3].read_text()
    with pytest.raises(Exception, match="first_episode"):
        DemoConfig(out=tmp_path / "x", first_episode=-1)


@pytest.mark.parametrize("factor, clock", [(1.0, "steady"), (4.0, "ros")])
def test_refiner_control_timer_on_the_steady_clock_only_at_real_time(tmp_path, factor, clock):
    from ecahd_ros.demo import _node_parameters

    config = DemoConfig(out=tmp_path, realtime_factor=factor)
    assert _node_parameters(config, START)["local_refiner"]["control_clock"] == clock
    override = DemoConfig(out=tmp_path, realtime_factor=factor,
                          refiner_params={"control_clock": "ros"})
    assert _node_parameters(override, START)["local_refiner"]["control_clock"] == "ros"


def test_node_parameters_from_the_command_line_reach_the_nodes(tmp_path):
    import argparse

    from ecahd_core.errors import EcahdError
    from ecahd_ros.demo import _node_parameters, add_arguments, parse_params

    p = argparse.ArgumentParser()
    add_arguments(p)
    args = p.parse_args(["--planner-param", "warm_fraction=0", "--planner-param",
                         "settle=false", "--refiner-param", "lanes=/x/lanes.npz"])
    planner = parse_params(args.planner_param, "--planner-param")
    assert planner == {"warm_fraction": 0, "settle": False}
    assert parse_params(args.refiner_param, "--refiner-param") == {"lanes": "/x/lanes.npz"}
    params = _node_parameters(DemoConfig(out=tmp_path, planner_params=planner), START)
    assert params["global_planner"]["warm_fraction"] == 0
    assert params["global_planner"]["settle"] is False
    for bad in ("warm_fraction", "=0"):
        with pytest.raises(EcahdError, match="--planner-param.*NAME=VALUE"):
            parse_params([bad], "--planner-param")
