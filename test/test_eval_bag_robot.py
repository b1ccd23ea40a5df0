"""``ecahd eval-bag`` on a real robot's bag (Nav2-style): topics under a namespace, the pose from
tf without odometry, goals from the global plans without goal_pose, contacts from the exact
checker without the simulator's flags. Each is the simulator's recording of the same run
(``test_eval_bag_no_rclpy.write_bag``) recorded another way, and must score as it does."""
import json
import logging

import numpy as np
import pytest

from ecahd_core.errors import BagError
from ecahd_core.evaluation import goals_from_plans
from ecahd_ros.cli import main
from ecahd_ros.eval_bag import evaluate_bag, write_outputs
from test_eval_bag_no_rclpy import copy_bag, write_bag


def _assert_same_metrics(got, want, tol: float = 1e-6) -> None:
    """Every episode's metrics equal, floats within ``tol``."""
    assert len(got.metrics) == len(want.metrics)
    for b, a in zip(got.metrics, want.metrics):
        a, b = a.to_dict(), b.to_dict()
        assert a.keys() == b.keys()
        for key in a:
            if isinstance(a[key], float):
                assert b[key] == pytest.approx(a[key], abs=tol), key
            else:
                assert b[key] == a[key], key


@pytest.mark.parametrize("global_tf", [False, True], ids=["own_tf", "global_tf"])
def test_a_namespaced_bag_scores_as_the_same_bag_without_namespace(tmp_path, global_tf):
    # odometry in odom: the namespace's tf (or the global one) places it in map
    write_bag(tmp_path / "root", odom_frame="odom")
    write_bag(tmp_path / "ns", odom_frame="odom", namespace="/robot1", global_tf=global_tf)
    want = evaluate_bag(tmp_path / "root")
    got = evaluate_bag(tmp_path / "ns")  # auto: no /odom at the root, one namespace has it
    assert got.sources.namespace == "/robot1" and want.sources.namespace == ""
    assert got.sources.topics["/tf"] == ("/tf" if global_tf else "/robot1/tf")
    _assert_same_metrics(got, want, tol=0.0)
    _assert_same_metrics(evaluate_bag(tmp_path / "ns", namespace="robot1/"), want, tol=0.0)


def test_several_namespaces_need_one_named_and_an_unknown_one_is_refused(tmp_path):
    write_bag(tmp_path / "root")
    write_bag(tmp_path / "two", namespace=("/robot1", "/robot2"))
    with pytest.raises(BagError, match=r"several namespaces \(/robot1, /robot2\).*--namespace"):
        evaluate_bag(tmp_path / "two")
    _assert_same_metrics(evaluate_bag(tmp_path / "two", namespace="/robot2"),
                         evaluate_bag(tmp_path / "root"), tol=0.0)
    with pytest.raises(BagError, match=r"no topic under namespace '/robot3' \(namespaces "
                                       r"in it: /robot1, /robot2\)"):
        evaluate_bag(tmp_path / "two", namespace="/robot3")


def test_without_odometry_the_pose_comes_from_tf_as_the_odometry_gave_it(tmp_path):
    """odom -> base_footprint at 50 Hz, base_footprint -> base_link static: base_link is
    sampled at base_footprint's stamps and matches the odometry bag of the run."""
    write_bag(tmp_path / "odom", odom_frame="odom")
    write_bag(tmp_path / "tf", poses="tf")
    want, got = evaluate_bag(tmp_path / "odom"), evaluate_bag(tmp_path / "tf")
    assert (want.sources.poses_from, got.sources.poses_from) == ("odom", "tf")
    for a, b in zip(want.episodes, got.episodes):
        assert b.odom.shape == a.odom.shape  # one pose per odom -> base_footprint stamp
        np.testing.assert_allclose(b.odom, a.odom, rtol=0, atol=1e-6)
    _assert_same_metrics(got, want)
    # another frame of the robot: base_scan is mounted 0.1 m ahead (the robot heads +x in map)
    scan = evaluate_bag(tmp_path / "tf", base_frame="base_scan")
    np.testing.assert_allclose(scan.episodes[0].odom[:, 1] - got.episodes[0].odom[:, 1], 0.1,
                               atol=1e-9)
    np.testing.assert_allclose(scan.episodes[0].odom[:, 2], got.episodes[0].odom[:, 2],
                               atol=1e-9)


def test_goals_come_from_the_plans_when_no_goal_pose_was_recorded(tmp_path, caplog):
    write_bag(tmp_path / "goal_pose")
    write_bag(tmp_path / "plan", goals="plan")  # a replan 0.03 m off and an empty plan too
    want = evaluate_bag(tmp_path / "goal_pose")
    with caplog.at_level(logging.INFO, logger="ecahd.eval_bag"):
        got = evaluate_bag(tmp_path / "plan")
    assert "goals from /plan (2)" in caplog.text
    assert got.sources.goals_from == "plan" and want.sources.goals_from == "goal_pose"
    assert [m.goal for m in got.metrics] == [(3.0, 1.0), (1.0, 1.0)]
    _assert_same_metrics(got, want, tol=0.0)


def test_goals_from_plans_start_a_goal_where_the_end_moves_more_than_5_cm():
    plans = [(0.0, [(0, 0), (1.0, 0.0)]),
             (1.0, [(0.5, 0), (1.04, 0.0)]),  # 0.04 m from the previous end: a replan
             (2.0, []),  # ignored
             (3.0, [(1.08, 0.0)]),  # 0.04 m from the previous end (0.08 from the goal): a replan
             (4.0, [(1.14, 0.0)]),  # 0.06 m from the previous end: a new goal
             (5.0, [(0, 0), (2.0, 1.0)])]
    np.testing.assert_allclose(goals_from_plans(plans),
                               [[0.0, 1.0, 0.0], [4.0, 1.14, 0.0], [5.0, 2.0, 1.0]])
    assert goals_from_plans([(0.0, [])]).shape == (0, 3)


def test_without_contact_flags_the_exact_checker_counts_the_contact_steps(tmp_path):
    # a wall across the map at x in [2.0, 2.1]; the 0.4 m circle at (x, 1.0) overlaps it for
    # 1.6 < x < 2.5, x = 0.55 + i / 50: i = 53..97, 45 odometry poses, all in episode 0
    # (goal 1 at 3.5 s: episode 0 holds i = 0..174, 175 poses; episode 1 i = 175..250, 76)
    write_bag(tmp_path / "wall", contacts=False, wall_x=2.0)
    result = evaluate_bag(tmp_path / "wall")
    assert result.sources.contacts_from == "exact_checker"
    ep0, ep1 = result.metrics
    assert (ep0.contact_steps, ep0.sim_steps) == (45, 175)
    assert ep0.collision_rate == pytest.approx(100 * 45 / 175)
    assert (ep1.contact_steps, ep1.sim_steps, ep1.collision_rate) == (0, 76, 0.0)
    assert ep0.contact_steps_wall is None  # no collision_detail: the kinds are not recorded
    # the same run along a free corridor: no contact
    write_bag(tmp_path / "free", contacts=False)
    free = evaluate_bag(tmp_path / "free")
    assert [m.contact_steps for m in free.metrics] == [0, 0]
    assert [m.sim_steps for m in free.metrics] == [175, 76]
    # the simulator's flags, when recorded, are the contacts (2 + 2 hand-set steps), as before
    write_bag(tmp_path / "sim", wall_x=2.0)
    sim = evaluate_bag(tmp_path / "sim")
    assert sim.sources.contacts_from == "simulator"
    assert [m.contact_steps for m in sim.metrics] == [2, 2]
    # the JSON and the table say where the contact figures came from
    table = write_outputs(result, tmp_path / "wall", json_path=tmp_path / "m.json",
                          md_path=tmp_path / "m.md")
    assert json.loads((tmp_path / "m.json").read_text())["contacts_from"] == "exact_checker"
    assert "contacts from the exact checker" in table
    assert "by the exact checker" in (tmp_path / "m.md").read_text()
    assert "contacts from the simulator's `/collision` flags" in write_outputs(sim, "sim")


def test_a_real_robots_bag_through_the_command(tmp_path):
    """Namespace with the global tf, no odometry, no goal_pose, no contact flags at once."""
    bag, out = tmp_path / "robot", tmp_path / "m.json"
    write_bag(bag, namespace="/robot1", global_tf=True, poses="tf", goals="plan",
              contacts=False, wall_x=2.0)
    assert main(["eval-bag", str(bag), "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert {k: result[k] for k in ("namespace", "poses_from", "goals_from", "contacts_from")} \
        == {"namespace": "/robot1", "poses_from": "tf", "goals_from": "plan",
            "contacts_from": "exact_checker"}
    assert [e["contact_steps"] for e in result["episodes"]] == [45, 0]
    assert result["episodes"][0]["first_reach"] == 20  # as the simulator's recording


def _no_pose_source(tmp_path):
    write_bag(tmp_path / "full", poses="tf")
    copy_bag(tmp_path / "full", tmp_path / "bag", drop={"/tf", "/tf_static"})
    return tmp_path / "bag", []


def _unknown_base_frame(tmp_path):
    write_bag(tmp_path / "bag", poses="tf")
    return tmp_path / "bag", ["--base-frame", "base_foot"]


def _no_goals(tmp_path):
    write_bag(tmp_path / "full")
    copy_bag(tmp_path / "full", tmp_path / "bag", drop={"/goal_pose"})
    return tmp_path / "bag", []


def _unknown_namespace(tmp_path):
    write_bag(tmp_path / "bag", namespace="/robot1")
    return tmp_path / "bag", ["--namespace", "robot2"]


@pytest.mark.parametrize("make, message", [
    (_no_pose_source, "has no /odom messages and no transforms on /tf / /tf_static: no pose "
                      "source"),
    (_unknown_base_frame, "has no frame 'base_foot' (frames: base_footprint, base_link, "
                          "base_scan, map, odom); pass --base-frame"),
    (_no_goals, "has no /goal_pose messages and no non-empty /plan to take goals from"),
    (_unknown_namespace, "has no topic under namespace '/robot2' (namespaces in it: /robot1)"),
], ids=["no_pose_source", "unknown_base_frame", "no_goals", "unknown_namespace"])
def test_what_a_bag_lacks_is_named_in_one_line_with_exit_code_2(tmp_path, capsys, make,
                                                                 message):
    bag, extra = make(tmp_path)
    assert main(["eval-bag", str(bag), *extra]) == 2
    errors = [line for line in capsys.readouterr().err.splitlines() if "error" in line]
    assert len(errors) == 1 and errors[0].startswith("ecahd eval-bag: error: bag ")
    assert message in errors[0]


def test_a_bag_without_the_map_at_the_root_names_its_namespaces(tmp_path):
    # /robot1 has odometry and goals but no map of its own: nothing to auto-detect
    write_bag(tmp_path / "full", namespace="/robot1")
    copy_bag(tmp_path / "full", tmp_path / "bag", drop={"/robot1/map"})
    with pytest.raises(BagError, match=r"has no /map messages \(namespaces in it: /robot1; "
                                       r"pass --namespace\)"):
        evaluate_bag(tmp_path / "bag")
    with pytest.raises(BagError, match="has no /robot1/map messages; cannot evaluate"):
        evaluate_bag(tmp_path / "bag", namespace="/robot1")
